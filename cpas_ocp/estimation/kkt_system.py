"""The estimation problem linearised at a point, and its KKT system reduced to the
coordinates that remain free.

With weighted residuals r(z), their Jacobian J, and the equality constraints'
Jacobian A (continuity, captures, parameter constraints), a step dz of the
linearised problem minimises |r + J dz|^2 subject to A dz = -c.  The shooting
states are eliminated: the continuity gaps x_{k+1} - F(x_k, p) are unit
lower-triangular in the states after the first node, so one sparse forward
substitution gives every state's sensitivity Z to the remaining coordinates w
(first-node states, parameters, captured speeds).  What is left is a dense
problem in a few dozen coordinates, solved on the null space of the remaining
constraints through the eigen-decomposition of its Hessian, which also tells a
direction the data do not determine (curvature below SINGULAR_RATIO of the
largest) from a determined one.  The Gauss-Newton step (`gauss_newton`) and the
covariance (`uncertainty`) both start here.
"""

from __future__ import annotations

from collections.abc import Callable
from contextlib import nullcontext
from dataclasses import dataclass, field

import numpy as np
import scipy.sparse as sp
from scipy.sparse.linalg import splu

from cpas_ocp.blas_threads import one_thread

# Smallest to largest curvature (in the scaled coordinates) below which the
# data are taken not to determine a combination of the free coordinates.
SINGULAR_RATIO = 1e-13

# The forward substitution through the shooting gaps runs with BLAS on one thread: its
# work is thousands of products a few rows wide, which a pool of spinning threads only
# delays, by minutes where another process holds a core (`blas_threads`).  False runs it
# on the pools as loaded (the earlier path, `benchmarks/chain_solve_threads.py`).
CHAIN_SOLVE_ON_ONE_THREAD = True


@dataclass
class Linearisation:
    """The estimation problem linearised at a point z (scaled decision vector).

    r, J: weighted residuals and their Jacobian; A, c: Jacobian and violation
    of the constraints that hold as equalities there (equality constraints and
    active inequalities).  The first `chain_rows` of them are the shooting
    gaps, which determine the `dependent` columns (the states after the first
    node) from the others; `held` columns are fixed (states pinned at the
    first node, free parameters on a bound); on_bound: which free parameters
    sit on a bound.
    """

    z: np.ndarray
    r: np.ndarray
    J: sp.csc_matrix
    A: sp.csc_matrix
    c: np.ndarray
    on_bound: np.ndarray
    chain_rows: int = 0
    dependent: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=int))
    held: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=int))

    @property
    def violation(self) -> float:
        """The largest scaled constraint violation at the point (0 without constraints)."""
        return float(np.max(np.abs(self.c))) if self.c.size else 0.0


Evaluation = Callable[[np.ndarray], tuple[np.ndarray, sp.csc_matrix]]


def linearise(residual_jacobian: Evaluation, constraints: Evaluation, z: np.ndarray,
              lbg: np.ndarray, ubg: np.ndarray, param_index: np.ndarray, lower: np.ndarray,
              upper: np.ndarray, chain_rows: int = 0,
              dependent: np.ndarray | None = None,
              pinned: np.ndarray | None = None) -> Linearisation:
    """Linearise at `z`: `residual_jacobian(z)` gives (r, dr/dz), `constraints(z)` gives
    (g, dg/dz) (`nlp_functions.PointEvaluations`); `param_index` locates the free
    parameters in z, `lower`/`upper` are their scaled bounds; the first `chain_rows`
    constraints determine the `dependent` columns; `pinned` columns are fixed."""
    r, J = residual_jacobian(z)
    g, A = constraints(z)
    holding = (ubg - lbg <= 0) | (g - lbg < 1e-8) | (ubg - g < 1e-8)
    if not holding[:chain_rows].all():
        raise ValueError("the chain constraints must be equalities")
    c = (g - np.clip(g, lbg, ubg))[holding]
    A = A[np.flatnonzero(holding), :]
    zp = z[param_index]
    bspan = upper - lower
    on_bound = (zp - lower < 1e-6 * bspan) | (upper - zp < 1e-6 * bspan)
    held = np.concatenate([np.asarray(pinned if pinned is not None else [], dtype=int),
                           param_index[on_bound]])
    return Linearisation(z, r, J, A.tocsc(), c, on_bound, chain_rows,
                         np.asarray(dependent if dependent is not None else [], dtype=int),
                         np.sort(held))


