"""Parameter covariance from the Gauss-Newton KKT system of the multiple-shooting NLP.

With weighted residuals r(z), their Jacobian J, and the equality constraints'
Jacobian A (continuity, captures, parameter constraints), the linearised
estimate has covariance equal to the top-left block of

    [ J'J  A' ]^-1
    [ A    0  ]

restricted to the parameters; the shooting states are eliminated through A
(Bock's constrained Gauss-Newton covariance, as in casiopeia).  Parameters
held on an active bound are projected out: they are reported as such and
enter as fixed.  Everything is computed in the NLP's scaled coordinates and
converted back to SI.  With `scale_by_residual` the covariance is multiplied
by chi^2 / (N - n_p), for when the sensor sigmas are not trusted.
"""

from __future__ import annotations

from dataclasses import dataclass

import casadi as ca
import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla


@dataclass
class Covariance:
    """Covariance of the free parameters (SI), in the order of `names`."""

    names: list[str]
    matrix: np.ndarray
    at_bound: list[str]
    residual_variance: float

    @property
    def std(self) -> dict[str, float]:
        return {n: float(np.sqrt(max(self.matrix[i, i], 0.0))) for i, n in enumerate(self.names)}

    def correlation(self) -> np.ndarray:
        d = np.sqrt(np.clip(np.diag(self.matrix), 1e-300, None))
        return self.matrix / np.outer(d, d)


def kkt_covariance(residual_jacobian: ca.Function, constraint_jacobian: ca.Function,
                   z: np.ndarray, param_index: np.ndarray, param_scale: np.ndarray,
                   lower: np.ndarray, upper: np.ndarray, names: list[str],
                   scale_by_residual: bool = False) -> Covariance:
    """Covariance of the parameters at the solution `z` (scaled decision vector).

    `param_index` locates the free parameters in z, `param_scale` turns their
    scaled values into SI, `lower`/`upper` are their scaled bounds.
    """
    r, J = residual_jacobian(z)
    r = np.asarray(r).ravel()
    J = _csc(J)
    A = _csc(constraint_jacobian(z))
    zp = z[param_index]
    span = upper - lower
    on_bound = (zp - lower < 1e-6 * span) | (upper - zp < 1e-6 * span)
    fixed_cols = param_index[on_bound]
    if fixed_cols.size:
        rows = sp.csc_matrix((np.ones(fixed_cols.size), (np.arange(fixed_cols.size), fixed_cols)),
                             shape=(fixed_cols.size, z.size))
        A = sp.vstack([A, rows]).tocsc()
    H = (J.T @ J).tocsc()
    K = sp.bmat([[H, A.T], [A, None]]).tocsc()
    rhs = np.zeros((K.shape[0], param_index.size))
    rhs[param_index, np.arange(param_index.size)] = 1.0
    lu = spla.splu(K)
    sol = lu.solve(rhs)
    cov_scaled = sol[param_index, :]
    cov_scaled = 0.5 * (cov_scaled + cov_scaled.T)
    n_free = int((~on_bound).sum())
    dof = max(r.size - n_free, 1)
    variance = float(r @ r) / dof
    cov = cov_scaled * np.outer(param_scale, param_scale)
    if scale_by_residual:
        cov = cov * variance
    cov[on_bound, :] = 0.0
    cov[:, on_bound] = 0.0
    return Covariance(list(names), cov, [n for n, b in zip(names, on_bound, strict=True) if b],
                      variance)


def _csc(m: ca.DM) -> sp.csc_matrix:
    m = ca.DM(m)
    sparsity = m.sparsity()
    colind = np.asarray(sparsity.colind())
    row = np.asarray(sparsity.row())
    return sp.csc_matrix((np.asarray(m.nonzeros()), row, colind), shape=m.shape)
