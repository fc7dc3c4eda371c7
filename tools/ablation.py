"""Ablation of the dcp profile's levers at a target PSNR (issue 8).

Usage: ``python -m tools.ablation SCENE [SCENE ...] --out DIR [--target 40] [--blocks 4,16]``

Each row adds one lever to the row above and runs the rate control it would ship with, to
PSNR_RGB >= target; it reports the whole file's bpp (the sections + 4 KiB of container and
metadata, as the rate control counts), the PSNR reached, the encode time, and the single-block
and batched random-access decode times of the resulting file on this machine:

1. ``bise``: the paper's profile (Gaussian key-view tree), Q searched.
2. ``dcp, whole-pixel disparity``: 3×3-cluster key views at target + 3 dB, Q searched, the
   disparity map and block index stored raw (int8 and u32), as the first dcp version did.
3. ``+ 1/8-px disparity`` (bilinear sub-pixel prediction), same rate control.
4. ``+ key-view quality search``: the key views' PSNR is bisected (prediction only), then one
   residual trial 0.5 dB lower.
5. ``+ coded index and map`` (zlib run lengths / zlib deltas).
6. ``+ regularized disparity map`` (3×3 median where it costs < 10% more): the shipped default.

The key-view search runs at 0.1 dB resolution here (the CLI's is 0.25 dB) so that rows differ
by their lever, not by where the bisection stopped.

Then variants of row 6: disparity precision 1/4 px, and other block sizes. Writes
``ablation.json`` and ``ablation.md`` to DIR.
"""
from __future__ import annotations

import argparse
import json
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

from formats.codec_api import EncodeOptions
from formats.metrics import bpp, psnr_rgb
from formats.scenes import read_scene
from rlfc import RlfcParams, get_profile
from rlfc.keytree import KeyTreeEncoder
from rlfc.profiles.dcp import search_psnr
from rlfc.ratecontrol import search_quant
from tools.bench import random_access_times
from tools.common import log as _log
from tools.common import open_encoded

META = 4096


def _timings(d, n_single: int = 200, n_batch: int = 20000) -> tuple[float, float]:
    """(median single-block µs, batched µs per block) of an opened file."""
    single, batch = random_access_times(d, np.random.default_rng(0), n_single, n_batch, 3)
    return single * 1e6, batch * 1e6


def _row(lf, name, enc, p, res, t_enc, raw_tables=False):
    cfg, secs = enc.pack(p, res)
    sizes = {n: len(s) for n, s in secs}
    if raw_tables and getattr(enc, "disp", None) is not None:   # the first dcp version's raw index and map
        sizes["rlfc.index"] = 4 * (enc.nby * enc.nbx + 1)
        sizes["rlfc.disp"] = enc.disp.size * (1 if np.abs(enc.disp).max(initial=0) < 128 else 2)
    d, _ = open_encoded(lf, (cfg, secs))
    nv = lf.rows * lf.cols
    dec = d.decode_all()
    us1, usb = _timings(d)
    row = {"variant": name, "bpp": bpp(sum(sizes.values()) + META, nv, lf.height, lf.width),
           "psnr_rgb": psnr_rgb(lf.views, dec), "top_psnr": p.top_psnr, "quant": p.quant,
           "sections": {k: bpp(v, nv, lf.height, lf.width) for k, v in sizes.items()},
           "encode_s": t_enc, "block_us": us1, "batch_block_us": usb}
    _log(f"  {name}: {row['bpp']:.4f} bpp at {row['psnr_rgb']:.2f} dB (K={p.top_psnr}, Q={p.quant:g}), "
         f"{t_enc:.0f} s, block {us1:.0f} µs, batched {usb:.2f} µs/block")
    return row


def ablate(lf, target: float, block_sizes=(4, 16)) -> list[dict]:
    rows = []

    def q_search(name, base, raw_tables):
        t = time.perf_counter()
        enc = KeyTreeEncoder(lf, base, get_profile(base.profile).strategy(lf))
        _, p, res, _ = search_quant(enc, base, target_psnr=target)
        rows.append(_row(lf, name, enc, p, res, time.perf_counter() - t, raw_tables))

    def dcp_search(name, base, raw_tables=False):
        t = time.perf_counter()
        _, enc, p, res, _ = search_psnr(lf, base, EncodeOptions(target_psnr=target), lambda *x: None, tol=0.1)
        rows.append(_row(lf, name, enc, p, res, time.perf_counter() - t, raw_tables))

    q_search("bise (paper profile)", RlfcParams(), False)
    dcp = RlfcParams(profile="dcp", top_psnr=target + 3)
    q_search("dcp, whole-pixel disparity, key views at target+3 dB", replace(dcp, disp_frac_bits=0, disp_smooth=0), True)
    q_search("+ 1/8-px disparity (bilinear)", replace(dcp, disp_smooth=0), True)
    dcp_search("+ key-view quality search", replace(dcp, disp_smooth=0), True)
    dcp_search("+ coded index and map (zlib)", replace(dcp, disp_smooth=0))
    dcp_search("+ regularized disparity map (default)", dcp)
    dcp_search("default, 1/4-px disparity", replace(dcp, disp_frac_bits=2))
    for b in block_sizes:
        dcp_search(f"default, {b}x{b} blocks", replace(dcp, block_size=b))
    return rows


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(prog="python -m tools.ablation", description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("scenes", nargs="+")
    ap.add_argument("--out", required=True)
    ap.add_argument("--target", type=float, default=40.0, help="PSNR_RGB target in dB (default 40)")
    ap.add_argument("--blocks", default="4,16", help="block sizes to try besides 8 ('' for none)")
    a = ap.parse_args(argv)
    out = Path(a.out)
    out.mkdir(parents=True, exist_ok=True)
    blocks = [int(x) for x in a.blocks.split(",") if x]
    result, lines = {}, []
    for s in a.scenes:
        name = Path(s).name
        _log(f"[{name}]")
        lf = read_scene(s)
        result[name] = ablate(lf, a.target, blocks)
        lines += [f"### {name} (target {a.target:g} dB)", "",
                  "| variant | bpp | PSNR_RGB | key views dB | Q | encode s | block µs | batched µs/block |",
                  "|---|---|---|---|---|---|---|---|"]
        for r in result[name]:
            k = "lossless" if r["top_psnr"] is None else f"{r['top_psnr']:.2f}"
            lines.append(f"| {r['variant']} | {r['bpp']:.4f} | {r['psnr_rgb']:.2f} | {k} | {r['quant']:g} | "
                         f"{r['encode_s']:.0f} | {r['block_us']:.0f} | {r['batch_block_us']:.2f} |")
        lines.append("")
    (out / "ablation.json").write_text(json.dumps(result, indent=1, default=float))
    (out / "ablation.md").write_text("\n".join(lines))
    print("\n".join(lines))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
