import sys, os, pickle, time, types, subprocess
sys.path.insert(0, "/work/main")
os.environ["OMP_NUM_THREADS"] = "1"
import cv2; cv2.setNumThreads(1)
import numpy as np
import formats.parallel as fp; fp.LOCAL_THREADS = 1
import rlfc.txestimate as new
rev = sys.argv[1]
src = open(rev).read() if rev.startswith("/") else subprocess.run(["git", "-C", "/work/main", "show", f"{rev}:rlfc/txestimate.py"], capture_output=True, text=True).stdout
old = types.ModuleType("rlfc._old_est"); old.__package__ = "rlfc"
exec(compile(src, "old_txestimate.py", "exec"), old.__dict__)
what = sys.argv[2]
for path in sys.argv[3:]:
    luma, struct, k = pickle.load(open(path, "rb"))
    res = {}
    tim = {"old": [], "new": []}
    for r in range(int(os.environ.get("ROUNDS", 3))):
        for name, mod in (("old", old), ("new", new)) if r % 2 == 0 else (("new", new), ("old", old)):
            t = time.process_time()
            if what == "global":
                est = mod.Estimator(luma, struct, list(struct.keys))
                out = est.costs_global_many(list(np.arange(-4, 5)))
                out = np.stack(out)
            else:
                out = mod.estimate_maps(luma, struct, **k)
                out = np.concatenate([np.ravel(x).astype(np.float64) for x in out])
            tim[name].append(time.process_time() - t)
            if name in res: assert np.array_equal(res[name], out)
            res[name] = out
    same = np.array_equal(res["old"], res["new"])
    mo, mn = np.median(tim["old"]), np.median(tim["new"])
    print(os.path.basename(path), what, "same", same, "old", round(mo, 3), "new", round(mn, 3), "x", round(mn / mo, 3), flush=True)
