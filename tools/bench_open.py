"""Time to first pixels: opening an RLFC file and its first random-access requests.

Usage: ``python -m tools.bench_open FILE.lfc ... [--rounds 3] [--against OLD_CHECKOUT] [--out F.jsonl]``

Each measurement runs in a fresh process (one thread; imports and a first open of the same file
warmed up beforehand, so the times are the decoder's, not the interpreter's), per file, round
and code version (``--against``: the same worker with ``PYTHONPATH=OLD_CHECKOUT``, interleaved):

- ``open_ms``: ``RlfcDecoder(open_lfc(FILE))``;
- ``first_block_ms``: then one random ``decode_block`` (``key_rows_frac``: the share of the
  key-view block rows decoded after it, where the decoder decodes them on demand);
- ``next_64_blocks_ms``: then one ``decode_blocks`` call of 64 random requests;
- ``open_all_keys_ms``: a fresh open plus every key view decoded;
- ``open_decode_all_ms``: a fresh open plus ``decode_all``;
- ``first_frame_ms``: after a fresh open, the first frame of the default renderer at the first
  camera of ``tools.bench_render``'s path (``open_first_frame_ms``: with the open).

Prints medians over rounds; ``--out`` appends one JSON line per measurement.
"""
from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

KEYS = ("open_ms", "first_block_ms", "key_rows_frac", "next_64_blocks_ms", "key_rows_frac_64", "open_all_keys_ms",
        "open_decode_all_ms", "first_frame_ms", "open_first_frame_ms")


def worker(path: str, seed: int) -> dict:
    import numpy as np

    from formats.lfcfile import open_lfc
    from rlfc import RlfcDecoder

    rng = np.random.default_rng(seed)
    RlfcDecoder(open_lfc(path)).decode_block(0, 0, 0, 0)          # imports and caches warm
    import rlfc.render  # noqa: F401  (the renderer's modules too: without a bytecode cache, as
    #                    under PYTHONDONTWRITEBYTECODE, compiling them is ~9 ms of the first frame)
    out = {}
    t = time.perf_counter()
    d = RlfcDecoder(open_lfc(path))
    out["open_ms"] = (time.perf_counter() - t) * 1e3
    v = int(rng.integers(d.rows * d.cols))
    by, bx = int(rng.integers(d.nby)), int(rng.integers(d.nbx))
    t = time.perf_counter()
    d.decode_block(v // d.cols, v % d.cols, by, bx)
    out["first_block_ms"] = (time.perf_counter() - t) * 1e3
    done = getattr(d.core, "_key_done", None)
    out["key_rows_frac"] = float(done.mean()) if done is not None else 1.0
    vs, bys, bxs = rng.integers(0, d.rows * d.cols, 64), rng.integers(0, d.nby, 64), rng.integers(0, d.nbx, 64)
    t = time.perf_counter()
    d.decode_blocks(vs, bys, bxs)
    out["next_64_blocks_ms"] = (time.perf_counter() - t) * 1e3
    out["key_rows_frac_64"] = float(done.mean()) if done is not None else 1.0
    t = time.perf_counter()
    d2 = RlfcDecoder(open_lfc(path))
    getattr(d2.core, "decode_keys", lambda: None)()
    out["open_all_keys_ms"] = (time.perf_counter() - t) * 1e3
    t = time.perf_counter()
    RlfcDecoder(open_lfc(path)).decode_all()
    out["open_decode_all_ms"] = (time.perf_counter() - t) * 1e3
    t = time.perf_counter()
    d3 = RlfcDecoder(open_lfc(path))
    t1 = time.perf_counter()
    rad = min(d3.rows, d3.cols) / 3                    # tools.bench_render's path, its first camera
    d3.renderer(cache_mib=1024).render((d3.rows - 1) / 2, (d3.cols - 1) / 2 + rad)
    t2 = time.perf_counter()
    out["first_frame_ms"], out["open_first_frame_ms"] = (t2 - t1) * 1e3, (t2 - t) * 1e3
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(prog="python -m tools.bench_open", description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("files", nargs="*")
    ap.add_argument("--rounds", type=int, default=3)
    ap.add_argument("--against", help="a checkout of older code, measured the same way, interleaved")
    ap.add_argument("--out", help="append one JSON line per measurement here")
    ap.add_argument("--worker", nargs=2, metavar=("FILE", "SEED"), help=argparse.SUPPRESS)
    a = ap.parse_args(argv)
    if a.worker:
        print(json.dumps(worker(a.worker[0], int(a.worker[1]))))
        return 0
    if not a.files:
        ap.error("give at least one .lfc file")
    here = Path(__file__).resolve().parents[1]
    versions = [("new", here)] + ([("old", Path(a.against).resolve())] if a.against else [])
    from tools.common import compile_checkouts

    compile_checkouts(*(code for _, code in versions))   # (a fresh process's imports are timed: .pyc in each)
    rows = []
    for rnd in range(a.rounds):
        for f in a.files:
            for ver, code in versions:
                env = dict(os.environ, PYTHONPATH=str(code), OMP_NUM_THREADS="1")
                r = subprocess.run([sys.executable, str(Path(__file__).resolve()), "--worker", str(Path(f).resolve()),
                                    str(rnd)], env=env, cwd=tempfile.gettempdir(), capture_output=True, text=True)
                if r.returncode:
                    raise SystemExit(f"worker failed on {f} ({code}):\n{r.stderr[-2000:]}")
                row = {"file": Path(f).name, "ver": ver, "round": rnd, "r": json.loads(r.stdout.splitlines()[-1])}
                rows.append(row)
                if a.out:
                    with open(a.out, "a") as fh:
                        fh.write(json.dumps(row) + "\n")
    print("| file | version | " + " | ".join(KEYS) + " |")
    print("|---|---|" + "---|" * len(KEYS))
    for f in a.files:
        for ver, _ in versions:
            xs = [r["r"] for r in rows if r["file"] == Path(f).name and r["ver"] == ver]
            print(f"| {Path(f).name} | {ver} | " + " | ".join(f"{statistics.median(x[k] for x in xs):.3g}" for k in KEYS)
                  + " |")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
