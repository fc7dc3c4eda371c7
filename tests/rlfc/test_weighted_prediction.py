"""Weighted prediction (``tx`` version 4): a gain and an offset per view and plane applied to
the blended prediction. Views exposed differently (a camera array whose cameras set their own
exposure) decode bit for bit on every path — whole light field, whole view, batched blocks,
single blocks (the lean pixel path), every level, torch — at a fraction of the bytes; the
layout's rules refuse bad parameters."""
from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from formats.codec_api import EncodeOptions
from formats.errors import FormatError
from formats.scenes import read_scene
from rlfc import encode
from rlfc.txlayout import WP_VERSION
from rlfc.txpredict import fit_price, fit_weights, priced_weights, weigh

from .helpers import check_agreement, make_lf, open_encoded

ROOT = Path(__file__).resolve().parents[2]


def _exposed(spread=0.12, seed=5):
    """The bundled Lytro crop (9×9 views of 128×160) with a gain per view in [1 − spread, 1 + spread]."""
    v = read_scene(ROOT / "samples" / "dino_crop").views
    g = np.random.default_rng(seed).uniform(1 - spread, 1 + spread, v.shape[:2] + (1, 1, 1))
    return make_lf(np.clip(np.rint(v * g), 0, 255).astype(np.uint8))


@pytest.fixture(scope="module")
def exposed():
    lf = _exposed()
    e = encode(lf, EncodeOptions(profile="tx", target_psnr=40.0, keep_decoded=True))    # (on by default)
    plain = encode(lf, EncodeOptions(profile="tx", target_psnr=40.0, params={"weighted": False}))
    return lf, e, plain


def test_exposed_views_decode_on_every_path_and_cost_less(exposed):
    lf, e, plain = exposed
    assert e.config["tx"]["version"] == WP_VERSION and plain.config["tx"]["version"] < WP_VERSION
    assert "weighted" not in e.config["params"] and plain.config["params"]["weighted"] is False
    d, blob = open_encoded(lf, e)
    assert d.core._weighted.sum() >= 0.7 * (~d.core.lay.intra).sum()
    assert e.summary["views_weighted"] == int(d.core._weighted.sum()) and plain.summary["views_weighted"] == 0     # most predicted views weighted (60 of 80)
    assert (d.decode_all() == e.decoded).all()                           # the encoder's closed loop
    check_agreement(d, lf.views.shape)          # whole light field, views, single and batched blocks, levels
    _, plain_blob = open_encoded(lf, plain)
    assert len(blob) < 0.5 * len(plain_blob), (len(blob), len(plain_blob))      # 4 127 against 10 319 bytes
    assert e.summary["psnr_rgb"] >= 40.0


