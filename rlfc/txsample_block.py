"""One random-access block predicted from its references through OpenCV's remap, in as few numpy
calls as the same integers allow (:func:`predict_block`: planes; :func:`predict_block_pixels`:
pixels, the YCoCg-R inverse folded in), with the per-view constants they read
(:func:`block_refs`, :func:`block_pixel_refs`). The same integers as :func:`rlfc.txsample.predict`
(tested); :mod:`rlfc.profiles.tx_single` calls them.
"""
from __future__ import annotations

import functools

import cv2
import numpy as np

from .txpredict import TB, W_BITS
from .txsample import _F16, KeyAtlas, _one_row, _sample_blend


def block_refs(atlas: KeyAtlas, slots: np.ndarray, weights_by_mode: np.ndarray, dpos: np.ndarray):
    """Per-view constants of :func:`predict_block`, or None where the view's references lie in
    more than one atlas group (then :func:`predict` serves the view).

    Args:
        slots: (R,) key slots of the view's references; weights_by_mode: (R + 1, R) blend
            weights of each 8×8 block mode (:func:`rlfc.txpredict.mode_weights`); dpos: (R, 2)
            position offsets (displacement = disparity × offset, in 1/16 pixel).

    Returns:
        (group image, (1, R, 1, 1) float32 first row of each reference in it, (R,) float32 and
        (R,) float32 offsets in pixels per unit of disparity, (R + 1, 1, R) weights in the
        atlas's float type).
    """
    g, within = np.divmod(np.asarray(slots, np.int64), atlas.per_group)
    if g.size == 0 or (g != g[0]).any():
        return None
    src = atlas.groups[int(g[0])]
    return (src, (within * atlas.hp).astype(np.float32).reshape(1, -1, 1, 1),
            (dpos[:, 0] * _F16).astype(np.float32), (dpos[:, 1] * _F16).astype(np.float32),
            np.asarray(weights_by_mode, src.dtype)[:, None, :])



def predict_block(atlas: KeyAtlas, refs, disp, modes, y0, x0) -> np.ndarray:
    """:func:`predict` of the few 8×8 blocks of one view that one random-access request
    needs, in about half the numpy calls of the general path (calls, not pixels, cost here).
    The coordinates are the same float32 values (``y0 + d·offset/16``: integers and sixteenths,
    exact), so the integers are those of :func:`predict`.

    Args:
        refs: :func:`block_refs` of the view (not None). disp: (M,) disparity of each 8×8
            block; modes: (M,) their modes; y0, x0: (M,) float32 pixel origins.

    Returns:
        (M, 8, 8, P) int32.
    """
    src, rows0, dpy, dpx, wm = refs
    d = np.asarray(disp).astype(np.float32)[:, None]                       # (M, 1)
    Y = d * dpy
    Y += y0[:, None]
    X = d * dpx
    X += x0[:, None]
    return _sample_blend(atlas, src, Y, X, rows0, wm[modes])


@functools.lru_cache(maxsize=32)
def pixel_matrix(P: int, C: int, ftype) -> np.ndarray:
    """(2C, P) matrix M with ``[planes, floor(planes / 2)] @ M`` = the YCoCg-R inverse of
    :func:`formats.pixels.inverse_int` (R, G, B; alpha and grey planes pass through): its
    ``>> 1`` steps are the floor halves, the rest is sums and differences, exact on integers in
    the float type. C: the atlas's channels (a fourth, unused one for three planes)."""
    M = np.zeros((2 * C, P), ftype)
    if P < 3:
        M[np.arange(P), np.arange(P)] = 1
        return M
    y, co, cg, co_h, cg_h = 0, 1, 2, C + 1, C + 2
    M[[y, co, co_h, cg_h], 0] = [1, 1, -1, -1]            # r = b + co
    M[[y, cg, cg_h], 1] = [1, 1, -1]                      # g = cg + t, t = y - (cg >> 1)
    M[[y, co_h, cg_h], 2] = [1, -1, -1]                   # b = t - (co >> 1)
    if P == 4:
        M[3, 3] = 1
    M.setflags(write=False)                               # (cached: one per layout)
    return M


