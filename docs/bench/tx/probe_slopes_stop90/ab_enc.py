"""One encode of GRID at a PSNR target, with the probe's prior slopes old (-2.5 both ways) or new
(rlfc.txrate.PROBE_SLOPES): prints one JSON line (grid, T, mode, cpu s, bytes, psnr, passes, met).
usage: python ab_enc.py GRID T old|new"""
import json, os, sys, time
os.environ.setdefault("OMP_NUM_THREADS", "1")
from formats.scenes import read_scene
from formats.codec_api import EncodeOptions
from rlfc import encode
import rlfc.txrate as R
from rlfc import txencode as T

grid, target, mode = sys.argv[1], float(sys.argv[2]), sys.argv[3]
if mode == "old":
    R.PROBE_SLOPES = (-2.5, -2.5)
passes = [0]
orig = T.TxEncoder.run
def run(self, *a, **k):
    passes[0] += 1
    return orig(self, *a, **k)
T.TxEncoder.run = run
lf = read_scene(f"/work/shared/data/{grid}")
c0 = time.process_time()
e = encode(lf, EncodeOptions(profile="tx", target_psnr=target, workers=1))
cpu = time.process_time() - c0
print(json.dumps(dict(grid=grid, T=target, mode=mode, cpu=round(cpu, 1),
                      bytes=sum(len(b) for _, b in e.sections), psnr=round(e.summary["psnr_rgb"], 4),
                      passes=passes[0], met=e.target_met)), flush=True)
