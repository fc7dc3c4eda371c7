"""Disparity-compensated prediction for the ``dcp`` profile.

Views on a grid are clustered 3×3; each cluster's key view is its most central member, coded
as a top-level image. A view at grid offset (oy, ox) from its key view is predicted, block by
block, from the decoded key view shifted by d·(oy, ox) pixels, d a disparity stored per
(cluster, block location) in units of 1/2^F pixel per view step (F = ``frac_bits``). Sub-pixel
positions are sampled bilinearly in integer arithmetic (weights in 1/2^F, one rounding at the
end), so every decoder computes the same prediction bit for bit; F = 0 is a plain integer
shift. The prediction reads only the key view (held decoded in memory), so one block of one
view still depends on exactly one stored residual block: the dependency cone does not grow
with anything.
"""
from __future__ import annotations

import zlib

import numpy as np

from formats.errors import FormatError

from .blocks import inflate_exact
from .kernels import bilinear
from .xp import NUMPY


def dcp_clusters(rows: int, cols: int, positions: np.ndarray):
    """3×3 grid clusters: (parent (N0,) cluster id, key (n_top,) key-view index, offsets (N0, 2))."""
    r, c = np.meshgrid(np.arange(rows), np.arange(cols), indexing="ij")
    nc = -(-cols // 3)
    par = ((r // 3) * nc + (c // 3)).reshape(-1)
    n_top = int(par.max()) + 1
    key = np.zeros(n_top, dtype=np.int64)
    rr, cc = r.reshape(-1), c.reshape(-1)
    for k in range(n_top):                                   # a handful of clusters
        members = np.flatnonzero(par == k)
        cy, cx = rr[members].mean(), cc[members].mean()
        key[k] = members[np.argmin((rr[members] - cy) ** 2 + (cc[members] - cx) ** 2)]
    offsets = np.stack([rr - rr[key[par]], cc - cc[key[par]]], axis=1).astype(np.int64)
    return par.astype(np.int64), key, offsets


def planar(top: np.ndarray) -> np.ndarray:
    """(n_top, Hp, Wp, P) key-view planes → (P, n_top·Hp·Wp) contiguous, for fast gathers."""
    return np.ascontiguousarray(np.moveaxis(top, -1, 0)).reshape(top.shape[-1], -1)


def predict_blocks(xp, tp, hw: tuple[int, int], key_of, offsets, disp, views, by, bx, B: int, nbx: int,
                   frac_bits: int = 0):
    """Predicted planes of many (view, block) requests (numpy or torch, ``xp`` from rlfc.xp).

    A block's shift is the same for all its pixels, so its sub-pixel phase is one (fy, fx) and
    its samples come from one (B+1)×(B+1) window: one gather per request window for all planes,
    then the 2×2 filter with per-block weights (:func:`rlfc.kernels.bilinear`). int32
    arithmetic is exact (|planes| < 2^18, weights <= 2^8).

    Args:
        tp: (P, n_top·Hp·Wp) int32 planar key views (:func:`planar`); hw: (Hp, Wp).
        key_of: (N0,) cluster of each view; offsets: (N0, 2) grid offset (oy, ox) to the key view.
        disp: (n_top, n_loc) int64 disparities (1/2^frac_bits pixels per view step).
        views, by, bx: (M,) int64 requests.

    Returns:
        (M, B·B, P) int32.
    """
    hp, wp = hw
    F = frac_bits
    k = key_of[views]
    d = disp[k, by * nbx + bx]                                                     # (M,)
    Y = ((by * B) << F) + d * offsets[views, 0]
    X = ((bx * B) << F) + d * offsets[views, 1]
    ext = xp.arange(B + 1)
    rows = ((Y >> F)[:, None] + ext[None, :]).clip(0, hp - 1)                       # (M, B+1)
    cols = ((X >> F)[:, None] + ext[None, :]).clip(0, wp - 1)
    idx = ((k * hp)[:, None, None] + rows[:, :, None]) * wp + cols[:, None, :]      # (M, B+1, B+1)
    win = xp.take_cols(tp, idx)                                                     # (P, M, B+1, B+1)
    s = 1 << F
    fy = xp.cast(Y & (s - 1), xp.int32)[None, :, None, None]
    fx = xp.cast(X & (s - 1), xp.int32)[None, :, None, None]
    out = bilinear(win, fy, fx, F)                                                  # (P, M, B, B)
    return xp.moveaxis(out, 0, -1).reshape(views.shape[0], B * B, tp.shape[0])


def predict_views(top: np.ndarray, key_of: np.ndarray, offsets: np.ndarray, disp: np.ndarray,
                  views: np.ndarray, B: int, frac_bits: int = 0, top_planar: np.ndarray | None = None) -> np.ndarray:
    """Predicted planes of whole views: (n, Hp, Wp, P) int32, the pixels of predict_blocks for
    every block (computed block-wise with its window gather, one view at a time)."""
    n_top, hp, wp, P = top.shape
    nby, nbx = hp // B, wp // B
    tp = planar(top) if top_planar is None else top_planar
    out = np.empty((len(views), hp, wp, P), dtype=np.int32)
    by, bx = np.divmod(np.arange(nby * nbx), nbx)
    for i, v in enumerate(np.asarray(views).tolist()):                  # one batched gather per view
        vv = np.full(nby * nbx, v)
        blocks = predict_blocks(NUMPY, tp, (hp, wp), key_of, offsets, disp, vv, by, bx, B, nbx, frac_bits)
        out[i] = blocks.reshape(nby, nbx, B, B, P).transpose(0, 2, 1, 3, 4).reshape(hp, wp, P)
    return out


def _costs(target, top, key_of, offsets, B, maps, frac_bits):
    """(len(maps), n_top, n_loc) SSE of each candidate disparity map on the first (luma) plane.

    Key views themselves (offset 0) are skipped: no disparity changes their prediction.
    """
    n0, hp, wp, _ = target.shape
    nby, nbx = hp // B, wp // B
    cost = np.zeros((len(maps), top.shape[0], nby * nbx))
    moving = np.flatnonzero(np.any(offsets != 0, axis=1))
    luma = np.ascontiguousarray(top[..., :1])
    luma_planar = planar(luma)                       # once, not per candidate map and chunk
    for j, m in enumerate(maps):
        for a in range(0, len(moving), 16):
            vs = moving[a:a + 16]
            pred = predict_views(luma, key_of, offsets, m, vs, B, frac_bits, luma_planar)[..., 0]
            err = (target[vs, :, :, 0] - pred).astype(np.float32) ** 2                # (n, Hp, Wp)
            e = err.reshape(len(vs), nby, B, nbx, B).sum(axis=(2, 4)).reshape(len(vs), -1)
            np.add.at(cost[j], key_of[vs], e)
    return cost


def estimate(target: np.ndarray, top: np.ndarray, key_of: np.ndarray, offsets: np.ndarray, B: int,
             max_disparity: int, frac_bits: int = 0, smooth_tol: float = 0.1, smooth_iters: int = 3,
             start_disparity: int = 4) -> np.ndarray:
    """Per (cluster, block) disparity (units 1/2^F px per view step) minimizing the cluster's luma SSE.

    Coarse to fine: whole pixels in [-4, 4] first, widened by doubling up to ``max_disparity``
    while more than 2% of the blocks pick the edge of the range and the wider range lowers the
    total error by at least 0.5%; then ±1/2, ±1/4, ... pixel around the best so far.

    Args:
        target: (N0, Hp, Wp, P) int32 planes of the views; top: decoded key-view planes.

    Returns:
        (n_top, nby·nbx) int64 disparities in 1/2^F pixels per view step.
    """
    n_top = top.shape[0]
    nloc = (target.shape[1] // B) * (target.shape[2] // B)
    s = 1 << frac_bits
    D = min(start_disparity, max_disparity)
    cands = np.arange(-D, D + 1)
    cost = _costs(target, top, key_of, offsets, B, [np.full((n_top, nloc), d) for d in cands.tolist()], 0)
    # widen the search while many blocks sit at its edge and widening pays (wide baselines)
    while D < max_disparity:
        at_edge = np.abs(cands[np.argmin(cost, axis=0)]) == D
        if at_edge.mean() <= 0.02:
            break
        D2 = min(2 * D, max_disparity)
        more = np.r_[np.arange(-D2, -D), np.arange(D + 1, D2 + 1)]
        mc = _costs(target, top, key_of, offsets, B, [np.full((n_top, nloc), d) for d in more.tolist()], 0)
        if np.minimum(mc.min(axis=0), cost.min(axis=0)).sum() >= 0.995 * cost.min(axis=0).sum():
            break                                     # the wider range does not pay
        cands, cost, D = np.r_[cands, more], np.concatenate([cost, mc]), D2
    best = cands[np.argmin(cost, axis=0)] * s
    best_cost = cost.min(axis=0)
    zero_cost = cost[np.flatnonzero(cands == 0)[0]]
    lim = D * s
    step = s // 2
    while step >= 1:                                  # refine: ±1/2, then ±1/4, ... pixel
        fine = [np.clip(best - step, -lim, lim), np.clip(best + step, -lim, lim)]
        fc = _costs(target, top, key_of, offsets, B, fine, frac_bits)
        j = np.argmin(fc, axis=0)
        c = np.take_along_axis(fc, j[None], 0)[0]
        better = c < best_cost
        best = np.where(better, np.take_along_axis(np.stack(fine), j[None], 0)[0], best)
        best_cost = np.where(better, c, best_cost)
        step //= 2
    # ties (flat or occluded blocks): prefer zero
    zero = best_cost >= zero_cost
    best, best_cost = np.where(zero, 0, best), np.where(zero, zero_cost, best_cost)
    # regularize: take the 3×3 median of the map wherever it costs within ``smooth_tol`` (plus
    # 1/4 grey level² per pixel) of the best; a smoother map compresses better (about 30% on
    # hci_antinous for -0.05 dB of prediction; BENCHMARKS.md)
    nby, nbx = target.shape[1] // B, target.shape[2] // B
    for _ in range(smooth_iters):
        g = np.pad(best.reshape(n_top, nby, nbx), ((0, 0), (1, 1), (1, 1)), mode="edge")
        nb = np.stack([g[:, 1 + dy:1 + dy + nby, 1 + dx:1 + dx + nbx] for dy in (-1, 0, 1) for dx in (-1, 0, 1)])
        med = np.sort(nb, axis=0)[4].reshape(n_top, -1)
        cm = _costs(target, top, key_of, offsets, B, [med], frac_bits)[0]
        ok = cm <= best_cost * (1 + smooth_tol) + B * B / 4
        best, best_cost = np.where(ok, med, best), np.where(ok, cm, best_cost)
    return best


def pack_disparity(disp: np.ndarray) -> tuple[bytes, str]:
    """(n_top, n_loc) ints → (zlib-compressed bytes of the row-wise deltas, dtype string)."""
    dt = "<i1" if -128 <= disp.min(initial=0) and disp.max(initial=0) <= 127 else "<i2"
    delta = np.diff(disp, axis=1, prepend=0).astype(dt)
    return zlib.compress(delta.tobytes(), 9), dt


def unpack_disparity(data: bytes, dt: str, shape: tuple[int, int], name: str) -> np.ndarray:
    """Inverse of :func:`pack_disparity`; a bad stream raises a FormatError naming ``name``."""
    if dt not in ("<i1", "<i2"):
        raise FormatError(f"{name}: unknown disparity type {dt!r}")
    raw = inflate_exact(data, shape[0] * shape[1] * np.dtype(dt).itemsize, name, "rlfc.disp", "disparities")
    delta = np.frombuffer(raw, dtype=dt).astype(np.int64).reshape(shape)
    return np.cumsum(delta, axis=1).astype(np.dtype(dt)).astype(np.int64)   # wrap like the encoder's cast
