"""Gauss-Newton descent through feasible points (`estimation.feasible_descent`) and the stall
rule that hands a creeping Ipopt run to it (`estimation.IterationMonitor`)."""

from __future__ import annotations

from itertools import pairwise

import casadi as ca
import numpy as np
import pytest
import scipy.sparse as sp
from scipy.optimize import minimize_scalar

from cpas_ocp.estimation.feasible_descent import DescentProblem, bounded_step, descend
from cpas_ocp.estimation.kkt_system import linearise
from cpas_ocp.estimation.solve import (
    AFTER_DESCENT_STALLS,
    MAX_DESCENTS,
    STALL_GAIN,
    STALL_ITERATIONS,
    STALL_SHARE,
    IterationMonitor,
    _Run,
)
from cpas_ocp.estimation.structured_secant import StructuredSecant


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
        return linearise(residual_jacobian, lambda z: (np.zeros(0), sp.csc_matrix((0, n))),
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


def test_every_step_taken_is_told_with_its_lower_chi_square() -> None:
    """The progress a long descent shows: one call per step, numbered, chi-square falling."""
    problem = _unconstrained(_rosenbrock, np.full(2, -5.0), np.full(2, 5.0))
    z0 = np.array([-1.2, 1.0])
    told: list[tuple[int, float]] = []
    start = problem.feasible_point(z0)[1]
    end = descend(z0, start, problem, tol=1e-8, max_steps=200,
                  step_taken=lambda k, chi2: told.append((k, chi2)))
    assert [k for k, _ in told] == list(range(1, end.steps + 1))
    chi2 = [start] + [c for _, c in told]
    assert all(b < a for a, b in pairwise(chi2))
    assert told[-1][1] == end.chi2


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
    step = bounded_step(problem.linearise(np.zeros(2)), problem).step
    np.testing.assert_allclose(step, [1.0, 0.0], atol=1e-12)


def test_a_descent_that_cannot_fall_says_so() -> None:
    """At a point that is no minimum but whose feasible neighbours all lie higher (here
    the feasible point always returns a worse value), the descent ends unconverged."""
    base = _unconstrained(_rosenbrock, np.full(2, -5.0), np.full(2, 5.0))
    worse = DescentProblem(base.linearise, lambda z: (z, 1e9), base.residual_value,
                           base.param_index, base.lower, base.upper)
    z0 = np.array([-1.2, 1.0])
    end = descend(z0, 24.2, worse, tol=1e-8, max_steps=50)
    assert not end.converged and end.steps == 0
    np.testing.assert_array_equal(end.z, z0)


def _iterate(monitor: IterationMonitor, chi2: float, violation: float = 0.0) -> int:
    return int(monitor.eval([ca.DM(0.0), ca.DM(chi2 / 2.0), ca.DM(violation), ca.DM(0.0),
                             ca.DM(0.0), ca.DM(0, 1)])[0])


def test_a_run_that_stops_falling_stalls_and_a_falling_one_does_not() -> None:
    monitor = IterationMonitor(1, 1, np.abs, lambda z: None, None, stall=STALL_ITERATIONS)
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


def test_a_run_going_on_after_a_failed_descent_gets_a_fresh_count_then_stalls() -> None:
    """After a descent that did not finish a stalled run, Ipopt goes on from its iterate:
    its iterations without progress are counted afresh from there, any fall of STALL_GAIN
    is progress (the decrement found before the descent no longer counts), and a run that
    makes none in AFTER_DESCENT_STALLS times STALL_ITERATIONS more stalls again (where it
    cycled to its cap before)."""
    monitor = IterationMonitor(1, 1, np.abs, lambda z: None, None, stall=STALL_ITERATIONS)
    box = (np.full(1, -np.inf), np.full(1, np.inf))
    monitor.reset(False, box)
    stops = [_iterate(monitor, 500.0) for _ in range(2 * STALL_ITERATIONS)]
    assert stops.index(1) == STALL_ITERATIONS and monitor.stalled
    patience = AFTER_DESCENT_STALLS * STALL_ITERATIONS
    done = STALL_ITERATIONS + 1
    monitor.reset(False, box, None, done)  # the run goes on from the stalled iterate
    monitor.count_progress_from(done)
    stops = [_iterate(monitor, 500.0) for _ in range(2 * patience)]
    assert stops.index(1) == patience - 1 and monitor.stalled
    # Falls of 2 per STALL_ITERATIONS / 2 iterations keep it going, small as they are
    # against the decrement on offer.
    monitor.reset(False, box, None, done)
    monitor.count_progress_from(done)
    monitor.promised = 300.0
    fall = 2.0 * STALL_GAIN / (STALL_ITERATIONS // 2)
    assert not any(_iterate(monitor, 500.0 - fall * k) for k in range(3 * patience))


def test_a_solve_never_inherits_an_earlier_solves_warm_start(problem_folder) -> None:
    """A restart (after a stall, or with wider windows) rebuilds Ipopt warm-started at the
    run's barrier parameter; the next solve of the same estimator starts cold again, also
    where no windows of action rebuild the solver at its start."""
    from cpas_ocp.estimation.estimator import Estimator, Settings
    from cpas_ocp.io.flight_test import load_test

    est = Estimator(load_test(problem_folder("fbcp", 1)), settings=Settings(window_margin=None))
    cold = est.solve()
    est.solver.make_solver(barrier=1e-9)  # what a restart leaves behind
    again = est.solve()
    assert again.solver.iterations == cold.solver.iterations
    assert again.chi_square == cold.chi_square


def _bent_valley(lam: float):
    """Four residuals in two coordinates with curvature lam, least squares 4 at the origin
    (Dennis & Schnabel's example 10.2.4 made two-dimensional and coupled): residuals
    that stay large at the minimum, whose curvature Gauss-Newton leaves out."""
    def residuals(z: np.ndarray) -> tuple[np.ndarray, sp.csc_matrix]:
        x, y = z
        r = np.array([x + 1.0, lam * (x * x + y * y) + x - 1.0, y + 1.0,
                      lam * x * y + y - 1.0])
        jac = np.array([[1.0, 0.0], [2.0 * lam * x + 1.0, 2.0 * lam * y], [0.0, 1.0],
                        [lam * y, lam * x + 1.0]])
        return r, sp.csc_matrix(jac)
    return residuals


def test_a_large_residual_descent_learns_the_curvature_gauss_newton_leaves_out() -> None:
    """With lam = 0.6 Gauss-Newton converges only linearly; the steps that learn the
    residuals' curvature (`structured_secant`) reach the same minimum in fewer than half
    as many steps."""
    problem = _unconstrained(_bent_valley(0.6), np.full(2, -5.0), np.full(2, 5.0))
    z0 = np.array([1.5, -1.0])
    ends = {learn: descend(z0, problem.feasible_point(z0)[1], problem, tol=1e-10,
                           max_steps=200, learn=learn) for learn in (False, True)}
    assert all(end.converged for end in ends.values())
    for end in ends.values():
        np.testing.assert_allclose(end.z, [0.0, 0.0], atol=1e-4)
        assert abs(end.chi2 - 4.0) < 1e-8
    assert 2 * ends[True].steps < ends[False].steps


def test_the_secant_update_meets_the_structured_secant_condition() -> None:
    """After a step s the learnt S is symmetric and S s = (G+ - G)' r+ exactly."""
    rng = np.random.default_rng(7)
    secant = StructuredSecant()
    columns = np.array([0, 2, 3])
    before = None
    updated = 0
    for _ in range(6):
        z, G, r = rng.normal(size=5), rng.normal(size=(8, 3)), rng.normal(size=8)
        secant.observe(z, columns, G, r)
        if before is not None:
            z0, G0, r0 = before
            s, y = z[columns] - z0[columns], G.T @ r - G0.T @ r0
            if y @ s > 0.0:  # else nothing is learnt from the step
                np.testing.assert_allclose(secant.S @ s, (G - G0).T @ r, atol=1e-10)
                updated += 1
        np.testing.assert_allclose(secant.S, secant.S.T, atol=1e-12)
        before = (z, G, r)
    assert updated >= 2


def test_a_step_along_a_steep_feasible_curve_ends_where_the_curve_offers_nothing() -> None:
    """The residual z - 1 promises a fall of 1 from 0, but along the feasible curve chi-square
    is (z - 1)^2 + K z^2: its least value lies 1 / (1 + K) below.  With K = 1e4 that is
    below the tolerance, which two trials on the curve's parabola show; halving alone
    never finds a lower point and gives up."""
    K = 1e4

    def residual(z: np.ndarray) -> tuple[np.ndarray, sp.csc_matrix]:
        return np.array([z[0] - 1.0]), sp.csc_matrix(np.ones((1, 1)))

    base = _unconstrained(residual, np.full(1, -5.0), np.full(1, 5.0))
    steep = DescentProblem(base.linearise, lambda z: (z, (z[0] - 1.0) ** 2 + K * z[0] ** 2),
                           base.residual_value, base.param_index, base.lower, base.upper)
    z0 = np.zeros(1)
    learnt = descend(z0, 1.0, steep, tol=1e-3, max_steps=10, learn=True)
    assert learnt.converged and learnt.steps == 0
    assert learnt.decrement == pytest.approx(1.0 / (1.0 + K), rel=1e-6)
    np.testing.assert_array_equal(learnt.z, z0)
    halved = descend(z0, 1.0, steep, tol=1e-3, max_steps=10, learn=False)
    assert not halved.converged and halved.steps == 0


def test_a_run_descends_again_only_where_it_has_gone_lower_since_the_last_descent() -> None:
    """The first stall descends; a stall after a descent that did not finish the run
    descends again only from STALL_GAIN below where that descent left it, and at most
    MAX_DESCENTS times in all."""
    run = _Run()
    assert run.may_descend(2689.0)
    run.stalls, run.after_descent_chi2 = 1, 2656.68
    assert not run.may_descend(2656.68 - 0.5 * STALL_GAIN)
    assert run.may_descend(2648.24)
    run.stalls = MAX_DESCENTS
    assert not run.may_descend(1.0)