@dataclass
class ReducedProblem:
    """The linearised problem in the coordinates w that remain free (shooting states eliminated).

    Along the shooting gaps (a unit lower-triangular system in the states
    after the first node) every step dz is dz_p + Z dw, where w are the
    first-node states, the free parameters and the captured speeds not held.
    What is left: minimise |r + JZ dw|^2 subject to B dw = -b (captures and
    parameter constraints).
    """

    free: np.ndarray
    Z: np.ndarray
    dz_p: np.ndarray
    JZ: np.ndarray
    r: np.ndarray
    B: np.ndarray
    b: np.ndarray

    def holding(self, columns: np.ndarray) -> ReducedProblem:
        """The same linearisation reduced with `columns` (of the decision vector) held too:
        each column of Z is its own forward substitution, so holding a coordinate drops
        its column of Z, JZ and B and leaves the rest as they are (`reduce_linearisation`
        with those columns held gives the same, at the cost of the chain's solve)."""
        keep = ~np.isin(self.free, columns)
        return ReducedProblem(self.free[keep], self.Z[:, keep], self.dz_p, self.JZ[:, keep],
                              self.r, self.B[:, keep], self.b)


def reduce_linearisation(lin: Linearisation) -> ReducedProblem:
    """Eliminate the `dependent` columns through the first `chain_rows` constraints."""
    nz = lin.z.size
    A = lin.A.tocsr()
    dep = lin.dependent
    mask = np.ones(nz, dtype=bool)
    mask[dep] = False
    mask[lin.held] = False
    free = np.flatnonzero(mask)
    Z = np.zeros((nz, free.size))
    Z[free, np.arange(free.size)] = 1.0
    dz_p = np.zeros(nz)
    if lin.chain_rows:
        chain = A[:lin.chain_rows]
        AD = chain[:, dep].tocsc()
        # Shooting gaps x_{k+1} - F(x_k) are unit lower-triangular in (x_1 .. x_N):
        # a natural-order LU has no fill and needs no pivoting.
        lu = splu(AD, permc_spec="NATURAL", diag_pivot_thresh=0.0)
        with one_thread() if CHAIN_SOLVE_ON_ONE_THREAD else nullcontext():
            Z[dep] = lu.solve(-(chain[:, free].toarray()))
            dz_p[dep] = lu.solve(-lin.c[:lin.chain_rows])
    rest = A[lin.chain_rows:]
    B = np.asarray(rest @ Z)
    b = lin.c[lin.chain_rows:] + rest @ dz_p
    return ReducedProblem(free, Z, dz_p, np.asarray(lin.J @ Z), lin.r + lin.J @ dz_p, B, b)


@dataclass
class NullSpace:
    """The reduced problem restricted to B dw = -b: dw = dw0 + N y, with Hessian N'HN in y.

    `determined` marks the eigen-directions whose curvature is above
    SINGULAR_RATIO of the largest; the others are left out of every inverse.
    """

    N: np.ndarray
    dw0: np.ndarray
    H_eigenvalues: np.ndarray
    H_eigenvectors: np.ndarray

    @property
    def largest(self) -> float:
        """The largest curvature (1 for an empty problem): the reference of every ratio."""
        return float(self.H_eigenvalues.max()) if self.H_eigenvalues.size else 1.0

    @property
    def determined(self) -> np.ndarray:
        """The eigen-directions with curvature above SINGULAR_RATIO of the largest."""
        return self.H_eigenvalues > SINGULAR_RATIO * max(self.largest, 1e-300)

    def inverse(self) -> np.ndarray:
        """(N'HN)^+ on the determined directions, in y."""
        V = self.H_eigenvectors[:, self.determined]
        return (V / self.H_eigenvalues[self.determined]) @ V.T


def null_space(red: ReducedProblem, hessian: np.ndarray | None = None) -> NullSpace:
    """Null space of the remaining constraints and the eigen-decomposition of the Hessian
    there; `hessian` is the reduced Hessian in w (default: Gauss-Newton, (JZ)'(JZ))."""
    n = red.free.size
    if red.B.size:
        U, sv, Vt = np.linalg.svd(red.B)
        rank = int(np.sum(sv > 1e-10 * max(sv.max(), 1e-300)))
        N = Vt[rank:].T
        dw0 = -Vt[:rank].T @ ((U[:, :rank].T @ red.b) / sv[:rank])
    else:
        N, dw0 = np.eye(n), np.zeros(n)
    if hessian is None:
        G = red.JZ @ N
        H = G.T @ G
    else:
        H = N.T @ hessian @ N
    if not np.all(np.isfinite(H)):
        raise NonFiniteCurvature("the reduced Hessian has non-finite entries")
    w, V = np.linalg.eigh(0.5 * (H + H.T))
    if not np.all(np.isfinite(w)):
        raise NonFiniteCurvature("the reduced Hessian's eigenvalues are not finite")
    return NullSpace(N, dw0, w, V)


class NonFiniteCurvature(ValueError):
    """The linearisation holds inf or NaN: the model overflows at the point (an extended
    model at a singular null, such as a stiff riser integrated backwards over a lag)."""
