"""Decode speed of .lfc files against JPEG 2000 on the same views, and against the gather limit.

Usage:
    python -m tools.bench_decode FILE.lfc [FILE.lfc ...] [--data ../shared/data] [--rounds 3]
        [--batch 20000] [--single 400] [--threads 1,2] [--against OLD_CHECKOUT] [--out docs/bench/decode]

Each file's scene is ``DATA/<file stem>`` (the originals, for PSNR and the JPEG 2000 peer; the
peer is cached by the file's content, so files of one scene at several rates each get theirs).
Before measuring, every view is coded with JPEG 2000 (imagecodecs/OpenJPEG) at the PSNR our
file reaches on that view, so both decoders deliver the same quality. Then, per round, one
fresh process per file (and per code version with ``--against``: the same measurements with
``PYTHONPATH=OLD_CHECKOUT``, rounds interleaved, so the ratios hold on a noisy box) measures:

- fresh: a fresh open and one random whole view, beside JPEG 2000 decoding that view; a fresh
  open and ``decode_all`` on one thread (its ratio: against the JPEG 2000 light field on one
  thread). The columns after it run once every key view is decoded, which on a posed capture
  (every view a key view) leaves copies of decoded views;
- open: seconds to open the file and decode every key view (since 2026-11-24 key views are
  decoded by block rows on demand; ``first block``: a fresh open plus one random block, after
  the process has imported every RLFC profile's modules, whose time is reported beside it: a
  process's first open imports them, ~0.1 s, more where Python compiles them from source);
- batched: one ``decode_blocks`` call of ``--batch`` random (view, block) requests over every
  view ("cold": the maps it touches are decoded in it), then the same call again ("warm": a
  renderer's steady state), µs per block and Mpix/s, with each thread count of ``--threads`` (``threads=`` of
  :meth:`rlfc.RlfcDecoder.decode_blocks` where the code has it); beside it the *gather limit*:
  numpy gathering the same blocks' pixels from the decoded light field in memory;
- single: ``--single`` random ``decode_block`` calls, each timed (p50/p90/p99 µs); then as many
  others after ``decode_keys()`` and ``decode_maps()`` ("warm": no first touches);
- views in sequence: right after the open, SEQ_VIEWS random views decoded one after another (a
  viewer stepping through the light field; before the batched calls, whose large frees change
  what malloc hands out next), median ms, then ``jpeg2k_decode`` of the same views in sequence;
- view: six non-key views decoded whole (median of 3 each) against ``jpeg2k_decode`` of the
  same views, interleaved;
- all: ``decode_all`` against decoding every view's JPEG 2000 codestream, on each thread count
  (JPEG 2000: the views on a thread pool of that size).

Thread settings: OMP/OpenBLAS one thread per process; OpenCV as the code under test sets it.
Writes decode.json, decode.md and decode.png (Mpix/s per grid) under ``--out``.
"""
from __future__ import annotations

import argparse
import json
import os
import pickle
import statistics
import subprocess
import sys
import tempfile
import time
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import numpy as np

from tools.common import log, machine

ROOT = Path(__file__).resolve().parents[1]


#: views decoded one after another for the "views in sequence" figure (random, keys included)
SEQ_VIEWS = 24


# -- the worker (one process per file, round and code version) ----------------------------------
def _single_us(d, sv, sy, sx) -> list:
    """µs of each ``decode_block`` call, one per request (flat view, block row, block column)."""
    lat = []
    for v, by, bx in zip(sv.tolist(), sy.tolist(), sx.tolist()):
        row, col = divmod(v, d.cols)
        t = time.perf_counter()
        d.decode_block(row, col, by, bx)
        lat.append((time.perf_counter() - t) * 1e6)
    return lat


