"""Warm frame time of the robust renderer (numpy) with the disagreement before stop 94 (no
brightness removal) and after, alternated in one process along the benchmark's circle path.
Usage: python frame_ab.py ROUNDS FILE.lfc ..."""
import sys
import time

import numpy as np

import rlfc.render_ops as ro
from formats import open_lfc
from rlfc import RlfcDecoder

new = ro.NumpyOps.disagreement


def old(self, lum, ws, k, kb):
    n = len(ws)
    return [self.blur(self.wsum(self.sq_dev(lum[i:i + n], self.wsum(lum[i:i + n], ws)), ws), k)
            for i in range(0, len(lum), n)]


rounds = int(sys.argv[1])
for path in sys.argv[2:]:
    d = RlfcDecoder(open_lfc(path))
    ren = d.renderer(cache_mib=1024)
    cs, ct = (d.rows - 1) / 2, (d.cols - 1) / 2
    rad = min(d.rows, d.cols) / 3
    ang = np.linspace(0, 2 * np.pi, 30, endpoint=False)
    cams = [(cs + rad * np.sin(a), ct + rad * np.cos(a)) for a in ang]
    for c in cams:
        ren.render(*c)
    T = {"old": [], "new": []}
    for i in range(rounds):
        for k, f in ((("old", old), ("new", new)) if i % 2 else (("new", new), ("old", old))):
            ro.NumpyOps.disagreement = f
            t = time.process_time()
            for c in cams:
                ren.render(*c)
            T[k].append((time.process_time() - t) / len(cams))
    o, w = np.median(T["old"]) * 1e3, np.median(T["new"]) * 1e3
    print(f"{path.split('/')[-1]:30s} robust frame CPU ms: old {o:.1f} new {w:.1f} ({w / o:.3f})", flush=True)
