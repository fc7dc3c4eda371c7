"""The open-loop map estimation: whole-pixel shifts equal OpenCV's warp, and the threaded cost
evaluation gives the maps of the serial one."""
import cv2
import numpy as np
import pytest

import formats.parallel as fp
from rlfc import txcosts, txestimate
from rlfc.txstructure import build


def _warp(img, dy, dx):
    h, w = img.shape
    mat = np.float32([[1, 0, dx], [0, 1, dy]])
    return cv2.warpAffine(img, mat, (w, h), flags=cv2.INTER_LINEAR | cv2.WARP_INVERSE_MAP,
                          borderMode=cv2.BORDER_REPLICATE)


@pytest.mark.parametrize("dy,dx", [(0, 0), (3, -5), (-7, 2), (12, 0), (-1, 39), (0, -40), (15, 3), (-15, -39),
                                   (16, 0), (0, -41), (2.5, -1.25)])
def test_shift_equals_warp(dy, dx):
    img = np.random.default_rng(3).random((16, 40), dtype=np.float32) * 255
    want = _warp(img, float(dy), float(dx))
    assert np.array_equal(txcosts._shift(img, float(dy), float(dx)), want)
    out = np.full_like(img, np.nan)                   # (the estimator's reused buffer)
    assert txcosts._shift(img, float(dy), float(dx), out) is out and np.array_equal(out, want)


def test_threads_give_the_serial_maps(monkeypatch):
    rng = np.random.default_rng(5)
    base = rng.integers(0, 256, (40, 56)).astype(np.float32)
    base = cv2.GaussianBlur(base, (5, 5), 1.5)
    s = build(5, 5, 2)
    luma = np.stack([np.roll(base, (int(r * 1.5), int(c * 1.5)), (0, 1))
                     for r in range(5) for c in range(5)]).astype(np.uint8)
    out = {}
    before = cv2.getNumThreads()
    for n in (1, 2):
        monkeypatch.setattr(fp, "LOCAL_THREADS", n)
        out[n] = txestimate.estimate_maps(luma, s, max_disparity=8)
    for a, b in zip(out[1], out[2]):
        assert np.array_equal(a, b)
    assert cv2.getNumThreads() == before   # OpenCV's own pool is given back
    assert np.any(out[1][0] != 0)          # the maps found the shift (not a trivial all-zero answer)


def test_the_views_luma_is_freed_when_the_maps_are_made():
    """Nothing the estimation leaves behind holds the luma stack (a third of an RGB light field):
    its runner handle made a reference cycle that kept it alive until a garbage collection."""
    import gc
    import weakref

    rng = np.random.default_rng(6)
    base = cv2.GaussianBlur(rng.integers(0, 256, (40, 56)).astype(np.float32), (5, 5), 1.5)
    luma = np.stack([np.roll(base, (r, c), (0, 1)) for r in range(3) for c in range(3)]).astype(np.uint8)
    alive = weakref.ref(luma)
    gc.disable()
    try:
        maps = txestimate.estimate_maps(luma, build(3, 3, 2), max_disparity=4)
        del luma
        assert alive() is None and len(maps) == 3
    finally:
        gc.enable()


def _noisy_shifted(seed=7, n=5):
    rng = np.random.default_rng(seed)
    base = cv2.GaussianBlur(rng.integers(0, 256, (48, 64)).astype(np.float32), (5, 5), 1.5)
    views = [np.roll(base, (int(r * 1.5), int(c * 1.5)), (0, 1)) + rng.normal(0, 6, base.shape)
             for r in range(n) for c in range(n)]
    return np.clip(np.stack(views), 0, 255).astype(np.uint8)


def test_repriced_maps_drop_the_corrections_that_no_longer_pay():
    """Maps estimated cheaply (side information worth little: noise buys many corrections) and
    then repriced at a larger correction λ keep fewer corrections; at an overwhelming one none
    is left (every block follows the shared map); at the λ they were estimated for, repricing
    adds none. Modes stay judged at the estimate's λ (an occluded block needs its reference)."""
    luma, s = _noisy_shifted(), build(5, 5, 2)
    base, disp, modes = txestimate.estimate_maps(luma, s, max_disparity=8, side_lambda=0.5)
    own = int((disp != base[None, :]).sum())
    assert own > 20 and (modes != 0).sum() > 20                  # (the cheap maps took many)
    for lam, most in ((0.5, own), (40.0, own - 1)):
        b2, d2, m2 = txestimate.reprice_maps(luma, s, base, disp, side_lambda=0.5, correction_lambda=lam)
        assert b2.shape == base.shape and d2.shape == disp.shape and m2.shape == modes.shape
        assert b2.dtype == d2.dtype == m2.dtype == np.int64
        assert (d2 != b2[None, :]).sum() <= most
    b3, d3, m3 = txestimate.reprice_maps(luma, s, base, disp, side_lambda=0.5, correction_lambda=1e12)
    assert np.array_equal(d3, np.broadcast_to(b3, d3.shape)) and m3.any()     # (modes were not repriced)
    _, _, m4 = txestimate.reprice_maps(luma, s, base, disp, side_lambda=1e12, correction_lambda=1e12)
    assert not m4.any()


