"""Sections' bytes of whole `tx` encodes with weighted prediction on (the default) or off, one
thread: ``python docs/bench/unseen_tx/weighted_default_stop69.py [--off] [--db T] SCENE...``,
SCENE a folder (a shared grid) or a ``tools.unseen`` variant name (antinous_exposure, ...).
Prints one line per scene: scene, target, bytes, PSNR reached, CPU seconds, views weighted."""
import argparse
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[3]
sys.path.insert(0, str(ROOT))

import formats.parallel as fp  # noqa: E402
from formats.codec_api import EncodeOptions  # noqa: E402
from formats.scenes import read_scene  # noqa: E402
from rlfc import encode  # noqa: E402
from tests.rlfc.helpers import open_encoded  # noqa: E402
from tools.unseen import scenes  # noqa: E402

fp.LOCAL_THREADS = 1
ap = argparse.ArgumentParser()
ap.add_argument("scenes", nargs="+")
ap.add_argument("--off", action="store_true")
ap.add_argument("--db", type=float, default=40.0)
ap.add_argument("--data", default=str(ROOT.parent / "shared" / "data"))
a = ap.parse_args()
for name in a.scenes:
    if Path(name).is_dir():
        lf = read_scene(name)
    else:
        lf = scenes(Path(a.data))[name]
        lf = lf() if callable(lf) else lf
    t = time.process_time()
    e = encode(lf, EncodeOptions(profile="tx", target_psnr=a.db, params={"weighted": not a.off}))
    cpu = time.process_time() - t
    d, _ = open_encoded(lf, e)
    n = sum(len(x) for _, x in e.sections)
    print(f"{'off' if a.off else 'on':3s} {Path(name).name:28s} {a.db:4.0f} {n:9d} B "
          f"{e.summary['psnr_rgb']:.3f} dB cpu {cpu:6.2f} s weighted views {int(d.core._weighted.sum())}", flush=True)
