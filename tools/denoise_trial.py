"""What a noise-aware mode would buy: a grid coded at a target PSNR as captured, and after a
per-view denoiser (OpenCV non-local means), with the PSNR of each file against both the coded
input and the captured original.

Usage:
    python -m tools.denoise_trial SCENE [--h 5] [--target 40]
"""
from __future__ import annotations

import argparse
import json

import cv2
import numpy as np

from formats.codec_api import EncodeOptions
from formats.metrics import bpp, psnr_rgb
from formats.scenes import read_scene
from rlfc import encode
from tools.common import log, open_encoded


def trial(scene: str, h: float, target: float) -> dict:
    lf = read_scene(scene)
    orig = lf.views.copy()
    den = np.stack([np.stack([cv2.fastNlMeansDenoisingColored(np.ascontiguousarray(v), None, h, h, 5, 15)
                              for v in row]) for row in orig])
    out = {"scene": scene, "h": h, "target": target, "denoised_vs_original_db": psnr_rgb(orig, den)}
    for name, views in (("original", orig), ("denoised", den)):
        lf.views = views
        d, blob = open_encoded(lf, encode(lf, EncodeOptions(target_psnr=target)))
        dec = d.decode_all()
        out[name] = {"bpp": bpp(len(blob), lf.rows * lf.cols, lf.height, lf.width),
                     "psnr_vs_coded_input": psnr_rgb(views, dec), "psnr_vs_original": psnr_rgb(orig, dec)}
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(prog="python -m tools.denoise_trial", description=__doc__.split("\n\n")[0])
    ap.add_argument("scene")
    ap.add_argument("--h", type=float, default=5.0, help="non-local means strength (grey levels)")
    ap.add_argument("--target", type=float, default=40.0)
    a = ap.parse_args(argv)
    log(json.dumps(trial(a.scene, a.h, a.target), indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