def test_lean_single_blocks_and_torch_apply_the_weights(exposed):
    torch = pytest.importorskip("torch")
    from rlfc.profiles.tx_torch import TorchTx

    lf, e, _ = exposed
    d, _ = open_encoded(lf, e)
    full = d.decode_all().reshape((-1,) + lf.views.shape[2:])
    B, core = d.block_size, d.core
    w = np.flatnonzero(core._weighted & ~core.is_key & ~core.coded.all(axis=1))
    hits = 0
    for v in w[:6].tolist():
        for loc in np.flatnonzero(~core.coded[v])[:8].tolist():      # predicted blocks: the lean pixel path
            by, bx = divmod(loc, d.nbx)
            assert core.block_pixels(v, by, bx, 0) is not None
            got = d.decode_block(v // d.cols, v % d.cols, by, bx)
            assert (got == full[v, by * B:(by + 1) * B, bx * B:(bx + 1) * B]).all()
            hits += 1
    assert hits >= 20
    torch.set_num_threads(1)
    views = np.arange(d.rows * d.cols)
    by = np.arange(views.size) % d.nby
    bx = (views * 3) % d.nbx
    got = TorchTx(core, "cpu").blocks(views, by, bx, 0).cpu().numpy()
    assert (got == core.blocks(views, by, bx, 0)).all()


def test_weigh_is_the_integer_rule():
    rng = np.random.default_rng(0)
    p = rng.integers(-255, 256, (5, 8, 8, 3)).astype(np.int32)
    g, o = np.array([32, 64, 96]), np.array([-7, 0, 300])
    lo, hi = np.array([0, -255, -255]), np.array([255, 255, 255])
    want = np.clip(((p.astype(np.int64) * g + 32) >> 6) + o, lo, hi)
    assert (weigh(p.copy(), g, o, lo, hi) == want).all()
    gm, om = rng.integers(32, 97, (5, 3)), rng.integers(-40, 41, (5, 3))   # per 8×8 block (one view each)
    want = np.clip(((p.astype(np.int64) * gm[:, None, None] + 32) >> 6) + om[:, None, None], lo, hi)
    assert (weigh(p.copy(), gm, om, lo, hi) == want).all()
    q = rng.integers(0, 256, (16, 24, 3)).astype(np.int32)             # a whole (tiny) view
    assert (weigh(q.copy(), [64] * 3, [0] * 3, [0] * 3, [255] * 3) == q).all()      # the identity
    # a fit recovers a known gain and offset
    x = rng.integers(0, 200, (4000, 1)).astype(np.int32)               # (a fit takes any (…, P))
    y = np.clip(np.rint(x * 1.25 + 9), 0, 255).astype(np.int32)
    gq, oq = fit_weights(x, y, np.array([0]), np.array([255]))[0]
    assert gq == 80 and abs(oq - 9) <= 1


def _tbs(rng, T=400, P=3):
    """T smooth-ish 8×8 blocks of P planes (int32 (T, 8, 8, P)), values in 40..215."""
    base = rng.integers(40, 216, (T, 1, 1, P))
    return (base + rng.integers(-8, 9, (T, 8, 8, P))).astype(np.int32)


def test_fits_are_priced_by_what_they_save():
    """A fit is kept where it lowers the view's estimated rate-distortion cost by more than its
    parameters' bits: a view exposed 10% darker keeps it; a view predicted exactly except in a few
    blocks coded either way (an occluder) refuses the least-squares shrink that would take error
    from those blocks and add it to every skipped one; a tiny gain is not worth its bytes."""
    rng = np.random.default_rng(3)
    lo, hi, w, lam = np.zeros(3, np.int64), np.full(3, 255), np.array([0.6, 0.2, 0.2]), 40.0
    orig = _tbs(rng)
    price = fit_price(lam, w, orig.shape[0] * 64)
    dark = np.rint(orig * 0.9).astype(np.int32)                         # exposure
    wp = fit_weights(dark, orig, lo, hi, price)
    assert (wp[:, 0] != 64).all()
    kept, pred = priced_weights(dark.copy(), orig, wp, w, lam, lo, hi)
    assert kept is not None and (kept == wp).all()
    assert ((pred - orig) ** 2).sum() < 0.1 * ((dark - orig) ** 2).sum()
    occluded = orig.copy()                                               # exact but for 40 blocks
    occluded[:40] = rng.integers(0, 256, (40, 8, 8, 3))
    wp = fit_weights(occluded, orig, lo, hi, price)
    assert (wp[:, 0] != 64).any()                                       # least squares shrinks the gain
    kept, pred = priced_weights(occluded.copy(), orig, wp, w, lam, lo, hi)
    assert kept is None and (pred == occluded).all()                    # and the price refuses it
    slight = np.clip(orig + 1, 0, 255).astype(np.int32)                  # one level: not worth 30 bits at a high λ
    assert (fit_weights(slight, orig, lo, hi, fit_price(1e4, w, orig.shape[0] * 64)) == [64, 0]).all()
    assert (fit_weights(slight, orig, lo, hi, fit_price(10.0, w, orig.shape[0] * 64))[:, 1] == -1).all()  # (at λ 10: worth it)


def test_layout_refuses_bad_weights(exposed):
    lf, e, _ = exposed
    d, _ = open_encoded(lf, e)
    lay = d.core.lay
    for bad, msg in ((lambda wp: wp.__setitem__((slice(None), slice(None), 0), 97), "gain"),
                     (lambda wp: wp.__setitem__((slice(None), slice(None), 1), 1 << 19), "offset"),
                     (lambda wp: wp.__setitem__((int(np.flatnonzero(lay.intra)[0]), 0, 0), 70), "intra")):
        wp = lay.wp.copy()
        bad(wp)
        with pytest.raises(FormatError, match=msg):
            replace(lay, wp=wp).check("t")
    with pytest.raises(FormatError, match="version"):
        replace(lay, wp=None).check("t")
    with pytest.raises(FormatError, match="version"):
        replace(lay, version=3).check("t")


def test_command_line_flag(tmp_path, capsys):
    from formats import open_decoder, open_lfc
    from formats.cli import main

    out = tmp_path / "w.lfc"
    assert main(["encode", str(ROOT / "samples" / "dino_crop"), str(out), "--target-psnr", "40",
                 "--weighted-prediction", "--quiet"]) == 0
    d = open_decoder(open_lfc(out))
    assert d.core.lay.version == WP_VERSION and d.core._weighted.any()
    assert main(["info", str(out), "--verify"]) == 0
    capsys.readouterr()
    assert main(["info", str(out), "--json"]) == 0
    import json

    dec = json.loads(capsys.readouterr().out)["decoder"]
    assert dec["layout_version"] == WP_VERSION and dec["weighted_views"] == int(d.core._weighted.sum()) > 0
    off = tmp_path / "n.lfc"
    assert main(["encode", str(ROOT / "samples" / "dino_crop"), str(off), "--target-psnr", "40",
                 "--no-weighted-prediction", "--quiet"]) == 0
    d = open_decoder(open_lfc(off))
    assert d.core.lay.version < WP_VERSION and not d.core._weighted.any()
    capsys.readouterr()
    assert main(["encode", str(ROOT / "samples" / "dino_crop"), str(tmp_path / "d.lfc"), "--profile", "dcp",
                 "--weighted-prediction", "--quiet"]) == 2
    assert "--weighted-prediction not used by profile 'dcp'" in capsys.readouterr().err


def test_weighted_files_split_key_rows_alike():
    """Version 4 keeps version 3's split key rows: a smooth grid exposed differently per view
    coded with three streams per key row decodes to the pixels of one stream per row on every
    path."""
    from .helpers import smooth_lf

    v = smooth_lf(rows=3, cols=4, h=40, w=70).views
    g = np.random.default_rng(2).uniform(0.85, 1.15, v.shape[:2] + (1, 1, 1))
    lf = make_lf(np.clip(np.rint(v * g), 0, 255).astype(np.uint8))
    one = encode(lf, EncodeOptions(profile="tx", params={"step": 4.0, "block_size": 8, "key_split": 1}))
    three = encode(lf, EncodeOptions(profile="tx", params={"step": 4.0, "block_size": 8, "key_split": 3}))
    assert one.config["tx"]["version"] == three.config["tx"]["version"] == WP_VERSION
    assert three.config["tx"]["key_split"] == 3
    d, _ = open_encoded(lf, three)
    assert d.core.key_split == 3 and d.core._weighted.any()
    assert (d.decode_all() == open_encoded(lf, one)[0].decode_all()).all()
    check_agreement(d, lf.views.shape)
