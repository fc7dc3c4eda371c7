"""Rectifying a grid whose views are rotated, scaled or shifted (``formats.rectify``, ``lfcodec
encode --rectify``): the warps come back from the views alone, undoing them restores the
rectified grid, a rectified grid is left as it is, and a posed capture is refused."""
import json

import cv2
import numpy as np
import pytest

from formats.cli import main
from formats.errors import ParameterError
from formats.lfcfile import open_lfc
from formats.lightfield import LightField, grid_positions
from formats.rectify import estimate_warps, largest_correction, rectify_grid, rectify_views, warp_matrix

H, W = 120, 160


def _texture(seed: int = 0) -> np.ndarray:
    rng = np.random.default_rng(seed)
    t = cv2.GaussianBlur(rng.random((H + 40, W + 60, 3)).astype(np.float32), (0, 0), 1.6)
    return (t - t.min()) / np.ptp(t) * 200 + 25


def _grid(rows: int, cols: int, warps=None, dtype=np.uint8) -> np.ndarray:
    """A textured plane seen by a rows × cols grid (1.5 px of parallax per view step), each view
    warped by its warp (θ, s, tx, ty) where given: captured(x) = rectified(M⁻¹ x)."""
    tex, peak = _texture(), np.iinfo(dtype).max
    out = np.empty((rows, cols, H, W, 3), dtype)
    for i in range(rows):
        for j in range(cols):
            m = np.float32([[1, 0, 1.5 * j + 20], [0, 1, 1.5 * i + 20]])
            v = cv2.warpAffine(tex, m, (W, H), flags=cv2.INTER_CUBIC | cv2.WARP_INVERSE_MAP)
            if warps is not None:
                v = cv2.warpAffine(v, warp_matrix(warps[i * cols + j], H, W), (W, H), flags=cv2.INTER_CUBIC,
                                   borderMode=cv2.BORDER_REPLICATE)
            out[i, j] = np.clip(np.rint(v * (peak / 255.0)), 0, peak).astype(dtype)
    return out


def _warps(rows: int, cols: int, seed: int = 1) -> np.ndarray:
    """Random warps (θ up to 0.8°, s up to 0.8%, shifts up to 0.8 px) whose vertical shifts sum to
    0 along each row and horizontal ones along each column: a shift shared by a row of views
    (vertical) or a column (horizontal) is where those cameras stand, which the views cannot
    tell from parallax (``estimate_warps`` leaves it 0)."""
    rng = np.random.default_rng(seed)
    n = rows * cols
    w = np.stack([np.radians(rng.uniform(-0.8, 0.8, n)), rng.uniform(-0.008, 0.008, n),
                  rng.uniform(-0.8, 0.8, n), rng.uniform(-0.8, 0.8, n)], 1)
    w = w - w.mean(0)
    g = w.reshape(rows, cols, 4)
    g[..., 2] -= g[..., 2].mean(0, keepdims=True)
    g[..., 3] -= g[..., 3].mean(1, keepdims=True)
    return g.reshape(n, 4)


@pytest.mark.parametrize("dtype", [np.uint8, np.uint16])
def test_warps_come_back_from_the_views_and_undoing_them_restores_the_grid(dtype):
    truth = _warps(3, 4)
    views = _grid(3, 4, truth, dtype)
    got = estimate_warps(views)
    assert got.shape == (12, 4) and np.allclose(got.mean(0), 0, atol=1e-9)
    assert np.abs(np.degrees(got[:, 0] - truth[:, 0])).max() < 0.05            # degrees
    assert np.abs(got[:, 1] - truth[:, 1]).max() < 0.001
    assert np.abs(got[:, 2:] - truth[:, 2:]).max() < 0.1                        # px
    assert largest_correction(got, H, W) > 1.0
    clean, fixed = _grid(3, 4, None, dtype), rectify_views(views, got)
    assert fixed.dtype == views.dtype and fixed.shape == views.shape
    peak, m = float(np.iinfo(dtype).max), 16
    err = lambda a: np.sqrt(np.mean((a[:, :, m:-m, m:-m].astype(float) - clean[:, :, m:-m, m:-m]) ** 2)) / peak
    assert err(fixed) < 0.25 * err(views) and err(fixed) < 0.01


def test_a_rectified_grid_is_left_as_it_is_and_a_posed_capture_is_refused():
    views = _grid(2, 3)
    lf = LightField(views=views, positions=grid_positions(2, 3), layout="grid")
    same, rep = rectify_grid(lf)
    assert same is lf and rep["applied"] is False and rep["largest_correction_px"] < 0.5
    posed = LightField(views=views.reshape(1, 6, H, W, 3), positions=np.zeros((1, 6, 3)), layout="posed")
    with pytest.raises(ParameterError, match="grid"):
        rectify_grid(posed)
    warped, rep = rectify_grid(LightField(views=_grid(2, 3, _warps(2, 3, 3)), positions=grid_positions(2, 3),
                                     layout="grid"))
    assert rep["applied"] is True and len(rep["warps"]) == 6 and warped.meta["rectified"]["largest_correction_px"] > 1


def test_one_row_of_views(monkeypatch):
    """A 1-row grid: rotations, scales and vertical shifts come back; horizontal shifts are 0."""
    truth = _warps(1, 4, 5)
    got = estimate_warps(_grid(1, 4, truth))
    assert np.abs(np.degrees(got[:, 0] - truth[:, 0])).max() < 0.05 and np.abs(got[:, 3] - truth[:, 3]).max() < 0.1
    assert np.allclose(got[:, 2], 0, atol=1e-9)


def test_encode_rectify_from_the_command_line(tmp_path, capsys):
    np.save(tmp_path / "rig.npy", _grid(3, 3, _warps(3, 3, 7)).reshape(9, H, W, 3))
    out = tmp_path / "rig.lfc"
    assert main(["encode", str(tmp_path / "rig.npy"), str(out), "--grid", "3x3", "--rectify", "--target-psnr", "36",
                 "--json", "--quiet"]) == 0
    rep = json.loads(capsys.readouterr().out)
    assert rep["rectify"]["applied"] is True and rep["rectify"]["largest_correction_px"] > 1
    assert any(n.startswith("--rectify: the views were resampled") for n in rep["notes"])
    assert rep["psnr_rgb"] >= 36 and rep["target_met"] is True
    with open_lfc(out) as f:                                          # the file says what was done
        assert f.meta["source"]["rectified"]["largest_correction_px"] == rep["rectify"]["largest_correction_px"]
    assert main(["info", str(out), "--json"]) == 0                    # ... and info says it
    assert json.loads(capsys.readouterr().out)["rectified"]["largest_correction_px"] == \
        rep["rectify"]["largest_correction_px"]
    assert main(["info", str(out)]) == 0
    assert "rectified when encoded (--rectify)" in capsys.readouterr().out
    np.save(tmp_path / "flat.npy", _grid(3, 3).reshape(9, H, W, 3))
    assert main(["encode", str(tmp_path / "flat.npy"), str(tmp_path / "flat.lfc"), "--grid", "3x3", "--rectify",
                 "--quant", "8", "--json", "--quiet"]) == 0
    rep = json.loads(capsys.readouterr().out)
    assert rep["rectify"]["applied"] is False and any("rectified already" in n for n in rep["notes"])
    with open_lfc(tmp_path / "flat.lfc") as f:
        assert "rectified" not in f.meta["source"]
    assert main(["info", str(tmp_path / "flat.lfc"), "--json"]) == 0
    assert "rectified" not in json.loads(capsys.readouterr().out)
