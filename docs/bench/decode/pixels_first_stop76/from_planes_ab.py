"""old vs new formats.pixels.from_planes in one process: on real decoded planes, in whole views and batched calls."""
import sys, os, time, types, hashlib
os.environ["OMP_NUM_THREADS"] = "1"
sys.path.insert(0, "/work/main")
import numpy as np
from formats.lfcfile import open_lfc
from rlfc import RlfcDecoder
import rlfc.decoder as dm
import formats.pixels as new
src = open(os.environ.get("OLD", "/tmp/oldB") + "/formats/pixels.py").read()
old = types.ModuleType("formats._old_pixels"); old.__package__ = "formats"
exec(compile(src, "old_pixels", "exec"), old.__dict__)
fns = {"old": old.from_planes, "new": new.from_planes}
def med(f, n):
    ts = []
    for _ in range(n):
        t = time.perf_counter(); f(); ts.append(time.perf_counter() - t)
    return ts
for path in sys.argv[1:]:
    d = RlfcDecoder(open_lfc(path)); c = d.core; c.decode_keys(); c.decode_maps()
    keys = set(np.flatnonzero(c.is_key).tolist())
    vs = [v for v in range(d.rows * d.cols) if v not in keys][::4][:10]
    planes = d.decode_views(vs, planes=True)
    rng = np.random.default_rng(0); n = d.rows * d.cols; N = 20000
    v, by, bx = rng.integers(0, n, N), rng.integers(0, d.nby, N), rng.integers(0, d.nbx, N)
    h = {}
    for k in fns:
        dm.from_planes = fns[k]
        h[k] = (hashlib.sha1(fns[k](planes, d.dtype).tobytes()).hexdigest()[:10], hashlib.sha1(d.decode_views(vs).tobytes()).hexdigest()[:10],
                hashlib.sha1(d.decode_blocks(v, by, bx, threads=1).tobytes()).hexdigest()[:10])
    assert h["old"] == h["new"], h
    T = {(k, w): [] for k in fns for w in ("fp", "view", "batch")}
    for rnd in range(6):
        for k in (["old", "new"] if rnd % 2 == 0 else ["new", "old"]):
            dm.from_planes = fns[k]
            T[k, "fp"] += med(lambda: fns[k](planes[rnd % len(vs)], d.dtype), 5)
            for x in vs[rnd % 2::2]:
                T[k, "view"] += med(lambda: d.decode_views([x], threads=1), 1)
            T[k, "batch"] += med(lambda: d.decode_blocks(v, by, bx, threads=1), 1)
    r = {w: np.median(T["new", w]) / np.median(T["old", w]) for w in ("fp", "view", "batch")}
    print(os.path.basename(path), "same", h["new"], " ".join("%s %.2f→%.2f ms (%.3f)" % (w, np.median(T["old", w]) * 1e3, np.median(T["new", w]) * 1e3, r[w]) for w in r), flush=True)