def _worker(path: str, peer: str, seed: int, n_batch: int, n_single: int, threads: list[int]) -> dict:
    import inspect

    import imagecodecs

    from formats.lfcfile import open_lfc
    from rlfc import RlfcDecoder

    with open(peer, "rb") as fh:
        p = pickle.load(fh)
    rng = np.random.default_rng(seed + 1)
    # the profiles' modules (and OpenCV) load on a process's first open: timed apart, once, so
    # that "first block" is the file's own work (a renderer imports them at its start)
    t = time.perf_counter()
    try:
        from rlfc.profiles import available_profiles, get_profile

        for pid in available_profiles():
            get_profile(pid)
    except ImportError:                         # (an older checkout without the registry)
        pass
    imports_s = time.perf_counter() - t
    t = time.perf_counter()
    d = RlfcDecoder(open_lfc(path))            # a fresh open, then one random block
    d.decode_block(int(rng.integers(d.rows)), int(rng.integers(d.cols)), int(rng.integers(d.nby)),
                   int(rng.integers(d.nbx)))
    r = {"first_block_s": time.perf_counter() - t, "imports_s": imports_s}
    # a fresh open's first whole view and whole light field (what a user who opens a file to
    # read views pays; the columns below run after every key view is decoded, which on a posed
    # capture, every view a key view, leaves them copies), beside JPEG 2000 on that view
    fv = int(rng.integers(d.rows * d.cols))
    del d
    t = time.perf_counter()
    d = RlfcDecoder(open_lfc(path))
    d.decode_view(*divmod(fv, d.cols))
    r["fresh_view_s"] = time.perf_counter() - t
    t = time.perf_counter()
    imagecodecs.jpeg2k_decode(p["blobs"][fv])
    r["j2k_fresh_view_s"] = time.perf_counter() - t
    del d
    t = time.perf_counter()
    d = RlfcDecoder(open_lfc(path))
    d.decode_all(**({"threads": 1} if "threads" in inspect.signature(d.decode_all).parameters else {}))
    r["fresh_all_s"] = time.perf_counter() - t
    del d
    t = time.perf_counter()
    d = RlfcDecoder(open_lfc(path))
    getattr(d.core, "decode_keys", lambda: None)()       # key views decoded on demand: all of them now
    r["open_s"] = time.perf_counter() - t
    # views in sequence (a viewer stepping through the light field), measured first, before the
    # batched calls' large arrays have moved malloc's thresholds: each view's time, then JPEG 2000
    # decoding the same views in sequence
    seq = np.random.default_rng(seed + 2).integers(0, d.rows * d.cols, SEQ_VIEWS + 4)
    for i in seq[:4].tolist():                                             # warm-up
        d.decode_view(*divmod(i, d.cols))
    tv, tj = [], []
    for i in seq[4:].tolist():
        t = time.perf_counter()
        d.decode_view(*divmod(i, d.cols))
        tv.append(time.perf_counter() - t)
    for i in seq[4:].tolist():
        t = time.perf_counter()
        imagecodecs.jpeg2k_decode(p["blobs"][i])
        tj.append(time.perf_counter() - t)
    r["view_seq_s"], r["j2k_view_seq_s"] = statistics.median(tv), statistics.median(tj)
    rng = np.random.default_rng(seed)
    B, n = d.block_size, d.rows * d.cols
    v, by, bx = rng.integers(0, n, n_batch), rng.integers(0, d.nby, n_batch), rng.integers(0, d.nbx, n_batch)
    has_threads = "threads" in inspect.signature(d.decode_blocks).parameters
    d.decode_blocks(v[:500], by[:500], bx[:500])                       # warm-up
    for th in threads:
        if th > 1 and not has_threads:
            continue
        kw = {"threads": th} if has_threads else {}
        t = time.perf_counter()
        d.decode_blocks(v, by, bx, **kw)
        dt = time.perf_counter() - t
        r[f"batch_us_t{th}"] = dt / n_batch * 1e6
        t = time.perf_counter()                         # warm: the same requests again, with the
        d.decode_blocks(v, by, bx, **kw)                # maps and key rows they touch decoded (a
        r[f"batch_warm_us_t{th}"] = (time.perf_counter() - t) / n_batch * 1e6   # renderer's steady state)
    all_threads = "threads" in inspect.signature(d.decode_all).parameters
    for th in threads:                                  # whole light field, ours and JPEG 2000 on
        if th > 1 and not all_threads:                  # the same number of threads
            continue
        t = time.perf_counter()
        full = d.decode_all(**({"threads": th} if all_threads else {})).reshape(n, d.height, d.width, d.channels)
        r[f"all_s_t{th}"] = time.perf_counter() - t
        t = time.perf_counter()
        with ThreadPoolExecutor(th) as pool:            # imagecodecs releases the GIL
            list(pool.map(imagecodecs.jpeg2k_decode, p["blobs"]))
        r[f"j2k_all_s_t{th}"] = time.perf_counter() - t
    pad = np.zeros((n, d.nby * B, d.nbx * B, d.channels), full.dtype)   # the gather limit: the same blocks'
    pad[:, :d.height, :d.width] = full                                   # pixels copied from memory, stored
    blk = np.ascontiguousarray(pad.reshape(n, d.nby, B, d.nbx, B, -1).swapaxes(2, 3)).reshape(-1, B * B * d.channels)
    flat, g = (v * d.nby + by) * d.nbx + bx, []                         # block-major (the fastest layout);
    for _ in range(3):                                                   # best of 3 (the first call's output
        t = time.perf_counter()                                          # pages are faulted in)
        blk.take(flat, axis=0)
        g.append(time.perf_counter() - t)
    r["gather_us"] = min(g) / n_batch * 1e6
    tv, tj = [], []
    for i in p["views"]:
        row, col = divmod(i, d.cols)
        a, b = [], []
        for _ in range(3):
            t = time.perf_counter()
            d.decode_view(row, col)
            a.append(time.perf_counter() - t)
            t = time.perf_counter()
            imagecodecs.jpeg2k_decode(p["blobs"][i])
            b.append(time.perf_counter() - t)
        tv.append(min(a))
        tj.append(min(b))
    r["view_s"], r["j2k_view_s"] = statistics.median(tv), statistics.median(tj)
    sv, sy, sx = rng.integers(0, n, n_single), rng.integers(0, d.nby, n_single), rng.integers(0, d.nbx, n_single)
    for i in range(min(20, n_single)):                                  # warm-up
        d.decode_block(*divmod(int(sv[i]), d.cols), int(sy[i]), int(sx[i]))
    r["single_us"] = _single_us(d, sv, sy, sx)
    # as many other requests once every key view and map is decoded and every view's constants
    # of the one-request path are built (what a user who will sweep pays up front: the p99 above
    # counts those first touches)
    d.decode_keys()
    getattr(d, "decode_maps", lambda: None)()           # (older checkouts, --against, have none)
    r["single_warm_us"] = _single_us(d, rng.integers(0, n, n_single), rng.integers(0, d.nby, n_single),
                                     rng.integers(0, d.nbx, n_single))
    r["block_size"], r["pixels"] = B, d.height * d.width
    return r


