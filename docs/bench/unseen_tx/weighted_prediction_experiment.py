# An experiment, not the codec: the decoders do not apply these parameters (BENCHMARKS.md, stop 68).
import sys, numpy as np
sys.path.insert(0,'/work/main')
from pathlib import Path
from formats.codec_api import EncodeOptions
from rlfc import RlfcCodec
import rlfc.txencode as te
from tools.unseen import scenes
name = sys.argv[1]; use = sys.argv[2] == "wp"
lf = scenes(Path('/work/shared/data'))[name] if name in ("antinous_exposure","antinous_jitter","antinous_vignette","antinous_noise3") else None
if lf is None:
    from formats.scenes import read_scene; lf = read_scene('/work/shared/data/'+name)
orig = te.TxEncoder.predict_view
stats = []
def pv(self, v, kp):
    p = orig(self, v, kp)
    o = self.planes(v).astype(np.float64)
    out = np.empty_like(p)
    for c in range(self.P):
        x = p[..., c].astype(np.float64); y = o[..., c]
        vx = x.var()
        g = ((x - x.mean()) * (y - y.mean())).mean() / vx if vx > 0 else 1.0
        gq = int(np.clip(np.rint(g * 64), 32, 96))
        b = int(np.rint(y.mean() - gq / 64 * x.mean()))
        q = ((p[..., c].astype(np.int64) * gq + 32) >> 6) + b
        out[..., c] = np.clip(q, self.lo[c], self.hi[c])
        stats.append((v, c, gq, b))
    return out
if use: te.TxEncoder.predict_view = pv
enc = RlfcCodec().encode(lf, EncodeOptions(target_psnr=40.0))
b = sum(len(x) for _, x in enc.sections)
npx = lf.rows*lf.cols*lf.height*lf.width
extra = lf.rows*lf.cols*lf.channels*3 if use else 0
print(f"{name} {'WP' if use else 'plain'}: {b} B + {extra} B params = {8*(b+extra)/npx:.4f} bpp at {enc.summary['psnr_rgb']:.2f} dB")
