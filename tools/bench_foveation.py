"""Foveated LFN rendering: time and transition artefacts of per-pixel network sizes.

For an LFN file and a few captured views, renders each view (at the scene's resolution) with
- the full network (every pixel at max neurons): the reference time and image;
- ``exact``: every pixel at its own fractional size, in 4 grouped passes
  (:meth:`lfn_stream.LfnRenderer.render_rays_lod`), no dithering: the reference transition;
- ``dither K``: each pixel at one of K integer sizes, interleaved-gradient-noise dither between
  neighbouring sizes (``foveation_map(dither=True, sizes=K)``), one fused pass per size;
- ``snap K``: the same K sizes, each pixel rounded to the nearest (no dither): level steps;
- ``native``: the full network rendered with ``native=True`` (on its own pixel grid where the
  frame is finer than the network was trained at, upsampled: no foveation);
- ``mip L``: the exact map drawn as mipmapping draws a texture
  (:meth:`lfn_stream.LfnRenderer.render_lod_mip`): lattices every 2^j pixels, j ≤ L, each at the
  size made for its scale, blended trilinearly; ``rays`` = network evaluations against the full
  render's (``--native``: each also with ``native=True``, on the network's own pixel grid).

Reports ms per view (medians; the modes are called in turn, round after round) and the ratio to
the full-width render (issue 17: ≤ 0.6×), and, against
the full render over the band between the inner and outer radius (grey levels of 255): PSNR
of one frame, of one frame seen through a 1-pixel Gaussian blur (what a display or an eye
integrates), and of the mean of 4 frames with the dither advancing (temporal dither); the
*ring error* (:func:`ring_error`: arcs and level steps around the gaze, the smooth loss of
detail with distance taken out); the transition roughness (mean |Laplacian| of (render −
full): pixel-scale noise); the fovea's PSNR (the full network up to rounding); and with
``--scene``, ``gt_psnr``: the band's PSNR against the captured view as the networks are trained
on it (:func:`lfn_stream.training.targets_of`: colour premultiplied by alpha), the measure of
what foveation loses that a viewer could see.

Usage:
    python -m tools.bench_foveation FILE.lfc [--views 0 7 33] [--rounds 3] [--sizes 4 8 16] [--mip 2 3]
        [--blend 1 0.25] [--bias 0] [--native] [--scene DIR] [--out JSON]
"""
from __future__ import annotations

import argparse
import json
import time

import numpy as np
import torch

from formats.lfcfile import open_lfc
from lfn_stream import LfnRenderer
from lfn_stream.foveation import MIP_BLEND, size_levels
from lfn_stream.training import targets_of
from tools.common import log, machine


def roughness(img: np.ndarray, ref: np.ndarray, band: np.ndarray) -> float:
    """Mean |4-neighbour Laplacian| of (img − ref) (RGB, grey levels of 255) over ``band``."""
    d = (img[..., :3].astype(np.float64) - ref[..., :3]) * 255
    lap = np.abs(4 * d[1:-1, 1:-1] - d[:-2, 1:-1] - d[2:, 1:-1] - d[1:-1, :-2] - d[1:-1, 2:]).mean(-1)
    return float(lap[band[1:-1, 1:-1]].mean())


def psnr_in(img: np.ndarray, ref: np.ndarray, mask: np.ndarray) -> float:
    mse = float(np.mean((img[mask][:, :3] - ref[mask][:, :3]) ** 2))
    return float("inf") if mse == 0 else 10 * np.log10(1 / mse)


def blur(img: np.ndarray, sigma: float = 1.0) -> np.ndarray:
    """RGB channels through a separable Gaussian of ``sigma`` pixels (edges reflected)."""
    r = int(np.ceil(3 * sigma))
    k = np.exp(-0.5 * (np.arange(-r, r + 1) / sigma) ** 2)
    k /= k.sum()
    out = img[..., :3].astype(np.float64)
    for axis in (0, 1):
        pad = [(r, r) if i == axis else (0, 0) for i in range(3)]
        p = np.pad(out, pad, mode="reflect")
        out = sum(k[i] * np.take(p, np.arange(i, i + out.shape[axis]), axis=axis) for i in range(k.size))
    return out


