"""Rate control: a bisection over one monotone knob, shared by every profile.

A profile names its knob (the quantizer step, the key views' quality, λ, ...) and an
``evaluate(x) -> (feasible, payload)``; :func:`bisect` finds the knob value at the edge of
feasibility to within a tolerance. :func:`search_quant` is the quantizer search of the
BISE-family profiles: one knob Q drives the pixel threshold T = Q/2 and the block-energy
threshold E = (Q/2)² (measured on hci_antinous to be the best simple coupling; BENCHMARKS.md)
unless the user fixes T or E.
"""
from __future__ import annotations

import math
from dataclasses import replace

import numpy as np

from formats.errors import ParameterError
from formats.metrics import bpp as bpp_of
from formats.metrics import psnr_rgb

from .params import RlfcParams

Q_MAX = 256.0          # in 8-bit pixel units; scaled by peak/255 for deeper input
DEFAULT_QUANT = 8.0    # likewise


def depth_scale(dtype) -> float:
    """Pixel-unit scale of an input depth relative to 8-bit (1 for uint8, 257 for uint16)."""
    return 65535.0 / 255.0 if np.dtype(dtype) == np.uint16 else 1.0


def default_quant(dtype) -> float:
    """The default quantizer step for an input depth (8 in 8-bit units)."""
    return DEFAULT_QUANT * depth_scale(dtype)


def check_targets(target_psnr=None, target_bpp=None) -> None:
    if target_psnr is not None and target_bpp is not None:
        raise ParameterError(f"give one rate target, a PSNR or a bpp (got {target_psnr} dB and {target_bpp} bpp)")
    if target_psnr is not None and not 10 <= target_psnr <= 200:
        raise ParameterError(f"target PSNR must be within 10..200 dB, got {target_psnr}")
    if target_bpp is not None and not target_bpp > 0:
        raise ParameterError(f"target bpp must be > 0, got {target_bpp}")


def bisect(evaluate, good: float, bad: float, *, iters: int = 9, tol: float = 0.0, better=None):
    """Bisect a monotone knob between a feasible end ``good`` and an infeasible end ``bad``.

    Args:
        evaluate: x → (feasible: bool, payload).
        good, bad: knob values (either order); ``evaluate`` is called at both ends first.
        iters: at most this many midpoints; tol: stop when |good − bad| <= tol.
        better: optional (payload, payload) → bool, whether a new feasible payload replaces
            the best so far (default: always — the one nearest the edge).

    Returns:
        (found, best_x, best_payload, last_payload): ``found`` False when even ``good`` is
        infeasible (then best is ``good``'s evaluation, the closest there is).
    """
    ok, pay = evaluate(good)
    if not ok:
        return False, good, pay, pay
    best = (good, pay)
    ok_bad, pay_bad = evaluate(bad)
    if ok_bad:
        return True, bad, pay_bad, pay_bad
    last = pay_bad
    for _ in range(iters):
        if abs(good - bad) <= tol:
            break
        mid = (good + bad) / 2
        ok, pay = evaluate(mid)
        last = pay
        if ok:
            good = mid
            if better is None or better(pay, best[1]):
                best = (mid, pay)
        else:
            bad = mid
    return True, best[0], best[1], last


def params_for_quant(base: RlfcParams, q: float, fixed_threshold: float | None = None,
                     fixed_energy: float | None = None) -> RlfcParams:
    """Parameters for quantizer step ``q`` with the coupled thresholds (Q=1 is lossless)."""
    q = max(1.0, round(q * 16) / 16)
    t = fixed_threshold if fixed_threshold is not None else (0.0 if q <= 1 else q / 2)
    e = fixed_energy if fixed_energy is not None else (0.0 if q <= 1 else (q / 2) ** 2)
    return replace(base, quant=q, threshold=t, energy=e)


def loop_psnr(enc, res) -> float:
    """Colour PSNR of a closed-loop result against the encoder's views."""
    return psnr_rgb(enc.lf.views, enc.decoded_views(res))


def search_quant(enc, base: RlfcParams, *, target_psnr: float | None = None, target_bpp: float | None = None,
                 fixed_threshold: float | None = None, fixed_energy: float | None = None, iters: int = 9,
                 meta_bytes: int = 4096, progress=None):
    """Find the quantizer meeting a target; returns (found, params, loop result, trace).

    Args:
        enc: a key-tree encoder (``closed_loop``, ``pack``, ``decoded_views``).
        target_psnr: colour PSNR floor in dB; or target_bpp: bpp ceiling (whole file).
        meta_bytes: estimate of the container + metadata overhead counted in bpp.
        progress: optional callable(step, params, psnr, bpp).

    Returns:
        found (False: even the best end misses the target; the closest is returned), params,
        its closed-loop result (with blocks), trace: list of {quant, psnr_rgb, bpp} dicts.
    """
    if (target_psnr is None) == (target_bpp is None):
        raise ParameterError("give exactly one of target_psnr and target_bpp")
    check_targets(target_psnr, target_bpp)
    lf = enc.lf
    nv = lf.rows * lf.cols
    trace = []

    def evaluate(logq):
        p = params_for_quant(base, 2 ** logq, fixed_threshold, fixed_energy)
        res = enc.closed_loop(p, keep_blocks=target_bpp is not None)
        ps = loop_psnr(enc, res)
        b = None
        if target_bpp is not None:
            _, secs = enc.pack(p, res)
            b = bpp_of(sum(len(s) for _, s in secs) + meta_bytes, nv, lf.height, lf.width)
        trace.append({"quant": p.quant, "psnr_rgb": ps, "bpp": b})
        if progress:
            progress(len(trace), p, ps, b)
        ok = ps >= target_psnr if target_psnr is not None else b <= target_bpp
        return ok, (p, res, ps)

    # PSNR target: feasible at fine steps, find the largest feasible Q.
    # bpp target: feasible at coarse steps, find the smallest feasible Q (best quality seen).
    fine, coarse = 0.0, math.log2(Q_MAX * depth_scale(lf.views.dtype))
    good, bad = (fine, coarse) if target_psnr is not None else (coarse, fine)
    better = None if target_psnr is not None else (lambda new, old: new[2] >= old[2])
    found, _, (p, res, _), _ = bisect(evaluate, good, bad, iters=iters, tol=0, better=better)
    if target_bpp is None or not res.levels:     # the PSNR search ran without keeping blocks
        res = enc.closed_loop(p)
    return found, p, res, trace
