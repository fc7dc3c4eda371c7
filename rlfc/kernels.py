"""RLFC's integer kernels, each written once for numpy and torch (``xp`` from :mod:`rlfc.xp`).

The scalar, batched, whole-view and torch decoders all call these, so they agree bit for bit.
"""
from __future__ import annotations

import numpy as np

from formats.errors import FormatError

from .bise import decode_words
from .bise_tables import RANGE_VALUES

# Plane modes of a BISE-family block header (on-wire values; do not reorder).
MODE_CONST = 21        # constant plane: q = min, no payload
MODE_PLAIN = 32        # 32 + k: B·B plain k-bit fields (k = 1..31)
MODE_RAW = 255         # plane 0 only: raw block of key-view pixels


def plain_values(xp, buf, starts, k: int, count: int):
    """(S,) byte offsets → (S, count) int64 LSB-first plain k-bit fields (k <= 31)."""
    pos = np.arange(count, dtype=np.int64) * k
    w = xp.word(buf, starts[:, None] + xp.asarray(pos >> 3)[None, :], 5)
    return xp.cast((w >> xp.cast(xp.asarray(pos & 7), w.dtype)[None, :]) & ((1 << k) - 1), xp.int64)


def decode_planes(xp, buf, modes, mins, pstart, skip, count: int):
    """Plane-mode dispatch: the quantization indices of many block planes.

    Args:
        buf: blocks section (uint8, 8 bytes of slack); modes, mins, pstart: (S, P) plane
            modes (uint8/int64), minimums and payload byte offsets; skip: (S,) bool rows not to
            decode (raw blocks: zero).
        count: values per plane (B·B).

    Returns:
        (S, P, count) int64 indices.

    Raises:
        FormatError: a plane mode that is not defined.
    """
    S, P = modes.shape
    q = xp.zeros((S, P, count), xp.int64)
    modes = xp.cast(modes, xp.int64)
    live = ~skip[:, None]
    for m in np.unique(_np(modes)).tolist():                 # <= ~30 distinct modes
        sel = (modes == m) & live
        kk, cc = _nonzero(sel)
        if kk.shape[0] == 0:
            continue
        if m == MODE_CONST:
            q[kk, cc] = mins[kk, cc][:, None]
        elif m < MODE_CONST:
            q[kk, cc] = decode_words(xp, buf, pstart[kk, cc], RANGE_VALUES[m], count) + mins[kk, cc][:, None]
        elif MODE_PLAIN < m < MODE_PLAIN + 32:
            q[kk, cc] = plain_values(xp, buf, pstart[kk, cc], m - MODE_PLAIN, count) + mins[kk, cc][:, None]
        elif m != MODE_RAW:
            raise FormatError(f"rlfc block has an undefined plane mode {m}")
    return q


def dequantize(xp, q, q16):
    """Indices → residual, exactly: sign(q)·((|q|·q16 + 8) >> 4). ``q16`` broadcasts against
    ``q`` (per plane); int64 arithmetic."""
    d = (abs(q) * q16 + 8) >> 4
    return xp.where(q < 0, -d, d)


def bilinear(win, fy, fx, frac_bits: int):
    """Integer bilinear sampling of windows whose last two axes are (B+1, B+1), at one
    sub-pixel phase per window.

    ``fy``, ``fx``: phases in 1/2^F pixel, broadcastable to ``win[..., :1, :1]``. Returns the
    (..., B, B) samples ``((a·(s−fx) + b·fx)·(s−fy) + (c·(s−fx) + e·fx)·fy + s²/2) >> 2F``,
    s = 2^F, as a horizontal then a vertical pass (one rounding). F = 0: the plain window.
    """
    B = win.shape[-1] - 1
    if frac_bits == 0:
        return win[..., :B, :B]
    s = 1 << frac_bits
    h = win[..., :, :B] * (s - fx) + win[..., :, 1:] * fx                  # (..., B+1, B)
    return (h[..., :B, :] * (s - fy) + h[..., 1:, :] * fy + (1 << (2 * frac_bits - 1))) >> (2 * frac_bits)


def _np(a):
    return a if isinstance(a, np.ndarray) else a.cpu().numpy()


def _nonzero(mask):
    if isinstance(mask, np.ndarray):
        return np.nonzero(mask)
    import torch

    return torch.nonzero(mask, as_tuple=True)
