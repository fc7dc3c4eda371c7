"""The 8×8 integer transform of the ``tx`` profile (H.265/HEVC's DCT approximation) and its
scan order.

Decoders reconstruct exactly in integers (int64, numpy or torch): for a block X of dequantized
coefficients (orthonormal-DCT units), residual = ((T^T · X + 64) >> 7 · T + 128) >> 8, i.e.
Y = (T^T X + 64) >> 7 (columns), R = (Y T + 128) >> 8 (rows), arithmetic shifts. T ≈ 64·√8·C
(C the orthonormal DCT-II), so T^T X T / 2^15 ≈ C^T X C. Encoders analyse with the exact
float inverse of that synthesis (:data:`FORWARD_SCAN`) and reconstruct with the integer inverse
(closed loop), so every decoder agrees bit for bit.
"""
from __future__ import annotations

import numpy as np

from .xp import shared

#: HEVC's 8-point DCT matrix (rows = basis functions); on-wire constants, do not change.
T8 = np.array([
    [64, 64, 64, 64, 64, 64, 64, 64],
    [89, 75, 50, 18, -18, -50, -75, -89],
    [83, 36, -36, -83, -83, -36, 36, 83],
    [75, -18, -89, -50, 50, 89, 18, -75],
    [64, -64, -64, 64, 64, -64, -64, 64],
    [50, -89, 18, 75, -75, -18, 89, -50],
    [36, -83, 83, -36, -36, 83, -83, 36],
    [18, -50, 75, -89, 89, -75, 50, -18],
], dtype=np.int64)

#: zig-zag scan of an 8×8 block: ZIGZAG[i] = raster index (row·8 + col) of scan position i.
ZIGZAG = np.array(sorted(range(64), key=lambda k: (k // 8 + k % 8, (k % 8) if (k // 8 + k % 8) % 2 == 0 else k // 8)),
                  dtype=np.int64)
#: inverse: scan position of each raster index.
UNZIG = np.argsort(ZIGZAG)

#: coefficient magnitude bound the decoder clips to (orthonormal units; 16-bit residuals need 2^20)
COEF_MAX = (1 << 21) - 1

# the encoder's analysis: the exact inverse of the synthesis R = T^T X T / 2^15, i.e.
# X = 2^15 · (T^T)^-1 R T^-1 (T is only nearly orthogonal, so the float DCT would miss by a few
# grey levels on large residuals)
_F = np.linalg.inv(T8.T.astype(np.float64)) * np.sqrt(2.0 ** 15)


#: the encoder's float analysis as one (64, 64) matrix on raster-flattened blocks, zig-zag scan
#: applied to its output: ``r.reshape(-1, 64) @ FORWARD_SCAN`` = the scan-order coefficients
#: whose exact synthesis is r (≈ the orthonormal DCT); quantize them and :func:`inverse` gives r
#: back within about ±1
FORWARD_SCAN = np.ascontiguousarray(np.kron(_F, _F).T[:, ZIGZAG])


def inverse(X: np.ndarray) -> np.ndarray:
    """Exact integer inverse of (..., 8, 8) int64 coefficient blocks, (..., 8, 8) int64 (the
    definition; decoders call :func:`inverse_float`, numpy or torch, which gives its integers)."""
    n = X.size // 64
    if n and int(np.abs(X).max()) < _FLOAT_EXACT:
        return _inverse_gemm(X.reshape(n, 8, 8)).reshape(X.shape)
    Y = (np.matmul(T8.T, X) + 64) >> 7
    return (np.matmul(Y, T8) + 128) >> 8


#: coefficients below this magnitude are transformed in float64 exactly: every
#: product and partial sum is an integer below 2^53 (8·89·2^40 < 2^50)
_FLOAT_EXACT = 1 << 40
_T8F = T8.astype(np.float64)


def _inverse_gemm(X: np.ndarray) -> np.ndarray:
    """(n, 8, 8) int64 → the integers of :func:`inverse` through float64 matrix products (the
    shifts as exact floors); measured 2.2× faster than int64 matmul."""
    return inverse_float(X.astype(np.float64)).astype(np.int64)


def inverse_float(X):
    """:func:`inverse` of (..., 8, 8) float64 blocks holding integers of magnitude below
    2^40, as float64 integers (exact), numpy or torch (on any device: the products and sums
    are integers below 2^53, exact in any order and with fused multiply-adds)."""
    if not isinstance(X, np.ndarray):
        import torch

        t = _torch_t8f(X.device)
        Y = torch.matmul(t.T, X).add_(64).mul_(1 / 128).floor_()
        return torch.matmul(Y, t).add_(128).mul_(1 / 256).floor_()
    # numpy: the shifts folded into the matrices, (a + 64) >> 7 = floor(a / 128 + 1/2): the
    # products and sums are integers below 2^53 over a power of two, exact as before (one pass
    # less per stage)
    Y = np.matmul(_T8F_128T, X)
    Y += 0.5
    np.floor(Y, out=Y)
    R = np.matmul(Y, _T8F_256)
    R += 0.5
    return np.floor(R, out=R)


_T8F_128T = np.ascontiguousarray(_T8F.T / 128)
_T8F_256 = _T8F / 256


def inverse_interleaved(X: np.ndarray, C: int) -> np.ndarray:
    """:func:`inverse_float` of (n, 8, 8·C) float64 blocks whose C channels are interleaved
    along the rows (element [i, y, x·C + c] is channel c's coefficient at raster (y, x)), the
    same layout out, exact: the column pass is one product for every channel, the row pass one
    product with kron(T/256, I_C) (its zeros add exact zeros)."""
    Y = np.matmul(_T8F_128T, X)
    Y += 0.5
    np.floor(Y, out=Y)
    R = np.matmul(Y, _kron_256(C))
    R += 0.5
    return np.floor(R, out=R)


_KRON_256: dict = {}


def _kron_256(C: int) -> np.ndarray:
    got = _KRON_256.get(C)
    if got is None:
        got = _KRON_256[C] = np.kron(_T8F_256, np.eye(C))
    return got


_T8F_TORCH: dict = {}


def _torch_t8f(device):
    import torch

    key = str(device)
    if key not in _T8F_TORCH:
        _T8F_TORCH[key] = shared(torch.as_tensor(_T8F, device=device))
    return _T8F_TORCH[key]
