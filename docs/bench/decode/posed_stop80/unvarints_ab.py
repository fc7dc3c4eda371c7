# usage: python unvarints_ab.py CHECKOUT   (one code version: run it for the old and the new checkout, alternated)
import sys, time, numpy as np
sys.path.insert(0, sys.argv[1])
from rlfc.txsections import varints, unvarints
rng = np.random.default_rng(0)
for name, v in [("thumb-like", rng.integers(-60, 60, 409600)), ("thumb-wide", rng.integers(-300, 300, 409600)), ("lengths", rng.integers(0, 3000, 80000)), ("wide", rng.integers(-2**62, 2**62, 20000))]:
    data = varints(v)
    assert (unvarints(data, v.size, "t") == v).all()
    t = []
    for _ in range(7):
        a = time.perf_counter(); unvarints(data, v.size, "t"); t.append(time.perf_counter() - a)
    print(sys.argv[1].split('/')[-1] or "x", name, "%.2f ms" % (1e3 * min(t)))
