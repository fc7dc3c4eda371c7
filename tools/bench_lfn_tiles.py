"""A tile set of light field networks against one global network (issue 17, larger scenes).

Trains, on the same scene, split and seed: one global network (``--max-neurons`` wide), one
global network ``--wide`` neurons wide (about as many bytes as the tile set), and tile sets of
``--tiles`` networks (each ``--max-neurons`` wide) at the same steps per network and at steps
divided by the tile count (the global network's compute). Each is scored as a user sees it:
files written, opened, the held-out views rendered at full size (the tile set blends its
submodels, :mod:`lfn_stream.tiles`), PSNR/SSIM against the views beside the nearest training
view; also at the middle size (half-way from the base to the full network, at its own scale).
Bytes are whole files (manifest included).

Usage:
    python -m tools.bench_lfn_tiles SCENE --steps 1000 --tiles 4 --wide 256 [--out JSON]
        [--device cuda] [--depth 8] [--min-neurons 16] [--time-limit S] [--lod-levels N]

SCENE is a scene folder or an .npz written by ``python -m tools.bench_lfn SCENE --export`` (for
a machine without OpenImageIO, e.g. a lent GPU machine).
"""
from __future__ import annotations

import argparse
import json
import tempfile
import time
from pathlib import Path

import torch

from formats.codec_api import EncodeOptions
from formats.lfcfile import open_lfc, write_lfc
from lfn_stream import LfnCodec
from lfn_stream.codec import encode_tiles
from lfn_stream.evaluate import evaluate
from lfn_stream.render import CODEC_ID, CODEC_VERSION, LfnRenderer
from lfn_stream.tiles import open_tiles
from lfn_stream.training import split_views
from tools.bench_lfn import load
from tools.common import log, machine


def score(r, lf, holdout: int, neurons: float) -> list[dict]:
    """Held-out rows at the full network's size (full scale) and at the middle size (half-way from the base network to the full one)."""
    train_v, test_v = split_views(lf, holdout)
    rows = evaluate(r, lf, test_v, train_v, [float(neurons)])
    half = r.cfg.min_neurons + (neurons - r.cfg.min_neurons) * 0.5
    rows += evaluate(r, lf, test_v, train_v, [float(half)])
    return [{k: (round(v, 4) if isinstance(v, float) else v) for k, v in row.items()} for row in rows]


def run_global(lf, params: dict, folder: Path, name: str, device: str = "cpu") -> dict:
    t = time.perf_counter()
    enc = LfnCodec().encode(lf, EncodeOptions(params=params))
    train_s = time.perf_counter() - t
    path = folder / f"{name}.lfc"
    nbytes = write_lfc(path, CODEC_ID, CODEC_VERSION, enc.config, lf.geometry(), enc.sections, more=enc.more)
    with open_lfc(str(path)) as f:
        r = LfnRenderer(f, device=device)
        rows = score(r, lf, params.get("holdout", 4), r.cfg.max_neurons)
    return {"model": name, "bytes": nbytes, "train_s": round(train_s, 1), "rows": rows}


def run_tiles(lf, params: dict, folder: Path, name: str, device: str = "cpu") -> dict:
    t = time.perf_counter()
    rep = encode_tiles(lf, EncodeOptions(params=params), folder / f"{name}.json")
    train_s = time.perf_counter() - t
    with open_tiles(folder / f"{name}.json", device=device) as r:
        rows = score(r, lf, params.get("holdout", 4), r.cfg.max_neurons)
        per_tile = [{"file": t["file"], "bytes": t["bytes"], "train_views": t["train_views"]} for t in rep["tiles"]]
        blended = r.tiles_rendered
    return {"model": name, "bytes": rep["bytes"], "train_s": round(train_s, 1), "rows": rows, "tiles": per_tile,
            "tile_renders": blended}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("scene")
    ap.add_argument("--steps", type=int, default=1000)
    ap.add_argument("--tiles", type=int, default=4)
    ap.add_argument("--wide", type=int, default=256, help="neurons of the wide global network")
    ap.add_argument("--band", type=float, default=0.5, help="the tile set's blend band (lfn_stream.tiles)")
    ap.add_argument("--max-neurons", type=int, default=128)
    ap.add_argument("--resolution", type=int, default=128)
    ap.add_argument("--batch", type=int, default=4096)
    ap.add_argument("--only", nargs="*", default=None, help="global, wide, tiles, tiles_equal_compute")
    ap.add_argument("--threads", type=int, default=1)
    ap.add_argument("--device", default="cpu", help="train and render on this torch device")
    ap.add_argument("--depth", type=int, default=None, help="hidden layers (default: the codec's)")
    ap.add_argument("--min-neurons", type=int, default=None, help="base network's neurons (default: the codec's)")
    ap.add_argument("--time-limit", type=float, default=None, help="stop each network's training after S seconds")
    ap.add_argument("--lod-levels", type=int, default=None, help="stratified levels per step (default: the codec's)")
    ap.add_argument("--out", default=None)
    a = ap.parse_args(argv)
    torch.set_num_threads(a.threads)
    lf = load(a.scene, 0)
    base = {"steps": a.steps, "resolution": a.resolution, "batch": a.batch, "max_neurons": a.max_neurons,
            "device": a.device}
    for key, val in (("depth", a.depth), ("min_neurons", a.min_neurons), ("time_limit_s", a.time_limit),
                     ("lod_levels", a.lod_levels)):
        if val is not None:
            base[key] = val
    runs = {"global": (run_global, base),
            "wide": (run_global, {**base, "max_neurons": a.wide}),
            "tiles": (run_tiles, {**base, "tiles": a.tiles, "tile_band": a.band}),
            "tiles_equal_compute": (run_tiles, {**base, "tiles": a.tiles, "tile_band": a.band,
                                                "steps": max(1, a.steps // a.tiles)})}
    out = {"scene": a.scene, "machine": machine(), "args": vars(a), "results": []}
    with tempfile.TemporaryDirectory() as d:
        for name, (fn, params) in runs.items():
            if a.only and name not in a.only:
                continue
            log(f"{name}: {params}")
            res = fn(lf, params, Path(d), name, a.device)
            res["params"] = params
            log(json.dumps({k: v for k, v in res.items() if k != "tiles"}))
            out["results"].append(res)
            if a.out:
                Path(a.out).write_text(json.dumps(out, indent=1))
    print("| model | steps per network | bytes | train s | held-out PSNR (full) | SSIM | nearest view | "
          "PSNR at the middle size (scale) | nearest view |")
    print("|---|---|---|---|---|---|---|---|---|")
    for r in out["results"]:
        f, h = r["rows"]
        print(f"| {r['model']} | {r['params']['steps']} | {r['bytes']} | {r['train_s']} | {f['psnr']:.2f} | "
              f"{f['ssim']:.3f} | {f['psnr_nearest_view']:.2f} | {h['psnr']:.2f} ({h['scale']:.2f}) | "
              f"{h['psnr_nearest_view']:.2f} |")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
