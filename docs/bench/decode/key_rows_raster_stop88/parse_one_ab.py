import sys, pickle, time, importlib, numpy as np
from formats.lfcfile import open_lfc
from rlfc import RlfcDecoder
mods = {}
for tag, path in (("old", "/tmp/old88"), ("new", "/work/main")):
    sys.path.insert(0, path)
    for m in [k for k in sys.modules if k.startswith("rlfc")]:
        del sys.modules[m]
    mods[tag] = importlib.import_module("rlfc.txparse_one").parse_one
    sys.path.pop(0)
for pk in sys.argv[1:]:
    f, calls = pickle.load(open(pk, "rb"))
    d = RlfcDecoder(open_lfc(f)); tables = d.core.tables
    res = {k: [] for k in mods}
    outs = {}
    for r in range(7):
        for tag, fn in (mods.items() if r % 2 else reversed(list(mods.items()))):
            t = time.perf_counter()
            o = [fn(c[0], tables, c[1], c[2], c[3], c[4]) for c in calls]
            res[tag].append(time.perf_counter() - t)
            outs[tag] = o
    same = all(np.array_equal(a.modes, b.modes) and np.array_equal(a.index, b.index) and np.array_equal(a.values, b.values) for a, b in zip(outs["old"], outs["new"]))
    print(f"{pk.split('/')[-1]:20s} old {min(res['old'])*1e3:6.2f} ms new {min(res['new'])*1e3:6.2f} ms x{min(res['new'])/min(res['old']):.3f} same={same}")
