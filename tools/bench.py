"""Benchmark runner: lfcodec RLFC against per-view JPEG 2000 / JPEG XL and an HEVC
pseudo-sequence, on the same views, in one run.

Usage:
    python -m tools.bench SCENE [SCENE ...] --out DIR [--quick] [--quants 4,8,16]

For each scene it records, per RLFC setting: bpp, PSNR_RGB, PSNR_YCoCg, SSIM, encode time,
full-decode time, random-access block decode time (single and batched, µs per block) and the
per-level progressive PSNR and time; per peer setting: bpp, PSNR, SSIM, decode time of one
view and of all views, and the random-access unit. Speeds are medians over repeats after a
warm-up. Writes DIR/results.json, DIR/results.csv, DIR/summary.md and PNG plots (when
matplotlib is installed): rd_<scene>.png, speed.png, random_access.png.
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
from rlfc import RlfcParams, get_profile
from rlfc.keytree import KeyTreeEncoder
from rlfc.ratecontrol import depth_scale, params_for_quant
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


def bench_rlfc(lf, points, repeats, n_single, n_batch, block_size=8, profile="bise"):
    """RLFC rows for ``points``: a list of (key-view PSNR dB or None = lossless, Q in 8-bit units).

    Points sharing a key-view quality share one encoder; the dcp disparity map is estimated
    once (on the first point's key views) and re-used, as the rate control does."""
    rows = []
    views = lf.views.reshape(-1, *lf.views.shape[2:])
    rng = np.random.default_rng(0)
    encoders, disp = {}, None
    for top_psnr, q in points:
        base = RlfcParams(block_size=block_size, profile=profile, top_psnr=top_psnr)
        t0 = time.perf_counter()
        if top_psnr not in encoders:
            enc = KeyTreeEncoder(lf, base, get_profile(profile).strategy(lf), side=disp)
            encoders[top_psnr] = (enc, time.perf_counter() - t0)
            disp = getattr(enc, "disp", None)
        enc, t_prep = encoders[top_psnr]
        p = params_for_quant(base, q * depth_scale(lf.views.dtype))   # q in 8-bit units
        t0 = time.perf_counter()
        res = enc.closed_loop(p)
        cfg, secs = enc.pack(p, res)
        t_enc = t_prep + time.perf_counter() - t0
        d, blob = open_encoded(lf, (cfg, secs))
        full = d.decode_all()
        t_full = _median(lambda: d.decode_all(), repeats)
        nv = d.rows * d.cols
        t_single, t_batch = random_access_times(d, rng, n_single, n_batch, repeats)
        prog = []
        for L in range(d.levels + 1):
            t = time.perf_counter()
            out = d.decode_all(L)
            prog.append({"level": L, "psnr_rgb": psnr_rgb(lf.views, out), "decode_s": time.perf_counter() - t})
        dec = full.reshape(views.shape)
        setting = f"Q={q:g}" if top_psnr is None else f"K={top_psnr:g} Q={q:g}"
        row = {"codec": f"lfcodec RLFC ({profile})", "setting": setting, "bytes": len(blob),
               "bpp": bpp(len(blob), nv, lf.height, lf.width), "psnr_rgb": psnr_rgb(views, dec),
               "psnr_ycocg": psnr_ycocg(views, dec), "ssim": ssim(views, dec), "encode_s": t_enc,
               "decode_all_s": t_full, "decode_view_s": None, "block_us": t_single * 1e6, "batch_block_us": t_batch * 1e6,
               "ra_unit": f"{d.block_size}x{d.block_size} block", "ra_latency_s": t_single, "progressive": prog}
        t = time.perf_counter()
        d.decode_view(d.rows // 2, d.cols // 2)
        row["decode_view_s"] = time.perf_counter() - t
        rows.append(row)
        log(f"  RLFC {profile} {setting}: {row['bpp']:.3f} bpp, {row['psnr_rgb']:.2f} dB, block {row['block_us']:.0f} µs, "
            f"batched {row['batch_block_us']:.2f} µs/block, full decode {t_full:.2f} s")
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


def summary(scene_rows: dict) -> str:
    lines = []
    for scene, rows in scene_rows.items():
        lines.append(f"### {scene}\n")
        lines.append("| codec | setting | bpp | PSNR_RGB | PSNR_YCoCg | SSIM | encode s | decode all s | decode 1 view ms | block µs | batched µs/block | RA unit |")
        lines.append("|---|---|---|---|---|---|---|---|---|---|---|---|")
        for r in rows:
            if "skipped" in r:
                lines.append(f"| {r['codec']} | {r.get('setting', '')} | skipped: {r['skipped']} |||||||||")
                continue
            f = lambda k, fmt: (fmt % r[k]) if r.get(k) is not None else "–"  # noqa: E731
            lines.append(f"| {r['codec']} | {r['setting']} | {r['bpp']:.3f} | {r['psnr_rgb']:.2f} | {f('psnr_ycocg', '%.2f')} | "
                         f"{r['ssim']:.4f} | {f('encode_s', '%.1f')} | {r['decode_all_s']:.2f} | {1e3 * r['decode_view_s']:.1f} | "
                         f"{f('block_us', '%.0f')} | {f('batch_block_us', '%.2f')} | {r['ra_unit']} |")
        ours_name = min((c for c in {r["codec"] for r in rows} if c.startswith("lfcodec") and bpp_at(rows, c)),
                        key=lambda c: bpp_at(rows, c), default="lfcodec RLFC (bise)")
        ours = bpp_at(rows, ours_name)
        lines.append("")
        for c in sorted(c for c in {r["codec"] for r in rows} if c.startswith("lfcodec")):
            b = bpp_at(rows, c)
            lines.append(f"bpp at 40 dB PSNR_RGB: {c} {b:.3f}" if b else f"bpp at 40 dB: {c} — (40 dB not bracketed)")
        lines.append(f"Ratios below use the better profile, {ours_name}:")
        for peer in sorted({r["codec"] for r in rows if not r["codec"].startswith("lfcodec") and "bpp" in r}):
            b = bpp_at(rows, peer)
            if b and ours:
                lines.append(f"- {peer}: {b:.3f} bpp → lfcodec / peer = {ours / b:.2f}×")
            elif b:
                lines.append(f"- {peer}: {b:.3f} bpp")
        ours_rows = [r for r in rows if r["codec"] == ours_name and "bpp" in r]
        if ours_rows:
            near = min(ours_rows, key=lambda r: abs(r["psnr_rgb"] - 40))
            lines.append(f"Decode speed, lfcodec ({near['setting']}, {near['psnr_rgb']:.1f} dB) over each peer's point "
                         "nearest 40 dB (ratio > 1: lfcodec faster):")
            for peer in sorted({r["codec"] for r in rows if not r["codec"].startswith("lfcodec") and "bpp" in r}):
                pr = [r for r in rows if r["codec"] == peer and "bpp" in r and math.isfinite(r["psnr_rgb"])]
                if not pr:
                    continue
                p = min(pr, key=lambda r: abs(r["psnr_rgb"] - 40))
                ra = (f"{p['ra_latency_s'] / near['ra_latency_s']:.1f}×" if p.get("ra_latency_s") else
                      "not comparable on a CPU")
                lines.append(f"- vs {peer} ({p['setting']}): full light field {p['decode_all_s'] / near['decode_all_s']:.2f}×, "
                             f"one view {p['decode_view_s'] / near['decode_view_s']:.2f}×, random access "
                             f"(one {near['ra_unit']} vs one {p['ra_unit']}) {ra}")
        for r in rows:
            if r["codec"].startswith("lfcodec") and r.get("progressive"):
                lines.append(f"- progressive ({r['setting']}): " + ", ".join(
                    f"level {p['level']}: {p['psnr_rgb']:.2f} dB / {p['decode_s']:.2f} s" for p in r["progressive"]))
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
    ap.add_argument("--quants", default="4,8,16", help="RLFC quantizer steps to sweep (bise profile)")
    ap.add_argument("--dcp-points", default="48:4,48:8,44:256,42:256,40:256,38:256",
                    help="dcp profile (grids only): KEY_PSNR:Q pairs; Q=256 is prediction only (no residual blocks)")
    a = ap.parse_args(argv)
    out = Path(a.out)
    out.mkdir(parents=True, exist_ok=True)
    quants = [8.0] if a.quick else [float(x) for x in a.quants.split(",")]
    scene_rows = {}
    t_start = time.perf_counter()
    for s in a.scenes:
        name = Path(s).name
        log(f"[{name}] reading")
        lf = read_scene(s)
        if a.quick and lf.height * lf.width > 256 * 256:
            lf.views = np.ascontiguousarray(lf.views[:, :, :128, :128])
        kw = dict(repeats=1 if a.quick else 3, n_single=50 if a.quick else 300, n_batch=2000 if a.quick else 20000)
        rows = bench_rlfc(lf, [(None, q) for q in quants], **kw)
        if lf.layout == "grid":
            pts = [(42.0, 256.0)] if a.quick else [tuple(float(v) for v in x.split(":")) for x in a.dcp_points.split(",")]
            rows += bench_rlfc(lf, pts, profile="dcp", **kw)
        rows += bench_peers(lf, a.quick)
        scene_rows[name] = rows
    meta = {"machine": machine(), "date": date.today().isoformat(), "quick": a.quick,
            "elapsed_s": time.perf_counter() - t_start}
    (out / "results.json").write_text(json.dumps({"meta": meta, "scenes": scene_rows}, indent=1, default=float))
    keys = ["scene", "codec", "setting", "bytes", "bpp", "psnr_rgb", "psnr_ycocg", "ssim", "encode_s", "decode_all_s",
            "decode_view_s", "block_us", "batch_block_us", "ra_unit", "skipped"]
    with open(out / "results.csv", "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=keys, extrasaction="ignore")
        w.writeheader()
        for scene, rows in scene_rows.items():
            for r in rows:
                w.writerow({"scene": scene, **r})
    text = f"Machine: {meta['machine']}; date {meta['date']}; {meta['elapsed_s']:.0f} s\n\n" + summary(scene_rows)
    (out / "summary.md").write_text(text)
    made = plots(scene_rows, out)
    print(text)
    if made:
        print("plots: " + ", ".join(str(out / m) for m in made))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
