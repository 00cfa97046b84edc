"""The package's shared argument checks."""

import numpy as np
import pytest

from hemg_drake._validate import all_finite, as_scalar, as_seed, as_vector


@pytest.mark.parametrize("value", ["fast", None, [1.0, 2.0]])
def test_a_non_number_is_named(value):
    with pytest.raises(ValueError, match="period must be a number"):
        as_scalar("period", value)


@pytest.mark.parametrize(
    "value, strict", [(0.0, True), (-1.0, False), (np.nan, False), (np.inf, True)]
)
def test_scalar_bounds(value, strict):
    with pytest.raises(ValueError, match="gain must be finite and"):
        as_scalar("gain", value, strict=strict)
    assert as_scalar("gain", 0.0, strict=False) == 0.0


def test_vector_and_seed():
    np.testing.assert_array_equal(as_vector("p", [1, 2, 3], 3), [1.0, 2.0, 3.0])
    with pytest.raises(ValueError, match=r"p must have shape \(3,\)"):
        as_vector("p", [1, 2], 3)
    with pytest.raises(ValueError, match="p must be finite"):
        as_vector("p", [1, np.nan, 3], 3)
    assert as_seed(np.int64(4)) == 4
    for bad in (-1, True, 1.0):
        with pytest.raises(ValueError, match="seed must be a non-negative integer"):
            as_seed(bad)
    assert all_finite([0.0, 1.0]) and not all_finite([0.0, np.inf])
