"""Ipopt's functions from one evaluation per point give what CasADi's expressions gave, the
parameters' windows of action leave out only entries that are zero, and the Marquardt
damping reacts to the progress the steps make."""

from __future__ import annotations

import dataclasses

import casadi as ca
import numpy as np
import pytest
import scipy.sparse as sp

from cpas_ocp.estimation.estimator import STATISTICALLY_CONVERGED, Estimator, Settings
from cpas_ocp.estimation.nlp_functions import MarquardtDamping
from cpas_ocp.estimation.simulate import simulate_problem
from cpas_ocp.estimation.solve import IterationMonitor
from cpas_ocp.io.flight_test import load_test
from cpas_ocp.io.model_spec import baseline_spec
from cpas_ocp.io.problems import load_problem
from cpas_ocp.physics.effects import AddedMass, baseline_effects

pytestmark = pytest.mark.slow

FUNCTIONS = ("nlp_f", "nlp_g", "nlp_grad_f", "nlp_jac_g", "nlp_hess_l")


@pytest.fixture(scope="module")
def estimators(drogue_folder):
    test = load_test(drogue_folder(1))
    return (Estimator(test, settings=Settings(point_cache=False)),
            Estimator(test, settings=Settings(window_margin=None, levenberg=None)))


def _outputs(est: Estimator, name: str, z: np.ndarray, lam: np.ndarray) -> list[ca.DM]:
    fn = est.ipopt.get_function(name)
    args = [z, np.zeros(0)] + ([0.7, lam] if name == "nlp_hess_l" else [])
    out = fn(*args)
    return list(out) if isinstance(out, tuple | list) else [out]


def test_cached_functions_equal_the_expressions(estimators) -> None:
    old, new = estimators
    z = new.initial_point()
    z = z * (1.0 + 1e-3 * np.random.default_rng(3).standard_normal(z.size))  # off the guess
    lam = np.random.default_rng(4).standard_normal(new.transcription.g.numel())
    for name in FUNCTIONS:
        expected, got = _outputs(old, name, z, lam), _outputs(new, name, z, lam)
        for a, b in zip(expected, got, strict=True):
            # The same pattern (the one promised to Ipopt), the same nonzeros.
            assert a.sparsity() == b.sparsity(), name
            x, y = np.asarray(a.nonzeros()), np.asarray(b.nonzeros())
            np.testing.assert_allclose(y, x, rtol=1e-10, atol=1e-10 * max(np.abs(x).max(), 1.0),
                                       err_msg=name)


def test_levenberg_term_is_on_the_parameters_diagonal_only(estimators) -> None:
    """The Levenberg term adds sigma delta to the Hessian's diagonal at the free parameters'
    columns and nothing anywhere else."""
    _, est = estimators
    z = est.initial_point()
    lam = np.zeros(est.transcription.g.numel())
    plain = ca.DM(est.ipopt.get_function("nlp_hess_l")(z, np.zeros(0), 0.7, lam))
    est.settings.levenberg = 2.0
    try:
        est.solver.make_solver()
        damped = ca.DM(est.ipopt.get_function("nlp_hess_l")(z, np.zeros(0), 0.7, lam))
    finally:
        est.settings.levenberg = None
        est.solver.make_solver()
    difference = damped - plain
    rows, cols = (np.asarray(i) for i in difference.sparsity().get_triplet())
    values = np.asarray(difference.nonzeros())
    changed = np.abs(values) > 1e-9 * np.abs(np.asarray(plain.nonzeros())).max()
    assert np.array_equal(rows[changed], cols[changed])
    assert set(rows[changed]) == set(est.transcription.param_index)
    np.testing.assert_allclose(values[changed], 0.7 * 2.0)


def test_each_point_is_evaluated_once(estimators) -> None:
    _, est = estimators
    z = est.initial_point() + 1e-4
    before = dict(est.transcription.points.evaluations)
    lam = np.zeros(est.transcription.g.numel())
    for name in FUNCTIONS:
        _outputs(est, name, z, lam)
    est.evaluate(z)  # the statistical test's linearisation of the same point
    made = {k: est.transcription.points.evaluations[k] - before[k] for k in before}
    # Values come from the Jacobian evaluation once one exists; nlp_f and nlp_g ran first.
    assert made == {"r": 1, "rJ": 1, "g": 1, "gA": 1}