def test_the_estimates_costs_are_those_the_repricing_would_evaluate():
    """estimate_maps(with_costs=True) returns every mode's costs at the disparities it returns
    (kept as the blocks moved): the same numbers as a fresh evaluation, so the repricing given
    them gives the maps it computes without them."""
    luma, s = _noisy_shifted(), build(5, 5, 2)
    base, disp, modes, full = txestimate.estimate_maps(luma, s, max_disparity=8, side_lambda=0.5, with_costs=True)
    assert (disp != base[None, :]).sum() > 20                    # (blocks moved off the shared map)
    est = txcosts.Estimator(luma, s, list(s.keys))
    assert np.array_equal(full, est.costs_maps(disp))
    for lam in (2.0, 50.0):
        a = txestimate.reprice_maps_both(luma, s, base, disp, side_lambda=0.5, correction_lambda=lam)
        b = txestimate.reprice_maps_both(luma, s, base, disp, side_lambda=0.5, correction_lambda=lam, costs=full)
        assert all(np.array_equal(x, y) for x, y in zip(a, b))
    assert np.array_equal(txestimate.estimate_maps(luma, s, max_disparity=8, side_lambda=0.5)[1], disp)


@pytest.mark.parametrize("dtype,scale", [(np.uint8, 1), (np.uint16, 257)])
def test_integer_luma_gives_the_costs_of_its_float32_copy(monkeypatch, dtype, scale):
    """8/16-bit luma takes the integer paths (whole-pixel shifts in the luma's dtype, OpenCV's
    errors and blend made in float32 from the integers; the view's samples subtracted as they
    are; the references' float32 luma made once per estimator): every cost equals that of the
    same luma as float32, which takes the float paths, and so do the references converted at
    every use (REF_FLOAT_BYTES 0)."""
    luma = (_noisy_shifted(seed=11).astype(np.int64) * scale).astype(dtype)
    s = build(5, 5, 2)
    as_float = luma.astype(np.float32)
    ints, floats = txcosts.Estimator(luma, s, list(s.keys)), txcosts.Estimator(as_float, s, list(s.keys))
    ds = [-3.0, 0.0, 2.0]
    for a, b in zip(ints.costs_global_many(ds), floats.costs_global_many(ds)):
        assert np.array_equal(a, b)
    d16 = np.random.default_rng(2).integers(-40, 41, (len(s.cell_views), ints.nby8 * ints.nbx8))
    want = floats.costs_maps(d16)
    assert np.array_equal(ints.costs_maps(d16), want)
    assert ints._refs32 and all(a.dtype == np.float32 for a in ints._refs32.values())   # (kept once)
    monkeypatch.setattr(txcosts, "REF_FLOAT_BYTES", 0)
    fresh = txcosts.Estimator(luma, s, list(s.keys))
    assert np.array_equal(fresh.costs_maps(d16), want) and fresh._refs32 == {}
    for n in (0, 1, 3):               # sampling arrays kept for none, one or a few view offsets
        monkeypatch.setattr(txcosts, "OFFSET_ARRAYS", n)
        assert np.array_equal(txcosts.Estimator(luma, s, list(s.keys)).costs_maps(d16), want)
    monkeypatch.setattr(txcosts, "OFFSET_ARRAYS", 8)
    monkeypatch.setattr(txcosts, "OFFSET_BYTES", 2 * 4 * luma[0].size)      # (a byte budget of two)
    assert np.array_equal(txcosts.Estimator(luma, s, list(s.keys)).costs_maps(d16), want)
    assert np.array_equal(txestimate.estimate_maps(luma, s, max_disparity=8)[1],
                          txestimate.estimate_maps(as_float, s, max_disparity=8)[1])


def test_fractional_global_shifts_take_the_float_path():
    """A rig whose view positions are not whole view steps shifts by fractions of a pixel at a
    whole-pixel disparity: those cells take the float path (bilinear warps), with the costs of the
    float32 copy."""
    luma, s = _noisy_shifted(seed=12), build(5, 5, 2)
    from dataclasses import replace
    s = replace(s, positions=s.positions * 1.5)
    a = txcosts.Estimator(luma, s, list(s.keys)).costs_global_many([1.0])[0]
    b = txcosts.Estimator(luma.astype(np.float32), s, list(s.keys)).costs_global_many([1.0])[0]
    assert np.array_equal(a, b)
