"""Sparse residual views: pixel threshold, quantization (fixed point, step q16/16) and
block-energy threshold. Integer arithmetic only, so encoder and decoders agree bit for bit."""
from __future__ import annotations

import numpy as np


def _q_scalar(a: np.ndarray, q16: int, threshold: float) -> np.ndarray:
    """The quantizer on non-negative magnitudes (int64), the definition the LUTs tabulate."""
    a = np.where(a <= threshold, 0, a)
    return (a * 16 + q16 // 2) // q16


def _dq_scalar(a: np.ndarray, q16: int) -> np.ndarray:
    return (a * q16 + 8) >> 4


def quantize_dequantize(r: np.ndarray, q16, threshold) -> tuple[np.ndarray, np.ndarray]:
    """Residual → (quantization indices, dequantized residual), both int32, via per-plane LUTs.

    q = sign(r)·floor((16|r| + q16/2) / q16) with |r| <= T → 0; deq = sign(q)·((|q|·q16 + 8) >> 4).

    Args:
        r: (..., P) int32 residual planes.
        q16: (P,) steps in 1/16 pixel units (16 = identity); threshold: (P,) pixel thresholds.
    """
    q16 = np.broadcast_to(np.asarray(q16, dtype=np.int64), (r.shape[-1],))
    thr = np.broadcast_to(np.asarray(threshold, dtype=np.float64), (r.shape[-1],))
    q = np.empty(r.shape, dtype=np.int32)
    dq = np.empty(r.shape, dtype=np.int32)
    for p in range(r.shape[-1]):          # one lookup table per plane (<= 4)
        rp = r[..., p]
        lo, hi = int(rp.min()), int(rp.max())
        m = max(-lo, hi, 0)
        mag = np.arange(m + 1, dtype=np.int64)
        qm = _q_scalar(mag, int(q16[p]), float(thr[p]))
        lut_q = np.concatenate([-qm[:0:-1], qm]).astype(np.int32)           # index r + m
        lut_d = np.concatenate([-_dq_scalar(qm, int(q16[p]))[:0:-1], _dq_scalar(qm, int(q16[p]))]).astype(np.int32)
        idx = rp + np.int32(m)
        q[..., p] = lut_q[idx]
        dq[..., p] = lut_d[idx]
    return q, dq


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
    d = deq_blocks.astype(np.float32)
    e = (d * d).mean(axis=(3, 4), dtype=np.float64)
    return e @ np.asarray(weights, dtype=np.float64)
