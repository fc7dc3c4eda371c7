"""Feasibility: PSNR of a horizontal band of every view against the whole views, at steps around
the 40 dB step, the same key ratio and entropy-model procedure (maps estimated per light field)."""
import sys, time
import numpy as np
import formats.parallel as fp
fp.LOCAL_THREADS = 1
from dataclasses import replace
from formats import EncodeOptions, read_scene
from rlfc.txencode import TxEncoder
from rlfc.txparams import TxParams
from rlfc.txrate import side_lambda
from rlfc.txmodel import Model, default_counts

g, s_star, frac = sys.argv[1], float(sys.argv[2]), float(sys.argv[3])
lf = read_scene("/work/shared/data/" + g)
R, C, H, W, Ch = lf.views.shape
band = int(round(H * frac / 16)) * 16
y0 = ((H - band) // 2) // 16 * 16
crop = replace(lf, views=np.ascontiguousarray(lf.views[:, :, y0:y0 + band]))
opts = EncodeOptions(target_psnr=40)
p = TxParams()
res = {}
for name, L in (("full", lf), ("band", crop)):
    t = time.process_time()
    enc = TxEncoder(L, p, None, side_lambda(L, opts, p))
    t_est = time.process_time() - t
    out = []
    for f in (-0.5, 0.0, 0.5):
        s = enc.grid_step(s_star * 2 ** f)
        t = time.process_time()
        r = enc.run(s, Model(default_counts()))
        r = enc.run(s, enc.model_of(r))
        out.append((s, enc.psnr(r), (time.process_time() - t) / 2))
    res[name] = out
    print(g, name, "rows", L.views.shape[2], "est %.1f s" % t_est, " ".join("step %.2f %.3f dB (%.2f s/pass)" % o for o in out), flush=True)
d = [a[1] - b[1] for a, b in zip(res["full"], res["band"])]
print(g, "delta full-band", " ".join("%.3f" % x for x in d), "spread %.3f" % (max(d) - min(d)))
