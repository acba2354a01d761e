"""Numbers printed to the precision their uncertainty allows.

A value with a standard deviation sigma is printed with sigma to two significant
digits and the value to the same decimal place: 80.257 ± 0.651 reads
80.26 ± 0.65, 0.29782 ± 0.005386 reads 0.2978 ± 0.0054, 12,345 ± 678 reads
12350 ± 680.  The third digit of a sigma estimated from a finite sample is noise
(a sigma from n residuals is itself uncertain by about 1/sqrt(2n)), and the
value's digits below it say nothing.  These are for people: CSV and JSON files
keep every digit.
"""

from __future__ import annotations

import math

SIGNIFICANT = 2  # significant digits of a sigma
PLAIN = ".4g"  # a value whose sigma says nothing of its precision (none, zero, infinite)
NONE = "—"  # in place of a sigma there is none of
Z95 = 1.959963984540054  # the normal quantile of a two-sided 95 % interval


class Measured(str):
    """The text of a number rounded to its sigma: a string that tables align as a number."""


def decimals(sigma: float | None) -> int | None:
    """Places after the decimal point that show `sigma` to SIGNIFICANT digits (negative:
    the digits left of the point rounded away); None where `sigma` is not a positive,
    finite number.  Taken from the rounded sigma, so 0.0996 shows as 0.10, not 0.100."""
    if sigma is None or not (math.isfinite(sigma) and sigma > 0.0):
        return None
    rounded = float(f"{sigma:.{SIGNIFICANT}g}")
    return SIGNIFICANT - 1 - math.floor(math.log10(rounded))


def _at(value: float, places: int) -> str:
    if places >= 0:
        return f"{value:.{places}f}"
    step = 10.0 ** (-places)  # halves away from zero, as on paper (not to even)
    return f"{math.copysign(math.floor(abs(value) / step + 0.5), value) * step:.0f}"


def rounded(value: float, sigma: float | None) -> Measured:
    """`value` alone, to the decimal place of its `sigma` (to 4 significant digits where
    the sigma gives no place)."""
    places = decimals(sigma)
    if places is None or not math.isfinite(value):
        return Measured(format(value, PLAIN))
    return Measured(_at(value, places))


def sigma_text(sigma: float | None) -> Measured:
    """`sigma` to SIGNIFICANT digits; NONE where there is none."""
    places = decimals(sigma)
    if places is None:
        return Measured(NONE if sigma is None or math.isnan(sigma) else format(sigma, PLAIN))
    return Measured(_at(sigma, places))


def with_sigma(value: float, sigma: float | None) -> Measured:
    """``value ± sigma``, both to the sigma's precision (the value alone where there is no
    sigma)."""
    if decimals(sigma) is None:
        return rounded(value, sigma)
    return Measured(f"{rounded(value, sigma)} ± {sigma_text(sigma)}")


def interval_text(lower: float, upper: float, sigma: float | None) -> Measured:
    """``[lower, upper]``, both ends to the decimal place of `sigma`."""
    return Measured(f"[{rounded(lower, sigma)}, {rounded(upper, sigma)}]")


def interval_sigma(lower: float, upper: float) -> float:
    """The sigma a 95 % interval [lower, upper] stands for (its half-width over 1.96): the
    precision to print a value with only an interval by."""
    return (upper - lower) / (2.0 * Z95)


def with_interval(value: float, lower: float, upper: float) -> tuple[Measured, Measured]:
    """`value` and ``[lower, upper]`` (a 95 % interval) to the precision the interval
    allows (`interval_sigma`)."""
    sigma = interval_sigma(lower, upper)
    return rounded(value, sigma), interval_text(lower, upper, sigma)
