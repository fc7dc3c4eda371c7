"""The safeguarded secant of rate control: few passes, the best feasible point, honest misses."""
import math

import numpy as np
import pytest

from rlfc.ratesearch import secant_search


def _psnr_curve(noise=0.0, slope=-2.5, seed=0):
    rng = np.random.default_rng(seed)
    calls = []

    def f(q):
        calls.append(q)
        return 48.0 + slope * q + noise * rng.standard_normal(), {"q": q}
    return f, calls


@pytest.mark.parametrize("slope", [-1.5, -2.5, -4.0])
def test_floor_reached_in_few_passes(slope):
    f, calls = _psnr_curve(slope=slope)
    r = secant_search(f, 1.0, 40.0, feasible_above=True, slope0=-2.5, lo=0, hi=9, tol=0.03)
    assert r.found and 40.0 <= 48 + slope * r.q <= 40.03 + 1e-9
    assert len(calls) <= 4                    # bracket-then-bisect to 1/64 octave needs ~11


def test_noisy_curve_still_ends_feasible_and_bounded():
    f, calls = _psnr_curve(noise=0.05, seed=3)
    r = secant_search(f, 0.5, 40.0, feasible_above=True, slope0=-2.5, lo=0, hi=9, tol=0.03, max_evals=14)
    assert r.found and len(calls) <= 14
    assert all(v >= 40.0 for q, v in r.points if q == r.q)


def test_ceiling_prefers_the_smallest_feasible_step():
    def f(q):                                  # log2 bpp falls 1 per octave
        return -1.0 - q, q
    r = secant_search(f, 0.0, math.log2(0.05), feasible_above=False, slope0=-1.0, lo=0, hi=9, tol=0.01)
    assert r.found and -1.0 - r.q <= math.log2(0.05) and -1.0 - r.q >= math.log2(0.05) - 0.011


def test_unreachable_target_returns_the_closest_and_not_found():
    f, calls = _psnr_curve()
    r = secant_search(f, 3.0, 60.0, feasible_above=True, slope0=-2.5, lo=0, hi=9, tol=0.03)
    assert not r.found and r.q == 0 and len(calls) <= 3


def test_bad_prior_slope_is_refused():
    with pytest.raises(ValueError):
        secant_search(lambda q: (0, 0), 0, 1, feasible_above=True, slope0=1.0, lo=0, hi=1, tol=0.1)


def _grid(unit):
    """Snap log2(step) to steps that are multiples of ``unit`` (the coder's 1/16 grid)."""
    return lambda q: math.log2(max(unit, round(2.0 ** q / unit) * unit))


@pytest.mark.parametrize("seed", range(6))
def test_snapped_search_never_evaluates_a_grid_point_twice(seed):
    """The coder's steps are quantized: a search that snaps its points evaluates each grid point
    once, only grid points, and ends feasible next to an infeasible neighbour (or within tol)."""
    rng = np.random.default_rng(seed)
    unit = 1 / 16
    snap = _grid(unit)
    off = rng.uniform(-0.5, 0.5)
    jitter = {}

    def f(q):                                  # a staircase: value depends on the grid point only
        s = round(2.0 ** q / unit)
        jitter.setdefault(s, 0.02 * rng.standard_normal())
        return 40.0 + off - 6.0 * (math.log2(s * unit) - 3.4) + jitter[s], s
    r = secant_search(f, 3.0, 40.0, feasible_above=True, slope0=-2.5, lo=0, hi=9, tol=0.03, snap=snap)
    steps = [round(2.0 ** q / unit) for q, _ in r.points]
    assert len(steps) == len(set(steps))                       # no grid point twice
    assert all(abs(q - snap(q)) < 1e-12 for q, _ in r.points)  # only grid points
    assert r.found and f(r.q)[0] >= 40.0
    s = round(2.0 ** r.q / unit)
    done = dict(zip(steps, (v for _, v in r.points)))
    assert f(r.q)[0] - 40.0 <= 0.03 or (s + 1 in done and done[s + 1] < 40.0)


def test_snapped_search_moves_off_a_known_point_without_a_bracket():
    """A secant step smaller than half a grid unit must still move (one unit), not stop short."""
    unit = 1 / 2                               # a coarse grid: one unit at step 8 is 0.17 octave
    snap = _grid(unit)
    calls = []

    def f(q):                                  # 0.005 dB short at step 8; one unit finer meets it
        s = round(2.0 ** q / unit)
        calls.append(s)
        return (39.995 if s >= 16 else 40.3), s
    r = secant_search(f, 3.0, 40.0, feasible_above=True, slope0=-2.5, lo=0, hi=9, tol=0.03, snap=snap)
    assert calls[:2] == [16, 15]               # the secant's step (0.008 octave) snaps back to 16
    assert r.found and round(2.0 ** r.q / unit) == 15


def test_points_that_disagree_near_the_target_do_not_end_the_search():
    """The bundled dino_crop at 36 dB with a JPEG 2000 key (2026-11-26): steps 58.1, 57.3 and 58.1
    − 1/16 all gave 35.90–35.97 dB, the finer one lower. The secant through them pointed back at
    points already seen and the search stopped as if at a bound: "the finest quantizer misses",
    and the CLI wrote a lossless file of 1.5 MB. Without a bracket it now steps past the points
    seen, by jumps that double, until it finds a feasible step."""
    edge = math.log2(56.6)
    calls = []

    def f(q):                                   # a plateau just under 36 dB above step 56.6
        calls.append(q)
        v = 36.02 + 2.5 * (edge - q) if q <= edge else 35.93 + 0.03 * math.sin(400 * q)
        return v, {"q": q}
    r = secant_search(f, math.log2(58.125), 36.0, feasible_above=True, slope0=-2.5, lo=0, hi=9, tol=0.03,
                      snap=_grid(1 / 16))
    assert r.found and r.q <= edge and f(r.q)[0] >= 36.0
    assert len(calls) <= 10
