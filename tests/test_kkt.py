"""The Gauss-Newton KKT solve: right answers, and a clear error where the data fix nothing."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse as sp

from cpas_ocp.uncertainty import SingularKKT, solve_kkt


def test_solves_an_equality_constrained_least_squares_step() -> None:
    rng = np.random.default_rng(11)
    J = sp.csc_matrix(rng.standard_normal((20, 4)))
    A = sp.csc_matrix(np.array([[1.0, -1.0, 0.0, 0.0]]))
    rhs = rng.standard_normal((5, 2))
    K = np.block([[(J.T @ J).toarray(), A.toarray().T], [A.toarray(), np.zeros((1, 1))]])
    np.testing.assert_allclose(solve_kkt(J, A, rhs), np.linalg.solve(K, rhs), rtol=1e-10)


def test_a_direction_no_residual_sees_is_reported_not_solved() -> None:
    # Parameters 3 and 4 enter only through their sum: J has a null direction.
    rng = np.random.default_rng(12)
    base = rng.standard_normal((20, 3))
    J = sp.csc_matrix(np.column_stack([base, base[:, 2]]))
    A = sp.csc_matrix((0, 4))
    with pytest.raises(SingularKKT, match="not determined"):
        solve_kkt(J, A, np.eye(4))