def ring_error(img: np.ndarray, ref: np.ndarray, radius: np.ndarray, angle: np.ndarray, band: np.ndarray,
               sectors: int = 16, window: int = 9) -> float:
    """Rings: the mean signed RGB difference (grey levels of 255) in cells of 1 pixel of radius
    × 1/``sectors`` of a turn around the gaze, minus its ``window``-pixel moving average along
    the radius (the smooth fall of detail with distance is what foveation is for), RMS over
    the cells (inside ``band``) with at least 8 pixels. Level steps and arcs show up here;
    dither noise averages out within a cell."""
    d = ((img[..., :3].astype(np.float64) - ref[..., :3]) * 255).mean(-1)[band]
    rb = np.floor(radius[band]).astype(np.int64)
    ab = np.floor((angle[band] + np.pi) / (2 * np.pi) * sectors).astype(np.int64) % sectors
    R = int(rb.max()) + 1
    cell = ab * R + rb
    n = np.bincount(cell, minlength=sectors * R).reshape(sectors, R)
    mean = np.bincount(cell, d, minlength=sectors * R).reshape(sectors, R) / np.maximum(n, 1)
    k = np.ones(window) / window
    res = []
    for a in range(sectors):
        ok = n[a] > 0
        p = np.interp(np.arange(R), np.flatnonzero(ok), mean[a][ok])
        smooth = np.convolve(np.pad(p, window // 2, mode="edge"), k, "valid")
        res.append((p - smooth)[n[a] >= 8])
    return float(np.sqrt(np.mean(np.concatenate(res) ** 2)))


def timed_modes(r, modes: dict, rounds: int) -> tuple[dict, dict, dict]:
    """Each mode's median ms, last image and network evaluations per call, the modes called in
    turn round after round (so that a noisy box's slow spells fall on every mode alike)."""
    ts = {k: [] for k in modes}
    imgs, rays = {}, {}
    for _ in range(rounds):
        for k, fn in modes.items():
            n0 = r.rays_evaluated
            t = time.perf_counter()
            imgs[k] = fn()
            ts[k].append(time.perf_counter() - t)
            rays[k] = r.rays_evaluated - n0
    return {k: float(np.median(v)) * 1e3 for k, v in ts.items()}, imgs, rays


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("file")
    ap.add_argument("--views", type=int, nargs="+", default=[0])
    ap.add_argument("--rounds", type=int, default=3)
    ap.add_argument("--inner", type=float, default=0.1)
    ap.add_argument("--outer", type=float, default=0.5)
    ap.add_argument("--sizes", type=int, nargs="+", default=[4, 8, 16])
    ap.add_argument("--mip", type=int, nargs="*", default=[3], help="render_lod_mip's max_level values to time")
    ap.add_argument("--blend", type=float, nargs="*", default=[MIP_BLEND], help="render_lod_mip's blend values")
    ap.add_argument("--bias", type=float, nargs="*", default=[0.0], help="render_lod_mip's bias values")
    ap.add_argument("--threads", type=int, default=1)
    ap.add_argument("--device", default="cpu", help="torch device the networks run on (cpu, cuda)")
    ap.add_argument("--scale", type=float, default=1.0,
                    help="render at this multiple of the views' size (a display's resolution)")
    ap.add_argument("--native", action="store_true", help="also each mip mode with native=True")
    ap.add_argument("--scene", default=None, help="the captured scene (scale 1 only): PSNR against its views")
    ap.add_argument("--out", default=None)
    a = ap.parse_args(argv)
    torch.set_num_threads(a.threads)
    r = LfnRenderer(open_lfc(a.file), device=a.device)
    lf = None
    if a.scene:
        from formats import read_scene

        lf = read_scene(a.scene)
        if a.scale != 1 or (lf.rows, lf.cols, lf.height, lf.width) != (r.rows, r.cols, r.height, r.width):
            raise SystemExit(f"{a.scene}: not the views of {a.file} at --scale 1")
    rows = []
    for v in a.views:
        row, col = divmod(v, r.cols)
        H, W = round(r.height * a.scale), round(r.width * a.scale)
        gaze = (W * 0.5, H * 0.5)
        ys, xs = np.mgrid[0:H, 0:W] + 0.5
        e = np.hypot(xs - gaze[0], ys - gaze[1]) / float(np.hypot(H, W))
        fovea, band = e < a.inner, (e >= a.inner) & (e <= a.outer)
        radius, angle = np.hypot(xs - gaze[0], ys - gaze[1]), np.arctan2(ys - gaze[1], xs - gaze[0])
        exact_map = r.foveation_map(gaze, a.inner, a.outer, dither=False, scale=a.scale)
        lo, hi = r.neuron_range
        modes = {"full": lambda: r.render(row, col, r.neurons, a.scale),
                 "native": lambda: r.render(row, col, r.neurons, a.scale, native=True),
                 "exact": lambda: r.render_lod_map(row, col, exact_map)}
        for k in a.sizes:
            dmap = r.foveation_map(gaze, a.inner, a.outer, dither=True, sizes=k, scale=a.scale)
            levels = size_levels(lo, hi, k)
            smap = levels[np.abs(exact_map[..., None] - levels).argmin(-1)]
            modes[f"dither_{k}"] = lambda m=dmap: r.render_lod_map(row, col, m)
            modes[f"snap_{k}"] = lambda m=smap: r.render_lod_map(row, col, m)
        for L, bl, bi in [(L, bl, bi) for L in a.mip for bl in a.blend for bi in a.bias]:
            modes[f"mip_{L}_{bl:g}_{bi:g}"] = lambda L=L, bl=bl, bi=bi: r.render_lod_mip(row, col, exact_map, max_level=L,
                                                                                       blend=bl, bias=bi)
            if a.native:
                modes[f"mip_{L}_{bl:g}_{bi:g}_native"] = lambda L=L, bl=bl, bi=bi: r.render_lod_mip(
                    row, col, exact_map, max_level=L, blend=bl, bias=bi, native=True)
        times, imgs, rays = timed_modes(r, modes, a.rounds)
        t_full, full, exact = times["full"], imgs["full"], imgs["exact"]

        gt = None
        if lf is not None:          # the networks' own targets: RGB premultiplied by alpha (grey as RGB)
            gt = targets_of(lf.views[row, col][None], lf.has_alpha)[0] / float(np.iinfo(lf.views.dtype).max)

        def measures(img, ms, frames=None):
            m = {"ms": round(ms, 1), "ratio": round(ms / t_full, 3),
                 "psnr": round(psnr_in(img, full, band), 2), "blur1_psnr": round(psnr_in(blur(img), blur(full), band), 2),
                 "ring_error": round(ring_error(img, full, radius, angle, band), 3),
                 "roughness": round(roughness(img, full, band), 3), "fovea_psnr": psnr_in(img, full, fovea)}
            if gt is not None:
                m["gt_psnr"] = round(psnr_in(np.clip(img, 0, 1), gt, band), 2)
            if frames is not None:
                m["frames4_psnr"] = round(psnr_in(np.mean(frames, 0), full, band), 2)
            return m

        res = {"view": v, "pixels": H * W, "full_ms": round(t_full, 1),
               **({"full_gt_psnr": round(psnr_in(np.clip(full, 0, 1), gt, band), 2)} if gt is not None else {}),
               "mean_neurons": round(float(exact_map.mean()), 2), "exact": measures(exact, times["exact"])}
        for name in modes:
            if name.startswith("dither_"):
                k = int(name.split("_")[1])
                frames = [imgs[name]] + [r.render_lod_map(row, col, r.foveation_map(
                    gaze, a.inner, a.outer, dither=True, sizes=k, frame=f, scale=a.scale)) for f in (1, 2, 3)]
                res[name] = measures(imgs[name], times[name], frames)
            elif name.startswith("snap_"):
                res[name] = measures(imgs[name], times[name])
            elif name == "native":
                res[name] = {**measures(imgs[name], times[name]), "stride": r.native_stride(r.neurons, a.scale)}
            elif name.startswith("mip_"):
                res[name] = {**measures(imgs[name], times[name]), "rays": round(rays[name] / rays["full"], 3),
                             "psnr_vs_exact": round(psnr_in(imgs[name], exact, band), 2)}
        log(json.dumps(res))
        rows.append(res)
    out = {"file": a.file, "machine": machine(), "device": a.device, "scale": a.scale, "threads": a.threads, "inner": a.inner, "outer": a.outer,
           "neurons": [r.cfg.min_neurons, r.neurons], "views": rows}
    if a.out:
        with open(a.out, "w") as f:
            json.dump(out, f, indent=1, allow_nan=True)
    print(json.dumps(out, allow_nan=True))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
