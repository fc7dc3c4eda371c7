"""Per-view warps of the ``tx`` profile (layout version 5): rigs whose cameras are not exactly
rectified (each view rotated, scaled or shifted a little against the grid) predicted without
resampling the views.

Each view v stores four integers (a, b, cx, cy): to first order its captured pixel x = (x, y)
lies u_v(x) away from where a rectified camera would see the same point, with

    u_v(x) = ((a·x − b·y) / 2^16 + cx / 2^8, (b·x + a·y) / 2^16 + cy / 2^8) pixels

(a: the scale less 1, b: the rotation in radians, both in units of 2^-16; cx, cy: the shift in
1/256 pixel). A view's 8×8 block (ty, tx) samples reference r at its disparity's position
plus u_r − u_v at the block's centre (x, y) = (8·tx + 3.5, 8·ty + 3.5), in 1/16 pixel:

    X2, Y2 = 16·tx + 7, 16·ty + 7                     (twice the centre)
    nx = Δa·X2 − Δb·Y2 + 512·Δcx,  ny = Δb·X2 + Δa·Y2 + 512·Δcy   (Δ: reference less view)
    offset = (floor((nx + 2^12) / 2^13), floor((ny + 2^12) / 2^13))   (x, y; 1/16 px)

Integers throughout (below 2^31 for views below 2^17 pixels a side), so every decoder (numpy,
torch, JavaScript) computes the same offsets. About 8 bytes a view stored (a scale and a
rotation to 1/65536, a shift to 1/256 px: under 1/100 px of error across a 512-pixel view). The first-order form differs from
the exact composition of the two warps by (scale or rotation)² × the view's size: below 1/100
pixel for the corrections this is for (a fraction of a degree, a fraction of a percent).
"""
from __future__ import annotations

import numpy as np

from formats.errors import FormatError

#: |a|, |b| at most this (2^-16 units: scale within ±6.25%, rotation within ±3.6°)
AB_MAX = 1 << 12
#: |cx|, |cy| at most this (1/256 px units: ±128 px)
C_MAX = 1 << 15
#: the fixed-point shift of an offset's numerator to 1/16 pixel, and the shifts' scale in it
SHIFT = 13
C_SCALE = 1 << 9


def warp_params(warps: np.ndarray, h: int, w: int) -> np.ndarray:
    """(N, 4) int64 stored parameters (a, b, cx, cy) of similarity warps (θ radians, s, tx, ty
    px about the view's centre, as :func:`formats.rectify.estimate_warps` gives them), clipped
    to the stored ranges. ``h``, ``w``: the views' size in pixels."""
    from formats.rectify import warp_matrix

    out = np.zeros((len(warps), 4), np.int64)
    for i, wp in enumerate(np.asarray(warps, np.float64)):
        m = warp_matrix(wp, h, w)                       # rectified q → captured x
        # first order: u(x) = x − M⁻¹x ≈ (M − [I|0]) (x, 1)
        a = 0.5 * ((m[0, 0] - 1) + (m[1, 1] - 1))
        b = 0.5 * (m[1, 0] - m[0, 1])
        out[i] = (round(a * 2 ** 16), round(b * 2 ** 16), round(m[0, 2] * 2 ** 8), round(m[1, 2] * 2 ** 8))
    out[:, :2] = out[:, :2].clip(-AB_MAX, AB_MAX)
    out[:, 2:] = out[:, 2:].clip(-C_MAX, C_MAX)
    return out


def check_params(warp: np.ndarray, where: str) -> None:
    """FormatError unless ``warp`` (N, 4) lies within the stored ranges."""
    if warp.size and (np.abs(warp[:, :2]).max() > AB_MAX or np.abs(warp[:, 2:]).max() > C_MAX):
        raise FormatError(f"{where}: a view's warp is out of range")


def pair_params(warp: np.ndarray, refs: np.ndarray) -> np.ndarray:
    """(N, R, 4) int64: each (view, reference slot)'s warp difference, reference less view (0
    where the slot is empty)."""
    d = warp[refs.clip(0)] - warp[:, None, :]
    d[refs < 0] = 0
    return d


def offsets(dw, ty, tx):
    """(oy, ox) in 1/16 pixel of 8×8 blocks (ty, tx) (M,) with pair parameters ``dw`` (M, R, 4)
    (numpy arrays or torch tensors, int64): each (M, R)."""
    X2 = (tx * 16 + 7)[:, None]
    Y2 = (ty * 16 + 7)[:, None]
    da, db, dcx, dcy = dw[..., 0], dw[..., 1], dw[..., 2], dw[..., 3]
    half = 1 << (SHIFT - 1)
    ox = (da * X2 - db * Y2 + dcx * C_SCALE + half) >> SHIFT
    oy = (db * X2 + da * Y2 + dcy * C_SCALE + half) >> SHIFT
    return oy, ox


def view_offsets(dw: np.ndarray, n8y: int, n8x: int) -> tuple[np.ndarray, np.ndarray]:
    """(oy, ox) (R, n8y, n8x) int64 in 1/16 pixel: every 8×8 block of a view whose pair
    parameters are ``dw`` (R, 4)."""
    ty, tx = np.divmod(np.arange(n8y * n8x, dtype=np.int64), n8x)
    oy, ox = offsets(np.broadcast_to(dw, (ty.size,) + dw.shape), ty, tx)
    R = dw.shape[0]
    return oy.T.reshape(R, n8y, n8x), ox.T.reshape(R, n8y, n8x)


def max_row_offset(dw: np.ndarray, hp: int, wp: int) -> np.ndarray:
    """(N,) int64: per view, the largest |vertical offset| (whole pixels, rounded up) over its
    references and its 8×8 blocks (the offset is affine in the block's centre: its extremes lie
    at the corner blocks)."""
    n8y, n8x = hp // 8, wp // 8
    N = dw.shape[0]
    m = np.zeros(N, np.int64)
    for ty, tx in ((0, 0), (0, n8x - 1), (n8y - 1, 0), (n8y - 1, n8x - 1)):
        oy, _ = offsets(dw, np.full(N, ty, np.int64), np.full(N, tx, np.int64))
        m = np.maximum(m, np.abs(oy).max(axis=1))
    return -(-m // 16)
