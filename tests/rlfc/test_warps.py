"""Per-view warps (``tx`` version 5, ``--warps``): a rig whose cameras are not exactly rectified
(each view shifted, rotated or scaled a little) predicted through stored warps. The integer
offsets follow the warps' composition; a warped file decodes bit for bit on every path (whole
light field, views, batched and single blocks, torch) to the encoder's closed loop, its
predictions are closer to the captured views than without the warps; the layout refuses bad
warps; the command line writes and describes them."""
from __future__ import annotations

import json
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from formats.codec_api import EncodeOptions
from formats.errors import FormatError
from formats.rectify import warp_matrix
from formats.scenes import read_scene
from rlfc import encode
from rlfc.txlayout import WARP_VERSION, TxLayout
from rlfc.txwarp import AB_MAX, C_MAX, max_row_offset, offsets, pair_params, view_offsets, warp_params

from .helpers import check_agreement, make_lf, open_encoded

ROOT = Path(__file__).resolve().parents[2]


def test_offsets_follow_the_composition_of_the_warps():
    """At every 8×8 block's centre of a 384×512 view, the stored offset (1/16 px) is within one
    sixteenth of the exact M_r M_v⁻¹ x − x (plus the parameters' rounding: < 0.2 sixteenths)."""
    h, w = 384, 512
    warps = np.array([[0.004, -0.003, 0.6, -0.4], [-0.005, 0.004, -0.9, 0.7]])     # θ, s, tx, ty
    p = warp_params(warps, h, w)
    dw = pair_params(p, np.array([[1, -1, -1, -1], [-1, -1, -1, -1]]))
    oy, ox = view_offsets(dw[0], h // 8, w // 8)
    full = [np.vstack([warp_matrix(x, h, w), [0, 0, 1]]) for x in warps]
    T = full[1] @ np.linalg.inv(full[0])
    yc, xc = np.mgrid[0:h // 8, 0:w // 8] * 8 + 3.5
    ex = T[0, 0] * xc + T[0, 1] * yc + T[0, 2] - xc
    ey = T[1, 0] * xc + T[1, 1] * yc + T[1, 2] - yc
    assert np.abs(ox[0] - 16 * ex).max() <= 1.0 and np.abs(oy[0] - 16 * ey).max() <= 1.0
    assert np.abs(ox[0]).max() > 16                         # (offsets of more than a pixel)
    assert (ox[1:] == 0).all() and (oy[1:] == 0).all()      # empty reference slots: no offset


@settings(max_examples=60, deadline=None)
@given(st.lists(st.tuples(st.integers(-AB_MAX, AB_MAX), st.integers(-AB_MAX, AB_MAX),
                          st.integers(-C_MAX, C_MAX), st.integers(-C_MAX, C_MAX)), min_size=2, max_size=5),
       st.integers(1, 40), st.integers(1, 40))
def test_row_reach_bounds_every_block(params, n8y, n8x):
    """:func:`max_row_offset` (the decoder's key-row reach) is at least every block's vertical
    offset, in whole pixels; the offsets are the same computed per block or per view."""
    warp = np.array(params, np.int64)
    n = len(warp)
    refs = np.full((n, 4), -1)
    refs[:, 0] = (np.arange(n) + 1) % n
    dw = pair_params(warp, refs)
    reach = max_row_offset(dw, 8 * n8y, 8 * n8x)
    for v in range(n):
        oy, ox = view_offsets(dw[v], n8y, n8x)
        assert -(-np.abs(oy).max() // 16) <= reach[v]
        ty, tx = np.divmod(np.arange(n8y * n8x), n8x)
        by, bx = offsets(np.broadcast_to(dw[v], (ty.size, 4, 4)), ty, tx)
        assert (by.T.reshape(oy.shape) == oy).all() and (bx.T.reshape(ox.shape) == ox).all()


def _shifted_crop(seed=5):
    """The bundled Lytro crop (9×9 views of 128×160) with each view shifted by its own offset
    within ±0.7 px, and rotated by its own angle within ±0.3° (a rig that is not rectified)."""
    import cv2

    v = read_scene(ROOT / "samples" / "dino_crop").views
    rng = np.random.default_rng(seed)
    out = np.empty_like(v)
    h, w = v.shape[2:4]
    for i in range(v.shape[0]):
        for j in range(v.shape[1]):
            m = cv2.getRotationMatrix2D((w / 2 - 0.5, h / 2 - 0.5), rng.uniform(-0.3, 0.3), 1.0)
            m[:, 2] += rng.uniform(-0.7, 0.7, 2)
            out[i, j] = cv2.warpAffine(v[i, j], m, (w, h), flags=cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)
    return make_lf(out)


@pytest.fixture(scope="module")
def warped():
    lf = _shifted_crop()
    e = encode(lf, EncodeOptions(profile="tx", target_psnr=42.0, keep_decoded=True, params={"warps": True}))
    plain = encode(lf, EncodeOptions(profile="tx", target_psnr=42.0, keep_decoded=True))
    return lf, e, plain


def _psnr(a, b):
    return 10 * np.log10(255.0 ** 2 / np.mean((a.astype(np.float64) - b) ** 2))


def test_warped_file_decodes_on_every_path_and_costs_less(warped):
    lf, e, plain = warped
    assert e.config["tx"]["version"] == WARP_VERSION and plain.config["tx"]["version"] < WARP_VERSION
    rep = e.summary["warps"]
    assert rep["applied"] and rep["largest_correction_px"] >= 0.5 and rep["error_drop"] >= 0.15
    assert e.config["params"]["warps"] is True and "warps" not in plain.config["params"]
    d, blob = open_encoded(lf, e)
    assert d.core.info()["warped_views"] == 81 and "per-view warps" in d.info()["summary"]
    assert (d.decode_all() == e.decoded).all()                           # the encoder's closed loop
    check_agreement(d, lf.views.shape)          # whole light field, views, single and batched blocks, levels
    # the predictions (level 1) are closer to the captured views with the warps, and the file is
    # smaller at the same target (measured: 4 919 against 10 471 bytes at 42 dB; 38 dB: +8%, the
    # warps' 8 bytes a view against a 3 KB file; 45 dB: 0.27x)
    dp, plain_blob = open_encoded(lf, plain)
    pw, pp = d.decode_all(1), dp.decode_all(1)
    pred = ~d.core.lay.intra.reshape(9, 9)
    assert _psnr(pw[pred], lf.views[pred]) > _psnr(pp[pred], lf.views[pred]) + 0.2     # (measured +0.47 dB)
    assert len(blob) < 0.7 * len(plain_blob), (len(blob), len(plain_blob))
    assert e.summary["psnr_rgb"] >= 42.0


def test_torch_applies_the_warps(warped):
    pytest.importorskip("torch")
    from rlfc.torch_decode import TorchBlockDecoder

    lf, e, _ = warped
    d, _ = open_encoded(lf, e)
    rng = np.random.default_rng(4)
    n = 600
    v, by, bx = rng.integers(0, 81, n), rng.integers(0, d.nby, n), rng.integers(0, d.nbx, n)
    for level in (0, 1):
        assert (TorchBlockDecoder(d, "cpu").decode_blocks(v, by, bx, level) == d.decode_blocks(v, by, bx, level)).all()


def test_layout_refuses_bad_warps(warped):
    lf, e, _ = warped
    d, _ = open_encoded(lf, e)
    lay = d.core.lay
    for col, big in ((0, AB_MAX + 1), (1, -AB_MAX - 1), (2, C_MAX + 1), (3, -C_MAX - 1)):
        wp = lay.warp.copy()
        wp[3, col] = big
        with pytest.raises(FormatError, match="warp"):
            replace(lay, warp=wp).check("t")
    with pytest.raises(FormatError, match="version"):
        replace(lay, warp=None).check("t")
    with pytest.raises(FormatError, match="version"):
        replace(lay, version=4).check("t")
    # the bytes round trip, and a version 4 header over version 5 tables is refused (its count)
    from formats.schema import Fields

    cfg = lay.to_config()
    again = TxLayout.read(Fields(cfg, "t"), lay.to_bytes(), lay.n_views, lay.step16.shape[1], "t")
    assert (again.warp == lay.warp).all() and (again.wp == lay.wp).all()
    with pytest.raises(FormatError):
        TxLayout.read(Fields(cfg | {"version": 4}, "t"), lay.to_bytes(), lay.n_views, lay.step16.shape[1], "t")


def test_command_line_flag(tmp_path, capsys, monkeypatch):
    import rlfc.txencode as te
    from formats import open_decoder, open_lfc
    from formats.cli import main
    from formats.scenes import write_views

    out = tmp_path / "rectified.lfc"             # the bundled crop: corrections below 0.5 px, nothing stored
    assert main(["encode", str(ROOT / "samples" / "dino_crop"), str(out), "--target-psnr", "38", "--warps", "--json",
                 "--quiet"]) == 0
    rep = json.loads(capsys.readouterr().out)
    assert rep["warps"]["applied"] is False and rep["warps"]["largest_correction_px"] < 0.5
    assert open_decoder(open_lfc(out)).core.lay.version < WARP_VERSION
    assert any("--warps" in n for n in rep["notes"])
    scene = tmp_path / "rig"
    write_views(scene, _shifted_crop().views)
    out = tmp_path / "w.lfc"
    assert main(["encode", str(scene), str(out), "--grid", "9x9", "--target-psnr", "38", "--warps", "--json",
                 "--quiet"]) == 0
    rep = json.loads(capsys.readouterr().out)
    assert rep["warps"]["applied"] and rep["warps"]["warp_bytes"] > 0 and rep["psnr_rgb"] >= 38.0
    assert main(["info", str(out), "--verify"]) == 0
    assert "81 views predicted through per-view warps" in capsys.readouterr().out
    # warps that would take too little of the prediction error away are not stored (the maps are
    # estimated again without them)
    monkeypatch.setattr(te, "WARP_MIN_ERROR_DROP", 1.01)
    out = tmp_path / "n.lfc"
    assert main(["encode", str(scene), str(out), "--grid", "9x9", "--target-psnr", "38", "--warps", "--json",
                 "--quiet"]) == 0
    rep = json.loads(capsys.readouterr().out)
    assert rep["warps"]["applied"] is False and 0.15 < rep["warps"]["error_drop"] < 1.01
    assert open_decoder(open_lfc(out)).core.lay.version < WARP_VERSION
    assert any("of the prediction error away" in n for n in rep["notes"])
    assert main(["encode", str(scene), str(tmp_path / "d.lfc"), "--grid", "9x9", "--profile", "dcp", "--warps",
                 "--quiet"]) == 2
    assert "--warps not used by profile 'dcp'" in capsys.readouterr().err


def test_renderer_moves_each_source_by_its_warp(warped):
    """Novel views of a warped file: a captured view is its own pixels; the blocks the renderer
    decodes cover the warped positions (the same frame as with every block decoded); numpy and
    torch agree; the warps change the frames between views."""
    lf, e, _ = warped
    d, _ = open_encoded(lf, e)
    full = d.decode_all()
    r = d.renderer()
    assert (r.render(4.0, 3.0) == full[4, 3]).all()
    everything = d.renderer()
    everything._needs_from_maps = lambda offs, *a, **k: np.ones((len(offs), d.nby, d.nbx), bool)
    plain = d.renderer()
    plain._warp = None
    for s, t, focus, ap in ((3.5, 4.25, None, 0.0), (0.3, 7.6, None, 0.0), (4.5, 4.5, 0.4, 1.5)):
        got = r.render(s, t, focus, ap)
        assert (got == everything.render(s, t, focus, ap)).all()
        assert np.abs(got.astype(int) - plain.render(s, t, focus, ap)).mean() > 0.1      # (a smooth crop: 0.2-0.5)
    pytest.importorskip("torch")
    tr = d.renderer(device="cpu")
    a, b = r.render(3.5, 4.25), tr.render(3.5, 4.25)
    assert np.abs(a.astype(int) - b).max() <= 1


@pytest.mark.parametrize("which", ["warped", "plain"])
def test_key_rows_in_raster_bands_are_the_block_paths(warped, which, monkeypatch):
    """Rows of predicted key views decoded in raster bands (runs of rows, not whole views: rows
    0, 2, 3 and the last first, then the rest) are the block-by-block path's integers, with and
    without warps (the crop's files have single-reference modes and weighted views too)."""
    import rlfc.profiles.tx_lazy as tl

    lf, e, plain = warped
    enc = e if which == "warped" else plain
    got = []
    for least in (1, 10 ** 9):                                        # raster bands always, never
        monkeypatch.setattr(tl, "KEY_ROWS_RASTER_MIN", least)
        d, _ = open_encoded(lf, enc)
        core = d.core
        assert (~core.lay.intra[np.asarray(core.lay.keys)]).sum() >= 1      # (keys with references)
        need = np.zeros(core._key_done.shape, bool)
        need[:, [0, 2, 3, -1]] = True
        core._have_keys(need)
        done = core._key_done.copy()
        part = core.keyplanes.reshape(done.shape[0], done.shape[1], -1)[done].copy()
        d.decode_keys()
        got.append((done, part, core.keyplanes.copy()))
    (d1, p1, k1), (d2, p2, k2) = got
    assert (d1 == d2).all() and (p1 == p2).all() and (k1 == k2).all()
