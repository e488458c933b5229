"""The column-at-a-time boxes and row tests give NumPy's own reductions' values."""

import numpy as np
import pytest

from tiledsimplify.core import bounds


def _arrays():
    rng = np.random.default_rng(0)
    yield rng.normal(size=(1000, 3)) * 1e6
    yield rng.integers(-5, 5, size=(300, 3))
    yield rng.random((1, 3))
    yield rng.random((50, 2))
    yield np.array([[0.0, -0.0, 1.0], [-0.0, 0.0, 1.0]])
    x = rng.random((200, 3))
    x[7, 1] = np.nan
    x[9, 2] = np.inf
    x[11, 0] = -np.inf
    yield x


@pytest.mark.parametrize("X", list(_arrays()))
def test_box_and_row_tests_equal_numpys(X):
    lo, hi = bounds.box(X)
    np.testing.assert_array_equal(lo, X.min(axis=0))
    np.testing.assert_array_equal(hi, X.max(axis=0))
    assert lo.dtype == X.dtype and hi.dtype == X.dtype
    np.testing.assert_array_equal(bounds.extent(X), X.max(axis=0) - X.min(axis=0))
    np.testing.assert_array_equal(bounds.row_min(X), X.min(axis=1))
    np.testing.assert_array_equal(bounds.finite_rows(X), np.isfinite(X).all(axis=1))


def test_an_empty_box_is_refused_as_numpy_refuses_it():
    with pytest.raises(ValueError):
        bounds.box(np.empty((0, 3)))
