"""Encode time and memory against light-field size, serial and on a local process pool.

Usage:
    python -m tools.bench_scale [--data ../shared/data] [--scene hci_antinous] [--grids 5,9,17] [--workers 1,2]
                                [--decoded dropped,kept] [--source memory,files] [--target-psnr 40]
                                [--out docs/bench/scale]

Grids of growing size are made from one shared dense grid: its centre 5×5, the grid itself
(9×9), and a 17×17 grid that mirrors it across its last row and column (rows 0..8, 7..0: a
real light field whose parallax turns around at the mirror, so each cell of views is still a
real one). Each encode runs in its own process (``lfcodec encode`` through the library),
sampled every 0.1 s for the resident memory of the
process and of its worker processes. Reported: wall and CPU seconds, the peak resident memory
of the parent and of the largest worker, both also as multiples of the raw input (views × H ×
W × C bytes), and above the same interpreter's resident memory after importing the codec (the
floor any run pays), the file's bytes and PSNR. ``--decoded``: ``dropped`` encodes with
``EncodeOptions(keep_decoded=False)`` (what ``lfcodec encode`` asks of a lossy grid: PSNR from
the encoder's per-view errors), ``kept`` holds the decoded views as before (PSNR measured on
them). ``--source``: ``memory`` gives the encoder the views as one array in memory; ``files``
writes them once as PNG files (an HCI folder, before the measured process starts) and reads that
folder as ``lfcodec encode`` does, each view decoded from its file when the encoder asks for it
(``read_scene(lazy=True)``). ``--arenas one`` (the default) asks malloc for one arena, as
``lfcodec`` does (:mod:`formats.heap`); ``default`` leaves glibc's. Writes scale.json, scale.md
and scale.png.
"""
from __future__ import annotations

import argparse
import json
import subprocess
import sys
import time
from pathlib import Path

from tools.common import log, machine

CHILD = r"""
import json, os, sys, time
import numpy as np
from formats.codec_api import EncodeOptions
from formats.metrics import psnr_rgb
from formats.scenes import read_scene
from rlfc.codec import RlfcCodec
from tools.bench_scale import grid_views
import psutil
if __name__ == "__main__":
    if sys.argv[7] == "one":
        from formats.heap import limit_arenas
        limit_arenas(1)
    scene, n, workers, target = sys.argv[1], int(sys.argv[2]), int(sys.argv[3]), float(sys.argv[4])
    keep, folder = sys.argv[5] == "kept", sys.argv[6]
    floor = psutil.Process().memory_info().rss
    if folder:
        lf = read_scene(folder, lazy=True)
        raw = lf.views.nbytes
    else:
        lf = grid_views(scene, n)
        raw = lf.views.nbytes
    print(json.dumps({"event": "start", "floor_rss": floor, "raw": raw}), flush=True)
    t = time.perf_counter(); cpu = time.process_time()
    e = RlfcCodec().encode(lf, EncodeOptions(target_psnr=target, workers=workers, keep_decoded=keep))
    out = {"event": "done", "wall_s": time.perf_counter() - t, "parent_cpu_s": time.process_time() - cpu,
           "bytes": sum(len(x) for _, x in e.sections),
           "psnr": psnr_rgb(np.asarray(lf.views), e.decoded) if keep else e.summary["psnr_rgb"],
           "passes": len(e.trace), "step": e.summary["params"]["step"],
           "decodes": getattr(getattr(lf.views, "arr", None), "decodes", None)}
    print(json.dumps(out), flush=True)
"""


def grid_views(scene, n: int):
    """The n×n grid made from ``scene`` (its centre, or mirrored past its edge; see the module
    docstring) as a light field in memory."""
    import numpy as np

    from formats.lightfield import LightField, grid_positions
    from formats.scenes import read_scene

    lf = read_scene(scene)
    r, c = lf.views.shape[:2]
    if n <= r:
        a, b = (r - n) // 2, (c - n) // 2
        idx_r, idx_c = np.arange(a, a + n), np.arange(b, b + n)
    else:                                   # mirror: 0..r-1, r-2..0, ... up to n
        period = 2 * (r - 1)
        k = np.arange(n) % period
        idx_r = idx_c = np.where(k < r, k, period - k)
    views = np.ascontiguousarray(lf.views[idx_r][:, idx_c])
    return LightField(views=views, positions=grid_positions(n, n), layout="grid")


