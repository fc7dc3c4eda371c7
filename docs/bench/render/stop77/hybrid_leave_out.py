"""Leave views out (as tools.bench_render): render, blending, and hybrids
blend + G_sigma * (render - blend) on the in-between views."""
import sys, os
os.environ.setdefault("OMP_NUM_THREADS", "1")
sys.path.insert(0, "/work/main")
import numpy as np, cv2
from formats.codec_api import EncodeOptions
from formats.metrics import psnr_rgb
from formats.scenes import read_scene
from rlfc import encode
from tools.common import open_encoded
from formats.lfcfile import open_lfc
from rlfc import RlfcDecoder
name = sys.argv[1]
lf = read_scene("/work/shared/data/" + name)
full = lf.views
fn = f"/tmp/w/s77/lo_{name}.lfc"
if not os.path.exists(fn):
    lf.views = np.ascontiguousarray(full[::2, ::2]); lf.positions = lf.positions[::2, ::2]
    d, blob = open_encoded(lf, encode(lf, EncodeOptions(target_psnr=40.0)))
    open(fn, "wb").write(blob)
d = RlfcDecoder(open_lfc(fn))
ren = d.renderer(cache_mib=1024)
R, C = full.shape[:2]
sig = [0.5, 0.7, 1.0, 1.5, 2.0]
acc = {k: [] for k in ["render", "blend"] + [f"h{s}" for s in sig]}
for r in range(R):
    for c in range(C):
        if r % 2 == 0 and c % 2 == 0:
            continue
        s, t = r / 2, c / 2
        img = ren.render(s, t).astype(np.float32)
        corners = [(int(np.floor(s)), int(np.floor(t))), (int(np.floor(s)), int(np.ceil(t))),
                   (int(np.ceil(s)), int(np.floor(t))), (int(np.ceil(s)), int(np.ceil(t)))]
        blend = np.mean([d.decode_view(*k).astype(np.float32) for k in corners], 0)
        peak = float(np.iinfo(full.dtype).max)
        q = lambda x: np.clip(np.rint(x), 0, peak).astype(full.dtype)
        acc["render"].append(psnr_rgb(full[r, c], q(img)))
        acc["blend"].append(psnr_rgb(full[r, c], q(blend)))
        for sg in sig:
            h = blend + cv2.GaussianBlur(img - blend, (0, 0), sg)
            acc[f"h{sg}"].append(psnr_rgb(full[r, c], q(h)))
print(name, " ".join("%s %.2f" % (k, np.mean(v)) for k, v in acc.items()), flush=True)
