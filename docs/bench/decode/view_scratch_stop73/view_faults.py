"""Whole views decoded one after another, with the page faults they take (stop 73).

Usage: PYTHONPATH=CHECKOUT python view_faults.py FILE.lfc [maps|nomaps]
  maps (default): decode_keys() and decode_maps() first; nomaps: decode_keys() only (each view's
  map decoded when a view first needs it). Prints the median ms of 60 random predicted views in
  sequence and their minor faults per view, the median of six views' best of 3, and decode_all.
"""
import os
import resource
import sys
import time

import numpy as np

os.environ["OMP_NUM_THREADS"] = "1"
from formats.lfcfile import open_lfc  # noqa: E402
from rlfc import RlfcDecoder  # noqa: E402

maps = (sys.argv[2] if len(sys.argv) > 2 else "maps") == "maps"
d = RlfcDecoder(open_lfc(sys.argv[1]))
d.core.decode_keys()
if maps:
    d.core.decode_maps()
keys = set(np.flatnonzero(d.core.is_key).tolist())
vs = [v for v in range(d.rows * d.cols) if v not in keys]
seq = np.random.default_rng(0).choice(vs, 60)
for v in seq[:10]:
    d.decode_views([v])
f0 = resource.getrusage(resource.RUSAGE_SELF).ru_minflt
ts = []
for v in seq:
    t = time.perf_counter()
    d.decode_views([v])
    ts.append(time.perf_counter() - t)
f1 = resource.getrusage(resource.RUSAGE_SELF).ru_minflt
b3 = []
for v in vs[:6]:
    b = 1e9
    for _ in range(3):
        t = time.perf_counter()
        d.decode_views([v])
        b = min(b, time.perf_counter() - t)
    b3.append(b)
t = time.perf_counter()
d.decode_all(threads=1)
ta = time.perf_counter() - t
print(f"{os.path.basename(sys.argv[1]):22s} seq median {np.median(ts) * 1e3:6.2f} ms faults/view {(f1 - f0) / len(ts):5.0f}  "
      f"best3 median {np.median(b3) * 1e3:6.2f} ms  all {ta:.3f} s")