# -- the parent -------------------------------------------------------------------------------
def _prepare_peer(path: Path, data: Path, cache: Path) -> dict:
    """JPEG 2000 codestreams of every view at the PSNR our file reaches on it (cached)."""
    import imagecodecs

    from formats.lfcfile import open_lfc
    from formats.metrics import psnr_views
    from formats.scenes import read_scene
    from rlfc import RlfcDecoder

    import hashlib

    key = f"{path.stem}_{hashlib.sha1(path.read_bytes()).hexdigest()[:16]}"   # files of one scene differ
    out = cache / (key + ".peer.pkl")
    if out.exists() and (cache / (key + ".peer.json")).exists():
        return {"file": str(out), **json.loads((cache / (key + ".peer.json")).read_text())}
    log(f"{path.name}: coding every view with JPEG 2000 at our per-view PSNR")
    d = RlfcDecoder(open_lfc(str(path)))
    n = d.rows * d.cols
    ref = np.asarray(read_scene(data / path.stem).views).reshape(n, d.height, d.width, -1)
    dec = d.decode_all().reshape(ref.shape)
    ours = psnr_views(ref, dec)
    blobs, got = [], []
    for i in range(n):
        a = ref[i, ..., 0] if ref.shape[-1] == 1 else ref[i]
        b = imagecodecs.jpeg2k_encode(a, level=float(min(ours[i], 80.0)))
        blobs.append(b)
        got.append(float(psnr_views(ref[i:i + 1], imagecodecs.jpeg2k_decode(b).reshape(ref[i:i + 1].shape))[0]))
    keys = set(np.flatnonzero(d.core.is_key).tolist()) if hasattr(d.core, "is_key") else set()
    cand = [i for i in range(n) if i not in keys] or list(range(n))        # (every view may be a key)
    views = [cand[int(k)] for k in np.linspace(0, len(cand) - 1, 6).round().astype(int)]
    with open(out, "wb") as fh:
        pickle.dump({"blobs": blobs, "views": views}, fh)
    meta = {"psnr_ours": float(np.mean(ours)), "psnr_j2k": float(np.mean(got)), "j2k_bytes": sum(map(len, blobs)),
            "views": views, "profile": d.profile, "geometry": f"{d.rows}x{d.cols} x {d.height}x{d.width}x{d.channels}"}
    (cache / (key + ".peer.json")).write_text(json.dumps(meta))
    return {"file": str(out), **meta}


