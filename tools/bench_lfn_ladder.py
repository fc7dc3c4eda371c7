"""Which display ladder keeps an LFN's held-out quality from falling as bytes arrive?

The encoder picks a display ladder (``config.display``) from measurements it can make without
the held-out views; issue 17 asks that the held-out PSNR of what a renderer shows never drop by
more than 0.1 dB from one step to the next. This tool measures, for one trained file, every
integer size's error on

- the held-out views at the display scale, view by view (what is scored);
- ``--rays`` counts of training rays drawn at the scene's resolution (what the encoder measures
  today: 16 384);
- ``--train-views`` training views rendered at the display scale (rays between the training
  pixels, as the held-out views' are);

then builds the ladder each way (:func:`lfn_stream.evaluate.display_ladder`), for each margin and
with or without the full size always listed,
and scores it on the held-out curve (steps dropping > 0.1 dB, worst drop, mean PSNR over the
steps). A ladder built on half the held-out views and scored on the other half is reported too.
Every per-size array is written to the JSON, so other rules can be tried offline.

Usage:
    python -m tools.bench_lfn_ladder FILE.lfc SCENE [--test-scene X] [--scale 0.5]
        [--rays 16384 262144] [--train-views 10] [--measure-scale S] [--margins 0.1 0.2 0.3 0.5] [--device cuda] [--out JSON]
"""
from __future__ import annotations

import argparse

import numpy as np
import torch

from lfn_stream import LfnRenderer
from lfn_stream.evaluate import display_ladder, sample_rays
from lfn_stream.sat import area_downsample
from lfn_stream.training import targets_of
from tools.bench_lfn_curve import displayed, open_with_scene, summary
from tools.common import log, machine, write_json


def view_mse(r: LfnRenderer, lf, views, scale: float) -> np.ndarray:
    """(len(views), sizes) float64: each view's mean squared error at every integer size."""
    peak = float(np.iinfo(lf.views.dtype).max)
    flat = lf.views.reshape(-1, lf.height, lf.width, lf.channels)
    nch = 4 if lf.has_alpha else 3
    out = np.empty((len(views), r.cfg.max_neurons - r.cfg.min_neurons + 1))
    for i, v in enumerate(views):
        ref = area_downsample(targets_of(flat[v][None], lf.has_alpha)[0].astype(np.float32) / peak, scale)[..., :nch]
        for j, w in enumerate(range(r.cfg.min_neurons, r.cfg.max_neurons + 1)):
            out[i, j] = np.mean((r.render(v // lf.cols, v % lf.cols, float(w), scale)[..., :nch] - ref) ** 2)
    return out


def ray_mse(r: LfnRenderer, lf, views, count: int, seed: int) -> np.ndarray:
    """(sizes,) float64: mean squared error of every integer size on ``count`` training rays."""
    norm = r.file.meta["config"]["norm"]
    rays, targets = sample_rays(lf, views, norm, count=count, seed=seed)
    nch = 4 if lf.has_alpha else 3
    return np.asarray([np.mean((r.render_rays(rays, float(w))[:, :nch] - targets[:, :nch]) ** 2)
                       for w in range(r.cfg.min_neurons, r.cfg.max_neurons + 1)])


def psnr(mse: np.ndarray) -> np.ndarray:
    return 10 * np.log10(1 / np.maximum(mse, 1e-12))


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("file")
    ap.add_argument("scene", help="the scene folder the network was trained on (or a .npz of tools.bench_lfn)")
    ap.add_argument("--test-scene", default=None, help="the separate test split (tools.bench_lfn --test-scene)")
    ap.add_argument("--scale", type=float, default=0.5, help="display scale relative to the views (default 0.5)")
    ap.add_argument("--rays", type=int, nargs="+", default=[16384, 262144])
    ap.add_argument("--train-views", type=int, default=10, help="training views rendered at --measure-scale")
    ap.add_argument("--measure-scale", type=float, default=None,
                    help="scale the training views are rendered at (default: --scale)")
    ap.add_argument("--margins", type=float, nargs="+", default=[0.1, 0.2, 0.3, 0.5])
    ap.add_argument("--device", default="cpu")
    ap.add_argument("--threads", type=int, default=1)
    ap.add_argument("--out", default=None)
    a = ap.parse_args(argv)
    torch.set_num_threads(a.threads)
    r, lf = open_with_scene(a.file, a.scene, a.test_scene, a.device)
    tr = r.file.full_meta()["config"]["train"]
    test, train = list(tr["test_views"]), list(tr["train_views"])
    lo = r.cfg.min_neurons
    log(f"{a.file}: {len(test)} held-out views at scale {a.scale}, sizes {lo}..{r.cfg.max_neurons}")
    held = view_mse(r, lf, test, a.scale)
    pick = [train[i] for i in np.linspace(0, len(train) - 1, min(a.train_views, len(train))).round().astype(int)]
    ms = a.scale if a.measure_scale is None else a.measure_scale
    sources = {f"train_views_x{ms:g}": psnr(view_mse(r, lf, pick, ms).mean(0))}
    for n in a.rays:
        sources[f"rays_{n}"] = psnr(ray_mse(r, lf, train, n, seed=0))
    half_a, half_b = held[0::2], held[1::2]
    score_all, score_b = psnr(held.mean(0)), psnr(half_b.mean(0))
    sources_b = {"heldout_half_a": psnr(half_a.mean(0))}
    rows = [{"source": "none (every size)", "margin": None, "full": None, "sizes": len(score_all),
             "scored_on": "all held-out", **summary(score_all)}]
    for name, src in list(sources.items()) + list(sources_b.items()):
        score, on = (score_b, "held-out half b") if name in sources_b else (score_all, "all held-out")
        for m in a.margins:
            for full in (True, False):
                lad = display_ladder(src, r.cfg, m, full)
                rows.append({"source": name, "margin": m, "full": full, "sizes": len(lad), "scored_on": on,
                             "ladder": lad, **summary(displayed(score, lad, lo))})
    print("| ladder measured on | margin | full size forced | sizes | scored on | drops > 0.1 dB | worst | mean PSNR | last |")
    print("|---|---|---|---|---|---|---|---|---|")
    for x in rows:
        print(f"| {x['source']} | {x['margin']} | {x['full']} | {x['sizes']} | {x['scored_on']} | "
              f"{x['drops_over_0.1dB']} | {x['worst_drop_db']:.2f} | {x['mean_psnr']:.2f} | {x['last_psnr']:.2f} |")
    write_json(a.out, {"file": a.file, "scene": a.scene, "scale": a.scale, "machine": machine(),
                       "test_views": test, "train_views_rendered": pick, "file_display": r.display,
                       "heldout_mse": held.round(8).tolist(),
                       "sources_psnr": {k: v.round(4).tolist() for k, v in sources.items()}, "rows": rows})
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
