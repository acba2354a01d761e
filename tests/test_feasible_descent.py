"""Gauss-Newton descent through feasible points (`cpas_ocp.feasible_descent`) and the stall
rule that hands a creeping Ipopt run to it (`estimation._Monitor`)."""

from __future__ import annotations

import casadi as ca
import numpy as np
import scipy.sparse as sp
from scipy.optimize import minimize_scalar

from cpas_ocp.estimation import STALL_ITERATIONS, STALL_SHARE, _Monitor
from cpas_ocp.feasible_descent import DescentProblem, bounded_step, descend
from cpas_ocp.uncertainty import linearize


def _rosenbrock(z: np.ndarray) -> tuple[np.ndarray, sp.csc_matrix]:
    """Residuals (10 (z1 - z0^2), 1 - z0), whose sum of squares is Rosenbrock's valley."""
    r = np.array([10.0 * (z[1] - z[0] ** 2), 1.0 - z[0]])
    jac = np.array([[-20.0 * z[0], 10.0], [-1.0, 0.0]])
    return r, sp.csc_matrix(jac)


def _unconstrained(residual_jacobian, lower: np.ndarray, upper: np.ndarray) -> DescentProblem:
    """Every coordinate a free parameter, no constraints: each point is feasible."""
    n = len(lower)
    index = np.arange(n)

    def lin(z: np.ndarray):
        return linearize(residual_jacobian, lambda z: (np.zeros(0), sp.csc_matrix((0, n))),
                         z, np.zeros(0), np.zeros(0), index, lower, upper)

    def feasible(z: np.ndarray) -> tuple[np.ndarray, float]:
        r, _ = residual_jacobian(z)
        return z, float(r @ r)

    return DescentProblem(lin, feasible, lambda z: residual_jacobian(z)[0], index, lower, upper)


def test_descent_follows_a_curved_valley_to_its_minimum() -> None:
    problem = _unconstrained(_rosenbrock, np.full(2, -5.0), np.full(2, 5.0))
    z0 = np.array([-1.2, 1.0])
    end = descend(z0, problem.feasible_point(z0)[1], problem, tol=1e-8, max_steps=200)
    assert end.converged and end.decrement < 1e-8
    np.testing.assert_allclose(end.z, [1.0, 1.0], atol=1e-4)
    assert end.chi2 < 1e-8


def test_descent_holds_a_parameter_on_the_bound_it_presses_against() -> None:
    """With z1 <= 0.5 the minimum lies on that bound, at the minimum of the valley's cut."""
    upper = np.array([5.0, 0.5])
    problem = _unconstrained(_rosenbrock, np.full(2, -5.0), upper)
    z0 = np.array([-1.2, 0.4])
    end = descend(z0, problem.feasible_point(z0)[1], problem, tol=1e-10, max_steps=200)
    cut = minimize_scalar(lambda x: 100.0 * (0.5 - x**2) ** 2 + (1.0 - x) ** 2,
                          bounds=(0.0, 2.0), method="bounded", options={"xatol": 1e-10})
    assert end.converged
    assert end.z[1] == 0.5
    assert abs(end.z[0] - cut.x) < 1e-5


def test_a_bound_holds_only_a_step_that_would_cross_it() -> None:
    """On the lower bound of both, a step back inside is taken and one outside is not."""
    def residuals(z: np.ndarray) -> tuple[np.ndarray, sp.csc_matrix]:
        return np.array([z[0] - 1.0, z[1] + 1.0]), sp.identity(2, format="csc")

    problem = _unconstrained(residuals, np.zeros(2), np.full(2, 3.0))
    step = bounded_step(problem.linearize(np.zeros(2)), problem).step
    np.testing.assert_allclose(step, [1.0, 0.0], atol=1e-12)


def test_a_descent_that_cannot_fall_says_so() -> None:
    """At a point that is no minimum but whose feasible neighbours all lie higher (here
    the feasible point always returns a worse value), the descent ends unconverged."""
    base = _unconstrained(_rosenbrock, np.full(2, -5.0), np.full(2, 5.0))
    worse = DescentProblem(base.linearize, lambda z: (z, 1e9), base.residual_value,
                           base.param_index, base.lower, base.upper)
    z0 = np.array([-1.2, 1.0])
    end = descend(z0, 24.2, worse, tol=1e-8, max_steps=50)
    assert not end.converged and end.steps == 0
    np.testing.assert_array_equal(end.z, z0)


def _iterate(monitor: _Monitor, chi2: float, violation: float = 0.0) -> int:
    return int(monitor.eval([ca.DM(0.0), ca.DM(chi2 / 2.0), ca.DM(violation), ca.DM(0.0),
                             ca.DM(0.0), ca.DM(0, 1)])[0])


def test_a_run_that_stops_falling_stalls_and_a_falling_one_does_not() -> None:
    monitor = _Monitor(1, 1, np.abs, lambda z: None, None, stall=STALL_ITERATIONS)
    monitor.reset(False, (np.full(1, -np.inf), np.full(1, np.inf)))
    chi2 = 1000.0
    for _ in range(3 * STALL_ITERATIONS):  # falls by 2 per iteration: progress
        chi2 -= 2.0
        assert _iterate(monitor, chi2) == 0
    for _ in range(STALL_ITERATIONS - 1):  # infeasible iterates far below count for nothing
        assert _iterate(monitor, 10.0, violation=1.0) == 0
    assert _iterate(monitor, 10.0, violation=1.0) == 1 and monitor.stalled
    # Falls that are small against the Gauss-Newton decrement on offer are no progress;
    # twice as fast, they are.
    needed = STALL_SHARE * 300.0  # over STALL_ITERATIONS iterations
    for rate, stalls in ((0.5, True), (2.0, False)):
        monitor.reset(False, (np.full(1, -np.inf), np.full(1, np.inf)))
        monitor.promised = 300.0
        fall = rate * needed / STALL_ITERATIONS
        stops = [_iterate(monitor, 1000.0 - fall * k) for k in range(3 * STALL_ITERATIONS)]
        assert stops[:STALL_ITERATIONS] == [0] * STALL_ITERATIONS
        assert (stops[STALL_ITERATIONS] == 1) is stalls and monitor.stalled is stalls
    # A run told not to stall (a what-if's) does not, and a new run counts afresh.
    monitor.reset(False, (np.full(1, -np.inf), np.full(1, np.inf)), stall=False)
    assert not any(_iterate(monitor, 1000.0) for _ in range(3 * STALL_ITERATIONS))
    assert not monitor.stalled


def test_a_solve_never_inherits_an_earlier_solves_warm_start(problem_folder) -> None:
    """A restart (after a stall, or with wider windows) rebuilds Ipopt warm-started at the
    run's barrier parameter; the next solve of the same estimator starts cold again, also
    where no windows of action rebuild the solver at its start."""
    from cpas_ocp.estimation import Estimator, Settings
    from cpas_ocp.flight_test import load_test

    est = Estimator(load_test(problem_folder("fbcp", 1)), settings=Settings(window_margin=None))
    cold = est.solve()
    est._make_solver(barrier=1e-9)  # what a restart leaves behind
    again = est.solve()
    assert again.solver.iterations == cold.solver.iterations
    assert again.chi_square == cold.chi_square