def _run_worker(code: Path, path: Path, peer: str, seed: int, a) -> dict:
    env = dict(os.environ, PYTHONPATH=str(code), OMP_NUM_THREADS="1", OPENBLAS_NUM_THREADS="1")
    cmd = [sys.executable, str(Path(__file__).resolve()), "--worker", str(path), "--peer", peer, "--seed", str(seed),
           "--batch", str(a.batch), "--single", str(a.single), "--threads", a.threads]
    r = subprocess.run(cmd, env=env, cwd=tempfile.gettempdir(), capture_output=True, text=True)
    if r.returncode:
        raise SystemExit(f"worker failed on {path.name} ({code}):\n{r.stderr[-3000:]}")
    return json.loads(r.stdout.strip().splitlines()[-1])


def _summarize(rounds: list[dict], threads: list[int]) -> dict:
    B = rounds[0]["block_size"]
    med = lambda k: statistics.median(x[k] for x in rounds)       # noqa: E731
    lat = np.concatenate([x["single_us"] for x in rounds])
    s = {"block_size": B, "open_s": med("open_s"), "first_block_ms": med("first_block_s") * 1e3, "view_ms": med("view_s") * 1e3,
         "imports_ms": med("imports_s") * 1e3 if all("imports_s" in x for x in rounds) else float("nan"),
         "j2k_view_ms": med("j2k_view_s") * 1e3,
         "gather_mpix": B * B / med("gather_us"),
         "single_p50_us": float(np.percentile(lat, 50)), "single_p90_us": float(np.percentile(lat, 90)),
         "single_p99_us": float(np.percentile(lat, 99)), "view_mpix": rounds[0]["pixels"] / med("view_s") / 1e6}
    if all("single_warm_us" in x for x in rounds):
        warm = np.concatenate([x["single_warm_us"] for x in rounds])
        s["single_warm_p50_us"], s["single_warm_p99_us"] = float(np.percentile(warm, 50)), float(np.percentile(warm, 99))
    for th in threads:
        k = f"batch_us_t{th}"
        if all(k in x for x in rounds):
            s[k] = med(k)
            s[f"batch_mpix_t{th}"] = B * B / med(k)
        k = f"batch_warm_us_t{th}"
        if all(k in x for x in rounds):
            s[k] = med(k)
            s[f"batch_warm_mpix_t{th}"] = B * B / med(k)
        k = f"all_s_t{th}"
        if all(k in x for x in rounds):
            s[k], s[f"j2k_all_s_t{th}"] = med(k), med(f"j2k_all_s_t{th}")
            s[f"all_vs_j2k_t{th}"] = s[k] / s[f"j2k_all_s_t{th}"]
    s["view_vs_j2k"] = s["view_ms"] / s["j2k_view_ms"]
    if all("fresh_view_s" in x for x in rounds):
        s["fresh_view_ms"], s["j2k_fresh_view_ms"] = med("fresh_view_s") * 1e3, med("j2k_fresh_view_s") * 1e3
        s["fresh_view_vs_j2k"] = s["fresh_view_ms"] / s["j2k_fresh_view_ms"]
        s["fresh_all_s"] = med("fresh_all_s")
        if "j2k_all_s_t1" in s:
            s["fresh_all_vs_j2k"] = s["fresh_all_s"] / s["j2k_all_s_t1"]
    if all("view_seq_s" in x for x in rounds):
        s["view_seq_ms"], s["j2k_view_seq_ms"] = med("view_seq_s") * 1e3, med("j2k_view_seq_s") * 1e3
        s["view_seq_vs_j2k"] = s["view_seq_ms"] / s["j2k_view_seq_ms"]
    return s


