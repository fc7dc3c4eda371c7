"""RLFC as an lfcodec codec plug-in (entry point ``rlfc`` in the ``lfcodec.codecs`` group)."""
from __future__ import annotations

import argparse
import dataclasses

import numpy as np

from formats.codec_api import Codec, EncodeOptions, Encoded
from formats.errors import ParameterError, UnsupportedError
from formats.parallel import one_blas_thread

from .decoder import RlfcDecoder
from .header import CODEC_ID, CODEC_VERSION
from .profiles import available_profiles, get_profile

#: ``--profile auto`` tries these in order and takes the first that accepts the light field.
AUTO_ORDER = ("tx", "bise")


def choose_profile(lf, requested: str) -> str:
    """The profile ``auto`` resolves to for ``lf``, or ``requested`` after checking it exists."""
    if requested != "auto":
        get_profile(requested)
        return requested
    for pid in AUTO_ORDER:
        if get_profile(pid).accepts(lf) is None:
            return pid
    return "bise"


class RlfcCodec(Codec):
    codec_id = CODEC_ID
    version = CODEC_VERSION
    description = "random-access key-view light-field codec (after Pratapa & Manocha, I3D 2019)"

    def encode(self, lf, options: EncodeOptions, progress=None) -> Encoded:
        if np.dtype(lf.views.dtype) not in (np.uint8, np.uint16):
            raise UnsupportedError(f"the rlfc codec codes 8- and 16-bit integer views; these are "
                                   f"{np.dtype(lf.views.dtype).name} (convert them to 8- or 16-bit integers first)")
        pid = choose_profile(lf, options.profile)
        if pid != "tx" and not isinstance(lf.views, np.ndarray):     # only tx reads views as it codes them
            lf = dataclasses.replace(lf, views=np.asarray(lf.views))
        with one_blas_thread():     # (our threads are the parallelism; and the same floats, so the same
            enc = get_profile(pid).encode(lf, options, progress)    # file, whatever the cores)
        enc.config["profile"] = pid
        enc.summary.setdefault("profile", pid)
        return enc

    def open(self, f, **kw) -> RlfcDecoder:
        return RlfcDecoder(f, **kw)

    # -- command line -----------------------------------------------------------------------
    def add_arguments(self, g) -> None:
        g.add_argument("--profile", default=None, choices=["auto"] + available_profiles(),
                       help="RLFC profile: tx (multi-key disparity prediction, transform + rANS residuals; "
                            "grids), dcp (disparity prediction from 3x3-cluster key views, BISE residuals; grids), "
                            "bise (the paper's key-view tree), or auto (default: tx for grids, bise for posed "
                            "captures)")
        g.add_argument("--quant", type=float, default=None,
                       help="quantizer step Q in pixel units, 1 = lossless (default 8 for 8-bit input, "
                            "8*257 for 16-bit); tx: the luma step of the views that are not key views")
        g.add_argument("--block-size", type=int, default=None,
                       help="random-access block edge in pixels (default 16 for tx, 8 for bise/dcp)")
        g.add_argument("--threshold", type=float, default=None, help="bise/dcp: pixel threshold T (default Q/2)")
        g.add_argument("--energy", type=float, default=None, help="bise/dcp: block-energy threshold E (default (Q/2)^2)")
        g.add_argument("--tree-height", type=int, default=None, help="bise: key-view tree height (default 3)")
        g.add_argument("--sigma", type=float, default=None, help="bise: Gaussian filter width (view spacings)")
        g.add_argument("--top-codec", default=None, choices=["auto", "j2k", "jxl"],
                       help="bise/dcp: top key-view image codec")
        g.add_argument("--top-psnr", type=float, default=None,
                       help="bise/dcp: lossy top level, JPEG 2000 at this PSNR (dcp default: searched with a "
                            "target, else 44)")
        g.add_argument("--max-disparity", type=int, default=None,
                       help="dcp: largest disparity searched, px per view step (default 32; the search starts "
                            "at 4 and widens where blocks need it)")
        g.add_argument("--disparity-bits", type=int, default=None,
                       help="dcp: fractional bits of the disparity (3 = 1/8 px per view step; 0 = whole pixels)")
        g.add_argument("--key-spacing", type=int, default=None,
                       help="tx: views between key views along rows and columns (default: 2 for grids up to 5x5, "
                            "else 4)")
        g.add_argument("--key-ratio", type=float, default=None,
                       help="tx: key views' quantizer step is the others' divided by this (default: set from a probe "
                            "pass, 1.2-2.5)")
        g.add_argument("--intra-codec", default=None, choices=["auto", "tx", "j2k"],
                       help="tx: the intra key view as JPEG 2000 where that is smaller (auto, default; views with "
                            "alpha: their colour, the alpha plane exact after it) or always with the transform coder")
        g.add_argument("--key-split", type=int, default=None,
                       help="tx: streams per key-view block row; a decoder parses them in parallel (default: as "
                            "many as keep each about 256 bytes or more; 1 = one stream per row)")
        g.add_argument("--weighted-prediction", action=argparse.BooleanOptionalAction, default=None,
                       help="tx: a gain and an offset per view and plane on the prediction, where they pay (camera "
                            "arrays whose views differ in exposure, vignetting; a version 4 file where one is kept; "
                            "default: on)")
        g.add_argument("--warps", action="store_true", default=None,
                       help="tx, grids: estimate each view's rotation, scale and shift against the grid (a rig that "
                            "is not rectified) and predict through them; the file (version 5) holds the captured "
                            "pixels and the warps (unlike --rectify, which resamples the views); 2-8 CPU-s more")

    def params_from_args(self, a) -> dict:
        names = {"quant": "quant", "block_size": "block_size", "threshold": "threshold", "energy": "energy",
                 "tree_height": "tree_height", "sigma": "sigma", "top_codec": "top_codec", "top_psnr": "top_psnr",
                 "max_disparity": "max_disparity", "disparity_bits": "disp_frac_bits", "key_spacing": "key_spacing",
                 "key_ratio": "key_ratio", "intra_codec": "intra_codec", "key_split": "key_split",
                 "weighted_prediction": "weighted", "warps": "warps"}
        return {k: getattr(a, arg) for arg, k in names.items() if getattr(a, arg, None) is not None}


def encode(lf, options: EncodeOptions | None = None, **params) -> Encoded:
    """Encode a light field with RLFC (``params``: profile options, e.g. ``quant=4``)."""
    if options is not None and params:
        raise ParameterError("give either options or keyword params")
    return RlfcCodec().encode(lf, options or EncodeOptions(profile=params.pop("profile", "auto"), params=params))
