"""Sparse residual views: pixel threshold, quantization (fixed point, step q16/16) and
block-energy threshold. Integer arithmetic only, so encoder and decoders agree bit for bit."""
from __future__ import annotations

import numpy as np


def quantize(r: np.ndarray, q16: np.ndarray, threshold: np.ndarray) -> np.ndarray:
    """Residual → quantization indices.

    Args:
        r: (..., P) int32 residual planes.
        q16: (P,) int steps in 1/16 pixel units (16 = identity).
        threshold: (P,) pixel thresholds: |r| <= T becomes 0.

    Returns:
        (..., P) int32 indices q = sign(r)·floor((16|r| + q16/2) / q16).
    """
    a = np.abs(r).astype(np.int64)
    a = np.where(a <= np.asarray(threshold), 0, a)
    q = (a * 16 + np.asarray(q16) // 2) // np.asarray(q16)
    return (np.sign(r) * q).astype(np.int32)


def dequantize(q: np.ndarray, q16: np.ndarray) -> np.ndarray:
    """Indices → residual: sign(q)·((|q|·q16 + 8) >> 4), int32."""
    a = (np.abs(q).astype(np.int64) * np.asarray(q16) + 8) >> 4
    return (np.sign(q) * a).astype(np.int32)


def to_blocks(x: np.ndarray, b: int) -> np.ndarray:
    """(N, Hp, Wp, P) → (N, nby, nbx, b, b, P) view-copy of B×B blocks."""
    n, h, w, p = x.shape
    return x.reshape(n, h // b, b, w // b, b, p).transpose(0, 1, 3, 2, 4, 5)


def from_blocks(x: np.ndarray) -> np.ndarray:
    """Inverse of :func:`to_blocks`."""
    n, by, bx, b, _, p = x.shape
    return x.transpose(0, 1, 3, 2, 4, 5).reshape(n, by * b, bx * b, p)


def block_energy(deq_blocks: np.ndarray, weights: np.ndarray) -> np.ndarray:
    """(N, nby, nbx, b, b, P) → (N, nby, nbx) weighted mean of squared values (pixel units²)."""
    e = (deq_blocks.astype(np.float64) ** 2).mean(axis=(3, 4))
    return e @ np.asarray(weights, dtype=np.float64)
