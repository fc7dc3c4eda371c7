"""SSIM of a decoded light field: scikit-image per view (the reference) against
:func:`formats.metrics.ssim` (OpenCV box filters), interleaved in one process.

Usage:
    python -m tools.bench_ssim FILE.lfc [FILE.lfc ...] [--data ../shared/data] [--rounds 3]

Each file's scene is ``DATA/<file stem>``; the file is decoded once, then each round times both
on every view (best of the rounds). Prints one JSON line per file: seconds, their ratio, both
values and their difference.
"""
from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import numpy as np


def _reference(ref: np.ndarray, dec: np.ndarray, peak: float) -> float:
    from skimage.metrics import structural_similarity

    from formats import metrics as M

    cs = M.colour_channels(ref.shape[-1])
    r, d = M._flat(ref)[..., cs], M._flat(dec).reshape(M._flat(ref).shape)[..., cs]
    return float(np.mean([structural_similarity(a, b, channel_axis=-1, data_range=peak) for a, b in zip(r, d)]))


def main(argv=None) -> int:
    from formats import metrics as M
    from formats.lfcfile import open_lfc
    from formats.scenes import read_scene
    from rlfc import RlfcDecoder

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("files", nargs="+", type=Path)
    ap.add_argument("--data", type=Path, default=Path(__file__).resolve().parents[2] / "shared" / "data")
    ap.add_argument("--rounds", type=int, default=3)
    a = ap.parse_args(argv)
    for f in a.files:
        ref = np.asarray(read_scene(str(a.data / f.stem)).views)
        dec = RlfcDecoder(open_lfc(f)).decode_all().reshape(ref.shape)
        peak = M.peak_of(ref.dtype)
        t_ref, t_new = [], []
        for _ in range(a.rounds):
            t = time.perf_counter()
            s_ref = _reference(ref, dec, peak)
            t_ref.append(time.perf_counter() - t)
            t = time.perf_counter()
            s_new = M.ssim(ref, dec)
            t_new.append(time.perf_counter() - t)
        print(json.dumps({"file": f.name, "shape": list(ref.shape), "skimage_s": min(t_ref), "ours_s": min(t_new),
                          "ratio": min(t_new) / min(t_ref), "ssim_skimage": s_ref, "ssim_ours": s_new,
                          "diff": abs(s_ref - s_new)}), flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
