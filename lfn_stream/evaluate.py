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

from .config import LfnConfig
from .rays import view_rays
from .render import LfnRenderer
from .stream import first_renderable_end, prefix_bytes  # noqa: F401 (imported from here by tools and tests)
from .sat import area_downsample
from .training import targets_of


def _ssim(a: np.ndarray, b: np.ndarray) -> float:
    """SSIM of two (h, w, c) images in [0, 1] (:func:`formats.metrics.ssim_image`, scikit-image's
    definition); NaN where the image is smaller than SSIM's 7-px window (tiny low levels), which
    the caller reports as None."""
    from formats.metrics import SSIM_WIN, ssim_image

    if min(a.shape[:2]) < SSIM_WIN:
        return float("nan")
    return ssim_image(a, b, 1.0)


def evaluate(r: LfnRenderer, lf: LightField, test_views, train_views, levels, baselines: bool = True) -> list[dict]:
    """Rows of level, width, scale, bytes, PSNR, SSIM, render ms per 256² view (+ baselines);
    ``r`` an :class:`LfnRenderer` or a tile set (:class:`lfn_stream.tiles.TiledLfnRenderer`)."""
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


DISPLAY_RAYS = 16384       # training rays sample_rays draws by default
DISPLAY_MARGIN_DB = 0.5    # a size joins a ladder when it beats every smaller listed one by this much
DISPLAY_TAIL_DB = 0.1      # ... and a per-scale ladder ends at its best size when that beats the last by this
DISPLAY_SCALES = (0.125, 0.25, 0.5, 1.0)   # display scales (of the views) a ladder is measured at
DISPLAY_VIEWS = 10         # training views rendered per scale, evenly spread over the capture ...
DISPLAY_PIXELS = 32768     # ... at most this many pixels per scale (fewer views at large scales)


def size_psnr(model, rays, targets, cfg: LfnConfig) -> np.ndarray:
    """PSNR (dB) of every integer size min_neurons..max_neurons on the same rays.

    Args:
        model: a :class:`~lfn_stream.model.NestedLFN`; rays: (N, 6) float32 Plücker rays;
            targets: (N, 4) float32 premultiplied RGBA in [0, 1].
    Returns:
        (max_neurons − min_neurons + 1,) float64.
    """
    import torch

    model.eval()
    out = []
    with torch.no_grad():
        dev = next(model.parameters()).device          # the model's device (a GPU where it was trained)
        x, t = torch.as_tensor(rays).to(dev), torch.as_tensor(targets).to(dev)
        for w in range(cfg.min_neurons, cfg.max_neurons + 1):
            mse = float(((model(x, float(w)) - t) ** 2).mean())
            out.append(10 * math.log10(1 / max(mse, 1e-12)))
    return np.asarray(out)


