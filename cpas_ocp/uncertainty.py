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

    def mahalanobis(self, delta: dict[str, float], rank_tol: float = 1e-9) -> tuple[float, int]:
        """Squared Mahalanobis length of a parameter offset, and the degrees of freedom.

        `delta[name]` is an offset (SI) of every free parameter not on a bound,
        e.g. estimate minus truth.  If the estimate is Gaussian with this
        covariance, the result follows chi-square with `rank` degrees of
        freedom.  Constrained combinations (the load-cell scales' fixed
        geometric mean) leave the covariance singular; the length is taken in
        the range of the correlation matrix, eigenvalues below `rank_tol` times
        the largest dropped.
        """
        keep = [i for i, n in enumerate(self.names) if n not in self.at_bound]
        d = np.sqrt(np.diag(self.matrix)[keep])
        x = np.array([delta[self.names[i]] for i in keep]) / d
        w, v = np.linalg.eigh(self.matrix[np.ix_(keep, keep)] / np.outer(d, d))
        ok = w > rank_tol * w.max()
        y = v[:, ok].T @ x
        return float(np.sum(y**2 / w[ok])), int(ok.sum())


@dataclass
class Linearization:
    """The estimation problem linearised at a point z (scaled decision vector).

    r, J: weighted residuals and their Jacobian; A, c: Jacobian and violation
    of the constraints that hold as equalities there (equality constraints,
    active inequalities, and the free parameters that sit on a bound, which
    enter as fixed); on_bound: which free parameters those are.
    """

    z: np.ndarray
    r: np.ndarray
    J: sp.csc_matrix
    A: sp.csc_matrix
    c: np.ndarray
    on_bound: np.ndarray


def linearize(residual_jacobian: ca.Function, constraints: ca.Function, z: np.ndarray,
              lbg: np.ndarray, ubg: np.ndarray, param_index: np.ndarray, lower: np.ndarray,
              upper: np.ndarray) -> Linearization:
    """Linearise at `z`: `constraints(z)` gives (g, dg/dz); `param_index` locates the free
    parameters in z, `lower`/`upper` are their scaled bounds."""
    r, J = residual_jacobian(z)
    g, A = constraints(z)
    g = np.asarray(g).ravel()
    A = _csc(A)
    holding = (ubg - lbg <= 0) | (g - lbg < 1e-8) | (ubg - g < 1e-8)
    c = (g - np.clip(g, lbg, ubg))[holding]
    A = A[np.flatnonzero(holding), :]
    zp = z[param_index]
    bspan = upper - lower
    on_bound = (zp - lower < 1e-6 * bspan) | (upper - zp < 1e-6 * bspan)
    fixed_cols = param_index[on_bound]
    if fixed_cols.size:
        rows = sp.csc_matrix((np.ones(fixed_cols.size), (np.arange(fixed_cols.size), fixed_cols)),
                             shape=(fixed_cols.size, z.size))
        A = sp.vstack([A, rows]).tocsc()
        c = np.concatenate([c, np.zeros(fixed_cols.size)])
    return Linearization(z, np.asarray(r).ravel(), _csc(J), A.tocsc(), c, on_bound)


def kkt_covariance(lin: Linearization, param_index: np.ndarray, param_scale: np.ndarray,
                   names: list[str], scale_by_residual: bool = False) -> Covariance:
    """Covariance of the free parameters at a solution, in SI (`param_scale` converts)."""
    rhs = np.zeros((lin.z.size + lin.A.shape[0], param_index.size))
    rhs[param_index, np.arange(param_index.size)] = 1.0
    sol = solve_kkt(lin.J, lin.A, rhs)
    cov_scaled = sol[param_index, :]
    cov_scaled = 0.5 * (cov_scaled + cov_scaled.T)
    n_free = int((~lin.on_bound).sum())
    dof = max(lin.r.size - n_free, 1)
    variance = float(lin.r @ lin.r) / dof
    cov = cov_scaled * np.outer(param_scale, param_scale)
    if scale_by_residual:
        cov = cov * variance
    on_bound = lin.on_bound
    cov[on_bound, :] = 0.0
    cov[:, on_bound] = 0.0
    return Covariance(list(names), cov, [n for n, b in zip(names, on_bound, strict=True) if b],
                      variance)


def gauss_newton_decrement(lin: Linearization) -> float:
    """Chi-square decrease the Gauss-Newton step from `lin.z` predicts.

    The step dz minimises |r + J dz|^2 subject to A dz = -c.  At a feasible
    point its decrease, |J dz|^2, bounds the squared Mahalanobis distance
    (in the covariance's metric) of the current parameters from the
    linearised optimum: a decrease below 0.01 puts every parameter within
    0.1 standard deviation of where the fit is heading.
    """
    rhs = np.concatenate([-(lin.J.T @ lin.r), -lin.c])
    dz = solve_kkt(lin.J, lin.A, rhs[:, None])[:lin.z.size, 0]
    after = lin.r + lin.J @ dz
    return max(float(lin.r @ lin.r - after @ after), 0.0)


class SingularKKT(ValueError):
    """The Gauss-Newton KKT system is singular: some parameter combination is undetermined."""


def solve_kkt(J: sp.csc_matrix, A: sp.csc_matrix, rhs: np.ndarray) -> np.ndarray:
    """Solve [[J'J, A'], [A, 0]] x = rhs by MUMPS (sparse LU), checking the solution.

    MUMPS orders the saddle-point system for its arrow structure (states
    banded in time, parameters dense); SuperLU's default ordering fills it in
    about ten times more and takes ten times longer.  CasADi's MUMPS wrapper
    does not report a singular matrix, so the relative residual of the
    solution is checked here: above 1e-6 raises `SingularKKT`.
    """
    K = sp.bmat([[(J.T @ J), A.T], [A, None]]).tocsc()
    K.sort_indices()
    sparsity = ca.Sparsity(K.shape[0], K.shape[1], K.indptr.tolist(), K.indices.tolist())
    Kdm = ca.DM(sparsity, K.data.tolist())  # a list converts twice as fast as an array
    solver = ca.Linsol("kkt", "mumps", sparsity)
    solver.sfact(Kdm)
    solver.nfact(Kdm)
    x = np.asarray(solver.solve(Kdm, ca.DM(rhs)))
    error = np.linalg.norm(K @ x - rhs) / max(np.linalg.norm(rhs), 1e-300)
    if not np.isfinite(error) or error > 1e-6:
        raise SingularKKT(f"the Gauss-Newton KKT system is singular (relative residual "
                          f"{error:.1e}): some parameter combination is not determined by "
                          f"the data")
    return x


def _csc(m: ca.DM) -> sp.csc_matrix:
    m = ca.DM(m)
    sparsity = m.sparsity()
    colind = np.asarray(sparsity.colind())
    row = np.asarray(sparsity.row())
    return sp.csc_matrix((np.asarray(m.nonzeros()), row, colind), shape=m.shape)
