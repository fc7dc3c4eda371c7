"""Per-view warps (tx layout version 5, ``--warps``) against the same encode without them: whole-file
bytes, PSNR reached and encode CPU (one process, one thread: run under ``taskset -c 1`` with
OMP_NUM_THREADS=1) of ``encode_tx`` at a PSNR target, per grid or tools.unseen rig variant.

    python docs/bench/tx/warps_ab_stop72.py TARGET_DB NAME ...   (NAME: a grid of ../shared/data, or
    antinous_rotate | antinous_zoom | antinous_jitter)

Prints one JSON line per name (warps_stop72.jsonl)."""
import json
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[3]
DATA = ROOT.parent / "shared" / "data"
sys.path.insert(0, str(ROOT))
from formats.scenes import read_scene
from formats.codec_api import EncodeOptions
from formats.lfcfile import lfc_bytes
from rlfc.txencode import encode_tx
from tools import unseen
tgt = float(sys.argv[1])
for name in sys.argv[2:]:
    if name.startswith("antinous_"):
        ant = read_scene(DATA / "hci_antinous")
        fn = {"antinous_rotate": unseen.rotated, "antinous_zoom": unseen.zoomed, "antinous_jitter": unseen.jittered}[name]
        lf = unseen._grid(fn(ant.views), name)
    else:
        lf = read_scene(DATA / name)
    row = {"grid": name, "target": tgt}
    for warps in (False, True):
        t = time.process_time()
        e = encode_tx(lf, EncodeOptions(target_psnr=tgt, params={"warps": warps}))
        cpu = time.process_time() - t
        b = len(lfc_bytes("rlfc", 1, e.config, lf.geometry(), e.sections, more=e.more))
        k = "warps" if warps else "plain"
        row[k] = {"bytes": b, "psnr": round(e.summary["psnr_rgb"], 3), "cpu_s": round(cpu, 2),
                  "version": e.config["tx"]["version"], "report": e.summary.get("warps")}
    row["ratio"] = round(row["warps"]["bytes"] / row["plain"]["bytes"], 4)
    print(json.dumps(row), flush=True)