@functools.lru_cache(maxsize=32)
def _window_grid(R: int, tpb: int) -> tuple:
    """The part of :func:`block_pixel_refs` every view of R references shares (read-only): per
    (reference, 8×8 block) pair, reference-major, the window's pixel rows and columns within the
    block (R·tpb², 64) float32 and the pair's 8×8 block (R·tpb²,)."""
    nt = tpb * tpb
    e = np.arange(TB * TB, dtype=np.float32)
    t = np.arange(nt)
    gy = np.tile((t // tpb * TB).astype(np.float32), R)[:, None] + (e // TB)[None, :]    # (R·nt, 64)
    gx = np.tile((t % tpb * TB).astype(np.float32), R)[:, None] + (e % TB)[None, :]
    rep = np.tile(t, R)
    for a in (gy, gx, rep):
        a.setflags(write=False)
    return gy, gx, rep


def block_pixel_refs(atlas: KeyAtlas, refs, tpb: int, wp=None, lo=None, hi=None) -> tuple:
    """Per-view constants of :func:`predict_block_pixels`, from :func:`block_refs`' tuple, for
    blocks of tpb × tpb 8×8 blocks (raster order within the block), in this order:

    - the atlas group image; per (reference, 8×8 block) pair (``R·nt`` rows, reference-major)
      the window's pixel grid (8×8 positions, flat: (2, R·nt, 64) rows in the atlas, its key
      view's first row added, and columns); the pairs' displacements (rows, then columns) as a
      (2·R·nt, nt + 2) matrix over a block's nt disparities and its pixel origin (each pair's
      offset per unit of disparity in its 8×8 block's column, 1 in the origin's); the rows'
      bounds in the atlas (the key view's first and last rows, each (R·nt, 1): the rows'
      clamp);
    - the blend's weights per mode over 64 and over 128, (R + 1, R, 2) (the blend and its half
      from one product); the YCoCg-R inverse as (2C, P) rows in channel order, each channel's
      plane then its floor half (:func:`pixel_matrix`'s rows interleaved); the roundings
      (0.5, 0.25) tiled to (nt·64·C, 2);
    - the view's weighted prediction, where ``wp`` (P, 2) gives one: its gains, offsets and the
      planes' bounds ``lo``, ``hi`` (P,) in the atlas's float type over its C channels, each
      tiled to (nt·64, C) (else None); the weights per mode over 64 (R + 1, R) and the two
      halves of :func:`pixel_matrix` (planes, floor halves): the path of a weighted or coded
      block;
    - the largest |row offset per unit of disparity| over the references (a Python float).
    """
    src, rows0, dpy, dpx, wm = refs
    R, nt = dpy.size, tpb * tpb
    C, P, ft = atlas.C, atlas.P, atlas.ftype
    gy, gx, rep = _window_grid(R, tpb)
    wpf = None
    if wp is not None:
        g, o = np.full(C, 64, ft), np.zeros(C, ft)
        lw, hg = np.full(C, -np.inf, ft), np.full(C, np.inf, ft)
        g[:P], o[:P], lw[:P], hg[:P] = wp[:, 0], wp[:, 1], lo, hi
        # tiled over a block's samples (nt·64, C): same-shape operands (the C values broadcast
        # along the last axis make numpy's inner loops C elements long: 4x the time, measured)
        wpf = tuple(np.tile(a, (nt * TB * TB, 1)) for a in (g, o, lw, hg))
    M = pixel_matrix(P, C, ft)
    w = np.asarray(wm, ft).reshape(R + 1, R)
    w2 = np.ascontiguousarray(np.stack([w / ft(1 << W_BITS), w / ft(2 << W_BITS)], axis=2))
    m2 = np.ascontiguousarray(M.reshape(2, C, P).transpose(1, 0, 2).reshape(2 * C, P))
    rnd = np.tile(np.array([0.5, 0.25], ft), (nt * TB * TB * C, 1))
    r0 = np.repeat(rows0.reshape(R), nt)[:, None]                          # (R·nt, 1) first rows in the atlas
    grid = np.stack([gy + r0, gx])                                         # (2, R·nt, 64) rows (in the atlas), columns
    dpm = np.zeros((2, R * nt, nt + 2), np.float32)                       # displacement = dpm @ (d, by_px, bx_px)
    pair = np.arange(R * nt)
    dpm[0, pair, rep], dpm[1, pair, rep] = np.repeat(dpy, nt), np.repeat(dpx, nt)
    dpm[0, :, nt], dpm[1, :, nt + 1] = 1, 1
    return (src, grid, dpm.reshape(2 * R * nt, nt + 2), r0, r0 + np.float32(atlas.hp - 1), w2, m2, rnd, wpf,
            w / ft(1 << W_BITS), M[:C], M[C:], float(np.abs(dpy).max()))


def predict_block_pixels(atlas: KeyAtlas, prefs, d, modes, by_px: int, tpb: int, peak, dtype, res=None,
                         bounds=None, warp=None, dmax: float | None = None, depth: int | None = None) -> np.ndarray:
    """The pixels of one random-access block predicted from its references (and a coded one's
    residual added, ``res``): the same values as :func:`predict_block` (and the residual added
    and clipped) followed by :func:`formats.pixels.from_planes`, in fewer numpy calls (a single
    request costs calls, not pixels).

    The sampling positions are the same exact values as :func:`predict_block`'s, summed in
    another order (disparity × offset + block origin, one matrix-vector product whose rows hold
    one offset and a 1, + the window's pixel grid; integers and sixteenths, exact in float32
    wherever they fall inside the image, and clamped alike where they do not). Columns are not
    clamped: the remap's replicated border gives the clamped coordinate's sample exactly, as
    rows clamped to their key view do in the stacked atlas. The
    blend's weights are divided by 64 (exact: each product and sum has at most 24 significant
    bits), so ``floor(x + 0.5)`` is its rounded shift; the YCoCg-R inverse is one product with
    :func:`pixel_matrix` of the planes and their floor halves. A block neither weighted nor coded
    takes its blend x and x / 2 from one product (weights over 64 and over 128: the same
    significant bits) and floor(x / 2 + 0.25) = floor(floor(x + 0.5) / 2) as the half: blend,
    rounding and halves in three calls, the YCoCg-R inverse in a fourth. Where ``dmax`` says no
    row can leave its key view (the block's rows ± dmax × the largest row offset inside it),
    the rows' clamp, a no-op there, is skipped.

    A coded block (``res``) adds its residual to the prediction and clips the sum to the planes'
    bounds before the YCoCg-R inverse, as :meth:`rlfc.profiles.tx.TxDecoder.block` does in
    integers. Exact: the prediction lies within the bounds (|bound| < 2^18), so a residual
    within ±(hi − lo) sums exactly, and a larger one (rounded or not: float rounding is
    monotone, the bounds are exact) puts the sum past the same bound.

    Args:
        prefs: :func:`block_pixel_refs` of the view; d: (nt + 2,) float32: the disparities of
            the block's 8×8 blocks (raster order), then its pixel origin (row, column);
            ``modes`` (nt,) their modes; by_px: the block's first pixel row (an int); tpb: 8×8
            blocks per block side; peak (a number of the atlas's float type), dtype: the
            pixels'.
        res: None (predicted only), or (nt·64, C) residual samples in the atlas's float type
            (0 past the P planes), 8×8 blocks and their samples in raster order; bounds: then
            the planes' (lo, hi) in that type (±inf past the P planes), each (C,) or tiled to
            (nt·64, C) (faster: no broadcast along the last axis).
        warp: None, or the (y, x) offsets in pixels (each (R·nt,) float32 sixteenths,
            reference-major as the pairs) of a view with per-view warps (:mod:`rlfc.txwarp`).
        dmax: None, or a bound on the view's |disparity| (the largest of its map).
        depth: None, or :func:`formats.pixels.cv_saturating_depth` of ``dtype`` and ``peak``
            (then OpenCV clips and casts in one call).

    Returns:
        (8·tpb, 8·tpb, P) pixels of ``dtype``.
    """
    src, grid, dpm, lo, hi, w2, m2, rnd, wpf, w64, M1, M2, dpy_max = prefs
    C = atlas.C
    nt = d.size - 2
    n = nt * TB * TB
    t = np.dot(dpm, d).reshape(2, -1)                                     # (2, R·nt) disparity × offset + origin
    if warp is not None:
        t[0] += warp[0]
        t[1] += warp[1]
    pos = t[:, :, None] + grid                                            # (2, R·nt, 64) rows in the atlas, columns
    mr = pos[0]
    reach = None if dmax is None or warp is not None else dmax * dpy_max
    if reach is None or not reach <= by_px <= atlas.hp - TB * tpb - reach:
        np.minimum(np.maximum(mr, lo, out=mr), hi, out=mr)              # rows within their key view (ufuncs)
    smp = cv2.remap(src, _one_row(pos[1]), _one_row(mr), cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)
    np.floor(smp, out=smp)                                                # atlas + 0.5: rounded
    R = grid.shape[1] // nt
    ml = modes.tolist()
    one = ml.count(ml[0]) == nt                                           # one mode (most blocks): one product
    if wpf is None and res is None:
        if one:                                                           # (n·C, 2): the blend, its half
            both = np.dot(smp.reshape(R, -1).T, w2[ml[0]])
        else:                                                             # (nt, 64·C, R) @ (nt, R, 2)
            both = np.matmul(smp.reshape(R, nt, -1).transpose(1, 2, 0), w2[modes]).reshape(-1, 2)
        both += rnd
        np.floor(both, out=both)                                          # (Σ w·p + 32) >> 6, and that >> 1
        px = np.dot(both.reshape(n, 2 * C), m2)
    else:
        if one:
            acc = np.dot(w64[ml[0]], smp.reshape(R, -1)).reshape(n, C)
        else:                                                             # (nt, 1, R) @ (nt, R, 64·C)
            acc = np.matmul(w64[modes][:, None], smp.reshape(R, nt, -1).transpose(1, 0, 2)).reshape(n, C)
        acc += 0.5
        np.floor(acc, out=acc)                                            # (Σ w·p + 32) >> 6
        if wpf is not None:               # weighted prediction: ((p·g + 32) >> 6) + o, clipped (exact:
            g, o, lw, hg = wpf            # products below 2^23, offsets below 2^18)
            acc *= g
            acc += 32
            acc *= 1 / 64
            np.floor(acc, out=acc)
            acc += o
            np.minimum(np.maximum(acc, lw, out=acc), hg, out=acc)
        if res is not None:               # a coded block: + its residual, clipped to the planes' bounds
            acc += res
            np.minimum(np.maximum(acc, bounds[0], out=acc), bounds[1], out=acc)
        half = acc * 0.5
        np.floor(half, out=half)                                          # the planes >> 1
        px = np.dot(acc, M1)
        px += np.dot(half, M2)
    P = atlas.P
    if depth is not None:                 # clipped to [0, peak] and cast in one call (OpenCV saturates;
        px = cv2.addWeighted(px, 1.0, px, 0.0, 0.0, dtype=depth)    # the values are integers: exact)
        return px.reshape(tpb, tpb, TB, TB, P).transpose(0, 2, 1, 3, 4).reshape(tpb * TB, tpb * TB, P)
    np.minimum(np.maximum(px, 0, out=px), peak, out=px)
    out = np.empty((tpb, TB, tpb, TB, P), dtype)
    np.copyto(out, px.reshape(tpb, tpb, TB, TB, P).transpose(0, 2, 1, 3, 4), casting="unsafe")
    return out.reshape(tpb * TB, tpb * TB, P)
