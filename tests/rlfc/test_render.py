"""Novel views (issue 16): disparity-compensated interpolation from the compressed file, checked
by leaving views out — a synthetic grid with known parallax encoded with every second view, the
missing views rendered and compared with the true ones, against the nearest view and plain
blending; exact at captured positions; refocus, quilts, the CLI and typed errors."""
import numpy as np
import pytest

from formats.cli import main
from formats.errors import ParameterError
from formats.metrics import psnr_rgb
from rlfc import encode
from tests.rlfc.helpers import make_lf, open_encoded


@pytest.fixture(scope="module")
def leave_out():
    rng = np.random.default_rng(0)
    base = rng.random((80, 120, 3))
    k = np.ones(3) / 3
    for ax in (0, 1):
        base = np.apply_along_axis(lambda m: np.convolve(m, k, mode="same"), ax, base)
    base = (base - base.min()) / np.ptp(base)
    full = np.zeros((5, 5, 40, 48, 3), np.uint8)           # 2 px of parallax per view step
    for r in range(5):
        for c in range(5):
            full[r, c] = np.rint(base[2 * r + 10:2 * r + 50, 2 * c + 20:2 * c + 68] * 255)
    lf = make_lf(np.ascontiguousarray(full[::2, ::2]))     # every second view is encoded
    d, blob = open_encoded(lf, encode(lf, profile="tx", step=2.0))
    return full, d, blob


def test_rendered_missing_views_beat_nearest_and_blending(leave_out):
    full, d, _ = leave_out
    ren = d.renderer()
    for (s, t), (r, c) in (((0.5, 0.5), (1, 1)), ((0, 0.5), (0, 1)), ((1.5, 1), (3, 2))):
        img = ren.render(s, t)
        near = d.decode_view(int(round(s)), int(round(t)))
        blend = ((d.decode_view(int(np.floor(s)), int(np.floor(t))).astype(float)
                  + d.decode_view(int(np.ceil(s)), int(np.ceil(t)))) / 2).astype(np.uint8)
        p = psnr_rgb(full[r, c], img)
        assert p > 30 and p > psnr_rgb(full[r, c], near) + 8 and p > psnr_rgb(full[r, c], blend) + 8


def test_captured_positions_are_the_decoded_views_and_blocks_are_cached(leave_out):
    _, d, _ = leave_out
    ren = d.renderer(cache_mib=64)
    assert (ren.render(1, 2) == d.decode_view(1, 2)).all()
    ren.render(0.5, 0.5)
    decoded = ren.blocks_decoded
    ren.render(0.5, 0.5)                               # a warm cache decodes nothing again
    assert ren.blocks_decoded == decoded and ren.blocks_requested > decoded


def test_refocus_quilt_and_bad_cameras(leave_out):
    _, d, _ = leave_out
    ren = d.renderer()
    sharp = ren.render(1, 1, focus=4.0, aperture=1.5)        # focused at the scene's disparity
    blurred = ren.render(1, 1, focus=-4.0, aperture=1.5)
    ref = d.decode_view(1, 1).astype(float)
    assert psnr_rgb(ref, sharp) > psnr_rgb(ref, blurred) + 3
    q = ren.quilt(3, 2)
    assert q.shape == (2 * d.height, 3 * d.width, 3)
    for bad in ((5.0, 0.0), (0.0, -2.0), (float("nan"), 1.0)):
        with pytest.raises(ParameterError):
            ren.render(*bad)


def test_render_cli(leave_out, tmp_path, capsys):
    from formats.imageio import read_image

    _, d, blob = leave_out
    f = tmp_path / "g.lfc"
    f.write_bytes(blob)
    assert main(["render", str(f), str(tmp_path / "v.png"), "--at", "0.5,1.5", "--quiet"]) == 0
    assert (read_image(tmp_path / "v.png") == d.renderer().render(0.5, 1.5)).all()
    assert main(["render", str(f), str(tmp_path / "q.png"), "--quilt", "4x2", "--quiet"]) == 0
    assert read_image(tmp_path / "q.png").shape == (2 * d.height, 4 * d.width, 3)
    assert main(["render", str(f), str(tmp_path / "v.png"), "--at", "9,9", "--quiet"]) == 2
    assert main(["render", str(f), str(tmp_path / "v.png"), "--at", "1", "--quiet"]) == 2
    assert main(["render", str(f), str(tmp_path / "v.jpg"), "--quiet"]) == 2
    assert "outside the grid" in capsys.readouterr().err
