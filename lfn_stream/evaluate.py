"""Held-out evaluation of an LFN stream, per level, beside two trivial baselines.

For each level (width) w: render each held-out view at w's scale, compare with the
area-downsampled reference (RGB premultiplied on black; alpha too when present), and report
PSNR, SSIM, the bytes of the file prefix that level needs, and the render time per 256² view.
Baselines on the same views and scale: the nearest training view (camera distance) and the
mean of the training views.
"""
from __future__ import annotations

import math
import time

import numpy as np

from formats.lightfield import LightField

from .pack import step_name, step_offsets
from .render import LfnRenderer
from .sat import area_downsample
from .train import targets_of


def _ssim(a: np.ndarray, b: np.ndarray) -> float:
    """SSIM of two (h, w, c) images in [0, 1]; NaN where the image is smaller than SSIM's 7-px
    window (tiny low levels), which the caller reports as None."""
    from skimage.metrics import structural_similarity

    if min(a.shape[:2]) < 7:
        return float("nan")
    return float(structural_similarity(a, b, channel_axis=-1, data_range=1.0))


def prefix_bytes(r: LfnRenderer, level: float) -> int:
    """Bytes of the file prefix holding the network a level needs (header, meta, base,
    occupancy, steps; version 3: up to the end of the checksum chunk holding the last step)."""
    c = r.file.container
    n = int(math.ceil(level - 1e-9)) - r.cfg.min_neurons
    names = ["lfn.base"] + (["lfn.occ"] if c.has("lfn.occ") else [])
    end = max(c.info(nm).offset + c.info(nm).length for nm in names)
    if n <= 0:
        return end
    if c.has("lfn.steps"):
        s = c.info("lfn.steps")
        stop = int(step_offsets(r.cfg, r.dtype_w)[n])
        return s.offset + min(-(-stop // s.chunk_size) * s.chunk_size, s.length)
    return max(end, *(c.info(step_name(j)).offset + c.info(step_name(j)).length for j in range(n)))


def evaluate(r: LfnRenderer, lf: LightField, test_views, train_views, levels, baselines: bool = True) -> list[dict]:
    """Rows of level, width, scale, bytes, PSNR, SSIM, render ms per 256² view (+ baselines)."""
    peak = float(np.iinfo(lf.views.dtype).max)
    flat = lf.views.reshape(-1, lf.height, lf.width, lf.channels)
    tg = targets_of(flat, lf.has_alpha).astype(np.float32) / peak        # (N, H, W, 4)
    nch = 4 if lf.has_alpha else 3
    pos = lf.positions.reshape(-1, 3)
    rows = []
    for level in levels:
        scale = r.cfg.scale_of(level)
        ps, ss, ts, npx = [], [], 0.0, 0
        base_near, base_mean = [], []
        mean_img = None
        if baselines:
            mean_img = area_downsample(tg[train_views].mean(0), scale)[..., :nch]
        for v in test_views:
            ref = area_downsample(tg[v], scale)[..., :nch]
            t = time.perf_counter()
            img = r.render(v // lf.cols, v % lf.cols, level, scale)[..., :nch]
            ts += time.perf_counter() - t
            npx += img.shape[0] * img.shape[1]
            ps.append(np.mean((img - ref) ** 2))
            ss.append(_ssim(np.clip(img, 0, 1), ref))
            if baselines:
                near = train_views[int(np.argmin(np.linalg.norm(pos[train_views] - pos[v], axis=1)))]
                base_near.append(np.mean((area_downsample(tg[near], scale)[..., :nch] - ref) ** 2))
                base_mean.append(np.mean((mean_img - ref) ** 2))
        row = {"level": level, "neurons": level, "scale": scale, "bytes": prefix_bytes(r, level),
               "psnr": 10 * math.log10(1 / float(np.mean(ps))),
               "ssim": None if np.isnan(ss).all() else float(np.nanmean(ss)),
               "ms_per_256sq": 1e3 * ts / npx * 65536}
        if baselines:
            row["psnr_nearest_view"] = 10 * math.log10(1 / float(np.mean(base_near)))
            row["psnr_mean_view"] = 10 * math.log10(1 / float(np.mean(base_mean)))
        rows.append(row)
    return rows
