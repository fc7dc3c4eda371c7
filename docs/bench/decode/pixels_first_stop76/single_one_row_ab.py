"""old vs new lean single-block path, alternated request by request (drift cancels)."""
import sys, os, time, types, hashlib
os.environ["OMP_NUM_THREADS"] = "1"
sys.path.insert(0, "/work/main")
import numpy as np
from formats.lfcfile import open_lfc
from rlfc import RlfcDecoder
import rlfc.profiles.tx as txp
import rlfc.txsample as new
src = open(os.environ.get("OLD", "/tmp/oldC") + "/rlfc/txsample.py").read()
old = types.ModuleType("rlfc._old_txsample"); old.__package__ = "rlfc"
exec(compile(src, "old_txsample", "exec"), old.__dict__)
fns = {"old": old.predict_block_pixels, "new": new.predict_block_pixels}
for path in sys.argv[1:]:
    d = RlfcDecoder(open_lfc(path)); c = d.core; c.decode_keys(); c.decode_maps()
    rng = np.random.default_rng(1)
    req = [(int(rng.integers(0, d.rows)), int(rng.integers(0, d.cols)), int(rng.integers(0, d.nby)), int(rng.integers(0, d.nbx))) for _ in range(12000)]
    req = [r for r in req if not c.is_key[r[0] * d.cols + r[1]] and not c.coded[r[0] * d.cols + r[1], r[2] * c.nbx + r[3]]]
    for k in fns:
        txp.predict_block_pixels = fns[k]
        h = hashlib.sha1(b"".join(d.decode_block(*r).tobytes() for r in req[:2000])).hexdigest()
        if k == "old": h0 = h
    assert h == h0
    T = {k: [] for k in fns}
    pc = time.perf_counter
    for i, r in enumerate(req):
        for k in (("old", "new") if i % 2 == 0 else ("new", "old")):
            txp.predict_block_pixels = fns[k]
            t = pc(); d.decode_block(*r); T[k].append(pc() - t)
    o, n = (np.percentile(np.array(T[k]) * 1e6, [50, 90, 99]) for k in ("old", "new"))
    print(os.path.basename(path), len(req), "predicted blocks, p50/p90/p99 µs: old %.1f/%.1f/%.1f new %.1f/%.1f/%.1f (p50 %.3f)" % (*o, *n, n[0] / o[0]), flush=True)
