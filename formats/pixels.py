"""Pixel conventions shared by every codec: sample peaks and lossless YCoCg-R planes.

Channel layouts (last axis): 1 = Y (grey), 2 = Y + A, 3 = RGB → Y Co Cg, 4 = RGBA → Y Co Cg A.
Y keeps the input's bit depth; Co and Cg need one extra bit (signed). All planes are int32.
The integer transforms are written once for numpy and torch arrays (same operators).
"""
from __future__ import annotations

import numpy as np


def peak_of(dtype) -> float:
    """Peak sample value for PSNR: 255 (uint8), 65535 (uint16), 1.0 (float)."""
    return {np.dtype(np.uint8): 255.0, np.dtype(np.uint16): 65535.0}.get(np.dtype(dtype), 1.0)


def _stack(parts, like):
    if isinstance(like, np.ndarray):
        return np.stack(parts, axis=-1)
    import torch

    return torch.stack(parts, -1)


def forward_int(x):
    """YCoCg-R forward on integer arrays of numpy or torch: (…, C) → (…, C) planes."""
    c = x.shape[-1]
    if c < 3:
        return x
    r, g, b = x[..., 0], x[..., 1], x[..., 2]
    co = r - b
    t = b + (co >> 1)
    cg = g - t
    y = t + (cg >> 1)
    return _stack([y, co, cg] + ([x[..., 3]] if c == 4 else []), x)


def inverse_int(p):
    """YCoCg-R inverse on integer arrays of numpy or torch (no clipping)."""
    if p.shape[-1] < 3:
        return p
    y, co, cg = p[..., 0], p[..., 1], p[..., 2]
    if isinstance(p, np.ndarray):                       # numpy: into one output, no stack
        out = np.empty_like(p)
        t = y - (cg >> 1)
        np.add(cg, t, out=out[..., 1])
        np.subtract(t, co >> 1, out=out[..., 2])
        np.add(out[..., 2], co, out=out[..., 0])
        if p.shape[-1] == 4:
            out[..., 3] = p[..., 3]
        return out
    t = y - (cg >> 1)
    g = cg + t
    b = t - (co >> 1)
    r = b + co
    return _stack([r, g, b] + ([p[..., 3]] if p.shape[-1] == 4 else []), p)


def to_planes(x: np.ndarray) -> np.ndarray:
    """(…, C) uint8/uint16 → (…, C) int32 planes (YCoCg-R for RGB; grey and alpha pass through)."""
    return forward_int(x.astype(np.int32))


def from_planes(p: np.ndarray, dtype=np.uint8) -> np.ndarray:
    """Inverse of :func:`to_planes`, clipped to the range of ``dtype`` (uint8 or uint16)."""
    peak = 65535 if dtype is np.uint16 or np.dtype(dtype) == np.uint16 else 255
    x = inverse_int(np.asarray(p, dtype=np.int32))
    return np.minimum(np.maximum(x, 0, out=x), peak, out=x).astype(dtype)     # ufuncs: np.clip costs µs


def plane_weights(channels: int) -> np.ndarray:
    """Weights of the planes in PSNR_YCoCg / block energy: (6·Y + Co + Cg)/8; alpha like Y."""
    return {1: np.array([1.0]), 2: np.array([1.0, 1.0]), 3: np.array([6, 1, 1]) / 8.0,
            4: np.array([6, 1, 1, 8]) / 8.0}[channels]


def rgb_mse_weights(channels: int) -> np.ndarray:
    """How much an error of 1 in each plane adds to the mean squared error over the colour
    channels (per pixel): YCoCg-R gives MSE_RGB = eY² + eCo²/6 + eCg²/4; alpha is not colour
    (weight 0); grey is Y alone."""
    return {1: np.array([1.0]), 2: np.array([1.0, 0.0]), 3: np.array([1.0, 1 / 6, 1 / 4]),
            4: np.array([1.0, 1 / 6, 1 / 4, 0.0])}[channels]
