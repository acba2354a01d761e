"""Several tests and a parameter's population in one NLP (`estimation.hierarchical_nlp`,
`inference.hierarchical_fit`): the copies' residuals and their Jacobians, the patterns Ipopt
is given, and the Laplace deviance.  `benchmarks/studies/test_hierarchical_fit.py` checks
the fit's limits (a wide population leaves each test its own estimate, a narrow one is the
joint fit's shared value) and its estimate of tau."""

from __future__ import annotations

import numpy as np
import pytest

from cpas_ocp.estimation.estimator import Estimator
from cpas_ocp.estimation.hierarchical_nlp import HierarchicalNlp, Population
from cpas_ocp.estimation.simulate import simulate_problem
from cpas_ocp.io.flight_test import load_test
from cpas_ocp.io.problems import load_problem

COPIES = ((0, "CdS[fbcp1,stage1]"), (0, "CdS[fbcp2,stage1]"), (1, "CdS[fbcp1,stage1]"))


@pytest.fixture(scope="module")
def nlp(tmp_path_factory) -> HierarchicalNlp:
    root = tmp_path_factory.mktemp("hierarchical")
    ests = []
    for i in range(2):
        simulate_problem(load_problem("fbcp"), root / f"t{i}", 700 + i)
        ests.append(Estimator(load_test(root / f"t{i}")))
    return HierarchicalNlp(ests, [Population("CdS[fbcp,stage1]", COPIES, 0.05),
                                  Population("t_k", ((0, "t_k[fbcp1,stage1]"),
                                                     (1, "t_k[fbcp1,stage1]")), 0.1, False)])


def _point(nlp: HierarchicalNlp) -> np.ndarray:
    tests = np.concatenate([e.initial_point() for e in nlp.estimators])
    return np.concatenate([tests, [np.log(2.1), 0.3]])


def test_the_copies_residuals_and_jacobians_match_differences(nlp) -> None:
    z = _point(nlp)
    d = np.random.default_rng(0).standard_normal(z.size) * 1e-6
    for value, with_jacobian in ((nlp.residual_value, nlp.residual_jacobian),
                                 (nlp.constraint_value, nlp.constraints)):
        _, M = with_jacobian(z)
        difference = (value(z + d) - value(z - d)) / 2.0
        np.testing.assert_allclose(M @ d, difference, rtol=1e-4, atol=1e-9)
    r = nlp.residual_value(z)[-5:]
    cds = [z[nlp.column(t, n)] * nlp.scale(t, n) for t, n in COPIES]
    assert np.allclose(r[:3], (np.log(cds) - np.log(2.1)) / 0.05)
    t_k = z[nlp.column(0, "t_k[fbcp1,stage1]")] * nlp.scale(0, "t_k[fbcp1,stage1]")
    assert r[3] == pytest.approx((t_k - 0.3) / 0.1)  # in the parameter itself


def test_the_patterns_hold_every_nonzero_and_the_means_are_parameters(nlp) -> None:
    z = _point(nlp)
    J_pattern, A_pattern = nlp.patterns()
    _, J = nlp.residual_jacobian(z)
    _, A = nlp.constraints(z)
    for M, P in ((J, J_pattern), (A, A_pattern)):
        assert M.shape == P.shape == (M.shape[0], nlp.nz)
        assert np.array_equal(M.indptr, P.indptr) and np.array_equal(M.indices, P.indices)
    assert nlp.names[-2:] == ["mu:CdS[fbcp,stage1]", "mu:t_k"]
    assert list(nlp.param_index[-2:]) == list(nlp.mean_columns)


def test_the_laplace_deviance_grows_with_log_tau_where_the_copies_agree(nlp) -> None:
    """Every copy at its mean: the copies' residuals vanish, and the deviance changes with
    tau by 2 log tau per copy plus the Hessian's log determinant.  At a large tau the
    copies' curvature 1/tau^2 is negligible beside their data's, but it is all a mean
    has: its log curvature falls by 2 per unit of log tau, so d(deviance)/d(log tau) =
    2 (copies - means).  At a small tau every copy's curvature is 1/tau^2 but for the
    one direction moving the copies and their mean together (the data's): the slope
    tends to 2 copies - 2 copies = 0."""
    z = _point(nlp)
    for g, pop in enumerate(nlp.populations):
        mean = z[nlp.mean_columns[g]]
        for t, n in pop.members:
            z[nlp.column(t, n)] = (np.exp(mean) if pop.log else mean) / nlp.scale(t, n)
    assert np.allclose(nlp.residual_value(z)[-len(nlp.copies):], 0.0)
    copies = len(nlp.copies)
    slopes = []
    for tau in (10.0, 1e-4):
        deviance = []
        for factor in (1.0, np.e):
            nlp.set_tau([tau * factor, 0.1 * tau * factor])
            deviance.append(nlp.laplace_deviance(z))
        slopes.append(deviance[1] - deviance[0])
    nlp.set_tau([0.05, 0.1])
    assert slopes[0] == pytest.approx(2 * (copies - len(nlp.populations)), rel=0.02)
    assert abs(slopes[1]) < 0.1 * copies
