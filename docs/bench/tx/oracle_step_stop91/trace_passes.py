"""Trace a PSNR-targeted encode pass by pass (step, views, key pixels kept, λ scale, CPU s, PSNR,
who asked), then the total CPU, bytes and PSNR. usage: python trace_passes.py GRID T
(env ORACLE_STEP / ORACLE_LAMBDA only act with the hooks of oracle.diff applied)."""
import os, sys, time
os.environ["OMP_NUM_THREADS"]="1"
from formats.scenes import read_scene
from formats.codec_api import EncodeOptions
from rlfc import encode
from rlfc import txencode as T
import traceback
orig=T.TxEncoder.run
def run(self, step, model, progress=None, keep_pixels=False, views=None, lam_scale=1.0):
    c=time.process_time(); r=orig(self, step, model, progress, keep_pixels, views, lam_scale)
    st=[f.name for f in traceback.extract_stack()[-4:-1]]
    print(f"step {step:7.2f} views {'all' if views is None else len(views):>4} keep {int(keep_pixels)} lam {lam_scale:.3f} cpu {time.process_time()-c:5.2f} psnr {self.psnr(r):.3f} by {'<'.join(reversed(st))}", flush=True)
    return r
T.TxEncoder.run=run
lf = read_scene(f"/work/shared/data/{sys.argv[1]}")
c=time.process_time()
e=encode(lf, EncodeOptions(profile="tx", target_psnr=float(sys.argv[2]), workers=1))
print("total cpu", round(time.process_time()-c,1), "bytes", sum(len(b) for _, b in e.sections), "psnr", round(e.summary["psnr_rgb"],4), "env", os.environ.get("ORACLE_STEP"), os.environ.get("ORACLE_LAMBDA"))
