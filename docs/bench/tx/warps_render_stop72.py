"""Leave views out on a grid: every 2nd view (rows and columns) encoded with and without per-view
warps (``warps``) at a PSNR target; the views between rendered (the default robust renderer,
numpy) and compared with the captured ones (PSNR); the warped file also rendered with its warps
ignored (the renderer before stop 72).

    python docs/bench/tx/warps_render_stop72.py NAME TARGET_DB   (NAME: a grid of ../shared/data,
    antinous_rotate | antinous_zoom | antinous_jitter, or antinous_drift: rotation 0.08° per
    column and 0.05° per row, scale 1 + 0.0008 per row, about the centre view)

One JSON line (warps_render_stop72.jsonl)."""
import json
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[3]
DATA = ROOT.parent / "shared" / "data"
sys.path.insert(0, str(ROOT))
import numpy as np  # noqa: E402
from formats.codec_api import EncodeOptions
from formats.metrics import psnr_rgb
from formats.scenes import read_scene
from rlfc import encode
from tools.common import open_encoded
from tools import unseen
name, target = sys.argv[1], float(sys.argv[2])
if name == "antinous_drift":
    import cv2
    src = read_scene(DATA / "hci_antinous")
    r_, c_, h, w, _ = src.views.shape
    mats = [cv2.getRotationMatrix2D((w / 2 - 0.5, h / 2 - 0.5), 0.08 * (j - 4) + 0.05 * (i - 4), 1.0 + 0.0008 * (i - 4))
            for i in range(r_) for j in range(c_)]
    lf = unseen._grid(unseen._warped(src.views, mats), name)
elif name.startswith("antinous_"):
    src = read_scene(DATA / "hci_antinous")
    lf = unseen._grid({"rotate": unseen.rotated, "zoom": unseen.zoomed, "jitter": unseen.jittered}[name.split("_")[1]](src.views), name)
else:
    lf = read_scene(DATA / name)
full = lf.views
lf.views = np.ascontiguousarray(full[::2, ::2]); lf.positions = lf.positions[::2, ::2]
out = {"grid": name, "target": target}
for w in (False, True):
    e = encode(lf, EncodeOptions(target_psnr=target, params={"warps": w}))
    d, blob = open_encoded(lf, e)
    ren = d.renderer(cache_mib=1024)
    ign = d.renderer(cache_mib=1024)
    ign._warp = None
    ps, pi = [], []
    R, C = full.shape[:2]
    for r in range(R):
        for c in range(C):
            if r % 2 == 0 and c % 2 == 0:
                continue
            ps.append(psnr_rgb(full[r, c], ren.render(r / 2, c / 2)))
            if w:
                pi.append(psnr_rgb(full[r, c], ign.render(r / 2, c / 2)))
    out["warps" if w else "plain"] = {"bytes": len(blob), "render_psnr_mean": round(float(np.mean(ps)), 3),
                                      "render_psnr_min": round(float(np.min(ps)), 3), "warps": e.summary.get("warps")}
    if w:
        out["warps"]["render_ignoring_warps_psnr_mean"] = round(float(np.mean(pi)), 3)
        out["warps"]["render_ignoring_warps_psnr_min"] = round(float(np.min(pi)), 3)
print(json.dumps(out), flush=True)
