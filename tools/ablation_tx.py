"""Ablation of the ``tx`` profile's levers at a target PSNR (issue 13).

Usage: ``python -m tools.ablation_tx SCENE [SCENE ...] --out DIR [--target 40] [--rows 1,2,...]``

Each row adds one lever to the row above; every row runs the rate control the CLI ships with
(``--target-psnr``, PSNR_RGB ≥ target) and reports the whole file as the CLI writes it (bpp,
bytes per section), the PSNR reached, the encode time (wall and CPU), and the random-access
decode cost of that file on this machine (median ``decode_block`` µs over 300 random requests;
µs per block of a 20 000-request ``decode_blocks`` call, median of 3):

1. ``no disparity``: every view that is not a key view blends its 2–4 key views at the same
   pixels (``max_disparity=0``, so no maps), every 8×8 block blends (no single-reference
   modes), levels rounded to nearest (no RDO quantization), no intra 8×8 blocks, key views at
   the same step as the others (``key_ratio=1``), the intra key transform-coded, no view coded
   alone, no λ trim.
2. ``+ disparity``: one disparity per 8×8 block and cell of views (1/16 px, the default search).
3. ``+ single-reference modes``: a block may take one reference instead of the blend.
4. ``+ RDO quantization``: per coefficient round / round − 1 / 0, and the last position, by
   D + λ·R.
5. ``+ intra 8×8 blocks``: a block may be coded without prediction (flat value + residual).
6. ``+ key step ratio √π``: key views at a finer step, from how much the others inherit.
7. ``+ JPEG 2000 intra keys, views coded alone``: the intra key as JPEG 2000 where smaller, and
   views that cost less alone become JPEG 2000 keys.
8. ``+ λ trim`` (the shipped default).

Then variants of row 8: random-access blocks of 8 and 32 pixels, key spacing 2 and 4; and rows
13–19, leave one out: the default with one lever off (disparity, single-reference modes, RDO
quantization, intra 8×8 blocks, the key step ratio, JPEG 2000, the λ trim), which says what each
lever buys in the shipped mix rather than in the order the rows above add them.
Rows are appended to ``DIR/ablation_tx.jsonl`` as they finish (one line per scene and row);
``DIR/ablation_tx.md`` is rewritten from it after each scene.
"""
from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import numpy as np

from formats.codec_api import EncodeOptions
from formats.metrics import bpp, psnr_rgb
from formats.scenes import read_scene
from rlfc.codec import RlfcCodec
from tools.bench import random_access_times
from tools.common import log, open_encoded

OFF_ALL = ["ref_modes", "rdoq", "intra_tbs", "promote", "lambda_trim", "maps_reprice"]

#: (name, params) of each row; params as ``EncodeOptions.params`` of the tx profile
ROWS = [
    ("no disparity, blend, rounding, one step, transform keys",
     {"max_disparity": 0.0, "key_ratio": 1.0, "intra_codec": "tx", "ablate": OFF_ALL}),
    ("+ disparity per 8x8 block",
     {"key_ratio": 1.0, "intra_codec": "tx", "ablate": OFF_ALL}),
    ("+ single-reference modes",
     {"key_ratio": 1.0, "intra_codec": "tx", "ablate": ["rdoq", "intra_tbs", "promote", "lambda_trim", "maps_reprice"]}),
    ("+ RDO quantization",
     {"key_ratio": 1.0, "intra_codec": "tx", "ablate": ["intra_tbs", "promote", "lambda_trim", "maps_reprice"]}),
    ("+ intra 8x8 blocks",
     {"key_ratio": 1.0, "intra_codec": "tx", "ablate": ["promote", "lambda_trim", "maps_reprice"]}),
    ("+ key step ratio sqrt(pi)",
     {"intra_codec": "tx", "ablate": ["promote", "lambda_trim", "maps_reprice"]}),
    ("+ JPEG 2000 intra keys, views coded alone",
     {"ablate": ["lambda_trim", "maps_reprice"]}),
    ("+ lambda trim", {"ablate": ["maps_reprice"]}),
    ("+ maps repriced at the coding lambda (default)", {}),
    ("default, 8x8 random-access blocks", {"block_size": 8}),
    ("default, 32x32 random-access blocks", {"block_size": 32}),
    ("default, key spacing 2", {"key_spacing": 2}),
    ("default, key spacing 4", {"key_spacing": 4}),
    # leave one out: the default with one lever off (what each lever buys in the shipped mix)
    ("default without disparity", {"max_disparity": 0.0}),
    ("default without single-reference modes", {"ablate": ["ref_modes"]}),
    ("default without RDO quantization", {"ablate": ["rdoq"]}),
    ("default without intra 8x8 blocks", {"ablate": ["intra_tbs"]}),
    ("default without key step ratio (1)", {"key_ratio": 1.0}),
    ("default without JPEG 2000 (transform keys, no view alone)", {"intra_codec": "tx"}),
    ("default without lambda trim", {"ablate": ["lambda_trim"]}),
    ("default without maps repriced", {"ablate": ["maps_reprice"]}),
]