def _table(res: dict, label: str, threads: list[int]) -> list[str]:
    th = [t for t in threads if any(f"batch_mpix_t{t}" in r[label] for r in res.values())]
    ta = [t for t in threads if any(f"all_s_t{t}" in r[label] for r in res.values())]
    head = ["grid", "open s", "first block ms (the process's imports before it, ms)",
            "fresh open + one view ms (J2K ms, ×)", "fresh open + all s, 1 thr (× J2K)"] + [
        f"batched Mpix/s ({t} thr) cold / warm" for t in th] + [
        "gather limit Mpix/s", "single p50/p90/p99 µs", "single warm p50/p99 µs", "view ms (J2K ms, ×)",
        "views in sequence ms (J2K ms, ×)"] + [
        f"all s, {t} thr (J2K s, ×)" for t in ta]
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for name, r in res.items():
        s = r[label]
        row = [name, f"{s['open_s']:.2f}", f"{s['first_block_ms']:.0f} ({s.get('imports_ms', float('nan')):.0f})",
               f"{s['fresh_view_ms']:.1f} ({s['j2k_fresh_view_ms']:.1f}, {s['fresh_view_vs_j2k']:.2f}×)"
               if "fresh_view_ms" in s else "–",
               f"{s['fresh_all_s']:.2f} ({s['fresh_all_vs_j2k']:.2f}×)" if "fresh_all_vs_j2k" in s else "–"] + [
            f"{s.get(f'batch_mpix_t{t}', float('nan')):.1f} / {s.get(f'batch_warm_mpix_t{t}', float('nan')):.1f}"
            for t in th] + [
            f"{s['gather_mpix']:.0f}", f"{s['single_p50_us']:.0f} / {s['single_p90_us']:.0f} / {s['single_p99_us']:.0f}",
            f"{s['single_warm_p50_us']:.0f} / {s['single_warm_p99_us']:.0f}" if "single_warm_p50_us" in s else "–",
            f"{s['view_ms']:.1f} ({s['j2k_view_ms']:.1f}, {s['view_vs_j2k']:.2f}×)",
            f"{s['view_seq_ms']:.1f} ({s['j2k_view_seq_ms']:.1f}, {s['view_seq_vs_j2k']:.2f}×)" if "view_seq_ms" in s
            else "–"] + [
            f"{s[f'all_s_t{t}']:.2f} ({s[f'j2k_all_s_t{t}']:.2f}, {s[f'all_vs_j2k_t{t}']:.2f}×)"
            if f"all_s_t{t}" in s else "–" for t in ta]
        lines.append("| " + " | ".join(row) + " |")
    return lines


def _ratio_table(res: dict, threads: list[int]) -> list[str]:
    keys = [("open_s", "open"), *[(f"batch_us_t{t}", f"batched µs/block ({t} thr)") for t in threads],
            *[(f"batch_warm_us_t{t}", f"warm batched ({t} thr)") for t in threads],
            ("single_p50_us", "single p50"), ("single_p99_us", "single p99"), ("single_warm_p99_us", "warm single p99"),
            ("fresh_view_ms", "fresh open + view"), ("fresh_all_s", "fresh open + all"),
            ("view_ms", "whole view"), ("view_seq_ms", "views in sequence"),
            *[(f"all_s_t{t}", f"whole light field ({t} thr)") for t in threads]]
    keys = [(k, n) for k, n in keys if all(k in r["new"] and k in r["old"] for r in res.values())]
    lines = ["| grid | " + " | ".join(n for _, n in keys) + " |", "|---|" + "---|" * len(keys)]
    for name, r in res.items():
        lines.append(f"| {name} | " + " | ".join(f"{r['new'][k] / r['old'][k]:.2f}×" for k, _ in keys) + " |")
    return lines


