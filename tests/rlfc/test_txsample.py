"""The remap prediction (rlfc.txsample) returns predict_tbs's integers exactly."""
import numpy as np
import pytest

from rlfc.txpredict import TB, planar, predict_tbs
from rlfc.txsample import KeyAtlas, predict
from rlfc.xp import NUMPY


def _case(rng, n_keys, hp, wp, P, lo, hi, M, reach):
    keys = rng.integers(lo, hi + 1, (n_keys, hp, wp, P)).astype(np.int32)
    R = 4
    slots = rng.integers(0, n_keys, (M, R))
    # weights summing to 64 with 1..4 nonzero references, as the layout and the modes give
    w = np.zeros((M, R), np.int64)
    k = rng.integers(1, R + 1, M)
    for c in range(1, R + 1):
        sel = np.flatnonzero(k == c)
        cuts = np.sort(rng.integers(1, 64, (sel.size, c - 1)), axis=1)
        parts = np.diff(np.concatenate([np.zeros((sel.size, 1), int), cuts, np.full((sel.size, 1), 64)], 1), axis=1)
        cols = np.argsort(rng.random((sel.size, R)), axis=1)[:, :c]
        w[sel[:, None], cols] = parts
    dy = rng.integers(-reach * 16, reach * 16, (M, R))
    dx = rng.integers(-reach * 16, reach * 16, (M, R))
    y0 = rng.integers(0, hp // TB, M) * TB
    x0 = rng.integers(0, wp // TB, M) * TB
    return keys, slots, w, dy, dx, y0, x0


@pytest.mark.parametrize("P,lo,hi,bits", [(3, -255, 255, 9), (1, 0, 255, 8), (4, -255, 255, 9),
                                          (2, 0, 65535, 16), (3, -65535, 65535, 17)])
def test_remap_prediction_is_predict_tbs(P, lo, hi, bits):
    rng = np.random.default_rng(P + bits)
    keys, slots, w, dy, dx, y0, x0 = _case(rng, 5, 32, 48, P, lo, hi, 3000, 40)
    ref = predict_tbs(NUMPY, planar(keys), (32, 48), slots, w, dy, dx, y0, x0)
    atlas = KeyAtlas(5, 32, 48, P, bits)
    for s in range(5):
        atlas.set(s, keys[s])
    got = predict(atlas, slots, w, dy, dx, y0, x0)
    assert got.dtype == np.int32 and got.shape == ref.shape
    assert np.array_equal(got, ref)


def test_remap_prediction_across_atlas_groups(monkeypatch):
    """Key views in several stacked groups, and calls cut into pieces, give the same integers."""
    import rlfc.txsample as ts

    monkeypatch.setattr(ts, "CV_MAX", 100)           # 3 keys of 32 rows per group, pieces of 100 blocks
    rng = np.random.default_rng(7)
    keys, slots, w, dy, dx, y0, x0 = _case(rng, 7, 32, 40, 3, -255, 255, 700, 50)
    ref = predict_tbs(NUMPY, planar(keys), (32, 40), slots, w, dy, dx, y0, x0)
    atlas = ts.KeyAtlas(7, 32, 40, 3, 9)
    assert len(atlas.groups) == 3
    for s in range(7):
        atlas.set(s, keys[s])
    assert np.array_equal(ts.predict(atlas, slots, w, dy, dx, y0, x0), ref)


@pytest.mark.parametrize("P,lo,hi,bits", [(3, -255, 255, 9), (1, 0, 255, 8), (4, -65535, 65535, 17)])
def test_remap_prediction_few_blocks(P, lo, hi, bits):
    """One request's tbs (the dense path that samples every reference) give the same integers."""
    rng = np.random.default_rng(11)
    keys, slots, w, dy, dx, y0, x0 = _case(rng, 4, 32, 40, P, lo, hi, 400, 30)
    ref = predict_tbs(NUMPY, planar(keys), (32, 40), slots, w, dy, dx, y0, x0)
    atlas = KeyAtlas(4, 32, 40, P, bits)
    for s in range(4):
        atlas.set(s, keys[s])
    for a in range(0, 400, 4):
        sl = slice(a, a + 4)
        got = predict(atlas, slots[sl], w[sl], dy[sl], dx[sl], y0[sl], x0[sl])
        assert np.array_equal(got, ref[sl])


def test_remap_prediction_of_no_blocks():
    atlas = KeyAtlas(1, 16, 16, 3, 9)
    z = np.zeros((0, 4), np.int64)
    assert predict(atlas, z, z, z, z, np.zeros(0, np.int64), np.zeros(0, np.int64)).shape == (0, 8, 8, 3)
