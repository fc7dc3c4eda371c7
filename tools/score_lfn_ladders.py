"""Score the encoder's display ladders on held-out curves measured beforehand.

Measures the ladders `lfcodec train` writes today (:func:`lfn_stream.evaluate.
measure_display_ladders`: training views rendered at each display scale) on a trained file's
network, then, for each held-out curve given (JSON of :mod:`tools.bench_lfn_ladder`: every
size's error on the held-out views at one scale), compares what a renderer at that scale shows
as bytes arrive with (a) these ladders, (b) the ladder the file holds (``config.display``) and
(c) every size: steps dropping > 0.1 dB, worst drop, mean PSNR over the steps, last PSNR.
Lets a ladder rule be re-tested on networks trained elsewhere (a GPU) without re-rendering the
held-out views.

Usage:
    python -m tools.score_lfn_ladders FILE.lfc SCENE CURVE.json [CURVE.json ...] [--out JSON]
"""
from __future__ import annotations

import argparse
import json

import numpy as np
import torch

from formats.lfcfile import open_lfc
from lfn_stream import LfnRenderer
from lfn_stream.evaluate import measure_display_ladders
from tools.bench_lfn_curve import displayed, summary
from tools.common import log, write_json


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("file")
    ap.add_argument("scene", help="the scene the network was trained on (folder or tools.bench_lfn .npz)")
    ap.add_argument("curves", nargs="+", help="tools.bench_lfn_ladder JSON files of this network")
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument("--out", default=None)
    a = ap.parse_args(argv)
    torch.set_num_threads(a.threads)
    from tools.bench_lfn import load

    r = LfnRenderer(open_lfc(a.file), device="cpu")
    lf = load(a.scene, max(r.height, r.width))
    conf = r.file.full_meta()["config"]
    log(f"{a.file}: measuring the display ladders on its training views")
    display, per_scale = measure_display_ladders(r.model.float(), lf, conf["train"]["train_views"], conf["norm"])
    lo = r.cfg.min_neurons
    res = {"file": a.file, "display": display, "display_scales": per_scale, "scores": []}
    print("| display scale | ladder | sizes | drops > 0.1 dB | worst | mean PSNR | last |\n|---|---|---|---|---|---|---|")
    for cf in a.curves:
        with open(cf) as fh:
            d = json.load(fh)
        sc = float(d["scale"])
        p = 10 * np.log10(1 / np.asarray(d["heldout_mse"]).mean(0))
        lad = min(per_scale, key=lambda q: abs(np.log(q[0] / sc)))[1]
        for name, ladder in (("per-scale (today's encoder)", lad), ("the file's config.display", d["file_display"]),
                             ("every size", None)):
            s = summary(displayed(p, ladder, lo))
            res["scores"].append({"curve": cf, "scale": sc, "ladder": name, "sizes": len(ladder or p), **s})
            print(f"| {sc:g} | {name} | {len(ladder or p)} | {s['drops_over_0.1dB']} | {s['worst_drop_db']:.2f} | "
                  f"{s['mean_psnr']:.2f} | {s['last_psnr']:.2f} |")
    write_json(a.out, res)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
