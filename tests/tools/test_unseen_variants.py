"""The hard variants of ``tools.unseen`` do what their docstrings say, deterministically, on a
small synthetic grid: a gain per view (exposure), a gain per view and channel (white balance), a
sub-pixel shift per view (jitter), noise per view."""
import numpy as np

from tools.unseen import exposed, jittered, noisy, white_balanced


def _grid():
    rng = np.random.default_rng(0)
    return rng.integers(60, 190, (3, 4, 16, 20, 3)).astype(np.uint8)


def _gains(out, v):
    """Least-squares gain of out against v, per view and channel: (rows, cols, C)."""
    a, b = v.astype(np.float64), out.astype(np.float64)
    return (a * b).sum((2, 3)) / (a * a).sum((2, 3))


def test_exposure_is_one_gain_per_view_and_white_balance_one_per_channel():
    v = _grid()
    e, w = exposed(v), white_balanced(v)
    for out in (e, w):
        assert out.dtype == np.uint8 and out.shape == v.shape
    ge, gw = _gains(e, v), _gains(w, v)
    assert np.abs(ge - ge[..., :1]).max() < 0.01                       # the channels share the view's gain
    assert 0.89 < ge.min() and ge.max() < 1.11 and ge.std() > 0.02
    assert np.abs(gw - gw[..., :1]).max() > 0.02                       # the channels differ
    assert 0.93 < gw.min() and gw.max() < 1.07
    assert (white_balanced(v) == w).all() and (exposed(v) == e).all()   # seeded


def test_jitter_and_noise_keep_the_grid_and_are_seeded():
    v = _grid()
    j, n = jittered(v), noisy(v, 3.0)
    assert j.shape == n.shape == v.shape and j.dtype == n.dtype == np.uint8
    assert (jittered(v) == j).all() and (noisy(v, 3.0) == n).all()
    assert 2.0 < (n.astype(float) - v).std() < 4.0
    assert not (j == v).all() and np.abs(j.astype(float) - v).mean() < 40
