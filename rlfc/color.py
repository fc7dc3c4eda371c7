"""Lossless YCoCg-R (Malvar & Sullivan) on integer planes, with grey and alpha layouts.

Channel layouts (last axis): 1 = Y (grey), 2 = Y + A, 3 = RGB → Y Co Cg, 4 = RGBA → Y Co Cg A.
Y keeps the input's bit depth; Co and Cg need one extra bit (signed). All planes are int32.
"""
from __future__ import annotations

import numpy as np


def forward_int(x):
    """YCoCg-R forward on integer arrays of numpy or torch (same code for both): (…, C) → (…, C)."""
    c = x.shape[-1]
    if c < 3:
        return x
    r, g, b = x[..., 0], x[..., 1], x[..., 2]
    co = r - b
    t = b + (co >> 1)
    cg = g - t
    y = t + (cg >> 1)
    parts = [y, co, cg] + ([x[..., 3]] if c == 4 else [])
    return np.stack(parts, axis=-1) if isinstance(x, np.ndarray) else _torch_stack(parts)


def inverse_int(p):
    """YCoCg-R inverse on integer arrays of numpy or torch (no clipping)."""
    if p.shape[-1] < 3:
        return p
    y, co, cg = p[..., 0], p[..., 1], p[..., 2]
    t = y - (cg >> 1)
    g = cg + t
    b = t - (co >> 1)
    r = b + co
    parts = [r, g, b] + ([p[..., 3]] if p.shape[-1] == 4 else [])
    return np.stack(parts, axis=-1) if isinstance(p, np.ndarray) else _torch_stack(parts)


def _torch_stack(parts):
    import torch

    return torch.stack(parts, -1)


def to_planes(x: np.ndarray) -> np.ndarray:
    """(…, C) uint8/uint16 → (…, C) int32 planes (YCoCg-R for RGB; grey and alpha pass through)."""
    return forward_int(x.astype(np.int32))


def from_planes(p: np.ndarray, dtype=np.uint8) -> np.ndarray:
    """Inverse of :func:`to_planes`, clipped to the range of ``dtype`` (uint8 or uint16)."""
    peak = 65535 if np.dtype(dtype) == np.uint16 else 255
    return np.clip(inverse_int(np.asarray(p, dtype=np.int32)), 0, peak).astype(dtype)


def plane_weights(channels: int) -> np.ndarray:
    """Weights of the planes in PSNR_YCoCg / block energy: (6·Y + Co + Cg)/8; alpha like Y."""
    return {1: np.array([1.0]), 2: np.array([1.0, 1.0]), 3: np.array([6, 1, 1]) / 8.0,
            4: np.array([6, 1, 1, 8]) / 8.0}[channels]
