"""The quantizer search of rate control: a safeguarded secant on log2(step).

Each evaluation is a whole closed-loop coding pass, so the search counts passes. The measured
quantity (colour PSNR, or log2 bpp) falls with the step, nearly linearly in log2(step) over an
octave or two (measured on the dense grids: 2.2–2.8 dB per octave around 40 dB). From one
point, a step along the prior slope; from two, the secant through the two points nearest the
target; once the target is bracketed, never outside the bracket, and a bisection whenever the
secant stalls (the bracket did not halve). It stops at a feasible point within ``tol`` of the
target, or when the bracket is narrower than ``min_width`` octaves. Compared with bracketing by
half-octaves then bisecting to 1/64 octave, it needs about a third of the passes (BENCHMARKS.md).
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Callable


@dataclass
class SearchResult:
    """found: a feasible point was reached; q, result: the chosen one (else the closest);
    points: every (q, value) evaluated, in order."""

    found: bool
    q: float
    result: Any
    points: list = field(default_factory=list)


def secant_search(evaluate: Callable[[float], tuple[float, Any]], q0: float, target: float, *,
                  feasible_above: bool, slope0: float, lo: float, hi: float, tol: float,
                  min_width: float = 1 / 64, max_evals: int = 14,
                  prefer: Callable[[float, Any, float, Any], bool] | None = None,
                  snap: Callable[[float], float] | None = None) -> SearchResult:
    """Search q in [lo, hi] for ``evaluate(q) = (value, result)``, value decreasing in q.

    Args:
        q0: the first point evaluated.
        target: the value wanted; feasible means value >= target (``feasible_above``, a PSNR
            floor: the largest such q is best) or value <= target (a size ceiling).
        slope0: the prior d value / d q (< 0), used until two points are known and to bound
            the secant's slope to [4·slope0, slope0/4].
        tol: a feasible point with |value - target| <= tol ends the search.
        prefer: prefer(q_new, result_new, q_old, result_old) among feasible points (default:
            the larger q for a floor, the smaller for a ceiling).
        snap: where q is quantized (the coder's step grid: 1/16 units), the grid point that
            codes like q; every point evaluated is snapped, none twice: where the secant lands
            on a point already evaluated, the bracket's middle grid point is taken, or without
            a bracket the next grid point in the secant's direction, and the search ends when
            the bracket has no grid point inside.
    """
    if not slope0 < 0:
        raise ValueError("slope0 must be negative")
    prefer = prefer or ((lambda qn, rn, qo, ro: qn > qo) if feasible_above else (lambda qn, rn, qo, ro: qn < qo))
    aim = target + tol / 2 if feasible_above else target - tol / 2
    pts: list = []                     # (q, value)
    good = bad = None                  # feasible / infeasible q nearest the boundary
    best = None                        # (q, result) preferred feasible
    closest = None                     # (|value - target|, q, result) when nothing is feasible
    width_before = [float("inf"), float("inf")]
    extended = 0                       # steps taken past the points seen, without a bracket
    snap = snap or (lambda q: q)

    def seen(q):
        return any(abs(q - p[0]) < 1e-9 for p in pts)

    def next_point(q, direction):
        """The next grid point from q in ``direction`` (±1), or q at a bound."""
        u = 1 / 1024
        while u < 1:
            qn = snap(min(max(q + direction * u, lo), hi))
            if abs(qn - q) > 1e-9:
                return qn
            u *= 2
        return q

    q = snap(min(max(q0, lo), hi))
    for _ in range(max_evals):
        v, r = evaluate(q)
        pts.append((q, v))
        ok = v >= target if feasible_above else v <= target
        if ok:
            if best is None or prefer(q, r, best[0], best[1]):
                best = (q, r)
            good = q if good is None else (max(good, q) if feasible_above else min(good, q))
            if abs(v - target) <= tol:
                break
        else:
            bad = q if bad is None else (min(bad, q) if feasible_above else max(bad, q))
            if closest is None or abs(v - target) < closest[0]:
                closest = (abs(v - target), q, r)
        if good is not None and bad is not None and abs(good - bad) <= min_width:
            break
        # the next point: a secant through the two points nearest the target
        near = sorted(pts, key=lambda p: abs(p[1] - target))
        slope = slope0
        for p in near[1:]:
            if abs(p[0] - near[0][0]) > 1e-9:
                s = (p[1] - near[0][1]) / (p[0] - near[0][0])
                slope = min(max(s, 4 * slope0), slope0 / 4) if s < 0 else slope0
                break
        qn = near[0][0] + (aim - near[0][1]) / slope
        if good is not None and bad is not None:
            a, b = sorted((good, bad))
            width = b - a
            stalled = width > 0.5 * width_before[1]
            width_before = [width, width_before[0]]
            if not a < qn < b or stalled:
                qn = (a + b) / 2
        want = qn                                          # (unclamped: its side of the nearest point)
        raw = min(max(qn, lo), hi)
        qn = snap(raw)
        if seen(qn):                                       # the grid point is known already
            if good is not None and bad is not None:
                a, b = sorted((good, bad))
                qn = snap((a + b) / 2)
                if not a + 1e-9 < qn < b - 1e-9 or seen(qn):
                    qn = next_point(a, 1)                    # the bracket's first inner point
                    if not qn < b - 1e-9 or seen(qn):
                        break                              # no grid point inside the bracket
            else:
                # no bracket yet: step past every point seen on that side, by the prior slope's
                # jump, doubled each time (points near the target can disagree by their noise:
                # the secant alone would stop there as if at a bound)
                d = 1 if want >= near[0][0] else -1
                ext = max(p[0] for p in pts) if d > 0 else min(p[0] for p in pts)
                jump = max(abs(aim - near[0][1]) / abs(slope0), min_width) * 2.0 ** extended
                extended += 1
                qn = snap(min(max(ext + d * jump, lo), hi))
                if seen(qn) or (qn - ext) * d <= 1e-9:
                    qn = next_point(ext, d)
                    if seen(qn):
                        break                              # nothing new to learn (at a bound)
        q = qn
    if best is not None:
        return SearchResult(True, best[0], best[1], pts)
    return SearchResult(False, closest[1], closest[2], pts)


__all__ = ["SearchResult", "secant_search"]
