"""`association.inputs._ranks_of`: the canonical ranks of a scan's rows by the small-problem
kernel are np.lexsort's (`_ranks`), ties, NaNs and signed zeros included."""

from __future__ import annotations

import numpy as np
import pytest

from association.inputs import _KERNEL_RANKS, _ranks, _ranks_of


@pytest.mark.parametrize("seed", range(20))
@pytest.mark.parametrize("size", ["drawn", 0, 1, 2])
def test_kernel_ranks_are_lexsort_ranks(seed, size):
    """Rows drawn from few values (so many columns tie and whole rows repeat), with NaN and
    -0.0 among them: the kernel's ranks equal the lexsort's, row for row, for a drawn number
    of rows and for none, one and two."""
    rng = np.random.default_rng(seed)
    k = int(rng.integers(0, _KERNEL_RANKS + 1)) if size == "drawn" else size
    values = np.array([-1.0, -0.0, 0.0, 0.5, 2.0, np.nan])
    a = values[rng.integers(0, values.size, (k, 2))]
    b = values[rng.integers(0, values.size, (k, 4))]
    want = _ranks(np.column_stack([a, b]))
    got = _ranks_of(a, b)
    assert got.dtype == np.int64
    np.testing.assert_array_equal(got, want)


def test_many_rows_take_the_lexsort():
    """Beyond the kernel's size the answer is still the lexsort's."""
    rng = np.random.default_rng(1)
    a, b = rng.normal(size=(3 * _KERNEL_RANKS, 2)), rng.normal(size=(3 * _KERNEL_RANKS, 4))
    a[::7] = a[0]
    b[::7] = b[0]
    np.testing.assert_array_equal(_ranks_of(a, b), _ranks(np.column_stack([a, b])))
