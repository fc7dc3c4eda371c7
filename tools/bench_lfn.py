"""LFN benchmark: train a continuous-LOD network and a single-scale network of the same size,
then report per level: width, bytes needed, held-out PSNR/SSIM at the level's scale (vs the
area-downsampled reference), render time per 256² view, and the trivial baselines.

Usage:
    python -m tools.bench_lfn SCENE --out DIR [--resolution 128] [--depth 6] [--min-neurons 16]
        [--max-neurons 128] [--steps 2000] [--device cpu|cuda] [--no-single-scale]

SCENE is a scene folder, or an .npz written by ``--export`` (views + geometry; lets the
benchmark run where OpenImageIO is not installed, e.g. the GPU machine).
"""
from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import numpy as np
import torch

from formats.lfcfile import open_lfc, write_lfc
from formats.lightfield import LightField
from tools.common import log
from lfn_stream import CODEC_ID, CODEC_VERSION, MOVED_KEYS, LfnConfig, LfnRenderer, TrainOptions, to_sections, train
from lfn_stream.evaluate import evaluate, measure_display_ladders, prefix_bytes
from lfn_stream.pack import step_bytes
from lfn_stream.rays import view_rays


def load(scene: str, resolution: int, split: str = "train") -> LightField:
    if scene.endswith(".npz"):
        with np.load(scene, allow_pickle=False) as z:
            g = json.loads(str(z["geometry"]))
            return LightField.from_geometry(z["views"], g, {"reader": "npz"})
    from formats.scenes import read_scene
    from formats.transform import resize_lightfield

    lf = read_scene(scene, split=split)
    return resize_lightfield(lf, resolution) if resolution else lf


def with_test_views(lf: LightField, test_lf: LightField) -> LightField:
    """One posed light field of the training views followed by a separate test split's views."""
    return LightField(views=np.concatenate([lf.views, test_lf.views], 1),
                      positions=np.concatenate([lf.positions, test_lf.positions], 1),
                      c2w=np.concatenate([lf.c2w, test_lf.c2w], 1), focal=lf.focal, principal=lf.principal,
                      layout="posed")


def export(lf: LightField, path: str) -> None:
    np.savez(path, views=lf.views, geometry=json.dumps(lf.geometry()))


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("scene")
    ap.add_argument("--out", required=True)
    ap.add_argument("--resolution", type=int, default=128)
    ap.add_argument("--depth", type=int, default=6)
    ap.add_argument("--min-neurons", "--min-width", dest="min_neurons", type=int, default=16,
                    help="neurons of the base network (hidden width)")
    ap.add_argument("--max-neurons", "--max-width", dest="max_neurons", type=int, default=128,
                    help="neurons of the full network")
    ap.add_argument("--steps", type=int, default=2000)
    ap.add_argument("--batch", type=int, default=4096)
    ap.add_argument("--lr", type=float, default=3e-3)
    ap.add_argument("--holdout", type=int, default=4)
    ap.add_argument("--test-scene", default=None, help="held-out views from another file (e.g. transforms_test)")
    ap.add_argument("--device", default="cpu")
    ap.add_argument("--lod-levels", type=int, default=TrainOptions.lod_levels,
                    help="levels trained per step (stratified over the width range)")
    ap.add_argument("--no-single-scale", action="store_true")
    ap.add_argument("--time-limit", type=float, default=None, help="stop each training after this many seconds")
    ap.add_argument("--export", default=None, help="write the (resized) scene as .npz and stop")
    a = ap.parse_args(argv)
    lf = load(a.scene, a.resolution)
    if a.export:
        export(lf, a.export)
        if a.test_scene:
            export(load(a.test_scene, a.resolution, split="test"), a.export.replace(".npz", "_test.npz"))
        return 0
    out = Path(a.out)
    out.mkdir(parents=True, exist_ok=True)
    test_lf = load(a.test_scene, a.resolution, split="test") if a.test_scene else None
    cfg = LfnConfig(depth=a.depth, min_neurons=a.min_neurons, max_neurons=a.max_neurons)
    results = {"scene": a.scene, "resolution": [lf.height, lf.width], "config": cfg.to_dict(), "device": a.device,
               "torch": torch.__version__}
    holdout = 0 if test_lf is not None else a.holdout

    def fit(lod_weight):
        opts = TrainOptions(steps=a.steps, batch=a.batch, lr=a.lr, holdout=holdout, device=a.device,
                            lod_weight=lod_weight, time_limit_s=a.time_limit, lod_levels=a.lod_levels)
        t = time.perf_counter()
        m, o, info = train(lf, cfg, opts, progress=lambda s, l: log(f"  step {s} loss {l:.5f}") if s % 1000 == 0 else None)
        info["train_s"] = time.perf_counter() - t
        return m, o, info

    # evaluation set: held-out views of the same grid, or a separate test capture
    def eval_set(info):
        if test_lf is None:
            return lf, np.asarray(info["test_views"]), np.asarray(info["train_views"]), None
        both = with_test_views(lf, test_lf)
        n = lf.cols
        return both, np.arange(n, n + test_lf.cols), np.arange(n), both

    log("training the continuous-LOD network")
    model, occ, info = fit(1.0)
    # the display ladders, as `lfcodec train` measures them (training views; held-out views unseen)
    info["display"], info["display_scales"] = measure_display_ladders(model, lf, info["train_views"], info["norm"],
                                                                      a.device)
    ev_lf, test_v, train_v, geom_lf = eval_set(info)
    info["test_views"] = [int(v) for v in test_v]         # views of the file's geometry (the test split's too)
    config, sections = to_sections(model, occ, info)
    path = out / "lfn.lfc"
    write_lfc(path, CODEC_ID, CODEC_VERSION, config, (geom_lf or lf).geometry(), sections, more=MOVED_KEYS)
    f = open_lfc(path)
    r = LfnRenderer(f, device=a.device)
    levels = sorted({float(cfg.min_neurons), float(cfg.neurons_of(0.25)), float(cfg.neurons_of(0.5)), float(cfg.max_neurons),
                     round(float(cfg.neurons_of(0.35)), 2)})
    results["train_s"] = info["train_s"]
    results["steps"] = info["steps"]
    results["file_bytes"] = path.stat().st_size
    results["params"] = model.n_params()
    results["delta_bytes_at_max_neurons"] = step_bytes(cfg, cfg.max_neurons - 1)
    results["first_renderable_bytes"] = prefix_bytes(r, float(cfg.min_neurons))   # header + meta + base + occ
    results["display_ladder"] = info["display"]
    results["lod"] = evaluate(r, ev_lf, test_v, train_v, levels)
    # checks: stream == trained model (fp16), prefix == full file at that level
    x = torch.from_numpy(view_rays(ev_lf, int(test_v[0]), 0.5, info["norm"]["centre"], info["norm"]["radius"]).reshape(-1, 6))
    with torch.no_grad():
        ref = model.to("cpu")(x).numpy()
    rc = LfnRenderer(open_lfc(path), device="cpu")
    got = rc.render_rays(x.numpy(), float(cfg.max_neurons), use_occupancy=False)
    results["stream_vs_trained_max_abs"] = float(np.abs(got - ref).max())
    mid = int(cfg.neurons_of(0.25))
    cut = prefix_bytes(rc, mid)
    blob = path.read_bytes()[:cut]
    rp = LfnRenderer(open_lfc(blob, partial=True), device="cpu")
    results["prefix_check"] = {"bytes": cut, "width": rp.width,
                               "max_abs_diff": float(np.abs(rp.render_rays(x.numpy(), mid) - rc.render_rays(x.numpy(), mid)).max())}
    if not a.no_single_scale:
        log("training the single-scale network (same size)")
        m1, o1, info1 = fit(0.0)
        c1, s1 = to_sections(m1, o1, info1)
        p1 = out / "single.lfc"
        write_lfc(p1, CODEC_ID, CODEC_VERSION, c1, (geom_lf or lf).geometry(), s1, more=MOVED_KEYS)
        r1 = LfnRenderer(open_lfc(p1), device=a.device)
        rows = []
        for lv in levels:   # the full single-scale network rendered at each level's scale
            scale = cfg.scale_of(lv)
            rr = evaluate(_AtScale(r1, scale), ev_lf, test_v, train_v, [float(cfg.max_neurons)], baselines=False)[0]
            rows.append({"scale": scale, "psnr": rr["psnr"], "ssim": rr["ssim"]})
        results["single_scale"] = rows
    (out / "lfn_results.json").write_text(json.dumps(results, indent=1))
    print(table(results))
    return 0


