"""Numbers to the precision their sigma allows (`cpas_ocp.precision`)."""

from __future__ import annotations

import math

import pytest

from cpas_ocp.precision import NONE, interval_text, rounded, sigma_text, with_sigma


@pytest.mark.parametrize(("value", "sigma", "text"), [
    (80.257, 0.651, "80.26 ± 0.65"),
    (0.29782, 0.005386, "0.2978 ± 0.0054"),
    (1.0177, 0.00859, "1.0177 ± 0.0086"),
    (12345.0, 678.0, "12350 ± 680"),
    (3.14159, 0.0996, "3.14 ± 0.10"),  # a sigma that rounds up to a new digit
    (-0.5, 2.5, "-0.5 ± 2.5"),
    (42.0, 0.0, "42"),
    (0.02104, 0.00123, "0.0210 ± 0.0012"),
    (1234.0, 152.0, "1230 ± 150"),  # no sigma to round to: four significant digits
])
def test_a_value_is_rounded_to_two_digits_of_its_sigma(value: float, sigma: float,
                                                        text: str) -> None:
    assert with_sigma(value, sigma) == text


def test_values_without_a_sigma_and_intervals() -> None:
    assert rounded(80.257, None) == "80.26"
    assert rounded(80.257, math.inf) == "80.26"
    assert sigma_text(None) == NONE and sigma_text(math.nan) == NONE
    assert sigma_text(0.651) == "0.65"
    assert interval_text(78.98, 81.53, 0.651) == "[78.98, 81.53]"
