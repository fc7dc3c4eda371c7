"""Parse-level A/B of rlfc.txparse._magnitudes (stop 87): the calls captured by capture.py (a first frame and a view of four 40 dB files, with the outputs of the code before), replayed on the code before (a copy as package rlfc_old) and this code, alternated; each checked bit for bit against the captured symbols, states and pointers."""
import sys, pickle, time, importlib.util, numpy as np
sys.path.insert(0, "/work/main")
from rlfc.rans import Tables
import os; caps = pickle.load(open(os.environ.get("CAPS", "/tmp/w87/caps.pkl"), "rb"))
def load(path, name):
    spec = importlib.util.spec_from_file_location(name, path); m = importlib.util.module_from_spec(spec); spec.loader.exec_module(m); return m
sys.path.insert(0, "/tmp/w87/oldpkg"); import rlfc_old.txparse as old; import rlfc.txparse as cur
mods = [old, cur] + [load(p, f"m{i}") for i, p in enumerate(sys.argv[2:])]
class D: pass
def run(mod, c, tabs):
    d = D(); d.x = c["x"].copy(); d.ptr = c["ptr"].copy(); d.buf = c["buf"]; d.top = c["top"]
    t = time.perf_counter()
    out = mod._magnitudes(d, tabs, c["S"], c["per_lane"], c["lane_start"], c["j"], c["ctx1"])
    dt = time.perf_counter() - t
    assert np.array_equal(out, c["out"]) and np.array_equal(d.x, c["x_after"]) and np.array_equal(d.ptr, c["ptr_after"]), "MISMATCH"
    return dt
tabs = [Tables(c["tables"][0]) for c in caps]
res = {i: [[] for _ in mods] for i in range(len(caps))}
for r in range(int(sys.argv[1])):
    for i, c in enumerate(caps):
        for mi, m in enumerate(mods):
            res[i][mi].append(run(m, c, tabs[i]))
for i, c in enumerate(caps):
    med = [np.median(x) * 1e3 for x in res[i]]
    print(f"S={c['S']} tot={c['ctx1'].size}: before {med[0]:.1f} ms | " + " | ".join(f"{m:.1f} x{m/med[0]:.3f}" for m in med[1:]))
