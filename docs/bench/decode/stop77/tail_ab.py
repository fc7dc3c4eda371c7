import sys, os, time
sys.path.insert(0, "/work/main")
import numpy as np
from formats.lfcfile import open_lfc
from rlfc import RlfcDecoder
import rlfc.txsyntax as tx
vals = [int(v) for v in os.environ.get("TAILS", "32,64,128").split(",")]
for g in sys.argv[1:]:
    d = RlfcDecoder(open_lfc(g)); c = d.core
    rng = np.random.default_rng(0)
    pv = np.flatnonzero(~c.is_key)
    for nviews in (1, 8):
        calls = []
        for _ in range(6):
            vs = rng.choice(pv, nviews, replace=False)
            locs = [np.flatnonzero(c.coded[v]) for v in vs]
            V = np.repeat(vs, [l.size for l in locs]); Lc = np.concatenate(locs)
            if V.size == 0: continue
            buf, s2, e2 = c._streams(c.start[V, Lc], c.end[V, Lc])
            calls.append((buf, s2, e2, c.tables, c.nt, c.pcs, c.lay.intra[V].astype(np.int64), c.is_key[V].astype(np.int64)))
        T = {v: [] for v in vals}
        for r in range(8):
            for i, a in enumerate(calls):
                for v in (vals if (r + i) % 2 == 0 else vals[::-1]):
                    tx.TAIL_LANES = v
                    t = time.perf_counter(); tx.parse_lanes(*a); T[v].append(time.perf_counter() - t)
        base = np.array(T[vals[0]])
        print(os.path.basename(g), nviews, "view(s):", ", ".join("TAIL %d %.2f ms (x %.3f)" % (v, np.median(T[v]) * 1e3, np.median(np.array(T[v]) / base)) for v in vals), flush=True)
