"""Decode speed against rate: what the residual coder costs in decode speed, as a curve of
bits against Mpix/s (issue 19), beside JPEG 2000 decoding the same views at the same PSNR.

Usage:
    python -m tools.bench_rate_speed GRID [GRID ...] --out docs/bench/decode/rate_speed
        [--targets 36,40,45] [--data ../shared/data] [--files DIR] [--rounds 2]

Each grid is encoded by the command line a user runs (``lfcodec encode DATA/GRID
FILES/T<T>/GRID.lfc --target-psnr T --json``; a file already there is reused). Then
:mod:`tools.bench_decode` measures every target's files (one fresh process per file and round:
batched random access on 1 and 2 threads, single blocks, whole views and the whole light field,
JPEG 2000 coded at the PSNR our file reaches on each view). Beside the speeds: the share of the
blocks of views that are not key views that carry a residual stream (the coded blocks, which
the rANS parse pays for) and the bytes of those streams.

Writes ``rate_speed.json``, ``rate_speed.md`` and ``rate_speed.png`` under ``--out`` (and each
target's ``decode.{json,md,png}`` under ``--out/T<T>``; a target measured before on these
grids is read back from there unless ``--remeasure``).
"""
from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np

from tools import bench_decode
from tools.common import log, machine

ROOT = Path(__file__).resolve().parents[1]


def encode(data: Path, grid: str, target: float, path: Path) -> dict:
    """The CLI's JSON report of ``lfcodec encode`` (run once; reused from ``path``.json)."""
    rep = path.with_suffix(".json")
    if path.exists() and rep.exists():
        return json.loads(rep.read_text())
    path.parent.mkdir(parents=True, exist_ok=True)
    log(f"encoding {grid} at {target:g} dB")
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    r = subprocess.run([sys.executable, "-m", "formats", "encode", str(data / grid), str(path), "--target-psnr",
                        f"{target:g}", "--json", "--quiet"], env=env, capture_output=True, text=True)
    if r.returncode:
        raise SystemExit(f"encode of {grid} at {target:g} dB failed:\n{r.stderr[-2000:]}")
    out = json.loads(r.stdout.strip().splitlines()[-1])
    rep.write_text(json.dumps(out))
    return out


def coded_blocks(path: Path) -> dict:
    """Share of the random-access blocks of views that are not key views with a residual
    stream, and those streams' bytes."""
    from formats.lfcfile import open_lfc
    from rlfc import RlfcDecoder

    d = RlfcDecoder(open_lfc(str(path)))
    core = d.core
    nk = ~np.asarray(core.is_key)
    coded = np.asarray(core.coded)[nk]
    span = (np.asarray(core.end) - np.asarray(core.start))[nk]
    return {"coded_share": float(coded.mean()) if coded.size else None, "stream_bytes": int(span[coded].sum()),
            "key_views": int((~nk).sum()), "views": int(nk.size)}


def curve_table(rows: list[dict], threads: list[int]) -> list[str]:
    head = ["grid", "target dB", "bpp (× J2K bytes)", "coded blocks", "residual stream bytes"] + [
        f"batched Mpix/s ({t} thr)" for t in threads] + ["single p50 µs", "whole view Mpix/s (J2K)",
                                                        "whole light field, 1 thr (× J2K)"]
    out = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for r in rows:
        s = r["speed"]
        out.append("| " + " | ".join([
            r["grid"], f"{r['target']:g}", f"{r['bpp']:.4f} ({r['bytes'] / r['j2k_bytes']:.2f}×)",
            f"{100 * r['coded_share']:.0f}%" if r["coded_share"] is not None else "– (every view a key)",
            f"{r['stream_bytes']:,}"] + [
            f"{s.get(f'batch_mpix_t{t}', float('nan')):.1f}" for t in threads] + [
            f"{s['single_p50_us']:.0f}", f"{s['view_mpix']:.1f} ({r['j2k_view_mpix']:.1f})",
            f"{s['all_s_t1']:.2f} s ({s['all_vs_j2k_t1']:.2f}×)" if "all_s_t1" in s else "–"]) + " |")
    return out


