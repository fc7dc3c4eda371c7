"""An experiment, not the codec (BENCHMARKS.md, stop 68): what weighted prediction would buy.

Usage: ``python docs/bench/unseen_tx/weighted_prediction_experiment.py GRID plain|wp|fits``
(GRID: a folder of ../shared/data or a ``tools.unseen`` variant name).

``wp`` follows the encoder's prediction of every predicted view with a gain per plane (1/64
units, 32..96) and an integer offset, fitted by least squares against the view's own planes at
every pass; the decoders do not read them, so the file is not decodable: the figure is its
bytes, the parameters counted at 3 bytes per view and plane. ``fits`` prints the last pass's
fits.
"""
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[3]))

from formats.codec_api import EncodeOptions  # noqa: E402
from formats.scenes import read_scene  # noqa: E402
from rlfc import RlfcCodec  # noqa: E402
import rlfc.txencode as te  # noqa: E402
from tools.unseen import scenes  # noqa: E402

DATA = Path(__file__).resolve().parents[4] / "shared" / "data"
name, mode = sys.argv[1], sys.argv[2]
lf = scenes(DATA)[name] if not (DATA / name).is_dir() else read_scene(DATA / name)
orig = te.TxEncoder.predict_view
fits = {}


def weighted(self, v, kp):
    p = orig(self, v, kp)
    o = self.planes(v).astype(np.float64)
    out = np.empty_like(p)
    for c in range(self.P):
        x, y = p[..., c].astype(np.float64), o[..., c]
        vx = x.var()
        g = ((x - x.mean()) * (y - y.mean())).mean() / vx if vx > 0 else 1.0
        gq = int(np.clip(np.rint(g * 64), 32, 96))
        b = int(np.rint(y.mean() - gq / 64 * x.mean()))
        out[..., c] = np.clip(((p[..., c].astype(np.int64) * gq + 32) >> 6) + b, self.lo[c], self.hi[c])
        fits[(v, c)] = (gq, b)
    return out


if mode in ("wp", "fits"):
    te.TxEncoder.predict_view = weighted
enc = RlfcCodec().encode(lf, EncodeOptions(target_psnr=40.0))
b = sum(len(x) for _, x in enc.sections)
npx = lf.rows * lf.cols * lf.height * lf.width
extra = lf.rows * lf.cols * lf.channels * 3 if mode != "plain" else 0
print(f"{name} {'WP' if mode != 'plain' else 'plain'}: {b} B + {extra} B params = {8 * (b + extra) / npx:.4f} bpp "
      f"at {enc.summary['psnr_rgb']:.2f} dB")
if mode == "fits":
    for lab, sel in (("luma", lambda c: c == 0), ("chroma", lambda c: c > 0)):
        g = np.array([f[0] for (v, c), f in fits.items() if sel(c)])
        o = np.array([f[1] for (v, c), f in fits.items() if sel(c)])
        print(f"{name} {lab} gain /64: min {g.min()} median {np.median(g):g} max {g.max()}; offset {o.min()} .. {o.max()}")
