"""Ray sampling for training: foreground/background split and saliency weighting.

With a mask (alpha), 67% of a batch comes from foreground pixels and 33% from background;
foreground pixels are drawn with weight 0.4 + 0.6·saliency (saliency from OpenCV contrib's
spectral-residual detector, normalized to [0, 1] per view). Without a mask every pixel is
drawn with that weight.
"""
from __future__ import annotations

import numpy as np
import torch

FG_FRACTION = 0.67


def spectral_residual(grey: np.ndarray) -> np.ndarray:
    """Spectral-residual saliency (Hou & Zhang 2007) in numpy, as OpenCV's detector computes it
    (64×64 working size); used where opencv-contrib's saliency module is missing."""
    import cv2

    h, w = grey.shape
    g = cv2.resize(grey.astype(np.float32), (64, 64), interpolation=cv2.INTER_AREA)
    f = np.fft.fft2(g)
    logamp = np.log(np.abs(f) + 1e-9)
    resid = logamp - cv2.blur(logamp, (3, 3))
    sal = np.abs(np.fft.ifft2(np.exp(resid + 1j * np.angle(f)))) ** 2
    sal = cv2.GaussianBlur(sal.astype(np.float32), (9, 9), 2.5)
    return cv2.resize(sal, (w, h), interpolation=cv2.INTER_LINEAR)


def saliency_map(img: np.ndarray) -> np.ndarray:
    """(H, W, C) uint8/uint16 → (H, W) float32 saliency in [0, 1]."""
    import cv2

    rgb = img[..., :3] if img.shape[-1] >= 3 else np.repeat(img[..., :1], 3, axis=-1)
    if rgb.dtype != np.uint8:
        rgb = (rgb.astype(np.float32) / rgb.max(initial=1) * 255).astype(np.uint8)
    if hasattr(cv2, "saliency"):
        sal = cv2.saliency.StaticSaliencySpectralResidual_create()
        ok, m = sal.computeSaliency(np.ascontiguousarray(rgb[..., ::-1]))
        if not ok:
            return np.zeros(img.shape[:2], np.float32)
    else:
        m = spectral_residual(cv2.cvtColor(np.ascontiguousarray(rgb), cv2.COLOR_RGB2GRAY))
    m = m.astype(np.float32)
    lo, hi = float(m.min()), float(m.max())
    return (m - lo) / (hi - lo) if hi > lo else np.zeros_like(m)


class RaySampler:
    """Draws (view, y, x) pixel indices with the split and weights above.

    Args:
        views: (N, H, W, C) training views.
        alpha: (N, H, W) float alpha in [0, 1], or None.
    """

    def __init__(self, views: np.ndarray, alpha: np.ndarray | None):
        n, h, w = views.shape[:3]
        self.shape = (n, h, w)
        sal = np.stack([saliency_map(v) for v in views]).reshape(-1)
        weight = 0.4 + 0.6 * sal
        if alpha is not None:
            fg = alpha.reshape(-1) > 0
        else:
            fg = np.ones(n * h * w, dtype=bool)
        self.fg_idx = np.flatnonzero(fg)
        self.bg_idx = np.flatnonzero(~fg)
        wf = weight[self.fg_idx]
        self.fg_cdf = np.cumsum(wf) / wf.sum() if wf.size else None
        self.has_bg = self.bg_idx.size > 0 and alpha is not None

    def sample(self, count: int, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(view, y, x) int64 arrays of length ``count``."""
        n_fg = int(round(count * FG_FRACTION)) if self.has_bg else count
        if self.fg_cdf is None:
            n_fg = 0
        idx = np.empty(count, dtype=np.int64)
        if n_fg:
            idx[:n_fg] = self.fg_idx[np.minimum(np.searchsorted(self.fg_cdf, rng.random(n_fg)), self.fg_idx.size - 1)]
        if count > n_fg:
            pool = self.bg_idx if self.bg_idx.size else self.fg_idx
            idx[n_fg:] = pool[rng.integers(0, pool.size, count - n_fg)]
        n, h, w = self.shape
        v, rem = np.divmod(idx, h * w)
        y, x = np.divmod(rem, w)
        return v, y, x


class TorchRaySampler:
    """The same distribution as :class:`RaySampler`, drawn on a torch device (no host sync)."""

    def __init__(self, base: RaySampler, device):
        self.shape = base.shape
        self.has_bg = base.has_bg
        self.fg = torch.from_numpy(base.fg_idx).to(device)
        self.bg = torch.from_numpy(base.bg_idx if base.bg_idx.size else base.fg_idx).to(device)
        self.cdf = torch.from_numpy(base.fg_cdf).to(device, torch.float64) if base.fg_cdf is not None else None
        self.device = device

    def sample(self, count: int, gen) -> tuple:
        """(view, y, x) int64 tensors of length ``count`` on the device."""
        n_fg = int(round(count * FG_FRACTION)) if self.has_bg else count
        if self.cdf is None:
            n_fg = 0
        parts = []
        if n_fg:
            u = torch.rand(n_fg, generator=gen, device=self.device, dtype=torch.float64)
            parts.append(self.fg[torch.clamp(torch.searchsorted(self.cdf, u), max=self.fg.numel() - 1)])
        if count > n_fg:
            parts.append(self.bg[torch.randint(0, self.bg.numel(), (count - n_fg,), generator=gen, device=self.device)])
        idx = torch.cat(parts)
        n, h, w = self.shape
        return idx // (h * w), (idx % (h * w)) // w, idx % w
