import sys, os, time
os.environ["OMP_NUM_THREADS"] = "1"
sys.path.insert(0, "/work/main")
import numpy as np
from formats.lfcfile import open_lfc
from formats.pixels import from_planes
from rlfc import RlfcDecoder
for path in sys.argv[1:]:
    d = RlfcDecoder(open_lfc(path)); c = d.core; c.decode_keys(); c.decode_maps()
    rng = np.random.default_rng(0); n = d.rows * d.cols; M = 2048
    v, by, bx = rng.integers(0, n, M), rng.integers(0, d.nby, M), rng.integers(0, d.nbx, M)
    o = np.lexsort((bx, by, v)); v, by, bx = v[o], by[o], bx[o]
    B = d.block_size
    old = lambda: from_planes(c.blocks(v, by, bx, 0).reshape(M, B, B, d.P), d.dtype)
    new = lambda: c.blocks(v, by, bx, 0, pixels=d.dtype)
    assert np.array_equal(old(), new().reshape(M, B, B, d.P))
    T = {"old": [], "new": []}
    for r in range(30):
        for k, f in (("old", old), ("new", new)) if r % 2 == 0 else (("new", new), ("old", old)):
            t = time.perf_counter(); f(); T[k].append(time.perf_counter() - t)
    print(os.path.basename(path), "chunk of %d: old min %.2f med %.2f ms, new min %.2f med %.2f ms (min ratio %.3f, median ratio %.3f)" % (M, min(T["old"])*1e3, np.median(T["old"])*1e3, min(T["new"])*1e3, np.median(T["new"])*1e3, min(T["new"])/min(T["old"]), np.median(T["new"])/np.median(T["old"])))
