"""The reduced Gauss-Newton KKT system: the same answers as the full one, and a clear error
where the data fix nothing."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse as sp

from cpas_ocp.uncertainty import (
    Linearization,
    SingularKKT,
    gauss_newton_decrement,
    kkt_covariance,
)

NX, NODES = 2, 6  # states per node, nodes


def _chain_problem(seed: int, singular: bool = False) -> tuple[Linearization, np.ndarray]:
    """A small shooting problem: z = (x_0 .. x_5, p_1, p_2, c), gaps x_{k+1} - M x_k - b p,
    one capture relation, p_1 on nothing; residuals see every node and p."""
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
        J[:, n_states + 1] = J[:, n_states]
        A[:, n_states + 1] = A[:, n_states]
    c = 1e-3 * rng.standard_normal(A.shape[0])
    lin = Linearization(np.zeros(nz), rng.standard_normal(40), sp.csc_matrix(J),
                        sp.csc_matrix(A), c, np.zeros(2, dtype=bool),
                        chain_rows=NX * (NODES - 1),
                        dependent=np.arange(NX, n_states))
    return lin, np.arange(n_states, n_states + 2)


def _dense_kkt(lin: Linearization) -> np.ndarray:
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
    expected = float(lin.r @ lin.r - after @ after)
    assert gauss_newton_decrement(lin) == pytest.approx(expected, rel=1e-9)


def test_a_parameter_on_its_bound_is_held() -> None:
    lin, params = _chain_problem(13)
    lin.on_bound = np.array([False, True])
    lin.held = params[1:]
    cov = kkt_covariance(lin, params, np.ones(2), ["p1", "p2"])
    assert cov.at_bound == ["p2"]
    assert cov.matrix[1, 1] == 0.0 and cov.matrix[0, 0] > 0.0
    # Holding p2 is a constraint dp2 = 0 on the full system.
    K = _dense_kkt(lin)
    row = np.zeros((1, K.shape[0]))
    row[0, params[1]] = 1.0
    K = np.block([[K, row.T], [row, np.zeros((1, 1))]])
    assert cov.matrix[0, 0] == pytest.approx(np.linalg.inv(K)[params[0], params[0]], rel=1e-9)


def test_a_direction_no_residual_sees_is_reported_not_solved() -> None:
    lin, params = _chain_problem(12, singular=True)
    with pytest.raises(SingularKKT, match="not determined"):
        kkt_covariance(lin, params, np.ones(2), ["p1", "p2"])
