"""Novel-view rendering on real grids, by leaving views out: every second view (rows and
columns) is encoded, the views in between are rendered from the file and compared with the
captured ones, beside the nearest encoded view and plain bilinear blending (no disparity), for
the default renderer (robust disparity choice) and ``robust=False`` (the file's maps as they
are, "fast"); then frame times of both along a camera path with a warm block cache, on each
``--device`` (numpy = numpy + OpenCV on the CPU; a torch device such as cuda or cpu), with the
largest difference of that device's planes from numpy's on the first camera.

``--midview`` instead checks, on the original views, whether a captured in-between view is a
geometric interpolation of its neighbours at all (see :func:`midview_check`).

Usage:
    python -m tools.bench_render SCENE [SCENE ...] [--target-psnr 40] [--device numpy cuda] [--out DIR]
    python -m tools.bench_render SCENE [SCENE ...] --midview
    python -m tools.bench_render FILE.lfc [...] [--device numpy cuda] [--malloc-default]   (frame times only)

Renderers ask malloc to keep freed blocks (``Renderer(keep_freed=True)``, the default since stop
89); ``--malloc-default`` makes them with ``keep_freed=False``, glibc's defaults, as library
renderers were before (call it in a fresh process: the setting is the process's).
"""
from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import numpy as np

from formats.codec_api import EncodeOptions
from formats.metrics import psnr_rgb, ssim
from formats.scenes import read_scene
from rlfc import encode
from tools.common import log, machine, open_encoded

#: what the renderers made here are given as ``keep_freed`` (``--malloc-default``: False)
KEEP_FREED = True


def bench_scene(path: str, target: float, devices=("numpy",)) -> dict:
    lf = read_scene(path)
    full = lf.views
    lf.views = np.ascontiguousarray(full[::2, ::2])
    lf.positions = lf.positions[::2, ::2]
    t0 = time.perf_counter()
    d, blob = open_encoded(lf, encode(lf, EncodeOptions(target_psnr=target)))
    t_enc = time.perf_counter() - t0
    ren = d.renderer(cache_mib=1024, keep_freed=KEEP_FREED)
    fast = d.renderer(cache_mib=1024, robust=False, keep_freed=KEEP_FREED)
    rows = {"render": [], "render_fast": [], "nearest": [], "blend": []}
    ss = {"render": [], "render_fast": [], "nearest": [], "blend": []}
    R, C = full.shape[:2]
    for r in range(R):
        for c in range(C):
            if r % 2 == 0 and c % 2 == 0:
                continue
            s, t = r / 2, c / 2
            img = ren.render(s, t)
            near = d.decode_view(int(round(s)), int(round(t)))
            corners = [(int(np.floor(s)), int(np.floor(t))), (int(np.floor(s)), int(np.ceil(t))),
                       (int(np.ceil(s)), int(np.floor(t))), (int(np.ceil(s)), int(np.ceil(t)))]
            blend = np.rint(np.mean([d.decode_view(*k).astype(np.float64) for k in corners], 0)).astype(full.dtype)
            for name, x in (("render", img), ("render_fast", fast.render(s, t)), ("nearest", near), ("blend", blend)):
                rows[name].append(psnr_rgb(full[r, c], x))
                ss[name].append(ssim(full[r, c][None], x[None]))
    speed = time_path(d, devices)
    return {"scene": Path(path).name, "encoded_views": f"{lf.rows}x{lf.cols}", "target_psnr": target,
            "file_bytes": len(blob), "encode_s": round(t_enc, 1),
            "psnr": {k: round(float(np.mean(v)), 2) for k, v in rows.items()},
            "psnr_worst": {k: round(float(np.min(v)), 2) for k, v in rows.items()},
            "ssim": {k: round(float(np.mean(v)), 4) for k, v in ss.items()},
            "frame": f"{d.height}x{d.width}", **speed}


def time_path(d, devices=("numpy",)) -> dict:
    """Frame times along a smooth camera path on each device, warm cache: first frame (ms),
    warm fps, cache hit rate and blocks per frame, for the robust and the fast renderer; for a
    torch device also the largest difference of its planes from numpy's on the first camera."""
    # a smooth path: a circle of radius 1/3 of the grid around the centre, 60 frames, twice
    cs, ct = (d.rows - 1) / 2, (d.cols - 1) / 2
    rad = min(d.rows, d.cols) / 3
    ang = np.linspace(0, 2 * np.pi, 60, endpoint=False)
    speed = {}
    for dev, (label, robust) in ((dv, lr) for dv in devices for lr in (("", True), ("_fast", False))):
        label = label if dev == "numpy" else f"{label}_{dev}"
        ren2 = d.renderer(cache_mib=1024, robust=robust, device=dev, keep_freed=KEEP_FREED)
        if dev != "numpy":
            ref = d.renderer(cache_mib=1024, robust=robust, keep_freed=KEEP_FREED).render_planes(cs + rad * np.sin(ang[0]), ct + rad * np.cos(ang[0]))
            got = ren2.render_planes(cs + rad * np.sin(ang[0]), ct + rad * np.cos(ang[0]))
            speed[f"max_plane_diff{label}"] = float(np.abs(ref - got.cpu().numpy()).max())
            ren2 = d.renderer(cache_mib=1024, robust=robust, device=dev, keep_freed=KEEP_FREED)
        t = time.perf_counter()
        ren2.render(cs + rad * np.sin(ang[0]), ct + rad * np.cos(ang[0]))
        first = time.perf_counter() - t
        for a in ang:                                   # warm the cache along the path
            ren2.render(cs + rad * np.sin(a), ct + rad * np.cos(a))
        dec0, req0 = ren2.blocks_decoded, ren2.blocks_requested
        t = time.perf_counter()
        for a in ang:
            ren2.render(cs + rad * np.sin(a), ct + rad * np.cos(a))
        warm = (time.perf_counter() - t) / len(ang)
        speed.update({f"first_frame_ms{label}": round(1e3 * first, 1), f"warm_fps{label}": round(1 / warm, 1),
                      f"warm_hit_rate{label}": round(1 - (ren2.blocks_decoded - dec0)
                                                     / max(1, ren2.blocks_requested - req0), 3),
                      f"blocks_per_frame{label}": round((ren2.blocks_requested - req0) / len(ang), 1)})
    return speed


