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


@pytest.mark.parametrize("P,bits", [(3, 9), (1, 8), (3, 17)])
def test_remap_prediction_of_blocks_sharing_weights(P, bits, monkeypatch):
    """Blocks grouped by their weights (as a view's blend and modes give them), their
    (block, reference) pairs laid out reference by reference and sampled in pieces of at most
    CV_MAX pairs that cut across groups: the same integers."""
    import rlfc.txsample as ts

    monkeypatch.setattr(ts, "CV_MAX", 100)           # 3 keys of 32 rows: one atlas group, pieces of 100 pairs
    rng = np.random.default_rng(11 + P + bits)
    lo, hi = (-255, 255) if bits == 9 else (0, 255) if bits == 8 else (-65535, 65535)
    keys, slots, w, dy, dx, y0, x0 = _case(rng, 3, 32, 40, P, lo, hi, 900, 50)
    w = w[rng.integers(0, 4, w.shape[0])]            # four weight rows, ~225 blocks each
    ref = predict_tbs(NUMPY, planar(keys), (32, 40), slots, w, dy, dx, y0, x0)
    atlas = ts.KeyAtlas(3, 32, 40, P, bits)
    assert len(atlas.groups) == 1
    for s in range(3):
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


@pytest.mark.parametrize("P,lo,hi,bits,cv_max", [(3, -255, 255, 9, None), (1, 0, 255, 8, None), (4, -255, 255, 9, None),
                                                 (2, 0, 65535, 16, None), (3, -65535, 65535, 17, None),
                                                 (3, -255, 255, 9, 100)])
@pytest.mark.parametrize("reach", [40, 4000, 1 << 20])
def test_whole_view_in_raster_bands_is_predict_tbs(P, lo, hi, bits, cv_max, reach, monkeypatch):
    """predict_view (blend blocks in raster bands, the others by the block kernel) gives every
    block predict_tbs's integers; bands of a few block rows, keys across atlas groups;
    displacements within a few pixels, far past the key views (clamped rows, replicated
    columns), and at the format's largest disparity."""
    import rlfc.txsample as ts

    if cv_max:
        monkeypatch.setattr(ts, "CV_MAX", cv_max)       # 3 keys of 32 rows per stacked group
    monkeypatch.setattr(ts, "BAND_TBS", 12)             # bands of 2 block rows of 6
    rng = np.random.default_rng(P + bits)
    n_keys, hp, wp, R = 7, 32, 48, 4
    n8y, n8x = hp // TB, wp // TB
    keys = rng.integers(lo, hi + 1, (n_keys, hp, wp, P)).astype(np.int32)
    atlas = ts.KeyAtlas(n_keys, hp, wp, P, bits)
    for s in range(n_keys):
        atlas.set(s, keys[s])
    slots = rng.choice(n_keys, R, replace=False)
    weights = np.array([30, 0, 20, 14])                  # one reference unused by the blend
    disp = rng.integers(-reach, reach, n8y * n8x)
    if reach == 40:
        disp[:2 * n8x] = 0                               # a band whose rows need no clamp
    modes = np.where(rng.random(n8y * n8x) < 0.3, rng.integers(1, R + 1, n8y * n8x), 0)
    dpos = rng.integers(-2, 3, (R, 2))
    got = ts.predict_view(atlas, slots, weights, disp, modes, dpos, n8y, n8x)
    T = n8y * n8x
    ty, tx = np.divmod(np.arange(T), n8x)
    w = np.where(modes[:, None] == 0, weights[None, :], 64 * (np.arange(R)[None, :] == modes[:, None] - 1))
    ref = predict_tbs(NUMPY, planar(keys), (hp, wp), np.broadcast_to(slots, (T, R)), w, disp[:, None] * dpos[None, :, 0],
                      disp[:, None] * dpos[None, :, 1], ty * TB, tx * TB)
    ref = ref.reshape(n8y, n8x, TB, TB, P).transpose(0, 2, 1, 3, 4).reshape(hp, wp, P)
    assert got.dtype == np.int32 and np.array_equal(got, ref)


def test_thumbnail_upsampling_is_the_bilinear_formula():
    """upsample_thumb (separable) gives, pixel by pixel, the module doc's formula: pixel y
    samples thumbnail row (2y − 7)/16, clamped, bilinear in 1/16 with one rounding."""
    from rlfc.txpredict import upsample_thumb

    rng = np.random.default_rng(5)
    for ty, tx, P in [(1, 1, 1), (2, 3, 4), (5, 9, 3)]:
        th = rng.integers(-(1 << 17), 1 << 17, (ty, tx, P))
        hp, wp = 8 * ty, 8 * tx
        got = upsample_thumb(th, hp, wp)
        q = lambda n: 2 * np.arange(n) - 7                               # noqa: E731
        qy, qx = q(hp), q(wp)
        y0, x0, fy, fx = qy >> 4, qx >> 4, qy & 15, qx & 15
        cy = lambda i: np.clip(i, 0, ty - 1)                             # noqa: E731
        cx = lambda i: np.clip(i, 0, tx - 1)                             # noqa: E731
        a = th[cy(y0)][:, cx(x0)]
        b = th[cy(y0)][:, cx(x0 + 1)]
        c = th[cy(y0 + 1)][:, cx(x0)]
        d = th[cy(y0 + 1)][:, cx(x0 + 1)]
        fy, fx = fy[:, None, None], fx[None, :, None]
        want = ((a * (16 - fx) + b * fx) * (16 - fy) + (c * (16 - fx) + d * fx) * fy + 128) >> 8
        assert got.dtype == np.int32 and np.array_equal(got, want)


@pytest.mark.parametrize("planes,bits", [(3, 9), (1, 8), (4, 9), (3, 17)])
@pytest.mark.parametrize("rows", [[0, 1, 2, 3], [3], [0, 2, 3], [1, 3], []])
def test_set_rows_is_set_of_those_rows(planes, bits, rows):
    # block rows stored by runs of consecutive rows: the same values as storing the whole view
    rng = np.random.default_rng(len(rows) + planes)
    hp, wp, b = 32, 24, 8
    lim = 1 << (bits - 1)
    full = rng.integers(-lim, lim, (hp, wp, planes)).astype(np.int32)
    a, ref = KeyAtlas(3, hp, wp, planes, bits), KeyAtlas(3, hp, wp, planes, bits)
    ref.set(1, full)
    rows = np.asarray(rows, np.int64)
    a.set_rows(1, rows, b, full.reshape(hp // b, b, wp, planes)[rows])
    got = a.groups[0][hp:2 * hp].reshape(hp // b, b, wp, a.C)
    want = ref.groups[0][hp:2 * hp].reshape(hp // b, b, wp, a.C)
    assert np.array_equal(got[rows], want[rows])
    rest = np.setdiff1d(np.arange(hp // b), rows)
    assert not got[rest].any() and not a.groups[0][:hp].any() and not a.groups[0][2 * hp:].any()