def plot(rows: list[dict], out: Path) -> None:
    try:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError:
        log("matplotlib not installed: no plot")
        return
    grids = list(dict.fromkeys(r["grid"] for r in rows))
    fig, ax = plt.subplots(1, 2, figsize=(11, 4.2))
    for i, g in enumerate(grids):
        rs = sorted((r for r in rows if r["grid"] == g), key=lambda r: r["bpp"])
        c = f"C{i}"
        x = [r["bpp"] for r in rs]
        ax[0].plot(x, [r["speed"]["batch_mpix_t1"] for r in rs], "o-", color=c, label=g)
        ax[0].plot(x, [r["j2k_view_mpix"] for r in rs], "x:", color=c)
        ax[1].plot(x, [r["speed"]["view_mpix"] for r in rs], "o-", color=c, label=g)
        ax[1].plot(x, [r["j2k_view_mpix"] for r in rs], "x:", color=c)
    ax[0].set_title("batched random access, 1 thread (x: JPEG 2000 whole view)", fontsize=9)
    ax[1].set_title("whole view (x: JPEG 2000, same views and PSNR)", fontsize=9)
    for a in ax:
        a.set_xscale("log")
        a.set_yscale("log")
        a.set_xlabel("bits per pixel (whole file)")
        a.set_ylabel("Mpix/s")
        a.grid(True, which="both", lw=0.3)
    ax[0].axhline(50, color="r", ls="--", lw=1)
    ax[0].legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(out / "rate_speed.png", dpi=110)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("grids", nargs="+")
    ap.add_argument("--targets", default="36,40,45")
    ap.add_argument("--data", default=str(ROOT.parent / "shared" / "data"))
    ap.add_argument("--files", default=None, help="where the encoded files live (default OUT/files)")
    ap.add_argument("--rounds", type=int, default=2)
    ap.add_argument("--batch", type=int, default=20000)
    ap.add_argument("--single", type=int, default=400)
    ap.add_argument("--threads", default="1,2")
    ap.add_argument("--out", required=True)
    ap.add_argument("--remeasure", action="store_true", help="measure targets whose OUT/T<T>/decode.json exists again")
    a = ap.parse_args(argv)
    out = Path(a.out)
    files = Path(a.files) if a.files else out / "files"
    data = Path(a.data)
    targets = [float(t) for t in a.targets.split(",")]
    threads = [int(t) for t in a.threads.split(",")]
    rows = []
    for t in targets:
        paths, reps = [], {}
        for g in a.grids:
            p = (files / f"T{t:g}" / f"{g}.lfc").resolve()
            reps[g] = encode(data, g, t, p)
            paths.append(p)
        tdir = out / f"T{t:g}"
        done = tdir / "decode.json"
        if a.remeasure or not done.exists() or set(a.grids) - set(json.loads(done.read_text())["results"]):
            bench_decode.main([*map(str, paths), "--data", str(data), "--rounds", str(a.rounds), "--batch",
                               str(a.batch), "--single", str(a.single), "--threads", a.threads, "--out", str(tdir)])
        res = json.loads(done.read_text())["results"]
        for g, p in zip(a.grids, paths):
            r, rep = res[g], reps[g]
            px = r["new"]["view_mpix"] * 1e6 * r["new"]["view_ms"] / 1e3          # pixels of one view
            rows.append({"grid": g, "target": t, "bytes": rep["bytes"], "bpp": rep["bpp"], "psnr": rep["psnr_rgb"],
                         "j2k_bytes": r["peer"]["j2k_bytes"], "j2k_psnr": r["peer"]["psnr_j2k"],
                         "j2k_view_mpix": px / (r["new"]["j2k_view_ms"] / 1e3) / 1e6,
                         **coded_blocks(p), "speed": r["new"]})
    text = [f"Machine: {machine()}; {a.rounds} rounds per file (medians), {a.batch} random requests per batched call.",
            "", *curve_table(rows, threads)]
    print("\n".join(text))
    out.mkdir(parents=True, exist_ok=True)
    (out / "rate_speed.json").write_text(json.dumps({"machine": machine(), "rows": rows}, indent=1))
    (out / "rate_speed.md").write_text("\n".join(text) + "\n")
    plot(rows, out)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
