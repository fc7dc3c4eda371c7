"""old vs new rlfc.txsyntax.parse_lanes on the coded blocks of real files (every coded stream of
N random views per call, as a whole-view and a batched call parse them), calls alternated; the
same Parsed checked."""
import sys, os, time, types, subprocess
os.environ["OMP_NUM_THREADS"] = "1"
sys.path.insert(0, "/work/main")
import numpy as np
from formats.lfcfile import open_lfc
from rlfc import RlfcDecoder
import rlfc.txsyntax as new
REV = os.environ.get("REV", "HEAD")
src = subprocess.run(["git", "-C", "/work/main", "show", f"{REV}:rlfc/txsyntax.py"], capture_output=True, text=True).stdout
old = types.ModuleType("rlfc._old_txsyntax"); old.__package__ = "rlfc"; sys.modules[old.__name__] = old
exec(compile(src, "old_txsyntax", "exec"), old.__dict__)
rounds = int(os.environ.get("ROUNDS", "8"))
for path in sys.argv[1:]:
    d = RlfcDecoder(open_lfc(path)); c = d.core
    rng = np.random.default_rng(0)
    pv = np.flatnonzero(~c.is_key)
    for nviews in (1, 8):
        calls = []
        for _ in range(6):
            vs = rng.choice(pv, nviews, replace=False)
            locs = [np.flatnonzero(c.coded[v]) for v in vs]
            V = np.repeat(vs, [l.size for l in locs]); Lc = np.concatenate(locs)
            if V.size == 0:
                continue
            s, e = c.start[V, Lc], c.end[V, Lc]
            buf, s2, e2 = c._streams(s, e)
            calls.append((buf, s2, e2, c.tables, c.nt, c.pcs, c.lay.intra[V].astype(np.int64), c.is_key[V].astype(np.int64)))
        if not calls:
            print(os.path.basename(path), "no coded blocks"); break
        for a in calls:
            po, pn = old.parse_lanes(*a), new.parse_lanes(*a)
            assert all(np.array_equal(getattr(po, f), getattr(pn, f)) for f in ("modes", "index", "values"))
        T = {"old": [], "new": []}
        for r in range(rounds):
            for i, a in enumerate(calls):
                for k, m in ((("old", old), ("new", new)) if (i + r) % 2 == 0 else (("new", new), ("old", old))):
                    t = time.perf_counter(); m.parse_lanes(*a); T[k].append(time.perf_counter() - t)
        o, n = np.array(T["old"]), np.array(T["new"])
        print("%s, %d view(s) per call (%d streams): same; ms median old %.2f new %.2f, median ratio %.3f"
              % (os.path.basename(path), nviews, np.mean([a[1].size for a in calls]), np.median(o) * 1e3, np.median(n) * 1e3, np.median(n / o)), flush=True)
