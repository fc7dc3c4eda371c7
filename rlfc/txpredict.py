"""Prediction of the ``tx`` profile, in integers (numpy or torch via :mod:`rlfc.xp`).

Multi-reference disparity compensation: an 8×8 block at pixel (y0, x0) of view v, with
disparity d (units 1/16 pixel per view step) and reference key views k_j at grid positions
pos_j, samples key k_j at (y0 + y, x0 + x)·16 + d·(pos_v − pos_j) in 1/16 pixel, bilinearly
(:func:`rlfc.kernels.bilinear`, F = 4, one (9×9) window per reference), giving p_j. With
weights w_j (integers summing to 64) the prediction is (Σ_j w_j·p_j + 32) >> 6; a block in
"single reference j" mode uses w = 64 on reference j (so the prediction is p_j exactly).

Intra views (no references) are predicted by the bilinear upsampling of a thumbnail (one
value per 8×8 block and plane): pixel y samples thumbnail row (2y − 7)/16 (likewise x),
clamped at the edges, bilinear with F = 4.
"""
from __future__ import annotations

import numpy as np

from .kernels import bilinear
from .xp import NUMPY

TB = 8            # transform / prediction block edge
DISP_BITS = 4     # disparities and sample positions in 1/16 pixel
W_BITS = 6        # blend weights sum to 64


def mode_weights(weights: np.ndarray) -> np.ndarray:
    """Blend weights per tb mode: (…, R) blend weights → (…, R + 1, R): mode 0 blends with
    ``weights``, mode k puts all 64 on reference k − 1 (index it with the modes)."""
    w = np.asarray(weights)
    R = w.shape[-1]
    one = np.broadcast_to(64 * np.eye(R, dtype=w.dtype), w.shape[:-1] + (R, R))
    return np.concatenate([w[..., None, :], one], axis=-2)


def planar(planes: np.ndarray) -> np.ndarray:
    """(n, Hp, Wp, P) planes → (P, n·Hp·Wp) contiguous (fast gathers)."""
    return np.ascontiguousarray(np.moveaxis(planes, -1, 0)).reshape(planes.shape[-1], -1)


def predict_tbs(xp, kp, hw, slots, weights, disp_y, disp_x, y0, x0):
    """Prediction of M 8×8 blocks from up to R references each.

    Args:
        kp: (P, n_keys·Hp·Wp) int32 planar decoded key views; hw: (Hp, Wp).
        slots: (M, R) key index of each reference (any valid index where the weight is 0).
        weights: (M, R) int weights summing to 64 per block.
        disp_y, disp_x: (M, R) displacements of each reference in 1/16 pixel.
        y0, x0: (M,) block origins in pixels.

    Returns:
        (M, 8, 8, P) int32.
    """
    hp, wp = hw
    M, R = slots.shape
    F = DISP_BITS
    groups = None
    if isinstance(weights, np.ndarray):                 # numpy: gather only the references that count,
        nz = weights > 0                                # blocks grouped by how many (reshape + sum, no scatter)
        cnt = nz.sum(1)
        order = np.argsort(cnt, kind="stable")
        groups = [(c, order[cnt[order] == c]) for c in np.unique(cnt).tolist()]
        m = np.concatenate([np.repeat(g, c) for c, g in groups]) if groups else np.zeros(0, np.int64)
        r = np.concatenate([np.nonzero(nz[g])[1] for c, g in groups]) if groups else np.zeros(0, np.int64)
    else:
        m, r = xp.arange(M).repeat_interleave(R), xp.arange(R).repeat(M)
    Y = (y0[m] << F) + disp_y[m, r]                                               # (N,)
    X = (x0[m] << F) + disp_x[m, r]
    ext = xp.arange(TB + 1)
    rows = ((Y >> F)[:, None] + ext).clip(0, hp - 1)                              # (N, 9)
    cols = ((X >> F)[:, None] + ext).clip(0, wp - 1)
    idx = ((slots[m, r] * hp)[:, None, None] + rows[:, :, None]) * wp + cols[:, None, :]
    win = xp.take_cols(kp, idx)                                                   # (P, N, 9, 9)
    fy = xp.cast(Y & ((1 << F) - 1), xp.int32)[None, :, None, None]
    fx = xp.cast(X & ((1 << F) - 1), xp.int32)[None, :, None, None]
    p = bilinear(win, fy, fx, F) * xp.cast(weights[m, r], xp.int32)[None, :, None, None]   # (P, N, 8, 8)
    if groups is not None:
        acc = np.empty((p.shape[0], M, TB, TB), np.int32)
        a = 0
        for c, g in groups:
            acc[:, g] = p[:, a:a + c * g.size].reshape(p.shape[0], g.size, c, TB, TB).sum(2)
            a += c * g.size
    else:
        acc = p.reshape(p.shape[0], M, R, TB, TB).sum(2)
    return xp.moveaxis((acc + (1 << (W_BITS - 1))) >> W_BITS, 0, -1)


def upsample_thumb(thumb: np.ndarray, hp: int, wp: int, xp=NUMPY):
    """(ty, tx, P) thumbnail values → (hp, wp, P) int32 bilinear prediction (see module doc)."""
    ty, tx = thumb.shape[:2]
    F = DISP_BITS

    def axis(n, m):
        q = 2 * np.arange(n, dtype=np.int64) - 7
        i0 = q >> F
        return np.clip(i0, 0, m - 1), np.clip(i0 + 1, 0, m - 1), q & ((1 << F) - 1)

    ya, yb, fy = axis(hp, ty)
    xa, xb, fx = axis(wp, tx)
    t = thumb.astype(np.int32)
    s = 1 << F
    # separable: the horizontal pass on the thumbnail's rows, then the rows gathered (the same
    # integers as gathering first: a row gather commutes with the horizontal blend)
    fxv = fx.astype(np.int32)[None, :, None]
    h = t[:, xa] * (s - fxv)
    h += t[:, xb] * fxv                                          # (ty, wp, P)
    fyv = fy.astype(np.int32)[:, None, None]
    out = h[ya] * (s - fyv)
    out += h[yb] * fyv
    out += 1 << (2 * F - 1)
    out >>= 2 * F
    return out
