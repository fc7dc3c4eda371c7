"""Per-view JPEG 2000 with exact alpha, the peer of tx layout version 6 on an RGBA capture.

python docs/bench/posed_alpha_stop81/j2k_alpha_peer.py ../shared/data/mitsuba_objects_360 36 40 45

Each view's colour channels coded alone (imagecodecs / OpenJPEG) at the lowest quality level on a
0.25 dB ladder whose colour PSNR reaches the target, its alpha plane exactly beside it (zlib
level 9 of the raw samples, and, for the record, PNG, JPEG-LS, reversible JPEG 2000 and lossless
JPEG XL). Prints bytes, bpp and the pooled colour PSNR, and each alpha coder's bytes.
"""
import sys
import zlib

import imagecodecs
import numpy as np

from formats import read_scene
from formats.metrics import psnr_rgb

lf = read_scene(sys.argv[1])
V = np.asarray(lf.views).reshape((-1,) + lf.views.shape[2:])
n, h, w, c = V.shape
assert c in (2, 4), "views with alpha"
alpha = [np.ascontiguousarray(V[i, ..., -1]) for i in range(n)]
coders = {"zlib": lambda a: zlib.compress(a.astype(a.dtype.newbyteorder("<")).tobytes(), 9),
          "png": lambda a: imagecodecs.png_encode(a, level=9),
          "jpegls": lambda a: imagecodecs.jpegls_encode(a),
          "j2k_reversible": lambda a: imagecodecs.jpeg2k_encode(a, level=0, reversible=True),
          "jxl_lossless": lambda a: imagecodecs.jpegxl_encode(a, lossless=True, effort=7)}
print({k: sum(len(f(a)) for a in alpha) for k, f in coders.items()})
a_bytes = sum(len(coders["zlib"](a)) for a in alpha)
for target in map(float, sys.argv[2:]):
    col_bytes, dec = 0, np.empty_like(V)
    for i in range(n):
        col = np.ascontiguousarray(V[i, ..., :c - 1])
        x = col[..., 0] if c == 2 else col
        for lev in np.arange(target - 1.0, target + 8.0, 0.25):
            b = imagecodecs.jpeg2k_encode(x, level=float(lev))
            d = np.asarray(imagecodecs.jpeg2k_decode(b)).reshape(col.shape)
            if psnr_rgb(col[None], d[None]) >= target:
                break
        col_bytes += len(b)
        dec[i, ..., :c - 1], dec[i, ..., -1] = d, alpha[i]
    tot = col_bytes + a_bytes
    print(f"target {target}: colour {col_bytes} + alpha {a_bytes} = {tot} bytes, {tot * 8 / (n * h * w):.4f} bpp, "
          f"pooled PSNR {psnr_rgb(V, dec):.3f} dB")
