"""Leave-views-out PSNR (``tools.bench_render.bench_scene``: every second view encoded at 40 dB,
the rest rendered) of the robust renderer's disagreement before stop 94 (the sources' luma as it
is) and after it (each source less its own box mean over ``MK`` × the averaging box; the library
takes MK = 4: ``rlfc.render.ROBUST_LEVEL_WINDOW`` = 64 px), in one process.
Usage: PYTHONPATH=. [MK=4] python zm_ab.py SCENE ..."""
import os
import sys

import rlfc.render_ops as ro
from tools.bench_render import bench_scene

MK = int(os.environ.get("MK", "4"))


def before(self, lum, ws, k, kb):
    n = len(ws)
    return [self.blur(self.wsum(self.sq_dev(lum[i:i + n], self.wsum(lum[i:i + n], ws)), ws), k)
            for i in range(0, len(lum), n)]


def after(self, lum, ws, k, kb):
    n = len(ws)
    costs = []
    for i in range(0, len(lum), n):
        smp = [x - self.blur(x, min(MK * k, kb)) for x in lum[i:i + n]]
        costs.append(self.blur(self.wsum(self.sq_dev(smp, self.wsum(smp, ws)), ws), k))
    return costs


for path in sys.argv[1:]:
    out = {}
    for name, f in (("before", before), ("after", after)):
        ro.NumpyOps.disagreement = f
        r = bench_scene(path, 40.0)
        out[name] = (r["psnr"]["render"], r["psnr_worst"]["render"], r["ssim"]["render"])
        blend, fast = r["psnr"]["blend"], r["psnr"]["render_fast"]
    print(f"{path.split('/')[-1]:22s} before {out['before'][0]:.2f} ({out['before'][1]:.2f}) ssim {out['before'][2]:.4f} | "
          f"after {out['after'][0]:.2f} ({out['after'][1]:.2f}) ssim {out['after'][2]:.4f} | fast {fast:.2f} "
          f"blend {blend:.2f}", flush=True)
