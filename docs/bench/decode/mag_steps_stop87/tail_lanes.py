"""TAIL_LANES (where _magnitudes finishes in plain Python) re-checked after the uint32 steps and the
per-lane tail (stop 87): the captured calls of caps.pkl and caps2.pkl, each value alternated, median
ms of N rounds, every run checked against the captured symbols."""
import sys, pickle, time, numpy as np
import rlfc.txparse as tp
from rlfc.rans import Tables
caps = pickle.load(open("/tmp/w87/caps.pkl", "rb")) + pickle.load(open("/tmp/w87/caps2.pkl", "rb"))
TLS = [int(v) for v in sys.argv[2].split(",")] if len(sys.argv) > 2 else [16, 32, 48, 64]
class D: pass
tabs = [Tables(c["tables"][0]) for c in caps]
res = {(i, t): [] for i in range(len(caps)) for t in TLS}
for r in range(int(sys.argv[1])):
    for i, c in enumerate(caps):
        for t in (TLS if r % 2 == 0 else TLS[::-1]):
            tp.TAIL_LANES = t
            d = D(); d.x = c["x"].copy(); d.ptr = c["ptr"].copy(); d.buf = c["buf"]; d.top = c["top"]
            t0 = time.perf_counter()
            out = tp._magnitudes(d, tabs[i], c["S"], c["per_lane"], c["lane_start"], c["j"], c["ctx1"])
            res[(i, t)].append(time.perf_counter() - t0)
            assert np.array_equal(out, c["out"]) and np.array_equal(d.ptr, c["ptr_after"])
for i, c in enumerate(caps):
    base = np.median(res[(i, 32)])
    print(f"S={c['S']:5d} tot={c['ctx1'].size:8d} K={int(c['per_lane'].max()):5d}: " + "  ".join(f"{t}: {np.median(res[(i, t)])*1e3:6.1f} ({np.median(res[(i, t)])/base:.3f})" for t in TLS))
