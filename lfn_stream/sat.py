"""Summed-area tables: exact box-filtered targets at the scale each width stands for.

Integer images give integer SATs (int64), so box sums are exact however large the image; the
division by the box area happens once, in float64. No float32 cancellation.

Fractional boxes (:func:`box_mean_frac`, :func:`box_mean_frac_torch`): the SAT at a real point
(y, x) is the integral of the piecewise-constant image over [0, y] × [0, x]; inside one pixel
that integral is bilinear in (y, x), so bilinear interpolation of the table at its four integer
corners gives it exactly. A box of any real side k ≥ 1 (the reciprocal of a width's exact image
scale) then costs four interpolated reads, like an integer box.
"""
from __future__ import annotations

import numpy as np


def summed_area_table(img: np.ndarray) -> np.ndarray:
    """(N, H, W, C) images → (N, H+1, W+1, C) int64 (float64 for float input) SATs, zero first row/col."""
    acc = np.int64 if img.dtype.kind in "ui" else np.float64
    s = np.zeros((img.shape[0], img.shape[1] + 1, img.shape[2] + 1, img.shape[3]), dtype=acc)
    s[:, 1:, 1:] = img.astype(acc).cumsum(1).cumsum(2)
    return s


def box_mean(sat: np.ndarray, view: np.ndarray, y: np.ndarray, x: np.ndarray, k: np.ndarray) -> np.ndarray:
    """Mean of the k×k box around pixel (y, x) of each view, clipped to the image.

    Args:
        sat: (N, H+1, W+1, C) from :func:`summed_area_table`.
        view, y, x: (M,) integer view indices and pixel coordinates.
        k: (M,) integer box sizes >= 1 (pixels).

    Returns:
        (M, C) float64 means.
    """
    h, w = sat.shape[1] - 1, sat.shape[2] - 1
    k = np.maximum(np.asarray(k, dtype=np.int64), 1)
    y0 = np.clip(y - (k - 1) // 2, 0, h)
    x0 = np.clip(x - (k - 1) // 2, 0, w)
    y1 = np.clip(y0 + k, 0, h)
    x1 = np.clip(x0 + k, 0, w)
    s = sat[view, y1, x1] - sat[view, y0, x1] - sat[view, y1, x0] + sat[view, y0, x0]
    area = ((y1 - y0) * (x1 - x0)).astype(np.float64)
    return s / area[:, None]


def area_downsample(img: np.ndarray, scale: float) -> np.ndarray:
    """Area-average an (H, W, C) image to (round(H·scale), round(W·scale)) (OpenCV INTER_AREA)."""
    import cv2

    h, w = img.shape[:2]
    nh, nw = max(1, round(h * scale)), max(1, round(w * scale))
    out = cv2.resize(img.astype(np.float32), (nw, nh), interpolation=cv2.INTER_AREA)
    return out.reshape(nh, nw, -1)


def box_mean_torch(sat, view, y, x, k: int):
    """:func:`box_mean` on torch tensors (SAT as float64 holding exact integer sums)."""
    import torch

    h, w = sat.shape[1] - 1, sat.shape[2] - 1
    y0 = torch.clamp(y - (k - 1) // 2, 0, h)
    x0 = torch.clamp(x - (k - 1) // 2, 0, w)
    y1 = torch.clamp(y0 + k, 0, h)
    x1 = torch.clamp(x0 + k, 0, w)
    s = sat[view, y1, x1] - sat[view, y0, x1] - sat[view, y1, x0] + sat[view, y0, x0]
    return s / ((y1 - y0) * (x1 - x0)).to(sat.dtype)[:, None]


def _frac_bounds(lib, y, x, k, h: int, w: int):
    """Box [cy − k/2, cy + k/2] × [cx − k/2, cx + k/2] about the pixel centres, clipped."""
    cy, cx, r = y + 0.5, x + 0.5, k / 2.0
    return (lib.clip(cy - r, 0, h), lib.clip(cy + r, 0, h), lib.clip(cx - r, 0, w), lib.clip(cx + r, 0, w))


def box_mean_frac(sat: np.ndarray, view, y, x, k) -> np.ndarray:
    """Mean of the image over the k×k box (k real, ≥ 1, pixels) centred on pixel (y, x), clipped
    to the image: (M, C) float64 from (M,) views, rows, columns and sides (k = 1: the pixel)."""
    h, w = sat.shape[1] - 1, sat.shape[2] - 1
    y, x, k = (np.asarray(a, np.float64) for a in (y, x, k))
    y0, y1, x0, x1 = _frac_bounds(np, y, x, np.maximum(k, 1.0), h, w)

    def at(yf, xf):
        i = np.minimum(np.floor(yf).astype(np.int64), h - 1)
        j = np.minimum(np.floor(xf).astype(np.int64), w - 1)
        fy, fx = (yf - i)[:, None], (xf - j)[:, None]
        s = sat.astype(np.float64, copy=False)
        return ((1 - fy) * ((1 - fx) * s[view, i, j] + fx * s[view, i, j + 1])
                + fy * ((1 - fx) * s[view, i + 1, j] + fx * s[view, i + 1, j + 1]))

    tot = at(y1, x1) - at(y0, x1) - at(y1, x0) + at(y0, x0)
    return tot / ((y1 - y0) * (x1 - x0))[:, None]


def box_mean_frac_torch(sat, view, y, x, k):
    """:func:`box_mean_frac` on torch tensors (SAT as float64): ``k`` is one real side for all
    rays, or a float64 tensor (M,) of sides, one per ray."""
    import torch

    h, w = sat.shape[1] - 1, sat.shape[2] - 1
    k = torch.clamp(k, min=1.0) if torch.is_tensor(k) else max(float(k), 1.0)
    y0, y1, x0, x1 = _frac_bounds(torch, y.double(), x.double(), k, h, w)

    def at(yf, xf):
        i = torch.clamp(torch.floor(yf).long(), max=h - 1)
        j = torch.clamp(torch.floor(xf).long(), max=w - 1)
        fy, fx = (yf - i)[:, None], (xf - j)[:, None]
        return ((1 - fy) * ((1 - fx) * sat[view, i, j] + fx * sat[view, i, j + 1])
                + fy * ((1 - fx) * sat[view, i + 1, j] + fx * sat[view, i + 1, j + 1]))

    tot = at(y1, x1) - at(y0, x1) - at(y1, x0) + at(y0, x0)
    return tot / ((y1 - y0) * (x1 - x0))[:, None]