class _AtScale:
    """A renderer wrapper that renders at a fixed scale whatever the level (single-scale net)."""

    def __init__(self, r, scale):
        self.r, self.scale = r, scale
        self.cfg = _CfgAt(r.cfg, scale)
        self.file = r.file

    def render(self, row, col, level, scale):
        return self.r.render(row, col, self.r.width, self.scale)


class _CfgAt:
    def __init__(self, cfg, scale):
        self._s = scale
        self.min_neurons = cfg.min_neurons

    def scale_of(self, _):
        return self._s


def table(res: dict) -> str:
    lines = [f"LFN on {res['scene']} at {res['resolution'][1]}x{res['resolution'][0]}, depth {res['config']['depth']}, "
             f"widths {res['config']['min_neurons']}..{res['config']['max_neurons']}, {res['steps']} steps in "
             f"{res['train_s']:.0f} s on {res['device']}; file {res['file_bytes']} bytes; delta at max width "
             f"{res['delta_bytes_at_max_neurons']} bytes; stream vs trained max |diff| {res['stream_vs_trained_max_abs']:.2e}; "
             f"prefix ({res['prefix_check']['bytes']} bytes, width {res['prefix_check']['width']}) vs full file "
             f"max |diff| {res['prefix_check']['max_abs_diff']:.1e}", "",
             "| level (width) | scale | bytes needed | PSNR | SSIM | ms / 256² view | nearest view PSNR | mean view PSNR |"
             + (" single-scale PSNR |" if "single_scale" in res else ""),
             "|---|---|---|---|---|---|---|---|" + ("---|" if "single_scale" in res else "")]
    for i, r in enumerate(res["lod"]):
        extra = f" {res['single_scale'][i]['psnr']:.2f} |" if "single_scale" in res else ""
        lines.append(f"| {r['level']:g} | 1/{1 / r['scale']:.2f} | {r['bytes']} | {r['psnr']:.2f} | {'—' if r['ssim'] is None else format(r['ssim'], '.3f')} | "
                     f"{r['ms_per_256sq']:.1f} | {r['psnr_nearest_view']:.2f} | {r['psnr_mean_view']:.2f} |{extra}")
    return "\n".join(lines)


if __name__ == "__main__":
    raise SystemExit(main())
