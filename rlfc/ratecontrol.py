"""Rate control: choose the quantizer for a target PSNR_RGB or bpp by bisection.

One knob, the quantization step Q, drives the pixel threshold T = Q/2 and the block-energy
threshold E = (Q/2)² (measured on hci_antinous to be the best of the simple couplings tried;
see BENCHMARKS.md) unless the user fixes T or E. PSNR falls and bits fall as Q grows, so a
bisection on log Q finds the largest Q that meets a PSNR target (or the smallest that meets a
bpp target) to within the tolerance.
"""
from __future__ import annotations

import math
from dataclasses import replace


import numpy as np

from formats.errors import ParameterError
from formats.metrics import bpp as bpp_of
from formats.metrics import psnr_rgb

from .color import from_planes
from .encoder import Encoder
from .params import RlfcParams

Q_MAX = 256.0          # in 8-bit pixel units; scaled by peak/255 for deeper input
DEFAULT_QUANT = 8.0    # likewise


def depth_scale(dtype) -> float:
    """Pixel-unit scale of an input depth relative to 8-bit (1 for uint8, 257 for uint16)."""
    return 65535.0 / 255.0 if np.dtype(dtype) == np.uint16 else 1.0


def default_quant(dtype) -> float:
    """The default quantizer step for an input depth (8 in 8-bit units)."""
    return DEFAULT_QUANT * depth_scale(dtype)


def params_for_quant(base: RlfcParams, q: float, fixed_threshold: float | None = None,
                     fixed_energy: float | None = None) -> RlfcParams:
    """Parameters for quantizer step ``q`` with the coupled thresholds (Q=1 is lossless)."""
    q = max(1.0, round(q * 16) / 16)
    t = fixed_threshold if fixed_threshold is not None else (0.0 if q <= 1 else q / 2)
    e = fixed_energy if fixed_energy is not None else (0.0 if q <= 1 else (q / 2) ** 2)
    return replace(base, quant=q, threshold=t, energy=e)


def _psnr(enc: Encoder, res) -> float:
    lf = enc.lf
    dec = from_planes(res.dec0[:, :lf.height, :lf.width], lf.views.dtype)
    return psnr_rgb(lf.views.reshape(dec.shape), dec)


def search(enc: Encoder, base: RlfcParams, *, target_psnr: float | None = None, target_bpp: float | None = None,
           fixed_threshold: float | None = None, fixed_energy: float | None = None, iters: int = 9,
           meta_bytes: int = 4096, progress=None):
    """Find parameters meeting a target; returns (params, loop result, trace).

    Args:
        enc: an :class:`Encoder` (RKVs and top level already built).
        target_psnr: PSNR_RGB floor in dB; or target_bpp: bpp ceiling (whole file).
        meta_bytes: estimate of the container + metadata overhead counted in bpp.
        progress: optional callable(i, params, psnr, bpp).

    Returns:
        params: the chosen parameters; res: its closed-loop result; trace: list of
        (quant, psnr, bpp or None) tried.
    """
    if (target_psnr is None) == (target_bpp is None):
        raise ParameterError("give exactly one of target_psnr and target_bpp")
    if target_psnr is not None and not 10 <= target_psnr <= 200:
        raise ParameterError(f"target PSNR must be within 10..200 dB, got {target_psnr}")
    if target_bpp is not None and not target_bpp > 0:
        raise ParameterError(f"target bpp must be > 0, got {target_bpp}")
    lf = enc.lf
    nv = lf.rows * lf.cols
    trace = []

    def evaluate(q):
        p = params_for_quant(base, q, fixed_threshold, fixed_energy)
        res = enc.closed_loop(p, keep_blocks=target_bpp is not None)
        ps = _psnr(enc, res)
        b = None
        if target_bpp is not None:
            _, secs = enc.pack(p, res)
            b = bpp_of(sum(len(s) for _, s in secs) + meta_bytes, nv, lf.height, lf.width)
        trace.append((p.quant, ps, b))
        if progress:
            progress(len(trace), p, ps, b)
        ok = ps >= target_psnr if target_psnr is not None else b <= target_bpp
        return ok, p, res

    # PSNR target: feasible at fine steps, find the largest feasible Q.
    # bpp target: feasible at coarse steps, find the smallest feasible Q.
    fine, coarse = 0.0, math.log2(Q_MAX * depth_scale(lf.views.dtype))
    good_end, bad_end = (fine, coarse) if target_psnr is not None else (coarse, fine)
    ok, p, res = evaluate(2 ** good_end)
    if not ok:                                # even the best end misses the target: closest we have
        return p, res, trace
    best = (p, res)
    ok_bad, p_bad, res_bad = evaluate(2 ** bad_end)
    if ok_bad:
        return p_bad, res_bad, trace
    for _ in range(iters):
        mid = (good_end + bad_end) / 2
        ok, p, res = evaluate(2 ** mid)
        if ok:
            good_end = mid
            if target_psnr is not None or _psnr(enc, res) >= _psnr(enc, best[1]):
                best = (p, res)   # bpp targets: keep the best quality seen under the ceiling
        else:
            bad_end = mid
        if abs(2 ** good_end - 2 ** bad_end) < 1 / 16:
            break
    return best[0], best[1], trace


def search_dcp(lf, base: RlfcParams, *, target_psnr: float, fixed_threshold=None, fixed_energy=None,
               top_margins=(3.0, 1.0), progress=None):
    """dcp rate control: the key views' quality is a second knob. For each margin m, key views
    are coded at target + m dB and Q is searched as in :func:`search`; the smallest file that
    meets the target wins. Returns (encoder, params, loop result, trace)."""
    best = None
    trace = []
    for m in top_margins:
        enc = Encoder(lf, replace(base, top_psnr=target_psnr + m))
        p, res, tr = search(enc, replace(base, top_psnr=target_psnr + m), target_psnr=target_psnr,
                            fixed_threshold=fixed_threshold, fixed_energy=fixed_energy, progress=progress)
        trace += [(q, ps, b) for q, ps, b in tr]
        res = enc.closed_loop(p)
        ok = _psnr(enc, res) >= target_psnr
        _, secs = enc.pack(p, res)
        size = sum(len(s) for _, s in secs)
        if ok and (best is None or size < best[0]):
            best = (size, enc, p, res)
        if best is None and m == top_margins[-1]:
            best = (size, enc, p, res)
    return best[1], best[2], best[3], trace


__all__ = ["search_dcp", "search", "params_for_quant", "Q_MAX", "default_quant", "depth_scale"]
