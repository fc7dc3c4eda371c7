# usage: python THIS.py THREADS FILE.lfc ...   with rlfc/_txsyntax_old.py = `git show fd561c2:rlfc/txsyntax.py`
import sys, time, numpy as np
sys.path.insert(0, ".")
import rlfc.txsyntax as new, rlfc._txsyntax_old as old
import rlfc.profiles.tx as txp
from formats.lfcfile import open_lfc
from rlfc import RlfcDecoder
impl = {"old": old.parse_lanes, "new": new.parse_lanes}
th = int(sys.argv[1])
for path in sys.argv[2:]:
    d = RlfcDecoder(open_lfc(path)); c = d.core; c.decode_keys(); c.decode_maps()
    n = d.rows * d.cols; N = 20000; B = d.block_size
    rng = np.random.default_rng(0)
    v, by, bx = rng.integers(0, n, N), rng.integers(0, d.nby, N), rng.integers(0, d.nbx, N)
    d.decode_blocks(v, by, bx, threads=th)
    T = {k: [] for k in impl}; outs = {}
    for r in range(8):
        for k in (("old", "new") if r % 2 == 0 else ("new", "old")):
            txp.parse_lanes = impl[k]
            t = time.perf_counter(); outs[k] = d.decode_blocks(v, by, bx, threads=th); T[k].append(time.perf_counter() - t)
    mo, mn = np.median(T["old"]), np.median(T["new"])
    print(path.split("/")[-1], "threads", th, "Mpix/s old %.1f new %.1f  time ratio %.3f (best %.3f) same %s" % (N*B*B/mo/1e6, N*B*B/mn/1e6, mn/mo, min(T["new"])/min(T["old"]), np.array_equal(outs["old"], outs["new"])))
