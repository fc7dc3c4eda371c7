"""old vs new txsample.predict on a chunk's prediction (level 1), alternated 40 rounds; same planes."""
import sys, os, time, types
os.environ["OMP_NUM_THREADS"] = "1"
sys.path.insert(0, "/work/main")
import numpy as np
from formats.lfcfile import open_lfc
from rlfc import RlfcDecoder
import rlfc.profiles.tx as txp
import rlfc.txsample as new
OLD = os.environ.get("OLD", "/tmp/oldG")
old = types.ModuleType("rlfc._old_txsample"); old.__package__ = "rlfc"; sys.modules[old.__name__] = old
exec(compile(open(OLD + "/rlfc/txsample.py").read(), "old_txsample", "exec"), old.__dict__)
fns = {"old": old.predict, "new": new.predict}
for path in sys.argv[1:]:
    d = RlfcDecoder(open_lfc(path)); c = d.core; c.decode_keys(); c.decode_maps()
    rng = np.random.default_rng(0); n = d.rows * d.cols; M = 2048
    v = rng.integers(0, n, M); v = v[~c.is_key[v]]; M = v.size
    by, bx = rng.integers(0, d.nby, M), rng.integers(0, d.nbx, M)
    o = np.lexsort((bx, by, v)); v, by, bx = v[o], by[o], bx[o]
    locs = by * c.nbx + bx
    res = {}
    for k in fns:
        txp.remap_predict = fns[k]; res[k] = c._reconstruct(v, locs, 1)
    assert np.array_equal(res["old"], res["new"])
    T = {"old": [], "new": []}
    for r in range(40):
        for k in (("old", "new") if r % 2 == 0 else ("new", "old")):
            txp.remap_predict = fns[k]
            t = time.perf_counter(); c._reconstruct(v, locs, 1); T[k].append(time.perf_counter() - t)
    print(os.path.basename(path), "%d requests predicted: old min %.2f med %.2f, new min %.2f med %.2f ms (min %.3f, med %.3f)" % (M, min(T["old"])*1e3, np.median(T["old"])*1e3, min(T["new"])*1e3, np.median(T["new"])*1e3, min(T["new"])/min(T["old"]), np.median(T["new"])/np.median(T["old"])), flush=True)
