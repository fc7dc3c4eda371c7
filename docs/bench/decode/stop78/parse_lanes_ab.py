# usage: python THIS.py CAPTURE.pkl ...  (captures from parse_lanes_capture.py FILE.lfc OUT.pkl views; rlfc/_txsyntax_old.py = `git show fd561c2:rlfc/txsyntax.py`)
import sys, pickle, time, numpy as np
sys.path.insert(0, ".")
import rlfc.txsyntax as new, rlfc._txsyntax_old as old
calls = []
for f in sys.argv[1:]:
    calls += [(f.split("_")[-1], a, k) for a, k in pickle.load(open(f, "rb"))]
def same(p, q):
    return all(np.array_equal(getattr(p, n), getattr(q, n)) for n in ("modes", "index", "values"))
for tag, a, k in calls:
    assert same(new.parse_lanes(*a, **k), old.parse_lanes(*a, **k))
T = {}
for r in range(12):
    for name, mod in ((("old", old), ("new", new)) if r % 2 == 0 else (("new", new), ("old", old))):
        for i, (tag, a, k) in enumerate(calls):
            t = time.perf_counter(); mod.parse_lanes(*a, **k); T.setdefault((i, name), []).append(time.perf_counter() - t)
for i, (tag, a, k) in enumerate(calls):
    o, n = np.median(T[i, "old"]), np.median(T[i, "new"])
    print(tag, i, "lanes", a[1].size, "old %.1f new %.1f ms ratio %.3f" % (o * 1e3, n * 1e3, n / o))
