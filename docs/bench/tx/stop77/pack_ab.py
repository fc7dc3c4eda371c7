"""old vs new txsyntax.block_symbols inside TxEncoder.pack of a real encode's final run (the
same sections checked), alternated."""
import sys, os, time, types, subprocess, hashlib
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
fn = {"old": old.block_symbols, "new": new.block_symbols}
for name in sys.argv[1:]:
    got = {}
    orig = te.TxEncoder.pack
    def pack(self, res):
        got["args"] = (self, res)
        return orig(self, res)
    te.TxEncoder.pack = pack
    te.encode_tx(read_scene("/work/shared/data/" + name), EncodeOptions(target_psnr=40.0))
    te.TxEncoder.pack = orig
    enc, res = got["args"]
    h = {}
    for k in ("old", "new"):
        te.block_symbols = fn[k]
        cfg, sec = enc.pack(res)
        h[k] = hashlib.sha1(b"".join(bytes(x) for _, x in sec)).hexdigest()
    assert h["old"] == h["new"]
    T = {"old": [], "new": []}
    for r in range(6):
        for k in (("old", "new") if r % 2 == 0 else ("new", "old")):
            te.block_symbols = fn[k]
            t = time.process_time(); enc.pack(res); T[k].append(time.process_time() - t)
    print("%s: the same sections; pack CPU-s median old %.3f new %.3f (x %.3f)" % (name, np.median(T["old"]), np.median(T["new"]), np.median(T["new"]) / np.median(T["old"])), flush=True)
