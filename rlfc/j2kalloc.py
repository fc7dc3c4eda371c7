"""How a pooled PSNR target is shared among images coded independently by JPEG 2000 (a posed
capture's views), without coding each image in another codec first.

One OpenJPEG quality level for every image (what a per-view JPEG 2000 coder does) gives every
image about the same PSNR. Sharing the error as one uniform quantizer step would (equal slopes at
high rate: textured images take more of the error, smooth ones less) costs fewer bytes: on the
LLFF captures at the same pooled PSNR, 0.5–2.8% fewer (BENCHMARKS.md). The transform path of the
``tx`` profile reached that sharing by coding every view in every pass of rate control (~50×
JPEG 2000's encode CPU); here it is estimated open loop: each image's 8×8 DCT coefficients
(YCoCg-R planes weighted by their share of the RGB error, one block in four), quantized to the
nearest multiple of one common step, give each image's PSNR at that step (:func:`share_psnrs`).
The images are then coded at those PSNRs plus one common shift, which rate control searches.
"""
from __future__ import annotations

import numpy as np

from formats.pixels import rgb_mse_weights, to_planes

#: OpenJPEG levels asked (dB)
MIN_LEVEL, MAX_LEVEL = 1.0, 99.0
#: every SAMPLE_STRIDE-th 8×8 block row and column is measured
SAMPLE_STRIDE = 2

_K = np.arange(8)
_DCT = np.sqrt(2 / 8) * np.cos(np.pi * (2 * _K[None, :] + 1) * _K[:, None] / 16)
_DCT[0] /= np.sqrt(2)                         # orthonormal 8-point DCT-II (rows: frequencies)


def dct_samples(pixels: np.ndarray) -> tuple[np.ndarray, int]:
    """An image's sampled 8×8 DCT coefficients, in units where a uniform quantizer of step Δ on
    every plane errs as the RGB error does (each plane's coefficients × √weight; the transform
    is orthonormal, so a coefficient's squared error is the pixels').

    Args:
        pixels: (H, W, C) uint8/uint16 image (C = 1 or 3; alpha has no colour weight).

    Returns:
        ((N,) float32 coefficients, pixels of the blocks sampled).
    """
    planes = to_planes(np.asarray(pixels))
    w = rgb_mse_weights(planes.shape[-1])
    h, wd = (planes.shape[0] // 8) * 8, (planes.shape[1] // 8) * 8
    keep = np.flatnonzero(w > 0)
    if h == 0 or wd == 0 or keep.size == 0:      # (smaller than a block: no sample)
        return np.zeros(0, np.float32), 0
    b = planes[:h, :wd, keep].astype(np.float32).reshape(h // 8, 8, wd // 8, 8, keep.size)
    b = b[::SAMPLE_STRIDE, :, ::SAMPLE_STRIDE].transpose(0, 2, 4, 1, 3)          # (by, bx, P, 8, 8)
    m = _DCT.astype(np.float32)
    c = (m @ b @ m.T) * np.sqrt(w[keep]).astype(np.float32)[:, None, None]
    return c.reshape(-1), b.shape[0] * b.shape[1] * 64


def smooth_psnr(pixels: np.ndarray) -> float:
    """How far an image is from smooth: PSNR (dB, colour channels) of its 8×-downsampled copy
    upsampled bilinearly, about what the transform path's thumbnail alone gives. Where this
    nears a target, the thumbnail + transform path can cost less than JPEG 2000 (gradients,
    flat renders: 50 dB and more); natural views stay far below (the LLFF captures: 27–34 dB)."""
    import cv2

    x = np.asarray(pixels, np.float32)
    c = x.shape[-1]
    x = x[..., :3] if c >= 3 else x[..., :1]
    h, w = x.shape[:2]
    small = cv2.resize(x, (max(w // 8, 1), max(h // 8, 1)), interpolation=cv2.INTER_AREA)
    up = cv2.resize(small, (w, h), interpolation=cv2.INTER_LINEAR).reshape(x.shape)
    mse = float(np.mean(np.square(x - up)))
    peak = float(np.iinfo(np.asarray(pixels).dtype).max)
    return 10 * np.log10(peak ** 2 / mse) if mse > 0 else float("inf")


def quantizer_mse(samples: list, step: float) -> np.ndarray:
    """(n,) each image's colour mean squared error per pixel under a uniform quantizer of
    ``step`` (nearest multiple), from ``samples`` as :func:`dct_samples` returns them (0 where
    an image has no sample)."""
    s = np.float32(step)
    return np.array([float(np.square(y - s * np.rint(y / s)).sum()) / px if px else 0.0 for y, px in samples])


def common_step(samples: list, cnt: np.ndarray, peak: float, target: float, tol: float = 0.02
                ) -> tuple[float, np.ndarray]:
    """The one quantizer step whose pooled PSNR is ``target`` (within ``tol`` dB), and (n,) each
    image's mean squared error there. ``cnt`` (n,): each image's weight in the pooled PSNR (its
    samples). (An all-zero set of coefficients, which no step errs on, gives the largest step
    tried and zeros.)"""
    cnt = np.asarray(cnt, np.float64)

    def pooled(step):
        mse = quantizer_mse(samples, step)
        return mse, 10 * np.log10(peak ** 2 * cnt.sum() / max(float((mse * cnt).sum()), 1e-30))

    # about −6 dB per octave of the step: secant steps on log2(step), bisection once bracketed
    q = float(np.log2(np.sqrt(12 * peak ** 2 * 10 ** (-target / 10))))
    lo = hi = None
    mse, p = pooled(2.0 ** q)
    for _ in range(40):
        if abs(p - target) <= tol:
            break
        if p > target:
            lo = q
        else:
            hi = q
        nq = (lo + hi) / 2 if lo is not None and hi is not None else q + (p - target) / 6.0
        nq = min(max(nq, -8.0, q - 8.0), 32.0, q + 8.0)       # (steps of 2^-8 .. 2^32 cover any image)
        if nq == q:
            break
        q = nq
        mse, p = pooled(2.0 ** q)
    return 2.0 ** q, mse


def share_psnrs(samples: list, cnt: np.ndarray, peak: float, target: float, tol: float = 0.02) -> np.ndarray:
    """(n,) each image's PSNR (dB) at the :func:`common_step` of ``target``: the images' shares
    of the error. Images a step does not err on (flat, or no sample) get the target."""
    _, mse = common_step(samples, cnt, peak, target, tol)
    with np.errstate(divide="ignore"):
        out = 10 * np.log10(peak ** 2 / mse)
    return np.where(np.isfinite(out), out, target)


def step_prior(samples: list, cnt: np.ndarray, peak: float, target: float) -> tuple[float, float]:
    """(the :func:`common_step` of ``target``, dB of pooled PSNR per octave of the step there),
    from the steps of target ± 1 dB: where a quantizer search over these images may start, and
    its prior slope (< 0)."""
    s_lo, _ = common_step(samples, cnt, peak, target - 1.0)
    s_hi, _ = common_step(samples, cnt, peak, target + 1.0)
    s, _ = common_step(samples, cnt, peak, target)
    octaves = float(np.log2(s_lo / s_hi))
    return s, (-2.0 / octaves if octaves > 1e-6 else -6.0)


__all__ = ["MIN_LEVEL", "MAX_LEVEL", "SAMPLE_STRIDE", "common_step", "dct_samples", "quantizer_mse", "share_psnrs",
           "smooth_psnr", "step_prior"]