def test_windows_leave_out_only_zeros_and_keep_their_promise(drogue_folder) -> None:
    """At the start, every entry left out of Ipopt's constraint Jacobian and Hessian is an
    exact zero, so Ipopt's functions equal the whole pattern's there; and a solve whose
    start times move further than the margin widens the windows and ends where the whole
    pattern's solve ends."""
    test = load_test(drogue_folder(1))
    whole = Estimator(test, settings=Settings(window_margin=None))
    est = Estimator(test, settings=Settings(nodes=whole.settings.nodes,
                                            interval_steps=whole.settings.interval_steps))
    z = whole.initial_point()
    est.solver.fit_windows(z)
    lam = np.random.default_rng(4).standard_normal(est.transcription.g.numel())
    kept = est.transcription.windows.keep
    assert 0.1 < kept[0].mean() < 0.5 and 0.1 < kept[1].mean() < 0.5  # most are left out
    for name in ("nlp_jac_g", "nlp_hess_l"):
        expected, got = (_outputs(e, name, z, lam)[-1].sparse() for e in (whole, est))
        assert got.nnz < expected.nnz, name
        assert abs(expected - got).max() <= 1e-9 * abs(expected).max(), name

    # Start times 0.8 s early, beyond the 0.5 s margin: the second stages' parameters
    # act where the first windows did not reach.
    starts = [n for n in est.free if n.startswith("t_start[") and "stage2" in n]
    z0 = z.copy()
    for name in starts:
        z0 = est.with_value(z0, name, est.free_values(z0)[name] - 0.8)
    fit, reference = est.solve(start=z0), whole.solve(start=z0)
    assert est.transcription.windows.widenings >= 1
    assert fit.chi_square == pytest.approx(reference.chi_square, abs=0.05)
    for name in starts:
        assert fit.parameters[name] == pytest.approx(reference.parameters[name], abs=2e-3)


def test_windows_are_widened_only_where_leaving_them_persists() -> None:
    """A watchdog's trial steps (at most 3) may leave the windows and come back: only a
    fourth successive iterate outside them stops the run, at that iterate."""
    monitor = IterationMonitor(2, 1, np.abs, lambda z: None, 0.01)
    monitor.reset(False, (np.full(2, -np.inf), np.full(2, np.inf)))
    for k, outside in enumerate((True, True, True, False, True, True, True)):
        monitor.window_check(np.full(2, float(k)), outside)
    assert monitor.left_at is None
    monitor.window_check(np.full(2, 7.0), True)
    np.testing.assert_array_equal(monitor.left_at, np.full(2, 7.0))
    monitor.window_check(np.full(2, 8.0), True)  # the first such iterate is kept
    np.testing.assert_array_equal(monitor.left_at, np.full(2, 7.0))


def test_an_unconverged_run_keeps_its_lowest_nearly_feasible_iterate() -> None:
    """The witness for an unconverged refit's likelihood-ratio bound: the iterate with
    the lowest chi-square among those whose constraints hold within
    POLISH_CONSTRAINT_TOL, kept through a widening restart, forgotten by a new solve."""
    monitor = IterationMonitor(1, 1, np.abs, lambda z: None, None)  # one constraint, held at 0

    def iterate(z: float, chi2: float, gap: float) -> None:
        monitor.eval([ca.DM(z), ca.DM(chi2 / 2.0), ca.DM(gap), ca.DM(0.0), ca.DM(0.0),
                      ca.DM(0, 1)])

    monitor.reset(False, (np.full(1, -np.inf), np.full(1, np.inf)))
    iterate(1.0, 10.0, 0.0)
    iterate(2.0, 5.0, 0.1)  # lower, but far from feasible (a watchdog's trial step)
    iterate(3.0, 8.0, 5e-4)
    iterate(4.0, 12.0, 0.0)
    iterate(4.5, 1.0, np.nan)  # a point that could not be evaluated is no witness
    np.testing.assert_array_equal(monitor.best, [3.0])
    monitor.reset(False, (np.full(1, -np.inf), np.full(1, np.inf)), done=4)  # widened
    iterate(5.0, 9.0, 0.0)
    np.testing.assert_array_equal(monitor.best, [3.0])
    monitor.reset(False, (np.full(1, -np.inf), np.full(1, np.inf)))  # a new solve
    iterate(6.0, 20.0, 0.0)
    np.testing.assert_array_equal(monitor.best, [6.0])


class _Points:
    """One residual r(z) = 1 - z^2 of one variable, with its Jacobian: Gauss-Newton leaves
    out its curvature, -2 r.  One constraint, z itself, held within [-10, 10]."""

    def constraint_value(self, z: np.ndarray) -> np.ndarray:
        return z

    def residual_jacobian(self, z: np.ndarray) -> tuple[np.ndarray, sp.csc_matrix]:
        return np.array([1.0 - z[0] ** 2]), sp.csc_matrix(np.array([[-2.0 * z[0]]]))


