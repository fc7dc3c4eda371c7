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
