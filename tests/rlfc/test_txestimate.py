"""The open-loop map estimation: whole-pixel shifts equal OpenCV's warp, and the threaded cost
evaluation gives the maps of the serial one."""
import cv2
import numpy as np
import pytest

import formats.parallel as fp
from rlfc import txestimate
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
    assert np.array_equal(txestimate._shift(img, float(dy), float(dx)), want)
    out = np.full_like(img, np.nan)                   # (the estimator's reused buffer)
    assert txestimate._shift(img, float(dy), float(dx), out) is out and np.array_equal(out, want)


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
