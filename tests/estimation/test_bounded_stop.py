"""The statistical stop at bounds: which parameter a Gauss-Newton step carries at once through
a bound (`gauss_newton.bound_reached`), and the chi-square decrease measured along a step that
leaves the bounds (`gauss_newton.measured_decrement`), on linear least squares whose answers
are known in closed form."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse as sp

from cpas_ocp.estimation.gauss_newton import bound_reached, gauss_newton, measured_decrement
from cpas_ocp.estimation.kkt_system import Linearisation

# r(z) = z - target, unconstrained: the Gauss-Newton step goes to the target, and the
# decrement is |z - target|^2 (chi-square falls by D a (2 - a) to the fraction a of it).
TARGET = np.array([1.0, -2.0])
ALL = np.arange(2)  # both coordinates are free parameters


def linearised(z: np.ndarray, held: tuple[int, ...] = ()) -> Linearisation:
    return Linearisation(z, z - TARGET, sp.identity(2, format="csc"),
                         sp.csc_matrix((0, 2)), np.zeros(0), np.zeros(0, dtype=bool),
                         held=np.array(held, dtype=int))


def residual(z: np.ndarray) -> np.ndarray:
    return z - TARGET


def test_a_parameter_the_step_carries_at_once_through_its_bound_is_reached() -> None:
    # The first coordinate sits 1e-6 inside its upper bound 0.5 with the target at 1: the
    # step crosses the bound at a = 2e-6 of it, where less than 0.01 is to be had.
    z = np.array([0.5 - 1e-6, -1.0])
    lower, upper = np.array([-5.0, -5.0]), np.array([0.5, 5.0])
    lin = linearised(z)
    gn = gauss_newton(lin)
    assert gn.decrement == pytest.approx(0.5**2 + 1.0**2)
    assert bound_reached(lin, gn, lower, upper, tol=0.01, coordinates=ALL) == (0, 0.5)
    # Held there, the decrement is what the other coordinate offers.
    on_face = gauss_newton(linearised(np.array([0.5, -1.0]), held=(0,)))
    assert on_face.decrement == pytest.approx(1.0)
    assert on_face.step[0] == 0.0


def test_a_bound_with_more_than_the_tolerance_before_it_is_not_reached() -> None:
    # 0.1 from the bound: a = 0.2 of the step, D a (2 - a) = 0.45 > 0.01.
    z = np.array([0.4, -2.0])
    lin = linearised(z)
    gn = gauss_newton(lin)
    assert bound_reached(lin, gn, np.full(2, -5.0), np.array([0.5, 5.0]), tol=0.01,
                         coordinates=ALL) is None
    # Nor one that is not among the coordinates offered (a state, a captured speed).
    near = linearised(np.array([0.5 - 1e-6, -1.0]))
    assert bound_reached(near, gauss_newton(near), np.full(2, -5.0), np.array([0.5, 5.0]),
                         tol=0.01, coordinates=np.array([1])) is None
    # A held coordinate is never reached, nor one whose step points away from its bound.
    held = linearised(np.array([0.5 - 1e-6, -1.0]), held=(0,))
    assert bound_reached(held, gauss_newton(held), np.full(2, -5.0), np.array([0.5, 5.0]),
                         tol=0.01, coordinates=ALL) is None
    away = linearised(np.array([0.5 - 1e-6, -1.0]))
    assert bound_reached(away, gauss_newton(away), np.array([0.5 - 2e-6, -5.0]),
                         np.array([5.0, 5.0]), tol=0.01, coordinates=ALL) is None


def test_the_measured_decrease_stops_at_the_bounds() -> None:
    z = np.array([0.0, -2.0])
    lin = linearised(z)
    gn = gauss_newton(lin)  # D = 1, and chi-square is exactly quadratic: c = D
    assert measured_decrement(residual, lin, gn) == pytest.approx(1.0)
    box = (np.array([-5.0, -5.0]), np.array([0.5, 5.0]))

    # A residual with no slope at z whose square falls along the step, 1 - a^2 + a^4 / 4:
    # chi-square is flatter than Gauss-Newton's model, -2a + a^4 / 4 from z.  Measured at
    # the step's end, c = 1/4 and D^2 / c = 4; at the bound halfway, c = 1/16 puts the
    # minimum at a = 16, beyond the bound, and the decrement D = 1 stands.
    def flat(x: np.ndarray) -> np.ndarray:
        return np.append(x - TARGET, 1.0 - 0.5 * (x[0] - z[0]) ** 2)

    lin_f = Linearisation(z, flat(z), sp.vstack([sp.identity(2), sp.csr_matrix((1, 2))],
                                                format="csc"),
                          sp.csc_matrix((0, 2)), np.zeros(0), np.zeros(0, dtype=bool))
    gn_f = gauss_newton(lin_f)
    assert gn_f.decrement == pytest.approx(1.0)
    assert measured_decrement(flat, lin_f, gn_f) == pytest.approx(4.0)
    assert measured_decrement(flat, lin_f, gn_f, box) == pytest.approx(1.0)

    # A residual whose chi-square rises steeply past a quarter of the step: measured
    # there (within the bounds), the minimum lies inside them and is D^2 / c.
    def curved(x: np.ndarray) -> np.ndarray:
        return np.append(x - TARGET, 4.0 * (x[0] - z[0]) ** 2)

    lin_c = Linearisation(z, curved(z), sp.vstack([sp.identity(2), sp.csr_matrix((1, 2))],
                                                  format="csc"),
                          sp.csc_matrix((0, 2)), np.zeros(0), np.zeros(0, dtype=bool))
    gn_c = gauss_newton(lin_c)
    b = 0.5
    r_b = curved(z + b * gn_c.step)
    c = (r_b @ r_b - lin_c.r @ lin_c.r + 2.0 * gn_c.decrement * b) / b**2
    assert gn_c.decrement / c < b
    assert measured_decrement(curved, lin_c, gn_c, box) == pytest.approx(gn_c.decrement**2 / c)
    # Without the bound the step's end (outside it) measures a different curvature.
    r_1 = curved(z + gn_c.step)
    c_end = r_1 @ r_1 - lin_c.r @ lin_c.r + 2.0 * gn_c.decrement
    assert measured_decrement(curved, lin_c, gn_c) == pytest.approx(gn_c.decrement**2 / c_end)
    assert c_end != pytest.approx(c)
