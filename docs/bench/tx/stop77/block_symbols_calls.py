import sys, os, time, types, subprocess
os.environ["OMP_NUM_THREADS"] = "1"
sys.path.insert(0, "/work/main")
import numpy as np
import formats.parallel as fp; fp.LOCAL_THREADS = 1
from formats.scenes import read_scene
from formats.codec_api import EncodeOptions
import rlfc.txencode as te, rlfc.txsyntax as new
src = subprocess.run(["git", "-C", "/work/main", "show", "HEAD:rlfc/txsyntax.py"], capture_output=True, text=True).stdout
old = types.ModuleType("rlfc._old_txsyntax"); old.__package__ = "rlfc"; sys.modules[old.__name__] = old
exec(compile(src, "old_txsyntax", "exec"), old.__dict__)
name = sys.argv[1]
calls = []
orig_pack = te.TxEncoder.pack
def pack(self, res):
    def rec(*a, **k):
        if not k.get("counts_only"):
            calls.append(a)
        return new.block_symbols(*a, **k)
    te.block_symbols = rec
    try:
        return orig_pack(self, res)
    finally:
        te.block_symbols = new.block_symbols
te.TxEncoder.pack = pack
te.encode_tx(read_scene("/work/shared/data/" + name), EncodeOptions(target_psnr=40.0))
print(len(calls), "calls; lanes", [a[0].shape[0] for a in calls][:10], "nt", calls[0][1].shape)
for label, sel in (("all", calls),):
    T = {"old": [], "new": []}
    for r in range(5):
        for k, m in ((("old", old), ("new", new)) if r % 2 == 0 else (("new", new), ("old", old))):
            t = time.process_time()
            for a in sel: m.block_symbols(*a)
            T[k].append(time.process_time() - t)
    print(name, "old %.4f new %.4f" % (np.median(T["old"]), np.median(T["new"])))
nsym = [int((np.abs(a[1]) > 0).sum()) for a in calls]
for a, ns in list(zip(calls, nsym))[:3] + list(zip(calls, nsym))[-3:]:
    T = {"old": [], "new": []}
    for r in range(20):
        for k, m in (("old", old), ("new", new)):
            t = time.perf_counter(); m.block_symbols(*a); T[k].append(time.perf_counter() - t)
    print("  lanes", a[0].shape[0], "nonzero levels", ns, "old %.2f new %.2f ms" % (np.median(T["old"]) * 1e3, np.median(T["new"]) * 1e3))
