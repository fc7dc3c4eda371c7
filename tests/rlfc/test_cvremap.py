"""rlfc.cvremap: OpenCV's remap for images wider or taller than OpenCV addresses, cut into
tiles and crops, gives OpenCV's values (checked with the limits made small)."""
import cv2
import numpy as np
import pytest

import rlfc.cvremap as cr


@pytest.mark.parametrize("interp", [cv2.INTER_LINEAR, cv2.INTER_CUBIC])
@pytest.mark.parametrize("channels", [None, 1, 3, 4])
def test_cut_remap_equals_opencv(interp, channels, monkeypatch):
    rng = np.random.default_rng(5)
    H, W = 37, 211
    shape = (H, W) if channels is None else (H, W, channels)
    src = rng.normal(0, 50, shape).astype(np.float32)
    gy, gx = np.mgrid[0:29, 0:180].astype(np.float32)
    # shifts in 1/16 px (as the codec's), a few far and out-of-range positions
    mx = gx + rng.integers(-64, 64, gx.shape) / 16 + 20
    my = gy + rng.integers(-64, 64, gy.shape) / 16 + 3
    mx[0, :7] = [-5, -1e6, W - 1, W + 3, 1e6, 0.5, 150.25]
    my[1, :5] = [-3, H + 10, -1e6, 1e6, H - 1]
    mx, my = mx.astype(np.float32), my.astype(np.float32)
    ref = cv2.remap(src, mx, my, interp, borderMode=cv2.BORDER_REPLICATE)
    monkeypatch.setattr(cr, "SIDE", 30)          # every call takes the cut path: sources and maps > 30
    monkeypatch.setattr(cr, "TILE", 8)
    got = cr.remap(src, mx, my, interp)
    assert got.shape == ref.shape and got.dtype == ref.dtype
    assert np.array_equal(got, ref)
    out = np.full_like(ref, -1)                  # into a caller's array
    assert cr.remap(src, mx, my, interp, out=out) is out and np.array_equal(out, ref)


def test_small_calls_are_opencv_itself():
    src = np.arange(48, dtype=np.float32).reshape(6, 8)
    gy, gx = np.mgrid[0:6, 0:8].astype(np.float32)
    ref = cv2.remap(src, gx + 0.25, gy, cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)
    assert np.array_equal(cr.remap(src, gx + 0.25, gy, cv2.INTER_LINEAR), ref)
    out = np.full_like(ref, -1)
    assert cr.remap(src, gx + 0.25, gy, cv2.INTER_LINEAR, out=out) is out and np.array_equal(out, ref)
