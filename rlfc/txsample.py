"""The ``tx`` prediction on the CPU through OpenCV's ``remap``: the same integers as
:func:`rlfc.txpredict.predict_tbs`, in one fused sampling pass instead of about ten numpy
passes over 9×9 windows.

Why it is exact. ``predict_tbs`` samples key views at positions with 4 fractional bits, taps
clamped to the image, ``((a(16−fx) + b·fx)(16−fy) + (c(16−fx) + e·fx)·fy + 128) >> 8``. Given a
float image and float coordinates ``Y/16`` (exact), ``remap`` (INTER_LINEAR) returns that sum
divided by 256: the bilinear weights are dyadic fractions with at most 8 bits, and every
intermediate of either evaluation order (weights × taps, or two lerps) is representable in
the float type when the samples have at most 10 bits (float32; 8-bit light fields, whose
Co/Cg planes span ±255) or 17 bits (float64; 16-bit light fields). Clamping each tap
(``BORDER_REPLICATE``) equals clamping the coordinate to [0, size − 1] first, which keeps every
tap inside its own key view when the views are stacked into one tall image. Then
``floor(r + 0.5)`` is the rounded shift (the atlas stores the planes + 0.5, so remap returns
r + 0.5 directly), and the blend ``(Σ w·p + 32) >> 6`` is done in the
same floats (integers below 2^24). ``tests/rlfc/test_txsample.py`` checks the equality on
random and edge cases, 8- and 16-bit.

Limits: OpenCV addresses source and destination images below 32767 pixels a side, so key
views are stacked in groups (:class:`KeyAtlas`) and calls are cut into pieces; a key view
32767 pixels or more on a side has no atlas (callers fall back to ``predict_tbs``).

One random-access block's lean paths are :mod:`rlfc.txsample_block`.
"""
from __future__ import annotations


import cv2
import numpy as np

from . import cvremap
from .txpredict import DISP_BITS, TB, W_BITS, mode_weights

CV_MAX = cvremap.SIDE   # largest image side OpenCV's remap accepts (< SHRT_MAX)
SMALL = 64              # (blocks × references) up to which every reference is sampled (fewer calls)
_E = np.arange(TB, dtype=np.float32)
_F16 = np.float32(1.0 / (1 << DISP_BITS))
_Z = np.zeros(TB, np.float32)


