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


class _KeyViewEncoders:
    """dcp encoders at different key-view PSNRs sharing one disparity map, estimated by the
    first encoder built (callers build the best key views first)."""

    def __init__(self, lf, base: RlfcParams):
        self.lf, self.base, self.disp = lf, base, None

    def __call__(self, top_psnr: float):
        p = replace(self.base, top_psnr=top_psnr)
        enc = Encoder(self.lf, p, disparity=self.disp)
        self.disp = enc.disp
        return enc, p


def search_dcp(lf, base: RlfcParams, *, target_psnr: float, fixed_threshold=None, fixed_energy=None,
               margins=(-1.0, 6.0), tol: float = 0.25, residual_steps=(0.5,), progress=None):
    """dcp rate control: the key views' quality is the main knob.

    With sub-pixel disparity the prediction alone often meets the target, and key-view bits
    are cheaper than residual blocks. So: (1) bisect the key views' PSNR (target + m dB, m in
    ``margins``) for the cheapest key views whose prediction alone meets the target (Q at its
    coarsest: no residual blocks); (2) for m* − each of ``residual_steps``, search Q as in
    :func:`search` (key views a little worse, residual blocks make up the difference); the
    smallest file that meets the target wins. When even the best key views miss the target,
    Q is searched at margins 3 and 1 dB. The disparity map is estimated once (against the
    best key views) and re-used. Returns (encoder, params, loop result, trace).
    """
    lo, hi = margins
    trace = []
    coarse_q = Q_MAX * depth_scale(lf.views.dtype)
    encoders = _KeyViewEncoders(lf, base)

    def encoder(m):
        return encoders(target_psnr + m)

    def packed_size(enc, p, res):
        _, secs = enc.pack(p, res)
        return sum(len(s) for _, s in secs)

    def coarse(m):
        enc, p0 = encoder(m)
        p = params_for_quant(p0, coarse_q, fixed_threshold, fixed_energy)
        res = enc.closed_loop(p, keep_blocks=False)
        ps = _psnr(enc, res)
        trace.append((p.quant, ps, None))
        if progress:
            progress(len(trace), p, ps, None)
        return ps >= target_psnr, enc, p

    def with_residuals(m):
        enc, p0 = encoder(m)
        p, res, tr = search(enc, p0, target_psnr=target_psnr, fixed_threshold=fixed_threshold,
                            fixed_energy=fixed_energy, progress=progress)
        trace.extend(tr)
        res = enc.closed_loop(p)
        return _psnr(enc, res) >= target_psnr, enc, p, res

    ok, enc, p = coarse(hi)
    if not ok:                                  # prediction alone never suffices: residuals needed
        best = None
        for m in (3.0, 1.0):
            ok, enc, p, res = with_residuals(m)
            size = packed_size(enc, p, res)
            if best is None or (ok, -size) > (best[0], -best[1]):
                best = (ok, size, enc, p, res)
        return best[2], best[3], best[4], trace
    found = (enc, p)
    ok, enc, p = coarse(lo)
    if ok:
        found, hi = (enc, p), lo
    else:
        while hi - lo > tol:
            mid = (lo + hi) / 2
            ok, enc, p = coarse(mid)
            if ok:
                found, hi = (enc, p), mid
            else:
                lo = mid
    enc, p = found
    res = enc.closed_loop(p)
    best = (packed_size(enc, p, res), enc, p, res)
    for step in residual_steps:
        if hi - step < margins[0]:
            continue
        ok, enc, p, res = with_residuals(hi - step)
        size = packed_size(enc, p, res)
        if ok and size < best[0]:
            best = (size, enc, p, res)
    return best[1], best[2], best[3], trace


def search_dcp_bpp(lf, base: RlfcParams, *, target_bpp: float, db_range=(10.0, 50.0), iters: int = 8,
                   meta_bytes: int = 4096, progress=None):
    """dcp rate control for a bpp ceiling.

    Bisects the key views' PSNR (dB, within ``db_range``) for the best key views whose
    prediction-only file (no residual blocks) fits under the ceiling. When even the best key
    views fit, the quantizer is searched as in :func:`search` to spend the rest on residual
    blocks. The disparity map is estimated once, against the best key views.
    Returns (encoder, params, loop result, trace).
    """
    if not target_bpp > 0:
        raise ParameterError(f"target bpp must be > 0, got {target_bpp}")
    nv = lf.rows * lf.cols
    coarse_q = Q_MAX * depth_scale(lf.views.dtype)
    trace = []
    encoders = _KeyViewEncoders(lf, base)

    def evaluate(db):
        enc, p0 = encoders(db)
        p = params_for_quant(p0, coarse_q)
        res = enc.closed_loop(p)
        _, secs = enc.pack(p, res)
        b = bpp_of(sum(len(s) for _, s in secs) + meta_bytes, nv, lf.height, lf.width)
        ps = _psnr(enc, res)
        trace.append((p.quant, ps, b))
        if progress:
            progress(len(trace), p, ps, b)
        return b <= target_bpp, enc, p, res

    lo, hi = db_range
    ok, enc, p, res = evaluate(hi)
    if ok:                                       # room for residual blocks on top of the best key views
        p2, res2, tr = search(enc, replace(base, top_psnr=hi), target_bpp=target_bpp, meta_bytes=meta_bytes,
                              progress=progress)
        trace.extend(tr)
        return enc, p2, res2, trace
    ok, enc, p, res = evaluate(lo)
    best = (enc, p, res)
    if not ok:                                   # even the worst key views are over: closest we have
        return enc, p, res, trace
    for _ in range(iters):
        mid = (lo + hi) / 2
        ok, enc, p, res = evaluate(mid)
        if ok:
            lo, best = mid, (enc, p, res)
        else:
            hi = mid
    return best[0], best[1], best[2], trace


__all__ = ["search_dcp_bpp", "search_dcp", "search", "params_for_quant", "Q_MAX", "default_quant", "depth_scale"]
