"""Batched requests and whole views with OpenCV's pool at its default (2) and at one thread,
alternated: wall and CPU seconds. Stop 82; not adopted.

    OMP_NUM_THREADS=1 python cv2_threads_views.py FILE.lfc
"""
import sys, time
import numpy as np, cv2
from formats import open_lfc
from rlfc import RlfcDecoder
path = sys.argv[1]
d = RlfcDecoder(open_lfc(path)); d.core.decode_keys()
rng = np.random.default_rng(0); M = 20000
v = rng.integers(d.rows * d.cols, size=M); by = rng.integers(d.nby, size=M); bx = rng.integers(d.nbx, size=M)
d.decode_blocks(v, by, bx)
res = {}
for r in range(4):
    for n in (cv2.getNumThreads(), 1):
        old = cv2.getNumThreads(); cv2.setNumThreads(n)
        w = time.perf_counter(); c = time.process_time()
        d.decode_blocks(v, by, bx)
        res.setdefault(n, []).append((time.perf_counter() - w, time.process_time() - c))
        cv2.setNumThreads(old)
for n, x in res.items():
    x = np.array(x); print(path.split("/")[-1], "cv2 threads", n, "batched wall %.3f CPU %.3f (median)" % tuple(np.median(x, axis=0)))
vs = list(range(0, d.rows * d.cols, 3))
for r in range(2):
    for n in (2, 1):
        cv2.setNumThreads(n)
        w = time.perf_counter(); c = time.process_time()
        for q in vs: d.decode_view(*divmod(q, d.cols))
        print("  views cv2", n, "wall %.3f CPU %.3f" % (time.perf_counter() - w, time.process_time() - c))