def write_grid(scene, n: int, folder: Path) -> None:
    """The n×n grid of :func:`grid_views` as an HCI folder (``input_CamNNN.png``, row-major)."""
    from formats.imageio import write_image

    v = grid_views(scene, n).views
    folder.mkdir(parents=True, exist_ok=True)
    for i in range(n * n):
        write_image(folder / f"input_Cam{i:03d}.png", v[i // n, i % n])


def run_one(scene: Path, n: int, workers: int, target: float, decoded: str = "dropped", folder: str = "",
            arenas: str = "one") -> dict:
    import psutil

    p = subprocess.Popen([sys.executable, "-c", CHILD, str(scene), str(n), str(workers), str(target), decoded, folder, arenas],
                         stdout=subprocess.PIPE, text=True, env={**__import__("os").environ, "OMP_NUM_THREADS": "1"})
    proc = psutil.Process(p.pid)
    peak_parent = peak_worker = peak_total = 0
    cpu_children: dict = {}
    import threading

    lines: list = []
    th = threading.Thread(target=lambda: lines.extend(p.stdout), daemon=True)
    th.start()
    while p.poll() is None:
        try:
            rp = proc.memory_info().rss
            kids = proc.children(recursive=True)
            rk = []
            for k in kids:
                try:
                    rk.append(k.memory_info().rss)
                    ct = k.cpu_times()
                    cpu_children[k.pid] = ct.user + ct.system
                except psutil.Error:
                    pass
            peak_parent = max(peak_parent, rp)
            peak_worker = max([peak_worker] + rk)
            peak_total = max(peak_total, rp + sum(rk))
        except psutil.Error:
            pass
        time.sleep(0.1)
    th.join()
    recs = [json.loads(x) for x in lines if x.startswith("{")]
    start = next(r for r in recs if r["event"] == "start")
    done = next(r for r in recs if r["event"] == "done")
    raw, floor = start["raw"], start["floor_rss"]
    return {"grid": f"{n}x{n}", "views": n * n, "workers": workers, "decoded": decoded,
            "source": "files" if folder else "memory", "arenas": arenas, "raw_mib": raw / 2 ** 20,
            "mpix": raw / 3 / 1e6, **{k: v for k, v in done.items() if k != "event"},
            "worker_cpu_s": sum(cpu_children.values()),
            "peak_parent_mib": peak_parent / 2 ** 20, "peak_worker_mib": peak_worker / 2 ** 20,
            "peak_total_mib": peak_total / 2 ** 20, "floor_mib": floor / 2 ** 20,
            "parent_x_raw": peak_parent / raw, "parent_above_floor_x_raw": (peak_parent - floor) / raw,
            "worker_x_raw": peak_worker / raw, "worker_above_floor_x_raw": max(peak_worker - floor, 0) / raw}


def write_outputs(rows: list, scene: str, target: float, out: Path) -> None:
    """scale.md and (with matplotlib) scale.png from the runs ``rows``."""
    md = ["| grid | raw MiB | workers | views from | decoded views | wall s | CPU s (parent + workers) | peak parent "
          "MiB (× raw; above floor × raw) | peak worker MiB | bytes | PSNR dB | passes |", "|" + "---|" * 12]
    for r in rows:
        md.append(f"| {r['grid']} | {r['raw_mib']:.0f} | {r['workers']} | {r.get('source', 'memory')} | "
                  f"{r.get('decoded', 'kept')} | {r['wall_s']:.0f} | "
                  f"{r['parent_cpu_s'] + r['worker_cpu_s']:.0f} | {r['peak_parent_mib']:.0f} ({r['parent_x_raw']:.1f}×; "
                  f"{r['parent_above_floor_x_raw']:.1f}×) | {r['peak_worker_mib']:.0f} | {r['bytes']} | "
                  f"{r['psnr']:.2f} | {r['passes']} |")
    (out / "scale.md").write_text("\n".join(md) + "\n")
    try:
        import matplotlib
        matplotlib.use("Agg")
        import matplotlib.pyplot as plt

        fig, ax = plt.subplots(1, 2, figsize=(10, 4))
        kind = lambda r: (r["workers"], r.get("decoded", "kept"), r.get("source", "memory"))  # noqa: E731
        for w, dk, src in sorted({kind(r) for r in rows}):
            rs = [r for r in rows if kind(r) == (w, dk, src)]
            tag = f"{w} worker(s), decoded views {dk}, views from {src}"
            ax[0].plot([r["mpix"] for r in rs], [r["wall_s"] for r in rs], "o-", label=tag)
            ax[1].plot([r["mpix"] for r in rs], [r["peak_parent_mib"] for r in rs], "o-", label=f"parent, {tag}")
            if w > 1:
                ax[1].plot([r["mpix"] for r in rs], [r["peak_worker_mib"] for r in rs], "s--", label=f"largest of {w} workers")
        rs = [r for r in rows if r["workers"] == rows[0]["workers"]]
        ax[1].plot([r["mpix"] for r in rs], [4 * r["raw_mib"] for r in rs], "k:", label="4x raw input")
        ax[0].set(xlabel="Mpix (all views)", ylabel="encode wall s", title=f"{scene} grids @ {target:g} dB")
        ax[1].set(xlabel="Mpix (all views)", ylabel="peak resident MiB")
        for x in ax:
            x.legend(fontsize=8)
            x.grid(alpha=0.3)
        fig.tight_layout()
        fig.savefig(out / "scale.png", dpi=110)
    except ImportError:
        log("matplotlib missing: no plot")


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--data", default="../shared/data", help="the shared data folder")
    ap.add_argument("--scene", default="hci_antinous")
    ap.add_argument("--grids", default="5,9,17")
    ap.add_argument("--workers", default="1,2")
    ap.add_argument("--decoded", default="dropped", help="dropped, kept or both (comma-separated)")
    ap.add_argument("--source", default="files", help="memory, files or both (comma-separated)")
    ap.add_argument("--arenas", default="one", choices=["one", "default"],
                    help="one: one malloc arena, as lfcodec asks (formats.heap); default: glibc's")
    ap.add_argument("--target-psnr", type=float, default=40.0)
    ap.add_argument("--out", default="docs/bench/scale")
    ap.add_argument("--plot-only", action="store_true", help="remake scale.md and scale.png from OUT/scale.json")
    a = ap.parse_args(argv)
    scene = Path(a.data) / a.scene
    out = Path(a.out)
    out.mkdir(parents=True, exist_ok=True)
    if a.plot_only:
        got = json.loads((out / "scale.json").read_text())
        write_outputs(got["runs"], got["scene"], got["target_psnr"], out)
        return 0
    rows = []
    kinds = [x for x in a.decoded.split(",") if x]
    if not kinds or set(kinds) - {"dropped", "kept"}:
        ap.error(f"--decoded takes dropped and/or kept, got {a.decoded!r}")
    sources = [x for x in a.source.split(",") if x]
    if not sources or set(sources) - {"memory", "files"}:
        ap.error(f"--source takes memory and/or files, got {a.source!r}")
    import tempfile

    tmp = tempfile.TemporaryDirectory(prefix="bench_scale_")
    for n in [int(x) for x in a.grids.split(",")]:
        folder = Path(tmp.name) / f"{n}x{n}"
        if "files" in sources:
            write_grid(scene, n, folder)
        for w, dk, src in [(int(x), k, s) for x in a.workers.split(",") for k in kinds for s in sources]:
            r = run_one(scene, n, w, a.target_psnr, dk, str(folder) if src == "files" else "", a.arenas)
            log(f"{a.scene} {n}x{n} workers {w} decoded {dk} from {src}: {r['wall_s']:.0f} s, parent {r['peak_parent_mib']:.0f} MiB "
                f"({r['parent_x_raw']:.1f}x raw), worker {r['peak_worker_mib']:.0f} MiB, {r['bytes']} B, "
                f"{r['psnr']:.2f} dB")
            rows.append(r)
            (out / "scale.json").write_text(json.dumps({"scene": a.scene, "target_psnr": a.target_psnr,
                                                        "machine": machine(), "runs": rows}, indent=1))
    tmp.cleanup()
    write_outputs(rows, a.scene, a.target_psnr, out)
    return 0


if __name__ == "__main__":
    sys.exit(main())
