"""Benchmark runner: lfcodec RLFC profiles against per-view JPEG 2000 / JPEG XL and an HEVC
pseudo-sequence, on the same views, in one run.

Usage:
    python -m tools.bench SCENE [SCENE ...] --out DIR [--quick] [--profiles tx,dcp]
        [--targets 36,40,45,48]

For each scene it encodes with every profile at every target PSNR (the profile's own rate
control, as ``lfcodec encode --target-psnr`` does) and records: bpp (whole file), PSNR_RGB,
PSNR_YCoCg, SSIM, encode time, the bytes of each section (the bit budget), full-decode time,
random-access block decode time (single and batched, µs per block and Mpix/s) and the
per-level progressive PSNR; per peer setting: bpp, PSNR, SSIM, decode time of one view and
of all views, and the random-access unit. Speeds are medians over repeats after a warm-up;
lfcodec's whole light field and one view are timed from a fresh open of the file (the peers
decode theirs from their codestreams).
Writes DIR/results.json, DIR/results.csv, DIR/summary.md and PNG plots (when matplotlib is
installed): rd_<scene>.png, speed.png, random_access.png.
"""
from __future__ import annotations

import argparse
import csv
import json
import math
import statistics
import time
from datetime import date
from pathlib import Path

import numpy as np

from formats.metrics import bpp, psnr_rgb, psnr_ycocg, ssim
from formats.scenes import read_scene
from formats.codec_api import EncodeOptions
from formats.errors import LfcError
from formats.lfcfile import open_lfc
from formats.registry import open_decoder
from rlfc import encode
from tools.common import log, machine, open_encoded
from tools.common import median_time as _median
from tools.peers import all_peers, serpentine


def random_access_times(d, rng, n_single: int, n_batch: int, repeats: int) -> tuple[float, float]:
    """(median seconds of one ``decode_block`` over random requests after 5 warm-ups, median
    seconds per block of one ``decode_blocks`` call of ``n_batch`` random requests)."""
    nv = d.rows * d.cols
    sv, sby, sbx = rng.integers(0, nv, n_single), rng.integers(0, d.nby, n_single), rng.integers(0, d.nbx, n_single)
    ts = []
    for i in range(n_single):
        r, c = divmod(int(sv[i]), d.cols)
        t = time.perf_counter()
        d.decode_block(r, c, int(sby[i]), int(sbx[i]))
        ts.append(time.perf_counter() - t)
    bv, bby, bbx = rng.integers(0, nv, n_batch), rng.integers(0, d.nby, n_batch), rng.integers(0, d.nbx, n_batch)
    return statistics.median(ts[5:]), _median(lambda: d.decode_blocks(bv, bby, bbx), repeats) / n_batch


