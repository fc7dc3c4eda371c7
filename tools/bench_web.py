"""The browser viewer's JavaScript decoder against the Python decoder on the same files, one
process per measurement, rounds interleaved: open with every key view decoded (both readers decode key
views on demand; ``decodeKeys()`` and ``decode_keys()`` are timed with the open),
median whole-view decode,
median novel-view frame (the viewer's renderer in JS against ``Renderer()`` in Python, both robust).

    python -m tools.bench_web FILE.lfc [FILE.lfc ...] [--rounds 3]

Prints a Markdown table (ratios JS / Python; this box is noisy, read the ratios)."""
from __future__ import annotations

import argparse
import json
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]

PY = r"""
import json, sys, time, numpy as np
from formats import open_decoder, open_lfc
t = time.perf_counter(); d = open_decoder(open_lfc(sys.argv[1]), threads=1); d.decode_keys(); o = time.perf_counter() - t
v = []
for i in range(d.rows * d.cols):
    t = time.perf_counter(); d.decode_views(np.array([i]), planes=True); v.append(time.perf_counter() - t)
r = d.renderer(); fr = []
for i in range(8):
    s, tt = (d.rows - 1) * (0.3 + 0.05 * i), (d.cols - 1) * (0.6 - 0.04 * i)
    t = time.perf_counter(); r.render(s, tt); fr.append(time.perf_counter() - t)
print(json.dumps({"open_ms": 1e3 * o, "view_ms": 1e3 * float(np.median(v)), "frame_ms": 1e3 * float(np.median(fr[1:]))}))
"""


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("files", nargs="+")
    ap.add_argument("--rounds", type=int, default=3)
    a = ap.parse_args(argv)
    node = shutil.which("node")
    if node is None:
        print("node is not installed", file=sys.stderr)
        return 2
    env = {"OMP_NUM_THREADS": "1", "PYTHONPATH": str(ROOT), "PATH": "/usr/bin:/bin"}
    print("| file | open JS / Py (ms) | view JS / Py (ms) | frame JS / Py (ms) |")
    print("|---|---|---|---|")
    for f in (str(Path(x).resolve()) for x in a.files):     # (the workers run in /tmp)
        got = {"js": [], "py": []}
        for _ in range(a.rounds):
            for k, cmd in (("js", [node, str(ROOT / "tools" / "web_bench.mjs"), f]), ("py", [sys.executable, "-c", PY, f])):
                out = subprocess.run(cmd, capture_output=True, text=True, env=env, cwd="/tmp", check=True)
                got[k].append(json.loads(out.stdout.strip().splitlines()[-1]))
        m = {k: {q: float(np.median([x[q] for x in v])) for q in ("open_ms", "view_ms", "frame_ms")} for k, v in got.items()}
        cells = [f"{m['js'][q]:.0f} / {m['py'][q]:.0f} ({m['js'][q] / m['py'][q]:.2f}×)" for q in ("open_ms", "view_ms", "frame_ms")]
        print(f"| {Path(f).stem} | " + " | ".join(cells) + " |", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
