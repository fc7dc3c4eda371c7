"""BISE throughput: encode and decode, single-block and batched, for several ASTC ranges.

Usage: python -m tools.bench_bise [--blocks N] [--json]

Prints values/s and MB/s (of encoded bytes) as medians over repeats after a warm-up.
"""
from __future__ import annotations

import argparse
import json

import numpy as np

from rlfc import bise
from tools.common import machine
from tools.common import median_time as _median_time


def run(n_blocks: int = 100_000, count: int = 48, ranges=(3, 5, 8, 12, 20, 32, 48, 96, 160, 256), repeats: int = 5):
    rng = np.random.default_rng(0)
    rows = []
    for n in ranges:
        vals = rng.integers(0, n, (n_blocks, count))
        enc = bise.encode_batch(vals, n)
        buf = np.concatenate([enc.reshape(-1), np.zeros(bise.SLACK, np.uint8)])
        starts = np.arange(n_blocks, dtype=np.int64) * enc.shape[1]
        t_enc = _median_time(lambda: bise.encode_batch(vals, n), repeats)
        t_dec = _median_time(lambda: bise.decode_at(buf, starts, n, count), repeats)
        one = enc[0].tobytes()
        t_enc1 = _median_time(lambda: bise.encode(vals[0], n), 200)
        t_dec1 = _median_time(lambda: bise.decode(one, n, count), 200)
        nv, nbytes = vals.size, enc.size
        rows.append({"range": n, "bits_per_value": bise.bit_length(count, n) / count,
                     "batched_encode_Mvals_s": nv / t_enc / 1e6, "batched_encode_MB_s": nbytes / t_enc / 1e6,
                     "batched_decode_Mvals_s": nv / t_dec / 1e6, "batched_decode_MB_s": nbytes / t_dec / 1e6,
                     "single_encode_us": t_enc1 * 1e6, "single_decode_us": t_dec1 * 1e6,
                     "single_decode_Mvals_s": count / t_dec1 / 1e6})
    return rows


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--blocks", type=int, default=100_000, help="blocks of 4x4x3 = 48 values per batch")
    ap.add_argument("--json", action="store_true")
    a = ap.parse_args(argv)
    rows = run(a.blocks)
    if a.json:
        print(json.dumps({"machine": machine(), "count": 48, "rows": rows}, indent=1))
        return 0
    print(f"BISE, blocks of 48 values (4x4x3), batch of {a.blocks} blocks; {machine()}")
    print("| range | bits/value | batched encode Mvals/s (MB/s) | batched decode Mvals/s (MB/s) | single encode µs | single decode µs |")
    print("|---|---|---|---|---|---|")
    for r in rows:
        print(f"| {r['range']} | {r['bits_per_value']:.2f} | {r['batched_encode_Mvals_s']:.1f} ({r['batched_encode_MB_s']:.1f}) | "
              f"{r['batched_decode_Mvals_s']:.1f} ({r['batched_decode_MB_s']:.1f}) | {r['single_encode_us']:.1f} | "
              f"{r['single_decode_us']:.1f} |")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
