"""Renderer frame times side by side in one process: this checkout's ``rlfc`` against another
checkout's (``--old DIR``, e.g. a ``git worktree`` of an earlier commit), on the same files.

The older package is copied to a temporary folder as ``rlfc_old`` (its modules import each other
relatively) and both are imported together. Per file and renderer (robust, fast): both warm their
caches along :func:`tools.bench_render.time_path`'s circle (60 frames), then the 60 frames are
timed in blocks of 10, alternating which version goes first, and the median ms per frame of each
is reported with their ratio and the largest pixel difference between the two versions' frames
(on every 7th camera). Alternating in one process is what makes small changes measurable on a
noisy machine; runs in separate processes differ by ±30% on the lent GPU machines.

Usage:
    python -m tools.bench_render_ab FILE.lfc [...] --old DIR [--device numpy|cpu|cuda] [--out F.json]
"""
from __future__ import annotations

import argparse
import atexit
import importlib
import shutil
import statistics
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from formats.lfcfile import open_lfc
from tools.common import log, machine, write_json


def import_old(old_dir: str):
    """The ``rlfc`` package of checkout ``old_dir``, imported as ``rlfc_old``."""
    src = Path(old_dir) / "rlfc"
    if not (src / "__init__.py").is_file():
        raise SystemExit(f"{old_dir}: no rlfc package there")
    tmp = Path(tempfile.mkdtemp(prefix="rlfc_old_"))
    atexit.register(shutil.rmtree, tmp, True)
    shutil.copytree(src, tmp / "rlfc_old", ignore=shutil.ignore_patterns("__pycache__"))
    sys.path.insert(0, str(tmp))
    return importlib.import_module("rlfc_old")


def pair(path: str, old, device: str | None, rounds: int = 6) -> dict:
    """Median ms per warm frame of both versions on one file, robust and fast renderers."""
    import rlfc

    dn, do = rlfc.RlfcDecoder(open_lfc(path)), old.RlfcDecoder(open_lfc(path))
    cs, ct = (dn.rows - 1) / 2, (dn.cols - 1) / 2
    rad = min(dn.rows, dn.cols) / 3
    cams = [(cs + rad * np.sin(a), ct + rad * np.cos(a)) for a in np.linspace(0, 2 * np.pi, 60, endpoint=False)]
    sync = lambda: None                                          # noqa: E731
    if device not in (None, "numpy"):
        import torch

        if torch.device(device).type == "cuda":
            sync = torch.cuda.synchronize
    per = len(cams) // rounds
    out = {}
    for robust in (True, False):
        rs = {v: d.renderer(cache_mib=1024, robust=robust, device=device) for v, d in (("new", dn), ("old", do))}
        for r in rs.values():
            for c in cams:
                r.render(*c)
        diff = max(int(np.abs(rs["new"].render(*c).astype(np.int64) - rs["old"].render(*c)).max()) for c in cams[::7])
        ts = {"new": [], "old": []}
        for k in range(rounds):
            for v in (("new", "old") if k % 2 else ("old", "new")):
                sync()
                t = time.perf_counter()
                for c in cams[k * per:(k + 1) * per]:
                    rs[v].render(*c)
                sync()
                ts[v].append((time.perf_counter() - t) / per)
        row = {v: round(1e3 * statistics.median(x), 3) for v, x in ts.items()}
        out["robust" if robust else "fast"] = {**row, "ratio_new_old": round(row["new"] / row["old"], 3),
                                               "max_pixel_diff": diff}
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(prog="python -m tools.bench_render_ab", description=__doc__.split("\n\n")[0])
    ap.add_argument("files", nargs="+")
    ap.add_argument("--old", required=True, help="a checkout (folder holding rlfc/) to compare against")
    ap.add_argument("--device", default="numpy", help="numpy, or a torch device (cpu, cuda)")
    ap.add_argument("--out", default=None)
    a = ap.parse_args(argv)
    old = import_old(a.old)
    res = {"machine": machine(), "device": a.device, "files": {}}
    for f in a.files:
        res["files"][Path(f).stem] = got = pair(f, old, None if a.device == "numpy" else a.device)
        log(f"{Path(f).stem}: {got}")
    if a.out:
        write_json(a.out, res)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
