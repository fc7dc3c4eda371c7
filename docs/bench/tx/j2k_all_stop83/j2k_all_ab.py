"""Every view as JPEG 2000 tried where most views go alone (stop 83): each (capture, target)
encoded by the default and with "j2k_all" ablated (the code before it), fresh process each,
sections' bytes, PSNR, CPU; and per-view JPEG 2000's bytes at the target (tools.unseen.j2k_at,
interpolated between OpenJPEG levels) for the ratio.

    python docs/bench/tx/j2k_all_stop83/j2k_all_ab.py SCENE TARGET [j2k_all]

SCENE: a folder of ../shared/data, or a tools.unseen variant name.
"""
import json
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[4]))     # (the repository: tools.unseen)
from formats import EncodeOptions, read_scene
from formats.metrics import bpp
from rlfc import RlfcCodec
from rlfc.txrate import file_bytes

DATA = Path("/work/shared/data")
name, target, abl = sys.argv[1], float(sys.argv[2]), sys.argv[3:]
if (DATA / name).is_dir():
    lf = read_scene(DATA / name)
else:
    from tools.unseen import scenes
    lf = scenes(DATA)[name]
t = time.process_time()
e = RlfcCodec().encode(lf, EncodeOptions(target_psnr=target, params={"ablate": abl} if abl else {}))
cpu = time.process_time() - t
out = {"scene": name, "target": target, "code": "ablated" if abl else "new",
       "sections": sum(len(bytes(s[1])) for s in e.sections), "file": file_bytes(lf, e.config, e.sections),
       "psnr": round(e.summary["psnr_rgb"], 4), "cpu_s": round(cpu, 1),
       "all_j2k": any("no view is predicted" in n for n in e.notes)}
out["bpp"] = round(bpp(out["file"], lf.rows * lf.cols, lf.height, lf.width), 5)
if "--peer" in sys.argv or not abl:
    from tools.unseen import j2k_at
    out["j2k_bpp"] = round(j2k_at(lf, target)[0], 5)
    out["x_j2k"] = round(out["bpp"] / out["j2k_bpp"], 4)
print(json.dumps(out), flush=True)
