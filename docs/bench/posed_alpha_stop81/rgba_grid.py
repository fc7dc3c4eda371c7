"""tools.unseen's layers_rgba_9x9 (an RGBA grid) at a target: per-view JPEG 2000 with exact alpha,
then the tx profile by default (JPEG 2000 colour + exact alpha where an intra key is smaller) and
with intra_codec "tx" (the transform path every view with alpha took before stop 81).

python docs/bench/posed_alpha_stop81/rgba_grid.py ../shared/data 36 40 45
"""
import json
import sys
import time
from pathlib import Path

import numpy as np

from formats.codec_api import EncodeOptions
from formats.metrics import bpp, psnr_rgb
from rlfc import encode
from tools.unseen import j2k_at, layers_rgba

lf = layers_rgba(Path(sys.argv[1]))
n = lf.rows * lf.cols
for target in map(float, sys.argv[2:]):
    jb, _ = j2k_at(lf, target)
    row = {"target": target, "j2k_alpha_bpp": jb}
    for ic in ("auto", "tx"):
        t = time.perf_counter()
        e = encode(lf, EncodeOptions(profile="tx", target_psnr=target, params={"intra_codec": ic}))
        size = sum(len(x) for _, x in e.sections)
        row[ic] = {"bpp_sections": bpp(size, n, lf.height, lf.width), "psnr_rgb": psnr_rgb(lf.views, e.decoded),
                   "alpha_exact": bool(np.array_equal(e.decoded[..., -1], lf.views[..., -1])),
                   "version": e.config["tx"]["version"], "j2k_keys": sum(1 for x in e.config["tx"]["key_images"] if x),
                   "keys": len(e.config["tx"]["keys"]), "encode_s": time.perf_counter() - t}
    print(json.dumps(row))
