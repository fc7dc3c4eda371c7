"""Quality and rate metrics, one definition everywhere (CLI --json, tests, benchmarks).

- bpp = 8 × file bytes / (views × H × W): bits per pixel of a view, all channels together.
- PSNR_RGB = 10·log10(peak² / MSE), MSE pooled over all views, pixels and channels;
  peak = 255 (8-bit), 65535 (16-bit), 1.0 (float).
- PSNR_YCoCg = (6·PSNR_Y + PSNR_Co + PSNR_Cg) / 8 on the YCoCg-R planes, same peak
  (grey input: PSNR_Y).
- SSIM = scikit-image structural_similarity per view (channel_axis=-1, data_range=peak),
  averaged over views.
"""
from __future__ import annotations

import math

import numpy as np


def peak_of(dtype) -> float:
    return {np.dtype(np.uint8): 255.0, np.dtype(np.uint16): 65535.0}.get(np.dtype(dtype), 1.0)


def _psnr_from_mse(mse: float, peak: float) -> float:
    return float("inf") if mse == 0 else 10.0 * math.log10(peak * peak / mse)


def mse(ref: np.ndarray, dec: np.ndarray) -> float:
    """Mean squared error pooled over every element, computed in float64 in chunks."""
    ref = ref.reshape(-1, *ref.shape[-3:]) if ref.ndim > 3 else ref[None]
    dec = dec.reshape(ref.shape)
    tot = 0.0
    for i in range(0, ref.shape[0], 8):
        d = ref[i:i + 8].astype(np.float64) - dec[i:i + 8]
        tot += float((d * d).sum())
    return tot / ref.size


def psnr_rgb(ref: np.ndarray, dec: np.ndarray, peak: float | None = None) -> float:
    """PSNR over all views, pixels and channels (dB; inf when identical)."""
    return _psnr_from_mse(mse(ref, dec), peak or peak_of(ref.dtype))


def psnr_ycocg(ref: np.ndarray, dec: np.ndarray, peak: float | None = None) -> float:
    """The RLFC paper's weighted PSNR (6·Y + Co + Cg)/8 on YCoCg-R planes (grey: Y only)."""
    from rlfc.color import to_planes

    peak = peak or peak_of(ref.dtype)
    c = ref.shape[-1]
    if c in (1, 2):
        return psnr_rgb(ref[..., :1], dec[..., :1], peak)
    sums = np.zeros(3)
    flat_r = ref.reshape(-1, *ref.shape[-3:])
    flat_d = dec.reshape(flat_r.shape)
    for i in range(0, flat_r.shape[0], 8):
        d = (to_planes(flat_r[i:i + 8, ..., :3]) - to_planes(flat_d[i:i + 8, ..., :3])).astype(np.float64)
        sums += (d * d).reshape(-1, 3).sum(0)
    n = flat_r[..., 0].size
    ps = [_psnr_from_mse(s / n, peak) for s in sums]
    if any(math.isinf(p) for p in ps):
        return float("inf") if all(math.isinf(p) for p in ps) else (6 * min(ps[0], 200) + min(ps[1], 200) + min(ps[2], 200)) / 8
    return (6 * ps[0] + ps[1] + ps[2]) / 8


def ssim(ref: np.ndarray, dec: np.ndarray, peak: float | None = None) -> float:
    """Mean SSIM over views (scikit-image, channel_axis=-1, data_range=peak)."""
    from skimage.metrics import structural_similarity

    peak = peak or peak_of(ref.dtype)
    r = ref.reshape(-1, *ref.shape[-3:])
    d = dec.reshape(r.shape)
    vals = [structural_similarity(a, b, channel_axis=-1, data_range=peak) if min(a.shape[:2]) >= 7 else
            float(np.all(a == b)) for a, b in zip(r, d)]
    return float(np.mean(vals))


def bpp(nbytes: int, n_views: int, height: int, width: int) -> float:
    """Bits per pixel of a view: 8 × bytes / (views × H × W)."""
    return 8.0 * nbytes / (n_views * height * width)