def _plot(res: dict, out: Path, threads: list[int]) -> None:
    try:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError:
        log("matplotlib not installed: no plot")
        return
    names = list(res)
    x = np.arange(len(names))
    fig, ax = plt.subplots(figsize=(9, 4))
    series = [(lab, t) for lab in ("old", "new") for t in threads if lab in res[names[0]]
              and f"batch_mpix_t{t}" in res[names[0]][lab]]
    w = 0.8 / max(1, len(series))
    for i, (lab, t) in enumerate(series):
        ax.bar(x + i * w, [res[n][lab][f"batch_mpix_t{t}"] for n in names], w, label=f"{lab}, {t} thread(s)")
    ax.plot(x + 0.4 - w / 2, [res[n]["new"]["view_mpix"] for n in names], "k^", label="whole view (new)")
    ax.axhline(50, color="r", ls="--", lw=1, label="50 Mpix/s goal")
    ax.set_xticks(x + 0.4 - w / 2, names, rotation=15, fontsize=8)
    ax.set_ylabel("Mpix/s")
    ax.set_yscale("log")
    ax.set_title("batched random access (20k random blocks)")
    ax.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(out / "decode.png", dpi=110)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("files", nargs="*")
    ap.add_argument("--data", default=str(ROOT.parent / "shared" / "data"))
    ap.add_argument("--rounds", type=int, default=3)
    ap.add_argument("--batch", type=int, default=20000)
    ap.add_argument("--single", type=int, default=400)
    ap.add_argument("--threads", default="1,2")
    ap.add_argument("--against", default=None, help="an older checkout to measure side by side (PYTHONPATH)")
    ap.add_argument("--out", default=None)
    ap.add_argument("--worker", default=None, help=argparse.SUPPRESS)
    ap.add_argument("--peer", default=None, help=argparse.SUPPRESS)
    ap.add_argument("--seed", type=int, default=0, help=argparse.SUPPRESS)
    a = ap.parse_args(argv)
    threads = [int(t) for t in a.threads.split(",")]
    if a.worker:
        print(json.dumps(_worker(a.worker, a.peer, a.seed, a.batch, a.single, threads)))
        return 0
    if not a.files:
        ap.error("no files")
    cache = Path(tempfile.gettempdir()) / "lfcodec_bench_decode"
    cache.mkdir(exist_ok=True)
    files = [Path(f).resolve() for f in a.files]
    peers = {f.stem: _prepare_peer(f, Path(a.data), cache) for f in files}
    codes = {"new": ROOT} | ({"old": Path(a.against).resolve()} if a.against else {})
    from tools.common import compile_checkouts         # (here: an older checkout's workers import its tools)

    compile_checkouts(*codes.values())                 # (the processes' imports are timed: .pyc in each)
    raw = {f.stem: {k: [] for k in codes} for f in files}
    for rnd in range(a.rounds):
        for f in files:
            for label, code in codes.items():
                log(f"round {rnd + 1}/{a.rounds}: {f.stem} ({label})")
                raw[f.stem][label].append(_run_worker(code, f, peers[f.stem]["file"], rnd, a))
    res = {name: {lab: _summarize(rs, threads) for lab, rs in r.items()} for name, r in raw.items()}
    for name in res:
        res[name]["peer"] = {k: v for k, v in peers[name].items() if k != "file"}
    md = [f"Machine: {machine()}; {a.rounds} rounds, {a.batch} random requests per batched call, "
          f"{a.single} single requests per round.", ""]
    for lab in codes:
        md += [f"**{lab}** ({codes[lab]})", ""] + _table(res, lab, threads) + [""]
    if a.against:
        md += ["new / old (< 1: faster):", ""] + _ratio_table(res, threads) + [""]
    md += ["JPEG 2000 peer at our per-view PSNR (mean over views, ours vs J2K): " + "; ".join(
        f"{n} {r['peer']['psnr_ours']:.2f} vs {r['peer']['psnr_j2k']:.2f} dB" for n, r in res.items())]
    text = "\n".join(md)
    print(text)
    if a.out:
        out = Path(a.out)
        out.mkdir(parents=True, exist_ok=True)
        (out / "decode.json").write_text(json.dumps({"machine": machine(), "results": res}, indent=1))
        (out / "decode.md").write_text(text + "\n")
        _plot(res, out, threads)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