def bench_profile(lf, profile: str, targets, repeats, n_single, n_batch):
    """RLFC rows of one profile: one file per target PSNR (the profile's rate control)."""
    rows = []
    views = lf.views.reshape(-1, *lf.views.shape[2:])
    rng = np.random.default_rng(0)
    for target in targets:
        t0 = time.perf_counter()
        try:
            enc = encode(lf, EncodeOptions(profile=profile, target_psnr=target))
        except LfcError as e:         # a profile that cannot code this scene (e.g. dcp on posed) is reported
            rows.append({"codec": f"lfcodec RLFC ({profile})", "setting": f"target {target:g} dB", "skipped": str(e)})
            log(f"  RLFC {profile} {target:g} dB: skipped ({e})")
            continue
        t_enc = time.perf_counter() - t0
        d, blob = open_encoded(lf, enc)
        nv = d.rows * d.cols
        full = d.decode_all()
        # the whole light field and one view from a fresh open, as the peers decode theirs from
        # their codestreams (a decoder kept open serves views it decoded from caches: a posed
        # capture's whole light field again in 0.01 s)
        t_full = _median(lambda: open_decoder(open_lfc(blob)).decode_all(), repeats)
        t_single, t_batch = random_access_times(d, rng, n_single, n_batch, repeats)
        prog = [{"level": L, "psnr_rgb": psnr_rgb(lf.views, d.decode_all(L))} for L in range(d.levels + 1)]
        dec = full.reshape(views.shape)
        B = d.block_size
        row = {"codec": f"lfcodec RLFC ({profile})", "setting": f"target {target:g} dB", "bytes": len(blob),
               "bpp": bpp(len(blob), nv, lf.height, lf.width), "psnr_rgb": psnr_rgb(views, dec),
               "psnr_ycocg": psnr_ycocg(views, dec), "ssim": ssim(views, dec), "encode_s": t_enc,
               "decode_all_s": t_full, "decode_view_s": None, "block_us": t_single * 1e6,
               "batch_block_us": t_batch * 1e6, "batch_mpix_s": B * B / t_batch / 1e6,
               "ra_unit": f"{B}x{B} block", "ra_latency_s": t_single, "progressive": prog,
               "sections": {n: len(x) for n, x in enc.sections}}
        row["decode_view_s"] = _median(lambda: open_decoder(open_lfc(blob)).decode_view(d.rows // 2, d.cols // 3),
                                       repeats)
        rows.append(row)
        log(f"  RLFC {profile} {target:g} dB: {row['bpp']:.4f} bpp, {row['psnr_rgb']:.2f} dB, {t_enc:.0f} s, block "
            f"{row['block_us']:.0f} µs, batched {row['batch_block_us']:.2f} µs/block, full decode {t_full:.2f} s")
    return rows


def bench_peers(lf, quick):
    views = lf.views.reshape(-1, *lf.views.shape[2:])
    nv = views.shape[0]
    rows = []
    for peer in all_peers():
        why = peer.available()
        if why:
            rows.append({"codec": peer.name, "skipped": why})
            log(f"  {peer.name}: skipped ({why})")
            continue
        settings = peer.settings[1:4] if quick else peer.settings
        for s in settings:
            try:
                kw = {"order": serpentine(lf.rows, lf.cols)} if peer.unit.startswith("whole") else {}
                r = peer.run(views, s, **kw)
            except Exception as e:   # a peer that cannot code this scene is reported, not fatal
                rows.append({"codec": peer.name, "setting": str(s), "skipped": str(e)})
                log(f"  {peer.name} {s}: skipped ({e})")
                continue
            dec = r.pop("decoded")
            row = {"codec": peer.name, "setting": str(s), "bytes": r["bytes"],
                   "bpp": bpp(r["bytes"], nv, lf.height, lf.width), "psnr_rgb": psnr_rgb(views, dec),
                   "psnr_ycocg": psnr_ycocg(views, dec) if views.shape[-1] >= 3 else None, "ssim": ssim(views, dec),
                   "decode_view_s": r["decode_view_s"], "decode_all_s": r["decode_all_s"], "ra_unit": peer.unit,
                   "ra_latency_s": r.get("ra_latency_s", r["decode_view_s"])}
            rows.append(row)
            log(f"  {peer.name} {s}: {row['bpp']:.3f} bpp, {row['psnr_rgb']:.2f} dB")
    return rows


def bpp_at(rows, codec, psnr_target=40.0):
    """bpp at a PSNR on a codec's rate-distortion curve (log-bpp linear interpolation)."""
    pts = sorted((r["psnr_rgb"], r["bpp"]) for r in rows if r.get("codec") == codec and "bpp" in r
                 and r["psnr_rgb"] is not None and math.isfinite(r["psnr_rgb"]))
    for (p0, b0), (p1, b1) in zip(pts, pts[1:]):
        if p0 <= psnr_target <= p1 and p1 > p0:
            t = (psnr_target - p0) / (p1 - p0)
            return math.exp(math.log(b0) + t * (math.log(b1) - math.log(b0)))
    return None


def _ours(rows) -> list[str]:
    return sorted({r["codec"] for r in rows if r["codec"].startswith("lfcodec") and "bpp" in r})


def _peers(rows) -> list[str]:
    return sorted({r["codec"] for r in rows if not r["codec"].startswith("lfcodec") and "bpp" in r})


def ratio_table(rows, targets) -> list[str]:
    """bpp of every codec at each target PSNR, and the best lfcodec profile over each peer."""
    codecs = _ours(rows) + _peers(rows)
    lines = ["| codec | " + " | ".join(f"bpp @ {t:g} dB" for t in targets) + " |",
             "|---|" + "---|" * len(targets)]
    at = {c: [bpp_at(rows, c, t) for t in targets] for c in codecs}
    for c in codecs:
        lines.append(f"| {c} | " + " | ".join("–" if b is None else f"{b:.4f}" for b in at[c]) + " |")
    best = [min((at[c][i] for c in _ours(rows) if at[c][i]), default=None) for i in range(len(targets))]
    for p in _peers(rows):
        lines.append(f"| lfcodec (best profile) / {p} | " + " | ".join(
            "–" if not (b and at[p][i]) else f"{b / at[p][i]:.2f}×" for i, b in enumerate(best)) + " |")
    return lines


def budget_table(rows) -> list[str]:
    """Share of each section in the lfcodec files (the bit budget)."""
    ours = [r for r in rows if r["codec"].startswith("lfcodec") and r.get("sections")]
    if not ours:
        return []
    names = list(dict.fromkeys(n for r in ours for n in r["sections"]))
    lines = ["| file | bpp | " + " | ".join(names) + " |", "|---|---|" + "---|" * len(names)]
    for r in ours:
        tot = sum(r["sections"].values())
        lines.append(f"| {r['codec']} {r['setting']} | {r['bpp']:.4f} | " +
                     " | ".join(f"{100 * r['sections'].get(n, 0) / tot:.0f}%" for n in names) + " |")
    return lines


def summary(scene_rows: dict, targets=(36.0, 40.0, 45.0, 48.0)) -> str:
    lines = []
    for scene, rows in scene_rows.items():
        lines.append(f"### {scene}\n")
        lines.append("| codec | setting | bpp | PSNR_RGB | PSNR_YCoCg | SSIM | encode s | decode all s | decode 1 view ms | "
                     "block µs | batched µs/block | batched Mpix/s | RA unit |")
        lines.append("|---|---|---|---|---|---|---|---|---|---|---|---|---|")
        for r in rows:
            if "skipped" in r:
                lines.append(f"| {r['codec']} | {r.get('setting', '')} | skipped: {r['skipped']} ||||||||||")
                continue
            f = lambda k, fmt: (fmt % r[k]) if r.get(k) is not None else "–"  # noqa: E731
            lines.append(f"| {r['codec']} | {r['setting']} | {r['bpp']:.4f} | {r['psnr_rgb']:.2f} | "
                         f"{f('psnr_ycocg', '%.2f')} | {r['ssim']:.4f} | {f('encode_s', '%.1f')} | "
                         f"{r['decode_all_s']:.2f} | {1e3 * r['decode_view_s']:.1f} | {f('block_us', '%.0f')} | "
                         f"{f('batch_block_us', '%.2f')} | {f('batch_mpix_s', '%.1f')} | {r['ra_unit']} |")
        lines += ["", "Rate at each PSNR (log-bpp interpolation on each RD curve):", ""]
        lines += ratio_table(rows, targets)
        bt = budget_table(rows)
        if bt:
            lines += ["", "Bit budget of the lfcodec files (share of the bytes of all sections):", ""] + bt
        for r in rows:
            if r["codec"].startswith("lfcodec") and r.get("progressive"):
                lines.append(f"- progressive {r['codec']} ({r['setting']}): " + ", ".join(
                    f"level {p['level']}: {p['psnr_rgb']:.2f} dB" for p in r["progressive"]))
        lines.append("")
    return "\n".join(lines)


def plots(scene_rows: dict, out: Path) -> list[str]:
    try:
        import matplotlib
        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError:
        log("matplotlib not installed: no plots (pip install matplotlib)")
        return []
    made = []
    for scene, rows in scene_rows.items():
        fig, ax = plt.subplots(figsize=(6, 4))
        for codec in dict.fromkeys(r["codec"] for r in rows if "bpp" in r):
            pts = sorted((r["bpp"], r["psnr_rgb"]) for r in rows if r["codec"] == codec and "bpp" in r and math.isfinite(r["psnr_rgb"]))
            if pts:
                ax.plot(*zip(*pts), marker="o", label=codec)
        ax.set_xscale("log")
        ax.set_xlabel("bpp (bits per pixel of a view)")
        ax.set_ylabel("PSNR_RGB (dB)")
        ax.set_title(f"rate-distortion: {scene}")
        ax.axhline(40, color="grey", lw=0.5)
        ax.grid(True, which="both", alpha=0.3)
        ax.legend(fontsize=7)
        fig.tight_layout()
        fig.savefig(out / f"rd_{scene}.png", dpi=110)
        plt.close(fig)
        made.append(f"rd_{scene}.png")
    for key, fname, label in (("decode_all_s", "speed.png", "full decode time (s)"),
                              ("ra_latency_s", "random_access.png", "random-access latency (s, one unit)")):
        fig, ax = plt.subplots(figsize=(6, 4))
        for scene, rows in scene_rows.items():
            for codec in dict.fromkeys(r["codec"] for r in rows if "bpp" in r):
                pts = sorted((r["psnr_rgb"], r[key]) for r in rows if r["codec"] == codec and "bpp" in r
                             and math.isfinite(r["psnr_rgb"]) and r.get(key))
                if pts:
                    ax.plot(*zip(*pts), marker="o", label=f"{codec} [{scene}]")
        ax.set_yscale("log")
        ax.set_xlabel("PSNR_RGB (dB)")
        ax.set_ylabel(label)
        ax.grid(True, which="both", alpha=0.3)
        ax.legend(fontsize=6)
        fig.tight_layout()
        fig.savefig(out / fname, dpi=110)
        plt.close(fig)
        made.append(fname)
    return made


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(prog="python -m tools.bench", description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("scenes", nargs="+")
    ap.add_argument("--out", required=True)
    ap.add_argument("--quick", action="store_true", help="a smoke run: one RLFC point, three per peer, few repeats")
    ap.add_argument("--profiles", default="tx,dcp", help="RLFC profiles to run (dcp refuses posed captures)")
    ap.add_argument("--targets", default="36,40,45,48", help="target PSNRs in dB")
    a = ap.parse_args(argv)
    out = Path(a.out)
    out.mkdir(parents=True, exist_ok=True)
    targets = [40.0] if a.quick else [float(x) for x in a.targets.split(",")]
    scene_rows = {}
    t_start = time.perf_counter()
    for s in a.scenes:
        name = Path(s).name
        log(f"[{name}] reading")
        lf = read_scene(s)
        if a.quick and lf.height * lf.width > 256 * 256:
            lf.views = np.ascontiguousarray(lf.views[:, :, :128, :128])
        kw = dict(repeats=1 if a.quick else 3, n_single=50 if a.quick else 300, n_batch=2000 if a.quick else 20000)
        profiles = a.profiles.split(",")          # a profile that refuses the scene is reported as such
        rows = []
        for prof in profiles:
            rows += bench_profile(lf, prof, targets, **kw)
        rows += bench_peers(lf, a.quick)
        scene_rows[name] = rows
    meta = {"machine": machine(), "date": date.today().isoformat(), "quick": a.quick,
            "elapsed_s": time.perf_counter() - t_start}
    (out / "results.json").write_text(json.dumps({"meta": meta, "scenes": scene_rows}, indent=1, default=float))
    keys = ["scene", "codec", "setting", "bytes", "bpp", "psnr_rgb", "psnr_ycocg", "ssim", "encode_s", "decode_all_s",
            "decode_view_s", "block_us", "batch_block_us", "batch_mpix_s", "ra_unit", "skipped"]
    with open(out / "results.csv", "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=keys, extrasaction="ignore")
        w.writeheader()
        for scene, rows in scene_rows.items():
            for r in rows:
                w.writerow({"scene": scene, **r})
    text = f"Machine: {meta['machine']}; date {meta['date']}; {meta['elapsed_s']:.0f} s\n\n" + summary(scene_rows, targets)
    (out / "summary.md").write_text(text)
    made = plots(scene_rows, out)
    print(text)
    if made:
        print("plots: " + ", ".join(str(out / m) for m in made))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
