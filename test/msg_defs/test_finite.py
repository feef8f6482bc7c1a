"""msg_defs.finite: the checks every message value passes: finite arrays of a shape, finite floats, unit
quaternions (on the 1 kHz path and the general one alike), colours; a refusal names the field."""
import math

import numpy as np
import pytest
from std_msgs.msg import ColorRGBA

from msg_defs.finite import colour_msg, finite_array, finite_floats, unit_quaternion


def test_a_finite_array_takes_any_length_where_the_shape_says_minus_one():
    arr = finite_array([[1, 2, 3], [4, 5, 6]], (-1, 3), "points")
    assert arr.dtype == np.float64 and arr.shape == (2, 3) and arr[1, 2] == 6.0
    assert finite_array(np.zeros((0, 3)), (-1, 3), "points").shape == (0, 3)
    assert finite_array([1.5, 2.5], (2,), "pair", dtype=np.float32).dtype == np.float32


@pytest.mark.parametrize("value, shape, message", [
    ([1.0, 2.0], (3,), r"^position must have shape \(3\), got \(2,\)$"),
    ([[1.0, 2.0]], (-1, 3), r"^position must have shape \(N, 3\), got \(1, 2\)$"),
    ([1.0, 2.0, 3.0], (-1, 3), r"^position must have shape \(N, 3\), got \(3,\)$"),
    ([[0.0, 0.0, 0.0], [0.0, np.nan, 0.0]], (-1, 3),
     r"^position must be finite \(float64\), got nan at index \[1, 1\]$"),
    ([0.0, 0.0, -np.inf], (3,), r"^position must be finite \(float64\), got -inf at index \[2\]$"),
])
def test_a_finite_array_refuses_a_wrong_shape_or_a_non_finite_value_naming_the_field(value, shape, message):
    with pytest.raises(ValueError, match=message):
        finite_array(value, shape, "position")


def test_a_value_beyond_the_dtype_overflows_and_is_refused():
    largest = float(np.finfo(np.float32).max)
    assert finite_array([largest], (1,), "x", dtype=np.float32)[0] == np.float32(largest)
    with pytest.raises(ValueError, match=r"^x must be finite \(float32\), got inf"):
        finite_array([largest * 1.01], (1,), "x", dtype=np.float32)


def test_finite_floats_pass_unchanged_and_refuse_naming_the_field():
    values = (0.1, -2.0, 3e300)
    assert finite_floats(values, (3,), "force") is values
    with pytest.raises(ValueError, match=r"^force must be finite \(float64\), got nan at index \[1\]$"):
        finite_floats((0.0, math.nan, 0.0), (3,), "force")


@pytest.mark.parametrize("quaternion, unit", [
    ((0.0, 0.0, 0.0, 2.0), (0.0, 0.0, 0.0, 1.0)),
    ((1.0, 1.0, 1.0, 1.0), (0.5, 0.5, 0.5, 0.5)),
    ((0.0, -3.0, 0.0, 4.0), (0.0, -0.6, 0.0, 0.8)),
    ((1e-200, 0.0, 0.0, 1e-200), (math.sqrt(0.5), 0.0, 0.0, math.sqrt(0.5))),  # |q|² underflows naively
    ((1.7e308, 0.0, -1.7e308, 0.0), (math.sqrt(0.5), 0.0, -math.sqrt(0.5), 0.0)),  # |q|² overflows naively
])
def test_a_quaternion_is_normalised_alike_from_a_tuple_an_array_and_a_list(quaternion, unit):
    for value in (quaternion, np.array(quaternion), list(quaternion)):
        q = unit_quaternion(value, "orientation")
        assert isinstance(q, np.ndarray) and q.shape == (4,)
        np.testing.assert_allclose(q, unit, rtol=0, atol=1e-15)
        assert math.hypot(*q) == pytest.approx(1.0, abs=1e-15)


@pytest.mark.parametrize("value, message", [
    ((0.0, 0.0, 0.0, 0.0),
     r"^orientation must be a non-zero quaternion \(x, y, z, w\), got \[0\.0, 0\.0, 0\.0, 0\.0\]$"),
    (np.zeros(4), r"^orientation must be a non-zero quaternion"),
    ((0.0, math.nan, 0.0, 1.0), r"^orientation must be finite \(float64\), got nan at index \[1\]$"),
    (np.array([0.0, 0.0, math.inf, 1.0]), r"^orientation must be finite"),
    ((0.0, 0.0, 1.0), r"^orientation must have shape \(4\), got \(3,\)$"),
    ([0.0, 0.0, 0.0, 1.0, 0.0], r"^orientation must have shape \(4\), got \(5,\)$"),
])
def test_a_quaternion_that_is_not_four_finite_non_zero_numbers_is_refused_naming_the_field(value, message):
    with pytest.raises(ValueError, match=message):
        unit_quaternion(value, "orientation")


def test_a_colour_is_four_finite_components_in_order():
    assert colour_msg((0.6, 0.25, 0.2, 1.0)) == ColorRGBA(r=0.6, g=0.25, b=0.2, a=1.0)
    with pytest.raises(ValueError, match=r"^colour must be finite"):
        colour_msg((0.6, 0.25, math.inf, 1.0))
    with pytest.raises(ValueError, match=r"^colour must have shape \(4\)"):
        colour_msg((0.6, 0.25, 0.2))