def run_row(lf, name: str, params: dict, target: float, n_single: int = 300, n_batch: int = 20000) -> dict:
    """One row: encode with the CLI's rate control, open the file in memory, measure."""
    t0, c0 = time.perf_counter(), time.process_time()
    enc = RlfcCodec().encode(lf, EncodeOptions(profile="tx", target_psnr=target, params=dict(params)))
    t_enc, c_enc = time.perf_counter() - t0, time.process_time() - c0
    d, blob = open_encoded(lf, enc)
    nv = lf.rows * lf.cols
    dec = d.decode_all()
    single, batch = random_access_times(d, np.random.default_rng(0), n_single, n_batch, 3)
    sizes = {n: len(s) for n, s in enc.sections}
    info = d.core.info() if hasattr(d.core, "info") else {}
    return {"variant": name, "params": params, "bytes": len(blob),
            "bpp": bpp(len(blob), nv, lf.height, lf.width), "psnr_rgb": psnr_rgb(lf.views, dec),
            "found": bool(enc.target_met), "sections": sizes, "encode_s": t_enc, "encode_cpu_s": c_enc,
            "block_us": single * 1e6, "batch_block_us": batch * 1e6,
            "coded_blocks": info.get("coded_blocks"), "key_views": info.get("key_views"),
            "views_alone": enc.summary.get("views_coded_alone")}


def table(rows: list[dict]) -> list[str]:
    """Markdown lines for one scene's rows (bytes against the shipped default's)."""
    ref = next((r for r in rows if r["variant"].endswith("(default)")), None)
    out = ["| variant | bpp | PSNR_RGB | bytes / default | blocks coded | encode s (CPU) | block µs | "
           "batched µs/block |", "|---|---|---|---|---|---|---|---|"]
    for r in rows:
        rel = f"{r['bytes'] / ref['bytes']:.3f}" if ref else "–"
        out.append(f"| {r['variant']} | {r['bpp']:.4f} | {r['psnr_rgb']:.2f}{'' if r['found'] else ' (missed)'} | "
                   f"{rel} | {r['coded_blocks']} | {r['encode_s']:.0f} ({r['encode_cpu_s']:.0f}) | "
                   f"{r['block_us']:.0f} | {r['batch_block_us']:.2f} |")
    return out


def write_md(out: Path, target: float) -> None:
    rows: dict[str, list] = {}
    for line in (out / "ablation_tx.jsonl").read_text().splitlines():
        r = json.loads(line)
        if r["target"] == target:
            rows.setdefault(r["scene"], []).append(r)
    lines = []
    for scene, rs in rows.items():
        lines += [f"### {scene} (target {target:g} dB)", ""] + table(rs) + [""]
    (out / "ablation_tx.md").write_text("\n".join(lines))


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(prog="python -m tools.ablation_tx", description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("scenes", nargs="+")
    ap.add_argument("--out", required=True)
    ap.add_argument("--target", type=float, default=40.0, help="PSNR_RGB target in dB (default 40)")
    ap.add_argument("--rows", default="", help="1-based rows to run, comma-separated (default: all)")
    a = ap.parse_args(argv)
    out = Path(a.out)
    out.mkdir(parents=True, exist_ok=True)
    pick = [int(x) for x in a.rows.split(",") if x] or list(range(1, len(ROWS) + 1))
    for s in a.scenes:
        name = Path(s).name
        log(f"[{name}]")
        lf = read_scene(s)
        for i in pick:
            vname, params = ROWS[i - 1]
            r = run_row(lf, vname, params, a.target)
            r.update(scene=name, target=a.target, row=i)
            with open(out / "ablation_tx.jsonl", "a") as f:
                f.write(json.dumps(r, default=float) + "\n")
            log(f"  {i}. {vname}: {r['bpp']:.4f} bpp at {r['psnr_rgb']:.2f} dB, {r['encode_s']:.0f} s, "
                f"block {r['block_us']:.0f} µs, batched {r['batch_block_us']:.2f} µs/block")
        write_md(out, a.target)
    print((out / "ablation_tx.md").read_text())
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
