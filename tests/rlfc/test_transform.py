"""The tx profile's 8×8 integer inverse transform: the float64 products decoders run (numpy, and
torch on any device) give the integers of its definition exactly, up to the coefficient bound."""
import numpy as np
import pytest
import torch

from rlfc.transform import COEF_MAX, T8, inverse, inverse_float


def _definition(X: np.ndarray) -> np.ndarray:
    """((Tᵀ X + 64) >> 7) T + 128) >> 8 in int64, arithmetic shifts."""
    Y = (np.matmul(T8.T, X) + 64) >> 7
    return (np.matmul(Y, T8) + 128) >> 8


@pytest.mark.parametrize("bound", [1, 40, 4096, COEF_MAX])
def test_inverse_float_gives_the_integer_definition(bound):
    rng = np.random.default_rng(bound)
    X = rng.integers(-bound, bound + 1, (3000, 8, 8)).astype(np.int64)
    X[:500] *= rng.random((500, 8, 8)) < 0.1                     # sparse blocks, as most are
    X[500:510] = np.where(rng.random((10, 8, 8)) < 0.5, bound, -bound)   # every coefficient at the bound
    ref = _definition(X)
    assert np.array_equal(inverse(X), ref)
    assert np.array_equal(inverse_float(X.astype(np.float64)).astype(np.int64), ref)
    got = inverse_float(torch.from_numpy(X.astype(np.float64)))
    assert got.dtype == torch.float64 and np.array_equal(got.numpy().astype(np.int64), ref)


@pytest.mark.parametrize("bound", [COEF_MAX, (1 << 40) - 1])
def test_inverse_float_is_exact_where_every_sum_is_largest(bound):
    """Each output sample driven to its largest magnitude (every coefficient at the bound with the
    sign of its basis product there): the float64 products stay exact integers (the numpy path
    folds the shifts into its matrices)."""
    T = T8.astype(np.int64)
    X = np.array([bound * np.sign(np.outer(T[:, i], T[:, j])) for i in range(8) for j in range(8)], np.int64)
    X = np.concatenate([X, -X])
    ref = _definition(X)
    assert np.abs(ref).max() > bound // 2
    assert np.array_equal(inverse_float(X.astype(np.float64)).astype(np.int64), ref)
    got = inverse_float(torch.from_numpy(X.astype(np.float64)))
    assert np.array_equal(got.numpy().astype(np.int64), ref)
