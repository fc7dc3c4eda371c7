import sys, os, time, collections, pickle
sys.path.insert(0, sys.argv[1])
os.environ["OMP_NUM_THREADS"] = "1"
import formats.parallel as fp; fp.LOCAL_THREADS = 1
from formats.scenes import read_scene
from formats.codec_api import EncodeOptions
import rlfc.txencode as te, rlfc.txestimate as tes
lf = read_scene(sys.argv[2])
acc = collections.Counter(); cnt = collections.Counter()
for n in ["costs_global_many", "costs_maps"]:
    f = getattr(tes.Estimator, n)
    def w(*a, _f=f, _n=n, **k):
        t = time.process_time(); r = _f(*a, **k); acc[_n] += time.process_time() - t; cnt[_n] += 1
        if _n == "costs_global_many": cnt["global_cands"] += len(a[1])
        return r
    setattr(tes.Estimator, n, w)
cap = {}
f0 = te.estimate_maps
def em(luma, struct, **k):
    cap["args"] = (luma, struct, k)
    t = time.process_time(); r = f0(luma, struct, **k); acc["estimate_maps"] += time.process_time() - t; return r
te.estimate_maps = em
class Stop(Exception): pass
orig = te.TxEncoder.run
def run(*a, **k): raise Stop
te.TxEncoder.run = run
try:
    te.encode_tx(lf, EncodeOptions(target_psnr=40.0, params={"warps": True} if os.environ.get("WARPS") else {}))
except Stop:
    pass
for k in acc: print(k, cnt[k], round(acc[k], 3))
print("global_cands", cnt["global_cands"], "cells", len(cap["args"][1].cell_views), "luma", cap["args"][0].shape, cap["args"][0].dtype)
if len(sys.argv) > 3:
    luma, struct, k = cap["args"]
    k.pop("runner", None); k.pop("progress", None)
    pickle.dump((luma, struct, k), open(sys.argv[3], "wb"))
