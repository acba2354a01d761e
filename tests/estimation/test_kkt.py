"""The reduced KKT system: the same answers as the full one, and an identifiability report
(never NaN) where the data fix a combination poorly or not at all."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
import scipy.sparse as sp

from cpas_ocp.estimation.gauss_newton import gauss_newton, gauss_newton_decrement
from cpas_ocp.estimation.kkt_system import Linearisation
from cpas_ocp.estimation.uncertainty import (
    POORLY_DETERMINED,
    _by_weight,
    _leading_rows,
    _oriented,
    kkt_covariance,
)
from cpas_ocp.reports.report import identifiability_text

NX, NODES = 2, 6  # states per node, nodes


def _chain_problem(seed: int, singular: bool = False, split: float = 0.0
                   ) -> tuple[Linearisation, np.ndarray]:
    """A small shooting problem: z = (x_0 .. x_5, p_1, p_2, c), gaps x_{k+1} - M x_k - b p,
    one capture relation, p_1 on nothing; residuals see every node and p.  `singular`:
    p_1 and p_2 enter only through their sum, apart from a residual-only difference of
    relative size `split`."""
    rng = np.random.default_rng(seed)
    n_states = NX * NODES
    nz = n_states + 3
    rows = []
    for k in range(NODES - 1):
        block = np.zeros((NX, nz))
        block[:, NX * (k + 1):NX * (k + 2)] = np.eye(NX)
        block[:, NX * k:NX * (k + 1)] = -(np.eye(NX) + 0.1 * rng.standard_normal((NX, NX)))
        block[:, n_states:n_states + 2] = -rng.standard_normal((NX, 2))
        block[:, n_states + 2] = -0.05 * rng.standard_normal(NX)
        rows.append(block)
    capture = np.zeros((1, nz))
    capture[0, n_states + 2] = 1.0
    capture[0, NX * 2] = -0.5
    A = np.vstack([*rows, capture])
    J = rng.standard_normal((40, nz))
    if singular:  # the residuals see p_1 and p_2 only through their sum
        J[:, n_states + 1] = J[:, n_states] * (1.0 + split * rng.standard_normal(J.shape[0]))
        A[:, n_states + 1] = A[:, n_states]
    c = 1e-3 * rng.standard_normal(A.shape[0])
    lin = Linearisation(np.zeros(nz), rng.standard_normal(40), sp.csc_matrix(J),
                        sp.csc_matrix(A), c, np.zeros(2, dtype=bool),
                        chain_rows=NX * (NODES - 1),
                        dependent=np.arange(NX, n_states))
    return lin, np.arange(n_states, n_states + 2)


def _dense_kkt(lin: Linearisation) -> np.ndarray:
    J, A = lin.J.toarray(), lin.A.toarray()
    return np.block([[J.T @ J, A.T], [A, np.zeros((A.shape[0], A.shape[0]))]])


def test_reduced_covariance_and_step_equal_the_full_kkt_solution() -> None:
    lin, params = _chain_problem(11)
    K = _dense_kkt(lin)
    full_inverse = np.linalg.inv(K)
    cov = kkt_covariance(lin, params, np.ones(2), ["p1", "p2"])
    np.testing.assert_allclose(cov.matrix, full_inverse[np.ix_(params, params)], rtol=1e-9)

    nz = lin.z.size
    rhs = np.concatenate([-(lin.J.T @ lin.r), -lin.c])
    dz = np.linalg.solve(K, rhs)[:nz]
    after = lin.r + lin.J @ dz
    # The step's whole predicted fall, the gaps' closing included, is the full KKT step's.
    step = gauss_newton(lin)
    np.testing.assert_allclose(step.step, dz, atol=1e-10)
    assert step.decrement - step.restoration == pytest.approx(
        float(lin.r @ lin.r - after @ after), rel=1e-9)


def test_the_decrement_is_counted_from_the_feasible_projection() -> None:
    """Closing the shooting gaps with the free coordinates held (the states following)
    changes chi-square by `restoration`; the decrement from an infeasible point is the one
    from that projection."""
    lin, _ = _chain_problem(17)
    chain = lin.chain_rows
    lin = replace(lin, A=lin.A[:chain], c=lin.c[:chain])  # the shooting gaps only
    dz_p = np.zeros(lin.z.size)
    dz_p[lin.dependent] = np.linalg.solve(lin.A[:, lin.dependent].toarray(), -lin.c)
    r_p = lin.r + lin.J @ dz_p
    projected = replace(lin, z=lin.z + dz_p, r=r_p, c=np.zeros(chain))
    step = gauss_newton(lin)
    assert step.restoration == pytest.approx(float(r_p @ r_p - lin.r @ lin.r), rel=1e-9)
    assert step.decrement == pytest.approx(gauss_newton_decrement(projected), rel=1e-9)
    assert gauss_newton(projected).restoration == pytest.approx(0.0, abs=1e-9)


def test_the_score_step_from_any_nuisance_point_gives_the_likelihood_ratio() -> None:
    """Neyman's C(alpha) test, which the score test of an effect with states takes from
    the fit instead of re-solving its null point: one Gauss-Newton step from a point
    where the nuisance coordinates are not at their optimum (nor the gaps closed) gives
    the tested parameter's estimate and, with the covariance, a statistic equal to the
    one from the null point itself and, the problem being linear, to the likelihood
    ratio."""
    lin, params = _chain_problem(23)
    theta = params[1]
    K = _dense_kkt(lin)
    nz = lin.z.size
    rhs = np.concatenate([-(lin.J.T @ lin.r), -lin.c])
    full = lin.r + lin.J @ np.linalg.solve(K, rhs)[:nz]
    held = np.zeros((1, nz))
    held[0, theta] = 1.0  # the null: theta stays at 0 (lin.z is 0)
    A0 = np.vstack([lin.A.toarray(), held])
    J = lin.J.toarray()
    K0 = np.block([[J.T @ J, A0.T], [A0, np.zeros((A0.shape[0],) * 2)]])
    dz0 = np.linalg.solve(K0, np.concatenate([rhs, [0.0]]))[:nz]
    null = lin.r + lin.J @ dz0
    ratio = float(null @ null - full @ full)
    cov = kkt_covariance(lin, params, np.ones(2), ["p1", "p2"])
    var = cov.matrix[1, 1]
    at_null = replace(lin, z=dz0, r=null, c=np.zeros_like(lin.c))
    rng = np.random.default_rng(5)
    moved = rng.standard_normal(nz)
    moved[theta] = 0.0
    elsewhere = replace(lin, z=moved, r=lin.r + lin.J @ moved,
                        c=lin.c + lin.A @ moved)
    for start in (at_null, elsewhere):
        estimate = start.z[theta] + gauss_newton(start).step[theta]
        assert estimate**2 / var == pytest.approx(ratio, rel=1e-8)


def test_a_parameter_on_its_bound_is_held() -> None:
    lin, params = _chain_problem(13)
    lin.on_bound = np.array([False, True])
    lin.held = params[1:]
    cov = kkt_covariance(lin, params, np.ones(2), ["p1", "p2"])
    assert cov.at_bound == ["p2"]
    assert cov.matrix[1, 1] == 0.0 and cov.matrix[0, 0] > 0.0
    # Held on its bound, p2 has no sigma (never 0) and is not counted as determined.
    assert set(cov.std) == {"p1"} and cov.std["p1"] > 0.0
    verdict = identifiability_text(cov)
    assert "every combination of the 1 parameters off their bounds" in verdict
    assert "on a bound" in verdict and "p2" in verdict
    # Holding p2 is a constraint dp2 = 0 on the full system.
    K = _dense_kkt(lin)
    row = np.zeros((1, K.shape[0]))
    row[0, params[1]] = 1.0
    K = np.block([[K, row.T], [row, np.zeros((1, 1))]])
    assert cov.matrix[0, 0] == pytest.approx(np.linalg.inv(K)[params[0], params[0]], rel=1e-9)


def test_an_undetermined_combination_is_named_and_nothing_is_nan() -> None:
    lin, params = _chain_problem(12, singular=True)
    cov = kkt_covariance(lin, params, np.ones(2), ["p1", "p2"])
    assert np.all(np.isfinite(cov.matrix))
    assert cov.undetermined == ["p1", "p2"] and cov.std == {}
    (weak,) = cov.weak
    assert weak.std is None
    # The data fix p1 + p2; the report names the difference, in equal and opposite parts.
    assert weak.weights["p1"] == pytest.approx(np.sqrt(0.5), abs=1e-6)
    assert weak.weights["p2"] == pytest.approx(-np.sqrt(0.5), abs=1e-6)
    assert weak.other < 1e-6
    assert "not determined at all" in str(weak)
    # The step takes no part in the undetermined direction and stays finite.
    assert np.isfinite(gauss_newton_decrement(lin))


def test_a_poorly_determined_combination_keeps_its_finite_sigma() -> None:
    lin, params = _chain_problem(12, singular=True, split=1e-3)
    cov = kkt_covariance(lin, params, np.ones(2), ["p1", "p2"])
    assert cov.undetermined == []
    (weak,) = cov.weak
    assert weak.std is not None and weak.std > POORLY_DETERMINED
    # The reported combination's sigma is the covariance's own along that direction.
    d = np.array([weak.weights["p1"], weak.weights["p2"]])
    assert weak.std == pytest.approx(float(np.sqrt(d @ cov.matrix @ d)), rel=1e-6)
    assert f"±{weak.std:.3g}" in str(weak)


def test_exact_hessian_of_a_linear_problem_is_the_gauss_newton_one() -> None:
    lin, params = _chain_problem(11)
    JtJ = (lin.J.T @ lin.J).toarray()
    gn = kkt_covariance(lin, params, np.ones(2), ["p1", "p2"])
    exact = kkt_covariance(lin, params, np.ones(2), ["p1", "p2"],
                           hessian_product=lambda Z: JtJ @ Z)
    np.testing.assert_allclose(exact.matrix, gn.matrix, rtol=1e-9)
    assert exact.hessian == "exact" and gn.hessian == "gauss-newton"
    # A curvature the residuals add (r'd2r) changes the answer the way it should.
    bent = kkt_covariance(lin, params, np.ones(2), ["p1", "p2"],
                          hessian_product=lambda Z: 2.0 * JtJ @ Z)
    np.testing.assert_allclose(bent.matrix, 0.5 * gn.matrix, rtol=1e-9)


@pytest.mark.parametrize("ulp", [-1e-13, 0.0, 1e-13])
def test_a_tied_combination_reads_the_same_whatever_the_rounding(ulp: float) -> None:
    # Two BLAS kernels return CdS[a] - CdS[b] with either weight the larger by a few
    # units in the last place, and with either overall sign: the report must not move.
    a = np.sqrt(0.5)
    for sign in (1.0, -1.0):
        comp = {"CdS[b]": sign * -a * (1.0 + ulp), "CdS[a]": sign * a}
        oriented = _oriented(comp)
        assert _by_weight(oriented) == ["CdS[a]", "CdS[b]"]
        assert oriented["CdS[a]"] > 0.0 > oriented["CdS[b]"]
    # The pivot row of a tied subspace is the first by name, not the one rounding favours.
    P = np.array([[a * (1.0 + ulp)], [-a], [0.1]])
    assert _leading_rows(P, ["p2", "p1", "p3"])[0] == 1


@pytest.mark.parametrize("held", [[0], [1], [0, 1]])
def test_holding_coordinates_of_a_reduction_is_reducing_with_them_held(held: list[int]) -> None:
    """`ReducedProblem.holding` drops the held coordinates' columns of one forward
    substitution: the same reduced problem, and the same Gauss-Newton step, as reducing
    the linearisation with them held."""
    from cpas_ocp.estimation.kkt_system import reduce_linearisation

    lin, params = _chain_problem(17)
    columns = params[held]
    derived = reduce_linearisation(lin).holding(columns)
    direct = reduce_linearisation(replace(lin, held=columns))
    for name in ("free", "Z", "dz_p", "JZ", "r", "B", "b"):
        np.testing.assert_allclose(getattr(derived, name), getattr(direct, name),
                                   rtol=1e-12, atol=1e-14, err_msg=name)
    heldlin = replace(lin, held=columns)
    np.testing.assert_allclose(gauss_newton(heldlin, derived).step,
                               gauss_newton(heldlin).step, rtol=1e-10, atol=1e-14)