def speed_file(path: str, devices=("numpy",)) -> dict:
    """Frame times only, on an encoded file (no leave-views-out quality): :func:`time_path`."""
    from formats.lfcfile import open_lfc
    from rlfc import RlfcDecoder

    d = RlfcDecoder(open_lfc(path))
    return {"file": Path(path).name, "views": f"{d.rows}x{d.cols}", "frame": f"{d.height}x{d.width}",
            **time_path(d, devices)}


def midview_check(path: str, step: int = 1) -> dict:
    """Is an in-between captured view a geometric interpolation of its neighbours? On the
    original views of the middle row (every ``step``-th view: step 2 is the baseline of a
    leave-views-out file): the horizontal shift per view step that best aligns a view with the
    next (one disparity for the frame, 0.05 px steps; 20-px border left out), then the PSNR of
    the middle view predicted by the mean of its two neighbours shifted by ±that disparity
    (bilinear, bicubic, Lanczos-4), against the mean without a shift (blending); and, bicubic,
    by ±a fraction of it (0, ¼, ½, ¾, 1: does any amount of shifting beat blending?)."""
    import cv2

    v = read_scene(path).views[::step, ::step]
    r, c = v.shape[0] // 2, v.shape[1] // 2
    a, m, b = (v[r, c + k].astype(np.float32) for k in (-1, 0, 1))
    H, W = a.shape[:2]
    yy, xx = np.mgrid[0:H, 0:W].astype(np.float32)
    e = min(20, H // 4, W // 4)                     # border left out (20 px; less on tiny views)
    inner = (slice(e, H - e), slice(e, W - e))

    def shift(img, dx, interp=cv2.INTER_LINEAR):
        out = cv2.remap(img, xx + np.float32(dx), yy, interp, borderMode=cv2.BORDER_REPLICATE)
        return out.reshape(img.shape)

    steps = np.round(np.arange(-2.0 * step, 2.0 * step + 1e-4, 0.05), 2)
    err = [float(np.mean(np.square(shift(a, dx) - m)[inner])) for dx in steps]
    disp = float(steps[int(np.argmin(err))])

    def mid(dx, interp):
        est = 0.5 * (shift(a, dx, interp) + shift(b, -dx, interp))
        est = np.clip(np.rint(est[inner]), 0, float(np.iinfo(v.dtype).max)).astype(v.dtype)
        return round(psnr_rgb(m[inner].astype(v.dtype), est), 2)

    kernels = {"bilinear": cv2.INTER_LINEAR, "bicubic": cv2.INTER_CUBIC, "lanczos4": cv2.INTER_LANCZOS4}
    return {"scene": Path(path).name, "view_step": step, "disparity_per_step": disp,
            "blend_no_shift": mid(0.0, cv2.INTER_LINEAR),
            **{f"shifted_{k}": mid(disp, it) for k, it in kernels.items()},
            "bicubic_fraction_of_shift": {str(f): mid(f * disp, cv2.INTER_CUBIC) for f in (0.0, 0.25, 0.5, 0.75, 1.0)}}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(prog="python -m tools.bench_render", description=__doc__.split("\n\n")[0])
    ap.add_argument("scenes", nargs="+")
    ap.add_argument("--target-psnr", type=float, default=40.0)
    ap.add_argument("--device", nargs="+", default=["numpy"],
                    help="where frames are timed: numpy and/or torch devices (cuda, cpu)")
    ap.add_argument("--out", default=None)
    ap.add_argument("--midview", action="store_true",
                    help="instead: check whether each scene's in-between views are geometric interpolations "
                         "of their neighbours (original views, no codec)")
    ap.add_argument("--view-step", type=int, nargs="+", default=[1],
                    help="--midview: use every k-th view (2 = the baseline of a leave-views-out file)")
    ap.add_argument("--malloc-default", action="store_true",
                    help="renderers made with keep_freed=False: glibc's malloc as it is, as library renderers "
                         "were before stop 89 (by default they ask it to keep freed blocks, formats.heap.keep_freed)")
    a = ap.parse_args(argv)
    global KEEP_FREED
    KEEP_FREED = not a.malloc_default
    if a.midview:
        res = {"machine": machine(), "midview": [midview_check(s, st) for st in a.view_step for s in a.scenes]}
    else:
        res = {"machine": machine(), "scenes": [speed_file(s, a.device) if s.endswith(".lfc")
                                                else bench_scene(s, a.target_psnr, a.device) for s in a.scenes]}
    log(json.dumps(res, indent=1))
    if a.out:
        Path(a.out).mkdir(parents=True, exist_ok=True)
        (Path(a.out) / "render.json").write_text(json.dumps(res, indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
