"""LFN training speed: optimizer steps per second with the level term run per group of rays
(one network pass per level, the CPU default) or in one pass with a size per ray (the CUDA
default), at a few batch sizes, each for a fixed time.

Usage:
    python -m tools.bench_lfn_steps SCENE.npz [--device cuda] [--seconds 12] [--batches 16384 65536]
        [--rounds 2] [--out JSON]

SCENE is a scene folder or an .npz of ``tools.bench_lfn --export``. The network is the one of the
GPU runs in BENCHMARKS.md (depth 8, 16..256 neurons) unless --depth/--min-neurons/--max-neurons.
"""
from __future__ import annotations

import argparse
import json

import torch

from lfn_stream import LfnConfig, TrainOptions, train
from tools.bench_lfn import load
from tools.common import log, machine, write_json


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("scene")
    ap.add_argument("--device", default="cuda" if torch.cuda.is_available() else "cpu")
    ap.add_argument("--seconds", type=float, default=12.0, help="training time per measurement")
    ap.add_argument("--batches", type=int, nargs="+", default=[16384, 65536])
    ap.add_argument("--rounds", type=int, default=2)
    ap.add_argument("--depth", type=int, default=8)
    ap.add_argument("--min-neurons", type=int, default=16)
    ap.add_argument("--max-neurons", type=int, default=256)
    ap.add_argument("--out", default=None)
    a = ap.parse_args(argv)
    lf = load(a.scene, 128)
    cfg = LfnConfig(depth=a.depth, min_neurons=a.min_neurons, max_neurons=a.max_neurons)
    res = {"machine": machine(), "device": a.device, "torch": torch.__version__, "runs": []}
    if a.device.startswith("cuda"):
        res["gpu"] = torch.cuda.get_device_name()
    for rnd in range(a.rounds):                  # rounds interleave the settings (a noisy machine)
        for one in (False, True):
            for batch in a.batches:
                opts = TrainOptions(steps=10 ** 8, batch=batch, holdout=0, device=a.device, lod_one_pass=one,
                                    time_limit_s=a.seconds)
                _, _, info = train(lf, cfg, opts)
                row = {"one_pass": one, "batch": batch, "round": rnd, "steps": info["steps"],
                       "steps_per_s": round(info["steps"] / info["train_s"], 2)}
                res["runs"].append(row)
                log(json.dumps(row))
    write_json(a.out, res)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
