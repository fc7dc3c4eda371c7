"""The browser viewer's novel views (``formats/web/render.js`` under Node) against the Python
renderer's (``Renderer()``, numpy) on the same files and cameras: per file, the worst PSNR (dB)
over the cameras, the largest difference of one sample, and the share of samples that differ.

    python -m tools.web_render_parity FILE.lfc [FILE.lfc ...] [--old CHECKOUT]

Cameras: 8 along ``tools.bench_web``'s path plus three grid corners and centres, each with four
option sets (robust, ``robust=False``, a focus, an aperture with a focus). ``--old CHECKOUT``
adds the columns of that checkout's ``render.js`` (this checkout's decoder), for a before/after
in one run. Prints a Markdown table."""
from __future__ import annotations

import argparse
import json
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
OPTIONS = ((None, 0.0, True), (None, 0.0, False), (1.5, 0.0, True), (0.5, 1.2, True))


def cameras(rows: int, cols: int) -> list[list]:
    """[[s, t, focus, aperture, robust], ...]: the cameras × option sets the tool compares."""
    pos = [((rows - 1) * (0.3 + 0.05 * i), (cols - 1) * (0.6 - 0.04 * i)) for i in range(8)]
    pos += [(1.0, 1.0), (0.0, 0.0), (rows - 1, (cols - 1) / 2)]
    return [[s, t, f, a, r] for f, a, r in OPTIONS for s, t in pos]


def js_frames(node: str, f: str, cams: list, root: str | None) -> tuple[list[np.ndarray], list[float]]:
    """The frames (H, W, C) the JavaScript renderer draws at ``cams``, and its ms per frame."""
    with tempfile.TemporaryDirectory() as tmp:
        cf, of = Path(tmp) / "cams.json", Path(tmp) / "out.bin"
        cf.write_text(json.dumps(cams))
        cmd = [node, str(ROOT / "tools" / "web_render_frames.mjs")] + ([root] if root else []) + [f, str(cf), str(of)]
        info = json.loads(subprocess.run(cmd, capture_output=True, text=True, check=True).stdout.strip().splitlines()[-1])
        raw = of.read_bytes()
    n = info["H"] * info["W"] * info["C"]
    dt = np.uint8 if len(raw) == n * len(cams) else np.uint16
    px = np.frombuffer(raw, dt).reshape(len(cams), info["H"], info["W"], info["C"])
    return list(px), info["ms"]


def compare(want: list[np.ndarray], got: list[np.ndarray]) -> tuple[float, int, float]:
    """(worst PSNR dB over the frames (inf where all equal), largest |difference|, share of
    samples that differ)."""
    peak = float(np.iinfo(want[0].dtype).max)
    worst, big, diff, total = np.inf, 0, 0, 0
    for a, b in zip(want, got):
        e = np.abs(a.astype(np.int64) - b.astype(np.int64))
        mse = float(np.mean(e.astype(np.float64) ** 2))
        worst = min(worst, np.inf if mse == 0 else 10 * np.log10(peak * peak / mse))
        big, diff, total = max(big, int(e.max())), diff + int((e > 0).sum()), total + e.size
    return worst, big, diff / total


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("files", nargs="+")
    ap.add_argument("--old", help="a checkout whose render.js to compare as well")
    a = ap.parse_args(argv)
    node = shutil.which("node")
    if node is None:
        print("node is not installed", file=sys.stderr)
        return 2
    from formats import open_decoder, open_lfc

    cols = ["new"] + (["old"] if a.old else [])
    head = " | ".join(f"{c}: worst dB / max diff / samples differing / median ms" for c in cols)
    print(f"| file | Python median ms | {head} |")
    print("|---|---|" + "---|" * len(cols))
    for f in (str(Path(x).resolve()) for x in a.files):
        d = open_decoder(open_lfc(f), threads=1)
        cams = cameras(d.rows, d.cols)
        r = d.renderer()
        import time
        want, pms = [], []
        for s, t, focus, ap_, robust in cams:
            r.robust = robust
            t0 = time.perf_counter()
            want.append(r.render(s, t, focus, ap_))
            pms.append(1e3 * (time.perf_counter() - t0))
        cells = []
        for c in cols:
            got, ms = js_frames(node, f, cams, a.old if c == "old" else None)
            w, big, share = compare(want, got)
            cells.append(f"{w:.1f} / {big} / {100 * share:.3f}% / {np.median(ms[1:]):.0f}")
        print(f"| {Path(f).stem} | {np.median(pms[1:]):.0f} | " + " | ".join(cells) + " |", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
