"""Foveated LFN rendering: time and transition artefacts of per-pixel network sizes.

For an LFN file and a few captured views, renders each view (at the scene's resolution) with
- the full network (every pixel at max neurons): the reference time and image;
- ``per-level``: the earlier method, sizes rounded to 1/8 neuron and ordered-dithered, one
  network pass per distinct size (what ``render_lod_map`` did before);
- ``exact, P passes``: every pixel at its own fractional size, grouped into at most P passes
  (:meth:`lfn_stream.LfnRenderer.render_rays_lod`), no dithering.

Reports ms per view, the ratio to the full-width render (issue 17: ≤ 0.6×), network passes,
and two image measures against the full-width render: PSNR inside the fovea (must be exact up
to rounding) and the *transition roughness* — the mean absolute Laplacian of (foveated − full)
over the pixels between the inner and outer radius, in grey levels: ordered dither and level
steps show up there as pixel-scale patterns and rings, a continuous size map does not.

Usage:
    python -m tools.bench_foveation FILE.lfc [--views 0 7 33] [--rounds 3] [--out JSON]
"""
from __future__ import annotations

import argparse
import json
import time

import numpy as np
import torch

from formats.lfcfile import open_lfc
from lfn_stream import LfnRenderer
from tools.common import log, machine


def per_level(r: LfnRenderer, row: int, col: int, lod: np.ndarray) -> tuple[np.ndarray, int]:
    """The earlier method: one network pass per distinct size (sizes already quantized)."""
    rays = r.view_rays(row, col, 1.0).reshape(-1, 6)
    out = np.zeros((rays.shape[0], 4), np.float32)
    levels = np.unique(lod.reshape(-1))
    for lv in levels:
        sel = np.flatnonzero(lod.reshape(-1) == lv)
        out[sel] = r.render_rays(rays[sel], float(lv))
    return out.reshape(r.height, r.width, 4), int(levels.size)


def roughness(img: np.ndarray, ref: np.ndarray, band: np.ndarray) -> float:
    """Mean |4-neighbour Laplacian| of (img − ref) (RGB, grey levels of 255) over ``band``."""
    d = (img[..., :3].astype(np.float64) - ref[..., :3]) * 255
    lap = np.abs(4 * d[1:-1, 1:-1] - d[:-2, 1:-1] - d[2:, 1:-1] - d[1:-1, :-2] - d[1:-1, 2:]).mean(-1)
    return float(lap[band[1:-1, 1:-1]].mean())


def psnr_in(img: np.ndarray, ref: np.ndarray, mask: np.ndarray) -> float:
    mse = float(np.mean((img[mask][:, :3] - ref[mask][:, :3]) ** 2))
    return float("inf") if mse == 0 else 10 * np.log10(1 / mse)


def timed(fn, rounds: int):
    ts, out = [], None
    for _ in range(rounds):
        t = time.perf_counter()
        out = fn()
        ts.append(time.perf_counter() - t)
    return float(np.median(ts)) * 1e3, out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("file")
    ap.add_argument("--views", type=int, nargs="+", default=[0])
    ap.add_argument("--rounds", type=int, default=3)
    ap.add_argument("--inner", type=float, default=0.1)
    ap.add_argument("--outer", type=float, default=0.5)
    ap.add_argument("--threads", type=int, default=1)
    ap.add_argument("--out", default=None)
    a = ap.parse_args(argv)
    torch.set_num_threads(a.threads)
    r = LfnRenderer(open_lfc(a.file), device="cpu")
    rows = []
    for v in a.views:
        row, col = divmod(v, r.cols)
        gaze = (r.width * 0.5, r.height * 0.5)
        ys, xs = np.mgrid[0:r.height, 0:r.width] + 0.5
        e = np.hypot(xs - gaze[0], ys - gaze[1]) / float(np.hypot(r.height, r.width))
        fovea, band = e < a.inner, (e >= a.inner) & (e <= a.outer)
        t_full, full = timed(lambda: r.render(row, col, r.neurons, 1.0), a.rounds)
        old_map = np.clip(np.round(r.foveation_map(gaze, a.inner, a.outer, dither=True) * 8) / 8, *r.neuron_range)
        t_old, (old, n_old) = timed(lambda: per_level(r, row, col, old_map), a.rounds)
        exact_map = r.foveation_map(gaze, a.inner, a.outer)
        res = {"view": v, "pixels": r.height * r.width, "full_ms": round(t_full, 1),
               "mean_neurons": round(float(exact_map.mean()), 2),
               "per_level": {"ms": round(t_old, 1), "ratio": round(t_old / t_full, 3), "passes": n_old,
                             "fovea_psnr": psnr_in(old, full, fovea), "roughness": round(roughness(old, full, band), 3)}}
        for p in (1, 2, 4):
            t_new, new = timed(lambda: r.render_lod_map(row, col, exact_map, passes=p), a.rounds)
            res[f"exact_{p}"] = {"ms": round(t_new, 1), "ratio": round(t_new / t_full, 3), "passes": p,
                                 "fovea_psnr": psnr_in(new, full, fovea),
                                 "roughness": round(roughness(new, full, band), 3)}
        log(json.dumps(res))
        rows.append(res)
    out = {"file": a.file, "machine": machine(), "threads": a.threads, "inner": a.inner, "outer": a.outer,
           "neurons": [r.cfg.min_neurons, r.neurons], "views": rows}
    if a.out:
        with open(a.out, "w") as f:
            json.dump(out, f, indent=1, allow_nan=True)
    print(json.dumps(out, allow_nan=True))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
