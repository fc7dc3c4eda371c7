import sys, json, subprocess, numpy as np
sys.path.insert(0, "/work/main")
from tools import unseen
from formats.scenes import read_scene
from formats import open_lfc, open_decoder
from formats.metrics import psnr_rgb
ant = read_scene("/work/shared/data/hci_antinous")
clean = ant.views
m = 24
for name, f in (("rotate", unseen.rotated), ("zoom", unseen.zoomed), ("jitter", unseen.jittered), ("clean", lambda v: v)):
    v = f(clean)
    np.save(f"/tmp/fl/{name}.npy", v.reshape(81, 512, 512, 3))
    for t in sys.argv[1:]:
        for rect in ([], ["--rectify"]):
            out = f"/tmp/fl/{name}{'_r' if rect else ''}_{t}.lfc"
            r = subprocess.run(["lfcodec", "encode", f"/tmp/fl/{name}.npy", out, "--grid", "9x9", "--target-psnr", t, "--json", "--quiet"] + rect,
                               capture_output=True, text=True, env={"OMP_NUM_THREADS": "1", "PATH": "/work/main/.venv/bin:/usr/bin:/bin"})
            rep = json.loads(r.stdout)
            dec = open_decoder(open_lfc(out)).decode_all()
            print(json.dumps({"variant": name, "target": float(t), "rectify": bool(rect), "bytes": rep["bytes"], "bpp": round(rep["bpp"], 5),
                              "psnr_vs_coded": round(rep["psnr_rgb"], 3), "target_met": rep.get("target_met"),
                              "rectified": (rep.get("rectify") or {}).get("applied"), "largest_px": (rep.get("rectify") or {}).get("largest_correction_px"),
                              "psnr_interior_vs_clean_grid": round(psnr_rgb(clean[:, :, m:-m, m:-m], dec[:, :, m:-m, m:-m]), 2),
                              "encode_s": rep["encode_s"]}), flush=True)
