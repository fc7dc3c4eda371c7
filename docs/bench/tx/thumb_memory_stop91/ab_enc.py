"""One encode of GRID at a PSNR target, with the thumbnail choice remembered across passes at
the same key step (new) or tried afresh each pass (old): prints one JSON line (grid, T, mode,
cpu s, bytes, sha1 of the sections, psnr, passes, code_intra calls, met).
usage: python ab_enc.py GRID T old|new"""
import hashlib, json, os, sys, time
os.environ.setdefault("OMP_NUM_THREADS", "1")
from formats.scenes import read_scene
from formats.codec_api import EncodeOptions
from rlfc import encode
from rlfc import txencode as T


class Forget(dict):
    """A dict that keeps nothing: every pass tries the thumbnails afresh (the old code)."""
    def setdefault(self, k, v=None):
        return v

    def __contains__(self, k):
        return False


grid, target, mode = sys.argv[1], float(sys.argv[2]), sys.argv[3]
cnt = dict(passes=0, intra=0)
orig_run, orig_ci, orig_init = T.TxEncoder.run, T.TxEncoder.code_intra, T.TxEncoder.__init__
def run(self, *a, **k):
    cnt["passes"] += 1
    return orig_run(self, *a, **k)
def ci(self, *a, **k):
    cnt["intra"] += 1
    return orig_ci(self, *a, **k)
def init(self, *a, **k):
    orig_init(self, *a, **k)
    if mode == "old":
        self._thumb_at = Forget()
T.TxEncoder.run, T.TxEncoder.code_intra, T.TxEncoder.__init__ = run, ci, init
lf = read_scene(f"/work/shared/data/{grid}")
c0 = time.process_time()
e = encode(lf, EncodeOptions(profile="tx", target_psnr=target, workers=1))
cpu = time.process_time() - c0
h = hashlib.sha1()
for _, b in e.sections:
    h.update(bytes(b))
print(json.dumps(dict(grid=grid, T=target, mode=mode, cpu=round(cpu, 1),
                      bytes=sum(len(b) for _, b in e.sections), sha1=h.hexdigest()[:12],
                      psnr=round(e.summary["psnr_rgb"], 4), passes=cnt["passes"],
                      intra=cnt["intra"], met=e.target_met)), flush=True)