class KeyAtlas:
    """Decoded key views as float images for ``remap``: key slot s lives in group
    ``s // per_group`` at rows ``(s % per_group)·Hp ..``; each group is (rows, Wp, P).

    Args:
        n_keys, hp, wp, planes: key views, padded size and planes.
        bits: bits of the samples' magnitude (Co/Cg included): ≤ 10 → float32, else float64.
    """

    def __init__(self, n_keys: int, hp: int, wp: int, planes: int, bits: int):
        self.hp, self.wp, self.P = hp, wp, planes
        self.ftype = np.float32 if bits <= 10 else np.float64
        # channels stored: three float32 planes get a fourth, unused one (OpenCV's remap has a
        # vectorized 4-channel float32 path: 0.5x the time of 3 channels, measured)
        self.C = 4 if planes == 3 and self.ftype is np.float32 else planes
        self.per_group = max(1, CV_MAX // hp)
        ng = -(-n_keys // self.per_group) if n_keys else 0
        self.groups = [np.zeros((min(self.per_group, n_keys - g * self.per_group) * hp, wp, self.C), self.ftype)
                       for g in range(ng)]

    @staticmethod
    def sample_bits(dtype, planes: int) -> int:
        """Bits of the planes' magnitude: the sample depth, plus one for Co/Cg (3-4 planes)."""
        return int(np.iinfo(dtype).bits) + (1 if planes >= 3 else 0)

    @staticmethod
    def fits(hp: int, wp: int, planes: int) -> bool:
        return hp <= CV_MAX and wp <= CV_MAX and 1 <= planes <= 4

    def set(self, slot: int, planes: np.ndarray) -> None:
        """Store key view ``slot``: (Hp, Wp, P) integer planes, plus 0.5 (bilinear weights sum
        to 1, so every sample comes out 0.5 higher: the rounding's offset for free, exactly)."""
        g, i = divmod(slot, self.per_group)
        dst = self.groups[g][i * self.hp:(i + 1) * self.hp, :, :self.P]
        np.add(planes, self.ftype(0.5), out=dst, casting="unsafe")      # (one pass: 0.35x two)

    def set_rows(self, slot: int, rows: np.ndarray, b: int, planes: np.ndarray) -> None:
        """Store block rows ``rows`` (n,) of ``b`` pixels of key view ``slot``: planes
        (n, b, Wp, P) integers (plus 0.5, as :meth:`set`)."""
        g, i = divmod(slot, self.per_group)
        dst = self.groups[g][i * self.hp:(i + 1) * self.hp].reshape(self.hp // b, b, self.wp, self.C)
        rows = np.asarray(rows)
        if rows.size == 0:
            return
        cut = (np.flatnonzero(np.diff(rows) != 1) + 1).tolist()
        for lo, hi in zip([0] + cut, cut + [rows.size]):       # runs of consecutive rows: slices, no temporaries
            np.add(planes[lo:hi], self.ftype(0.5), out=dst[rows[lo]:rows[hi - 1] + 1, ..., :self.P], casting="unsafe")

    def nbytes(self) -> int:
        return sum(g.nbytes for g in self.groups)


def predict(atlas: KeyAtlas, slots, weights, disp_y, disp_x, y0, x0) -> np.ndarray:
    """Prediction of M 8×8 blocks from up to R references each (see
    :func:`rlfc.txpredict.predict_tbs`, whose integers this returns).

    The blocks are grouped by their weights (a view's blend, or one of its single-reference
    modes; the order of the requests is kept within a group), and the (block, reference) pairs
    laid out group by group and reference by reference, then sampled by one remap (one per atlas
    image). Consecutive windows then lie in one key view, in the requests' order, so the caches
    hold them, and each reference of a group is added with its weight as one scalar over a
    contiguous slice. The pairs in block order, blended with per-pair weights, took 1.04-1.4x
    the time on random-access calls (BENCHMARKS.md).

    Args:
        slots: (M, R) key slot of each reference; weights: (M, R) ints summing to 64 per block
            (references of weight 0 are not sampled); disp_y, disp_x: (M, R) displacements in
            1/16 pixel; y0, x0: (M,) block origins in pixels.

    Returns:
        (M, 8, 8, P) int32.
    """
    M, R = slots.shape
    P, C, ft = atlas.P, atlas.C, atlas.ftype
    if M == 0:
        return np.zeros((0, TB, TB, P), np.int32)
    if M * R <= SMALL and len(atlas.groups) == 1:
        return _predict_dense(atlas, slots, weights, disp_y, disp_x, y0, x0)
    key = weights.astype(np.int64) @ (np.int64(65) ** np.arange(R, dtype=np.int64))   # (weights < 65)
    order = np.argsort(key, kind="stable")
    ks = key[order]
    cut = [0] + (np.flatnonzero(ks[1:] != ks[:-1]) + 1).tolist() + [M]
    # the (block, reference) pairs, group by group and reference by reference:
    # pieces (group's blocks g0..g1, reference, first pair, the group's first reference?)
    pieces, blk, ref = [], [], []
    n = 0
    for g0, g1 in zip(cut[:-1], cut[1:]):
        for i, r in enumerate(np.flatnonzero(weights[order[g0]]).tolist()):
            pieces.append((g0, g1, r, n, i == 0))
            blk.append(np.arange(g0, g1))
            ref.append(np.full(g1 - g0, r))
            n += g1 - g0
    blk, ref = np.concatenate(blk), np.concatenate(ref)
    m = order[blk]                                                   # each pair's block, in the call's order
    Y = ((y0[m] << DISP_BITS) + disp_y[m, ref]).astype(np.float32) * _F16
    X = ((x0[m] << DISP_BITS) + disp_x[m, ref]).astype(np.float32) * _F16
    grp, within = np.divmod(slots[m, ref], atlas.per_group)         # each pair's atlas image, key view's row
    rows = Y[:, None] + _E
    np.minimum(np.maximum(rows, 0, out=rows), np.float32(atlas.hp - 1), out=rows)   # clamped to the key view
    rows += (within * atlas.hp).astype(np.float32)[:, None]
    cols = X[:, None] + _E
    np.minimum(np.maximum(cols, 0, out=cols), np.float32(atlas.wp - 1), out=cols)
    mc, mr = np.tile(cols, (1, TB)), np.repeat(rows, TB, axis=1)    # (n, 64): each pixel's column, row
    smp = np.empty((n, TB * TB, C), ft)
    ng = len(atlas.groups)
    for k, sel in enumerate([None] if ng == 1 else [np.flatnonzero(grp == k) for k in range(ng)]):
        if sel is not None and sel.size == 0:
            continue
        for a in range(0, n if sel is None else sel.size, CV_MAX):    # (OpenCV's size limit)
            part = slice(a, a + CV_MAX) if sel is None else sel[a:a + CV_MAX]
            dst = smp[part] if sel is None else None                   # (a slice: OpenCV writes there)
            o = cv2.remap(atlas.groups[k], mc[part], mr[part], cv2.INTER_LINEAR, dst=dst,
                          borderMode=cv2.BORDER_REPLICATE)
            if dst is None or not np.shares_memory(o, dst):            # (OpenCV allocated its own output)
                smp[part] = o.reshape(o.shape[0], TB * TB, C)
    np.floor(smp, out=smp)                                           # each reference's sample, rounded (atlas +0.5)
    acc = np.empty((M, TB * TB, C), ft)
    for g0, g1, r, a, first in pieces:                               # the blend: scalar weights, contiguous slices
        w, p = weights[order[g0], r], smp[a:a + g1 - g0]
        if first:
            np.multiply(p, ft(w), out=acc[g0:g1])
        else:
            cv2.scaleAdd(p, float(w), acc[g0:g1], dst=acc[g0:g1])    # integers < 2^24 (2^53): exact
    grouped = _drop_pad(acc, C, P).astype(np.int32)
    grouped += 1 << (W_BITS - 1)
    grouped >>= W_BITS
    out = np.empty((M, TB * TB, P), np.int32)
    out[order] = grouped
    return out.reshape(M, TB, TB, P)


def _drop_pad(a: np.ndarray, C: int, P: int) -> np.ndarray:
    """(…, C) → (…, P): the atlas's unused fourth channel dropped (OpenCV's BGRA → BGR copy, 4x
    faster than numpy's strided read of the first three)."""
    if C == P:
        return a
    if a.dtype == np.float32 and C == 4 and P == 3:
        return cv2.cvtColor(a.reshape(-1, a.shape[-2], 4), cv2.COLOR_BGRA2BGR).reshape(a.shape[:-1] + (3,))
    return a[..., :P]


def row_grids(atlas: KeyAtlas, slots, weights, disp_y, disp_x, first: int = 0) -> list:
    """The sampling rows and columns of :func:`predict_rows` for every reference of nonzero
    weight, over all the 8×8 block rows given, in one pass per reference (their values are
    small: one per pixel row or column of each 8×8 block).

    Args:
        slots: (R,) key slots; weights: (R,) blend weights; disp_y, disp_x: (R, n, n8x)
            displacements in 1/16 pixel of the blocks of 8×8 block rows ``first`` .. first + n − 1.

    Returns:
        per reference of nonzero weight, (weight, atlas group, rows (n, 8, n8x) float32: the
        row of each pixel row of each block in the atlas group, clamped to its key view; cols
        (n, n8x, 8) float32: the column of each pixel column, clamped).
    """
    R, n, n8x = disp_y.shape
    yb = ((np.arange(n) + first) * TB) << DISP_BITS
    xb = (np.arange(n8x) * TB) << DISP_BITS
    out = []
    for r in range(R):
        w = int(weights[r])
        if w == 0:
            continue
        g, within = divmod(int(slots[r]), atlas.per_group)
        Y = (yb[:, None] + disp_y[r]).astype(np.float32) * _F16                          # (n, n8x)
        X = (xb[None, :] + disp_x[r]).astype(np.float32) * _F16
        rows = Y[:, None, :] + _E[:, None]                                               # (n, 8, n8x)
        np.minimum(np.maximum(rows, 0, out=rows), np.float32(atlas.hp - 1), out=rows)
        rows += np.float32(within * atlas.hp)
        cols = X[:, :, None] + _E                                                        # (n, n8x, 8)
        np.minimum(np.maximum(cols, 0, out=cols), np.float32(atlas.wp - 1), out=cols)
        out.append((w, g, rows, cols))
    if not out:                                                                          # (weights sum to 64)
        raise ValueError("a view's prediction needs a reference of nonzero weight")
    return out


def predict_rows(atlas: KeyAtlas, grids: list, a: int, b: int, out: np.ndarray | None = None) -> np.ndarray:
    """:func:`predict` of whole rows of 8×8 blocks that all blend the same references with the
    same weights (tb mode 0), sampled in raster order: one remap per reference over the band
    of block rows [a, b) (its maps are the pixel grid shifted per block: :func:`row_grids`'
    ``grids``, spread to every pixel by OpenCV's nearest resize, the values np.repeat gives), no
    per-block bookkeeping, no transposes.

    Returns:
        (8·(b − a), 8·n8x, P) int32: the integers :func:`predict` gives for those blocks
        (written to ``out`` where given: a C-contiguous int32 array of that shape).
    """
    acc = None
    n, n8x = b - a, grids[0][2].shape[2]
    size = (n8x * TB, n * TB)                                                            # (OpenCV's width, height)
    for w, g, rows, cols in grids:
        mr = cv2.resize(rows[a:b].reshape(n * TB, n8x), size, interpolation=cv2.INTER_NEAREST)
        mc = cv2.resize(cols[a:b].reshape(n, n8x * TB), size, interpolation=cv2.INTER_NEAREST)
        smp = cv2.remap(atlas.groups[g], mc, mr, cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)
        np.floor(smp, out=smp)                                                           # atlas + 0.5: rounded
        if acc is None:
            smp *= w
            acc = smp
        else:
            cv2.scaleAdd(smp, w, acc, dst=acc)                                           # integers < 2^24: exact
    blend = _drop_pad(acc.reshape(n * TB, n8x * TB, atlas.C), atlas.C, atlas.P)
    if out is None:
        out = np.empty(blend.shape, np.int32)
    np.copyto(out, blend, casting="unsafe")                                             # (integers: exact)
    out += 1 << (W_BITS - 1)
    out >>= W_BITS
    return out


#: 8×8 blocks per band of :func:`predict_view` (its temporaries stay in the caches)
BAND_TBS = 1024


def predict_view(atlas: KeyAtlas, slots, weights, disp, modes, dpos, n8y: int, n8x: int,
                 out: np.ndarray | None = None, warp=None, rows: tuple[int, int] | None = None) -> np.ndarray:
    """The prediction of a whole view with references (or of its 8×8 block rows ``rows`` =
    (a, b): rows a .. b − 1): the blend-mode blocks by :func:`predict_rows` in bands, the
    single-reference blocks by :func:`predict`.

    Args:
        slots: (R,) key slots of the references; weights: (R,) blend weights (sum 64);
            disp: (T,) disparity of each 8×8 block (raster order, T = n8y·n8x); modes: (T,)
            0 = blend, k = reference k − 1 alone; dpos: (R, 2) position offsets (displacement
            = disparity × offset, in 1/16 pixel); warp: None, or (oy, ox) (R, n8y, n8x) ints
            added to each reference's displacements (1/16 px: :func:`rlfc.txwarp.view_offsets`).

    Returns:
        (8·n, 8·n8x, P) int32 (n = b − a, or n8y), the integers of :func:`predict` for every
        block (written to ``out`` where given: a C-contiguous int32 array of that shape; no band
        is copied).
    """
    R, P = slots.size, atlas.P
    a0, b0 = (0, n8y) if rows is None else rows
    n = b0 - a0
    d = np.asarray(disp).reshape(1, n8y, n8x)[:, a0:b0]
    dy, dx = d * dpos[:, 0, None, None], d * dpos[:, 1, None, None]                  # (R, n, n8x)
    if warp is not None:
        dy, dx = dy + warp[0][:, a0:b0], dx + warp[1][:, a0:b0]
    if out is None:
        out = np.empty((n * TB, n8x * TB, P), np.int32)
    band = max(1, BAND_TBS // n8x)
    grids = row_grids(atlas, slots, weights, dy, dx, a0)         # (each reference's, for all the rows at once)
    for a in range(0, n, band):
        b = min(n, a + band)
        predict_rows(atlas, grids, a, b, out=out[a * TB:b * TB])
    m = np.asarray(modes).reshape(n8y, n8x)[a0:b0].reshape(-1)
    other = np.flatnonzero(m != 0)
    if other.size:
        ty, tx = np.divmod(other, n8x)
        w = mode_weights(weights)[m[other]]
        p = predict(atlas, np.broadcast_to(slots, (other.size, R)), w, dy.reshape(R, -1)[:, other].T,
                    dx.reshape(R, -1)[:, other].T, (ty + a0) * TB, tx * TB)
        out.reshape(n, TB, n8x, TB, P)[ty, :, tx] = p
    return out


def _predict_dense(atlas: KeyAtlas, slots, weights, disp_y, disp_x, y0, x0) -> np.ndarray:
    """:func:`predict` for a few blocks (one random-access request): every reference sampled,
    weight 0 or not, in about a third of the numpy calls (calls, not pixels, cost here)."""
    Y = ((y0[:, None] << DISP_BITS) + disp_y).astype(np.float32) * _F16                 # (M, R)
    X = ((x0[:, None] << DISP_BITS) + disp_x).astype(np.float32) * _F16
    rows0 = (slots * atlas.hp).astype(np.float32)[:, :, None, None]
    return _sample_blend(atlas, atlas.groups[0], Y, X, rows0, weights.astype(atlas.ftype)[:, None, :])


def _one_row(m: np.ndarray) -> np.ndarray:
    """A small call's remap map (n, 64) as one row (1, 64·n) where OpenCV takes that width: a
    one-row remap runs in the calling thread, without waking OpenCV's thread pool (1.5-2.5 µs
    less for a single request where the pool has two threads, measured; the same samples, in
    the same order)."""
    return m.reshape(1, -1) if m.size <= CV_MAX else m


def _sample_blend(atlas: KeyAtlas, src: np.ndarray, Y, X, rows0, w) -> np.ndarray:
    """The kernel of the few-block paths: every reference's 8×8 window at (Y, X) (M, R)
    float32 pixels, rows clamped to its key view and offset by ``rows0`` (broadcast to
    (M, R, 1, 1): its first row in ``src``), columns clamped, sampled bilinearly in one remap
    call, rounded (the atlas holds planes + 0.5), blended with ``w`` (M, 1, R) weights summing
    to 64 and rounded: (M, 8, 8, P) int32."""
    mr = Y[:, :, None, None] + _E[:, None]                                 # (M, R, 8, 1)
    np.minimum(np.maximum(mr, 0, out=mr), np.float32(atlas.hp - 1), out=mr)
    mr = mr + _Z                                                           # (M, R, 8, 8)
    mr += rows0
    mc = X[:, :, None] + _E                                                # (M, R, 8)
    np.minimum(np.maximum(mc, 0, out=mc), np.float32(atlas.wp - 1), out=mc)
    mc = mc[:, :, None, :] + _Z[:, None]                                   # (M, R, 8, 8)
    M, R = Y.shape
    smp = cv2.remap(src, _one_row(mc.reshape(M * R, TB * TB)), _one_row(mr.reshape(M * R, TB * TB)), cv2.INTER_LINEAR,
                    borderMode=cv2.BORDER_REPLICATE)
    np.floor(smp, out=smp)                                                 # atlas + 0.5: rounded
    acc = np.matmul(w, smp.reshape(M, R, -1))                              # (M, 1, 64·C) integers
    out = acc.reshape(M, TB, TB, atlas.C)[..., :atlas.P].astype(np.int32)
    out += 1 << (W_BITS - 1)
    out >>= W_BITS
    return out
