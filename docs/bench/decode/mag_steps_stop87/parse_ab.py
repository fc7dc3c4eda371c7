"""Whole parse_lanes calls, the code before (a copy as package rlfc_old) against this code (stop 87):
every `_parse_streams` call of a fresh first block, a first frame, every key and decode_all of each
file, parsed as lanes by both (whatever ONE_BY_ONE_RATIO picks), alternated, best of 3 ms each;
the same modes, indices and values checked. Args: OLD_PKG_DIR ROUNDS FILE..."""
import sys, time
import numpy as np
sys.path.insert(0, sys.argv[1])
import rlfc_old.txparse as old
import rlfc.txparse as new
sys.path.insert(0, __file__.rsplit('/', 1)[0])
import captures
captured = captures.parse_streams()
from formats.lfcfile import open_lfc
from rlfc import RlfcDecoder
rounds = int(sys.argv[2])
for f in sys.argv[3:]:
    captured.clear()
    d = RlfcDecoder(open_lfc(f)); d.decode_block(0, 0, 0, 0)
    d3 = RlfcDecoder(open_lfc(f)); rad = min(d3.rows, d3.cols) / 3
    d3.renderer(cache_mib=1024).render((d3.rows - 1) / 2, (d3.cols - 1) / 2 + rad)
    d.core.decode_keys(); d.decode_all(threads=1)
    seen = set()
    for (self, buf, s2, e2, nt, kind, key) in captured:
        n = e2 - s2
        sig = (n.size, int(n.sum()), nt)
        if n.size < 4 or sig in seen:
            continue
        seen.add(sig)
        args = (buf, s2, e2, self.tables, nt, self.pcs, kind, key, "")
        a, b = old.parse_lanes(*args), new.parse_lanes(*args)
        assert np.array_equal(a.modes, b.modes) and np.array_equal(a.index, b.index) and np.array_equal(a.values, b.values)
        T = {"old": [], "new": []}
        for r in range(rounds):
            for k, m in ((("old", old), ("new", new)) if r % 2 == 0 else (("new", new), ("old", old))):
                t = time.perf_counter(); m.parse_lanes(*args); T[k].append(time.perf_counter() - t)
        o, w = min(T["old"]) * 1e3, min(T["new"]) * 1e3
        print(f"{f.split('/')[-1]:28s} streams {n.size:5d} nt {nt:4d} bytes {int(n.sum()):8d} ratio {n.sum() / max(n.max(), 1):6.1f}: old {o:7.1f} ms new {w:7.1f} ms x{w / o:.3f}", flush=True)
