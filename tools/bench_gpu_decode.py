"""Batched random-access decode: numpy (CPU) against torch (GPU when present), same requests.

Usage: python -m tools.bench_gpu_decode FILE.lfc [--counts 20000,200000,1000000] [--parse host,steps,triton]
       [--old DIR]
Prints µs per block and Mpix/s (median of 3 after a warm-up) and checks every path agrees with
numpy bit for bit. ``--parse`` times the torch decoder once per way of parsing residual streams,
side by side on the same requests: ``host`` (numpy lanes on the CPU, then copied), ``steps``
(torch operations on the device), ``triton`` (the Triton kernel; CUDA only), ``auto`` (the
decoder's own choice, the default), ``serial`` (auto, one chunk in flight at a time). ``--old DIR`` adds another checkout's torch decoder as way
``old`` (before/after in one process: separate runs on the lent machines differ by ±30%).
"""
from __future__ import annotations

import argparse
import statistics
import time

import numpy as np
import torch

from formats.lfcfile import open_lfc
from rlfc import RlfcDecoder
from rlfc.torch_decode import TorchBlockDecoder


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("file")
    ap.add_argument("--counts", default="20000,200000,1000000")
    ap.add_argument("--device", default=None)
    ap.add_argument("--numpy-max", type=int, default=200000,
                    help="time numpy only for calls of at most this many requests (it takes ~1 min per 1M)")
    ap.add_argument("--parse", default="",
                    help="comma-separated: host, steps, triton, auto (the decoder's choice; the default), serial (auto with "
                         "one chunk in flight at a time), inflightN (auto with N in flight)")
    ap.add_argument("--old", default=None,
                    help="another checkout (e.g. `git archive REV rlfc | tar -x -C .old`): its torch decoder "
                         "timed as way 'old', in this process")
    ap.add_argument("--torch-profile", type=int, default=0,
                    help="also run torch's profiler on one torch call of this many requests (device time per kernel, "
                         "the parse and the prediction labelled)")
    ap.add_argument("--check", type=int, default=20000,
                    help="requests each way is checked equal to numpy on (the first of each count's; more than "
                         "PIPELINE_MIN exercises the chunks in flight together on a CUDA device)")
    ap.add_argument("--shapes", action="store_true",
                    help="with --torch-profile: record input shapes and group the table by them")
    ap.add_argument("--profile", type=int, default=0,
                    help="also profile one torch call of this many requests (cProfile, device synchronized)")
    a = ap.parse_args(argv)
    d = RlfcDecoder(open_lfc(a.file))
    td = TorchBlockDecoder(d, a.device)
    sync = torch.cuda.synchronize if td.dev.type == "cuda" else (lambda: None)
    ways = {}
    for w in [x for x in a.parse.split(",") if x]:
        ways[w] = td if w == "auto" else TorchBlockDecoder(d, a.device)        # (auto: the decoder's own choice)
        if w == "serial" or w.startswith("inflight"):     # one (or inflightN: N) chunks in flight at a time
            ways[w].in_flight = 1 if w == "serial" or ways[w].dev.type != "cuda" else int(w[8:])
        elif w != "auto":
            ways[w].core.device_parse_min = None if w == "host" else 0
            ways[w].core.triton = {"host": None, "steps": False, "triton": True}[w]
    ways = ways or {"torch": td}
    if a.old:
        import importlib

        from tools.bench_render_ab import import_old

        old = import_old(a.old)
        ways["old"] = importlib.import_module("rlfc_old.torch_decode").TorchBlockDecoder(
            old.RlfcDecoder(open_lfc(a.file)), a.device)
    rng = np.random.default_rng(0)

    def requests(n):
        return rng.integers(0, d.rows * d.cols, n), rng.integers(0, d.nby, n), rng.integers(0, d.nbx, n)

    print(f"device {td.dev} ({torch.cuda.get_device_name() if td.dev.type == 'cuda' else 'cpu'}), "
          f"{d.rows}x{d.cols} views, {d.nby}x{d.nbx} blocks of {d.block_size}")
    for n in [int(x) for x in a.counts.split(",")]:
        v, by, bx = requests(n)
        c = a.check
        ref = d.decode_blocks(v[:c], by[:c], bx[:c])
        for w, t in ways.items():
            t0 = time.perf_counter()
            for _ in range(2 if c >= 32768 else 1):          # (twice where chunks run in flight: no race)
                assert (t.decode_blocks(v[:c], by[:c], bx[:c]) == ref).all(), f"torch ({w}) != numpy"
            print(f"  {w}: first call (compiles) {time.perf_counter() - t0:.2f} s, equal to numpy")
        fns = [(w, lambda t=t: (t.decode_blocks(v, by, bx, to_numpy=False), sync())) for w, t in ways.items()]
        if n <= a.numpy_max:
            fns.insert(0, ("numpy", lambda: d.decode_blocks(v, by, bx)))
        ts = {name: [] for name, _ in fns}
        for name, fn in fns:
            fn()
        for _ in range(3):                              # rounds interleaved: the ways side by side
            for name, fn in fns:
                t = time.perf_counter()
                fn()
                ts[name].append(time.perf_counter() - t)
        res = {name: statistics.median(x) / n * 1e6 for name, x in ts.items()}
        px = d.block_size ** 2
        np_txt = (f"numpy {res['numpy']:.3f} µs/block ({px / res['numpy']:.1f} Mpix/s), " if "numpy" in res
                  else "numpy not timed, ")
        print(f"{n} blocks: {np_txt}" + ", ".join(
            f"torch {w} {res[w]:.3f} µs/block ({px / res[w]:.1f} Mpix/s"
            + (f", {res['numpy'] / res[w]:.1f}x numpy)" if "numpy" in res else ")") for w in ways))
    if a.profile:
        import cProfile
        import pstats

        v, by, bx = requests(a.profile)
        td.decode_blocks(v, by, bx, to_numpy=False)                 # (warm)
        sync()
        pr = cProfile.Profile()
        pr.enable()
        td.decode_blocks(v, by, bx, to_numpy=False)
        sync()
        pr.disable()
        pstats.Stats(pr).sort_stats("cumulative").print_stats(25)
    if a.torch_profile:
        from torch.profiler import ProfilerActivity, profile, record_function

        v, by, bx = requests(a.torch_profile)
        td.decode_blocks(v, by, bx, to_numpy=False)                 # (warm)
        sync()
        acts = [ProfilerActivity.CPU] + ([ProfilerActivity.CUDA] if td.dev.type == "cuda" else [])
        core = td.core
        for name in ("_parse_device", "_pred", "_add_residual"):        # the parts of a call, labelled
            fn = getattr(core, name)
            setattr(core, name, lambda *x, fn=fn, name=name: _labelled(record_function, name, fn, *x))
        with profile(activities=acts, record_shapes=a.shapes) as prof:
            td.decode_blocks(v, by, bx, to_numpy=False)
            sync()
        key = "self_cuda_time_total" if td.dev.type == "cuda" else "self_cpu_time_total"
        print(prof.key_averages(group_by_input_shape=a.shapes).table(sort_by=key, row_limit=40 if a.shapes else 30))
    return 0


def _labelled(record_function, name, fn, *args):
    with record_function(name):
        return fn(*args)


if __name__ == "__main__":
    raise SystemExit(main())
