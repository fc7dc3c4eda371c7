"""Summed-area tables: exact box-filtered targets at the scale each width stands for.

Integer images give integer SATs (int64), so box sums are exact however large the image; the
division by the box area happens once, in float64. No float32 cancellation.
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