def display_samples(lf: LightField, train_views, norm: dict, scale: float):
    """(rays (N, 6) float32, targets (N, 4) float32): up to DISPLAY_VIEWS training views, evenly
    spread, rendered at ``scale`` (rays through the pixel centres of the scaled view, targets the
    area-downsampled view: what a display at that scale shows and is compared with), at most
    DISPLAY_PIXELS pixels in all: fewer views at large scales, and where one view alone holds
    more, every k-th of its pixels."""
    h, w = max(1, round(lf.height * scale)), max(1, round(lf.width * scale))
    views = np.asarray(train_views)
    n = max(1, min(DISPLAY_VIEWS, len(views), DISPLAY_PIXELS // (h * w)))
    step = -(-(h * w) // DISPLAY_PIXELS)          # 1 unless one view is over the budget
    pick = views[np.linspace(0, len(views) - 1, n).round().astype(int)]
    flat = lf.views.reshape(-1, lf.height, lf.width, lf.channels)
    peak = float(np.iinfo(lf.views.dtype).max)
    rays, tg = [], []
    for v in pick:
        r = view_rays(lf, int(v), scale, norm["centre"], norm["radius"])
        t = area_downsample(targets_of(flat[v][None], lf.has_alpha)[0].astype(np.float32) / peak, scale)
        rays.append(r.reshape(-1, 6)[::step])
        tg.append(t.reshape(-1, t.shape[-1])[::step])
    return np.concatenate(rays), np.concatenate(tg)


def measure_display_ladders(model, lf: LightField, train_views, norm: dict, device: str = "cpu",
                            view_scale: float = 1.0) -> tuple[list[int], list[list]]:
    """The display ladders of a trained network, measured on training views of ``lf`` (the views
    it trained on) rendered at each of DISPLAY_SCALES (held-out views stay unseen) on
    ``device``; the model is left on the CPU.

    Args:
        view_scale: the size of ``lf``'s views relative to the views the file describes (a
            network trained at reduced resolution: e.g. 0.5 for 128 px of 256 px views); the
            ladders are stored at the file's scales (DISPLAY_SCALES × view_scale).
    Returns:
        (``display``: the ladder at scale 1 of ``lf`` with the full size appended (what readers
        that do not know ``display_scales`` use), ``display_scales``: [[scale of the file's
        views, ladder], ...], each ladder ending at its best size, the full size only where it
        is best).
    """
    try:
        model.to(device)
        per_scale = []
        for s in DISPLAY_SCALES:
            rays, targets = display_samples(lf, train_views, norm, s)
            psnr = size_psnr(model, rays, targets, model.cfg)
            per_scale.append([s * view_scale, display_ladder(psnr, model.cfg, full=False, tail_db=DISPLAY_TAIL_DB)])
    finally:
        model.cpu()
    top = per_scale[-1][1]
    return top + ([model.cfg.max_neurons] if top[-1] != model.cfg.max_neurons else []), per_scale


def display_ladder(psnr: np.ndarray, cfg: LfnConfig, margin_db: float = DISPLAY_MARGIN_DB,
                   full: bool = True, tail_db: float | None = None) -> list[int]:
    """The sizes worth displaying: the base size, then each size whose PSNR beats every smaller
    listed size's by ``margin_db``; then (``tail_db``) the best size, where it lies above the
    last listed one and beats it by ``tail_db`` (so a large margin does not leave the end of the
    stream short of the best network); and (``full``) the full size (the whole file shows the
    whole network). A renderer holding the steps up to size j shows the largest listed size ≤ j,
    so quality (where ``psnr`` was measured) never falls as bytes arrive (up to the full size,
    when it is appended)."""
    sizes, best = [cfg.min_neurons], float(psnr[0])
    for i in range(1, len(psnr)):
        if psnr[i] >= best + margin_db:
            sizes.append(cfg.min_neurons + i)
            best = float(psnr[i])
    top = int(np.argmax(psnr))
    if tail_db is not None and cfg.min_neurons + top > sizes[-1] and psnr[top] >= best + tail_db:
        sizes.append(cfg.min_neurons + top)
    if full and sizes[-1] != cfg.max_neurons:
        sizes.append(cfg.max_neurons)
    return sizes


def sample_rays(lf: LightField, views, norm: dict, count: int = DISPLAY_RAYS, seed: int = 0):
    """(rays (N, 6) float32, targets (N, 4) float32): ``count`` pixels drawn uniformly from the
    given views at the scene's resolution (with replacement), as the network sees them."""
    rng = np.random.default_rng(seed)
    views = np.asarray(views)
    v = views[rng.integers(0, len(views), count)]
    y, x = rng.integers(0, lf.height, count), rng.integers(0, lf.width, count)
    flat = lf.views.reshape(-1, lf.height, lf.width, lf.channels)
    peak = float(np.iinfo(lf.views.dtype).max)
    rays, tg = np.empty((count, 6), np.float32), np.empty((count, 4), np.float32)
    for u in np.unique(v):                      # one view's rays at a time (bounded memory)
        sel = v == u
        r = view_rays(lf, int(u), 1.0, norm["centre"], norm["radius"])
        rays[sel] = r[y[sel], x[sel]]
        tg[sel] = targets_of(flat[u][y[sel], x[sel]][None], lf.has_alpha)[0] / peak
    return rays, tg