def test_damping_rises_on_failed_steps_and_falls_on_good_ones() -> None:
    damping = MarquardtDamping(_Points(), np.array([-10.0]), np.array([10.0]))  # type: ignore[arg-type]
    mu0 = MarquardtDamping.MU_START
    damping.observe(np.array([0.5]))
    assert damping.mu == 0.0
    # 0.5 -> 1.5: the linear model predicts chi-square 0.5625 -> 0.0625, it rises to 1.5625.
    damping.observe(np.array([1.5]))
    assert damping.mu == mu0
    # 1.5 -> 0.5: the model predicts a rise; nothing is learnt.  0.5 -> 1.5 fails again.
    damping.observe(np.array([0.5]))
    damping.observe(np.array([1.5]))
    assert damping.mu == 4.0 * mu0
    # 1.5 -> 1.0: predicted 1.5625 -> 0.0625, got 0: the model holds, the damping falls.
    damping.observe(np.array([1.0]))
    assert damping.mu == pytest.approx(4.0 * mu0 / 3.0)
    # Steps to or from an infeasible point are not judged: 1.0 -> 12 -> 0.5 -> 1.5 fails
    # only once, the step from 12 is not counted.
    damping.observe(np.array([12.0]))
    damping.observe(np.array([0.5]))
    damping.observe(np.array([1.5]))
    assert damping.mu == pytest.approx(4.0 * 4.0 * mu0 / 3.0)
    damping.reset()
    assert damping.mu == 0.0


def test_damping_adds_to_the_hessians_diagonal(estimators) -> None:
    _, est = estimators
    z = est.initial_point()
    lam = np.zeros(est.transcription.g.numel())
    plain = _outputs(est, "nlp_hess_l", z, lam)[0].sparse()
    est.transcription.damping.mu = 0.5
    try:
        damped = _outputs(est, "nlp_hess_l", z, lam)[0].sparse()
    finally:
        est.transcription.damping.reset()
    _, J = est.transcription.points.residual_jacobian(z)
    column_squares = np.asarray(J.multiply(J).sum(axis=0)).ravel()
    added = (damped - plain).tocsr()
    np.testing.assert_allclose(added.diagonal(), 0.7 * 0.5 * column_squares,
                               rtol=1e-12, atol=1e-9 * column_squares.max())
    added.setdiag(0.0)
    assert abs(added).max() <= 1e-9 * column_squares.max()  # nothing off the diagonal


def test_a_misspecified_fit_converges(tmp_path) -> None:
    """`drogue` flown with added mass and fitted without it: undamped, Gauss-Newton steps
    overshoot along weakly determined directions and the fit crawls to its iteration
    limit (500 iterations, 24 minutes); damped, it ends at the statistical stop."""
    problem = load_problem("drogue")
    values = {f"added_mass_factor[{c}]": 1.4 for c in ("drogue1", "drogue2")}
    simulate_problem(dataclasses.replace(problem, truth={**problem.truth, **values}),
                     tmp_path / "test", 1, effects=[*baseline_effects(), AddedMass()])
    est = Estimator(load_test(tmp_path / "test"), baseline_spec(), Settings(max_iter=60))
    fit = est.solve()
    assert fit.solver.status == STATISTICALLY_CONVERGED
    assert fit.solver.chi2_decrement is not None and fit.solver.chi2_decrement < 0.01
    # The misspecification shows: chi-square well above its degrees of freedom.
    assert fit.chi_square > fit.dof + 5.0 * np.sqrt(2.0 * fit.dof)


def test_a_run_whose_chi_square_explodes_stops_as_diverged() -> None:
    """A watchdog's trial step may leave the physics (chi-square 1e40): the run ends there,
    measured against its first iterate, and a new solve starts the count afresh."""
    from cpas_ocp.estimation.estimator import DIVERGED_FACTOR
    monitor = IterationMonitor(1, 1, np.abs, lambda z: None, None)

    def iterate(chi2: float) -> int:
        return int(monitor.eval([ca.DM(0.0), ca.DM(chi2 / 2.0), ca.DM(0.0), ca.DM(0.0),
                                 ca.DM(0.0), ca.DM(0, 1)])[0])

    monitor.reset(False, (np.full(1, -np.inf), np.full(1, np.inf)))
    assert iterate(100.0) == 0
    assert iterate(0.5 * DIVERGED_FACTOR * 100.0) == 0  # a far excursion may come back
    assert not monitor.diverged
    assert iterate(2.0 * DIVERGED_FACTOR * 100.0) == 1
    assert monitor.diverged
    monitor.reset(False, (np.full(1, -np.inf), np.full(1, np.inf)))
    assert iterate(1e9) == 0 and not monitor.diverged
    assert iterate(np.nan) == 1 and monitor.diverged
