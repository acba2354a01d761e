"""Parameter covariance from the Gauss-Newton KKT system of the multiple-shooting NLP.

With weighted residuals r(z), their Jacobian J, and the equality constraints'
Jacobian A (continuity, captures, parameter constraints), the linearised
estimate has covariance equal to the parameter block of

    [ J'J  A' ]^-1
    [ A    0  ]

(Bock's constrained Gauss-Newton covariance, as in casiopeia).  It is formed
with the shooting states eliminated: the continuity gaps x_{k+1} - F(x_k, p)
are unit lower-triangular in the states after the first node, so one sparse
forward substitution gives every state's sensitivity Z to the remaining
coordinates w (first-node states, parameters, captured speeds).  What is left
is a dense problem in a few dozen coordinates: the reduced Hessian (JZ)'(JZ)
on the null space of the remaining constraints.  Its inverse, restricted to
the parameters, is the covariance; its eigen-decomposition tells a singular
problem (a combination the data do not determine) from a regular one.  On
the 120 s `main3` problem (144,000-row KKT system) this takes about 2 s and
little memory, where a sparse LU of the whole KKT matrix took 10 s and 1 GB.

The exact alternative replaces (JZ)'(JZ) by Z' H Z, where H is the Hessian
of the Lagrangian 0.5 |r|^2 + lambda' g at the solution's multipliers: the
observed information, with the residuals' own curvature and the curvature of
the shooting gaps.  For a small-residual fit the two agree; where they differ
the quadratic model of chi-square is poor and a profile likelihood tells more.

Parameters held on an active bound are projected out: they are reported as
such and enter as fixed.  Everything is computed in the NLP's scaled
coordinates and converted back to SI.  With `scale_by_residual` the
covariance is multiplied by chi^2 / (N - n_p), for when the sensor sigmas are
not trusted.

Identifiability: a direction of the reduced Hessian whose curvature is below
SINGULAR_RATIO of the largest is not determined by the data at all; one whose
standard deviation exceeds POORLY_DETERMINED (in units of the parameters'
typical magnitudes, `Parameter.scale`) is determined too poorly to mean
anything.  Both are named as parameter combinations (`WeakCombination`).
The covariance is then the inverse on the determined directions only (a
pseudo-inverse); the parameters that take part in an undetermined direction
get no standard deviation (never NaN) and are listed as `undetermined`.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np
import scipy.sparse as sp
from scipy.sparse.linalg import splu


@dataclass(frozen=True)
class WeakCombination:
    """A parameter combination the data determine poorly or not at all.

    `weights`: the unit direction's components on the free parameters, each
    in units of that parameter's typical magnitude (`Parameter.scale`),
    largest first and only those above 0.05 in size; `other` is the part of
    the direction (0-1) that lies in the initial state or the captured
    speeds.  `std` is the standard deviation along the direction in the same
    units (None where the data do not determine it at all; `curvature_ratio`
    is then the largest of the undetermined subspace).
    """

    weights: dict[str, float]
    other: float
    std: float | None
    curvature_ratio: float

    def __str__(self) -> str:
        terms = " ".join(f"{w:+.2f} {n}" for n, w in self.weights.items()) or "(no parameter)"
        if self.other > 0.05:
            terms += f" (+{self.other:.2f} initial state / captured speeds)"
        if self.std is None:
            return f"{terms}: not determined at all (curvature below {SINGULAR_RATIO:.0e} " \
                   f"of the largest)"
        return (f"{terms}: determined only to ±{self.std:.3g} parameter scales "
                f"(curvature {self.curvature_ratio:.1e} of the largest)")


@dataclass
class Covariance:
    """Covariance of the free parameters (SI), in the order of `names`.

    `hessian` names the curvature it inverts ("gauss-newton" or "exact");
    `scaled` says whether it was multiplied by `residual_variance`
    (chi^2 per degree of freedom); `weak` lists the combinations the data
    determine poorly or not at all, `undetermined` the parameters in the
    latter: they have no std, and their rows and columns hold the inverse on
    the determined directions only, so that a combination orthogonal to the
    undetermined ones (the sum of two drag areas the data cannot split) has
    its proper variance d' C d.
    """

    names: list[str]
    matrix: np.ndarray
    at_bound: list[str]
    residual_variance: float
    hessian: str = "gauss-newton"
    scaled: bool = False
    weak: list[WeakCombination] = field(default_factory=list)
    undetermined: list[str] = field(default_factory=list)

    @property
    def std(self) -> dict[str, float]:
        """Standard deviation (SI) of every parameter the data determine.

        A parameter on an active bound has none: the optimum lies on the bound,
        the fit holds it there, and its zero row in `matrix` says only that; a
        sigma of 0 would read as a perfectly determined value.
        """
        return {n: float(np.sqrt(max(self.matrix[i, i], 0.0))) for i, n in enumerate(self.names)
                if n not in self.undetermined and n not in self.at_bound}

    def describe(self) -> str:
        """How the covariance was obtained, for reports."""
        how = "exact Hessian of the Lagrangian" if self.hessian == "exact" else "Gauss-Newton"
        return (f"KKT parameter block, {how}; sensor sigmas "
                + (f"scaled by chi^2/dof = {self.residual_variance:.3f}" if self.scaled
                   else "as given"))

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
        keep = [i for i, n in enumerate(self.names)
                if n not in self.at_bound and n not in self.undetermined]
        d = np.sqrt(np.diag(self.matrix)[keep])
        x = np.array([delta[self.names[i]] for i in keep]) / d
        w, v = np.linalg.eigh(self.matrix[np.ix_(keep, keep)] / np.outer(d, d))
        ok = w > rank_tol * w.max()
        y = v[:, ok].T @ x
        return float(np.sum(y**2 / w[ok])), int(ok.sum())


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
        Z[dep] = lu.solve(-(chain[:, free].toarray()))
        dz_p[dep] = lu.solve(-lin.c[:lin.chain_rows])
    rest = A[lin.chain_rows:]
    B = np.asarray(rest @ Z)
    b = lin.c[lin.chain_rows:] + rest @ dz_p
    return ReducedProblem(free, Z, dz_p, np.asarray(lin.J @ Z), lin.r + lin.J @ dz_p, B, b)


@dataclass
class _NullSpace:
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


def _null_space(red: ReducedProblem, hessian: np.ndarray | None = None) -> _NullSpace:
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
    return _NullSpace(N, dw0, w, V)


class NonFiniteCurvature(ValueError):
    """The linearisation holds inf or NaN: the model overflows at the point (an extended
    model at a singular null, such as a stiff riser integrated backwards over a lag)."""


HESSIANS = ("gauss-newton", "exact")  # curvatures a covariance may invert
# Smallest to largest curvature (in the scaled coordinates) below which the
# data are taken not to determine a combination of the free coordinates.
SINGULAR_RATIO = 1e-13
# Standard deviation along a direction, in units of the parameters' typical magnitudes
# (`Parameter.scale`), above which the combination is reported as poorly determined: the
# data then leave it uncertain by more than the size of the parameters themselves.
POORLY_DETERMINED = 1.0
# Part of a parameter's unit vector in the undetermined directions above which the
# parameter itself is undetermined (eigenvectors are accurate to far better than this).
UNDETERMINED_LOADING = 1e-2
WEIGHT_SHOWN = 0.05  # smallest component of a weak combination that is named


def log_det_information(lin: Linearisation) -> float:
    """log det of the Gauss-Newton information (J'J) of the free coordinates in the scaled
    decision vector, on the null space of the constraints that remain after the shooting
    gaps: the Laplace approximation's volume term.  Directions the data do not determine
    enter at SINGULAR_RATIO of the largest curvature (a constant where they do not change
    between the models compared)."""
    ns = _null_space(reduce_linearisation(lin))
    floor = SINGULAR_RATIO * max(ns.largest, 1e-300)
    return float(np.sum(np.log(np.maximum(ns.H_eigenvalues, floor))))


def kkt_covariance(lin: Linearisation, param_index: np.ndarray, param_scale: np.ndarray,
                   names: list[str], scale_by_residual: bool = False,
                   hessian_product: Callable[[np.ndarray], np.ndarray] | None = None
                   ) -> Covariance:
    """Covariance of the free parameters at a solution, in SI (`param_scale` converts).

    `hessian_product(Z)` returns H Z for the Hessian H of the Lagrangian in the
    scaled decision vector; without it the Gauss-Newton curvature is used.
    """
    red = reduce_linearisation(lin)
    if hessian_product is None:
        ns = _null_space(red)
    else:
        ns = _null_space(red, red.Z.T @ np.asarray(hessian_product(red.Z)))
    cov_w = ns.N @ ns.inverse() @ ns.N.T
    position = {int(col): i for i, col in enumerate(red.free)}
    cov_scaled = np.zeros((param_index.size, param_index.size))
    rows = [i for i, col in enumerate(param_index) if int(col) in position]
    at = [position[int(param_index[i])] for i in rows]
    cov_scaled[np.ix_(rows, rows)] = cov_w[np.ix_(at, at)]
    cov_scaled = 0.5 * (cov_scaled + cov_scaled.T)
    weak, undetermined = _weak_combinations(ns, rows, at, names)
    n_free = int((~lin.on_bound).sum())
    dof = max(lin.r.size - n_free, 1)
    variance = float(lin.r @ lin.r) / dof
    cov = cov_scaled * np.outer(param_scale, param_scale)
    if scale_by_residual:
        cov = cov * variance
    return Covariance(list(names), cov,
                      [n for n, b in zip(names, lin.on_bound, strict=True) if b], variance,
                      "gauss-newton" if hessian_product is None else "exact", scale_by_residual,
                      weak, undetermined)


def _weak_combinations(ns: _NullSpace, rows: list[int], at: list[int], names: list[str]
                       ) -> tuple[list[WeakCombination], list[str]]:
    """The poorly or un-determined directions as parameter combinations, and the parameters
    that take part in an undetermined one (`rows`: parameter indices, `at`: their w index).

    The undetermined directions span a subspace in which any basis is as good
    as another; it is rotated so that each direction leads with its own
    parameter and has none of the other directions' leading parameters (a
    pivoted Gram-Schmidt picks them): two canopies the data cannot tell apart
    then read CdS[a] - CdS[b], stage by stage, rather than an arbitrary mixture.
    Signs and orders follow the weights, with ties broken by name, so the
    report is the same whatever the BLAS kernel's rounding.
    """
    top = ns.largest
    undetermined_w = ns.N @ ns.H_eigenvectors[:, ~ns.determined]
    loading = np.zeros(len(names))
    for i, a in zip(rows, at, strict=True):
        loading[i] = float(np.linalg.norm(undetermined_w[a]))
    directions: list[tuple[np.ndarray, float | None, float]] = []
    if undetermined_w.shape[1]:
        P = undetermined_w[at]
        k = undetermined_w.shape[1]
        lead = P[_leading_rows(P, [names[i] for i in rows])[:k]]
        if np.linalg.matrix_rank(lead) == k:
            undetermined_w = undetermined_w @ np.linalg.inv(lead)
        for j in range(k):
            d = undetermined_w[:, j]
            directions.append((d / np.linalg.norm(d), None,
                               float(ns.H_eigenvalues[~ns.determined].max() / top)))
    for j in np.flatnonzero(ns.determined):
        std = 1.0 / np.sqrt(ns.H_eigenvalues[j])
        if std > POORLY_DETERMINED:
            directions.append((ns.N @ ns.H_eigenvectors[:, j], float(std),
                               float(ns.H_eigenvalues[j] / top)))
    weak = []
    for d, std, ratio in directions:
        comp = _oriented({names[i]: float(d[a]) for i, a in zip(rows, at, strict=True)})
        shown = {n: comp[n] for n in _by_weight(comp) if abs(comp[n]) >= WEIGHT_SHOWN}
        other = float(np.sqrt(max(1.0 - sum(c * c for c in comp.values()), 0.0)))
        weak.append(WeakCombination(shown, other, std, ratio))
    return weak, [n for i, n in enumerate(names) if loading[i] > UNDETERMINED_LOADING]


TIE = 1e-6  # relative difference below which two weights or row norms count as equal


def _by_weight(comp: dict[str, float]) -> list[str]:
    """Names by decreasing |weight|; weights equal to within TIE in order of name.

    Equal weights (CdS[a] - CdS[b]) are common, and which of two equal numbers
    comes out larger depends on the BLAS kernel's rounding: the order must not.
    """
    top = max((abs(c) for c in comp.values()), default=0.0)
    if top == 0.0:
        return sorted(comp)
    return sorted(comp, key=lambda n: (-round(abs(comp[n]) / top / TIE), n))


def _oriented(comp: dict[str, float]) -> dict[str, float]:
    """The combination with its sign fixed: the leading parameter (largest |weight|,
    ties to within TIE broken by name) counts positive."""
    order = _by_weight(comp)
    if not order or comp[order[0]] >= 0.0:
        return comp
    return {n: -c for n, c in comp.items()}


def _leading_rows(P: np.ndarray, names: list[str]) -> list[int]:
    """Rows of P (parameters x directions) in the order a pivoted Gram-Schmidt picks
    them: each time the row with the largest norm after projecting out the rows
    already picked, rows equal to within TIE taken in order of name.  It is the
    column pivoting of a QR of P', made deterministic where norms tie."""
    R = np.array(P, dtype=float)
    picked: list[int] = []
    for _ in range(min(R.shape)):
        norms = np.linalg.norm(R, axis=1)
        norms[picked] = -1.0
        top = norms.max()
        if top <= 0.0:
            break
        tied = [i for i in range(len(names)) if norms[i] >= top * (1.0 - TIE)]
        i = min(tied, key=lambda j: names[j])
        picked.append(i)
        q = R[i] / np.linalg.norm(R[i])
        R = R - np.outer(R @ q, q)
    return picked + [i for i in range(len(names)) if i not in picked]


def gauss_newton_decrement(lin: Linearisation) -> float:
    """Chi-square decrease the Gauss-Newton step from `lin.z` predicts, counted from the
    point's feasible projection (`GaussNewtonStep.decrement`)."""
    return gauss_newton(lin).decrement


@dataclass(frozen=True)
class GaussNewtonStep:
    """The Gauss-Newton step from a linearisation and what it predicts (chi-square).

    The step dz minimises |r + J dz|^2 subject to A dz = -c.  It closes the
    constraints' gaps c and moves along them; the two parts are told apart
    at the point's feasible projection: the gaps closed with the free
    coordinates (parameters, first node, captures) held, the shooting
    states following them.

    `restoration`: the chi-square change of that projection, |r_p|^2 - |r|^2.
    Small gaps can be worth much: on `drogue` gaps of 1e-6 (0.1 mm/s per
    10 ms interval) drift the velocity by centimetres per second over the
    phase, and a point with such gaps sat 4 below the feasible optimum.
    `decrement`: the decrease from the projection to the step's end,
    |r_p|^2 - |r + J dz|^2; it bounds the squared Mahalanobis distance (in
    the covariance's metric) of the parameters from the linearised optimum:
    a decrement below 0.01 puts every parameter within 0.1 standard
    deviation of where the fit is heading.  Directions the data do not
    determine take no step.
    """

    step: np.ndarray
    decrement: float
    restoration: float
    projection: np.ndarray  # the step to the feasible projection (to first order)


def gauss_newton(lin: Linearisation, red: ReducedProblem | None = None,
                 curvature: tuple[np.ndarray, np.ndarray] | None = None) -> GaussNewtonStep:
    """The Gauss-Newton step, its decrement and the gaps' restoration cost, from one
    factorisation (`red`: `lin` already reduced).

    `curvature` = (columns, S) adds S, a second-order part of the reduced Hessian over
    those columns of the decision vector (`structured_secant`), to (JZ)'(JZ); the
    decrement is then the model's, -g'dw with g the reduced gradient, the slope of
    chi-square along the step being -2 times it as without."""
    if curvature is None:
        dz, after, projected, to_projection, _ = _gauss_newton(lin, red)
        return GaussNewtonStep(dz, max(float(projected @ projected - after @ after), 0.0),
                               float(projected @ projected - lin.r @ lin.r), to_projection)
    red = red or reduce_linearisation(lin)
    columns, S = curvature
    at = np.searchsorted(columns, red.free)
    known = (at < columns.size) & (columns[np.minimum(at, columns.size - 1)] == red.free)
    extra = np.zeros((red.free.size, red.free.size))
    extra[np.ix_(known, known)] = S[np.ix_(at[known], at[known])]
    dz, _, projected, to_projection, decrement = _gauss_newton(lin, red,
                                                              red.JZ.T @ red.JZ + extra)
    return GaussNewtonStep(dz, max(decrement, 0.0),
                           float(projected @ projected - lin.r @ lin.r), to_projection)



DECREMENT_FLOOR = 1e-4  # chi-square: below it the decrement is taken as the model gives it


def measured_decrement(residual_value: Callable[[np.ndarray], np.ndarray],
                       lin: Linearisation, gn: GaussNewtonStep) -> float:
    """The chi-square decrease still to be had along the Gauss-Newton step `gn` from
    `lin.z`, with the step's curvature measured rather than taken from the
    Gauss-Newton model.

    Along the step d, chi^2(z + a d) - chi^2(z) = -2 D a + c a^2 + O(a^3), D the
    Gauss-Newton decrement, and Gauss-Newton takes c = D: it leaves out the
    curvature of the residuals themselves, which a misspecified model's large
    residuals make large (on `drogue` with added mass left out, c = 5 D: the full
    step raised chi-square by 0.15 where the model promised a fall of 0.047, and
    Ipopt cut every step for hundreds of iterations).  One evaluation of the
    residuals at the step's end measures c; the minimum along the step then
    lies D^2 / c below chi^2(z).  A step along which chi-square is not convex
    (c <= 0) gives infinity: no statistical stop there.  Where D is already below
    DECREMENT_FLOOR the measurement is lost in rounding, and where the step's end
    cannot be evaluated there is none: D is returned.
    """
    decrement = gn.decrement
    if decrement < DECREMENT_FLOOR:
        return decrement
    r1 = residual_value(lin.z + gn.step)
    if not np.all(np.isfinite(r1)):  # the step left the model's domain: no measurement
        return decrement
    curvature = float(r1 @ r1 - lin.r @ lin.r) + 2.0 * decrement
    return decrement**2 / curvature if curvature > 0.0 else np.inf


def gauss_newton_step(lin: Linearisation) -> np.ndarray:
    """The Gauss-Newton step dz (scaled decision vector) of `gauss_newton_decrement`.

    At a fit of a smaller model extended by parameters at their null values,
    its components along those parameters are their linearised estimates:
    the basis of the score test (`score_test`).
    """
    return _gauss_newton(lin)[0]


def _gauss_newton(lin: Linearisation, red: ReducedProblem | None = None,
                  hessian: np.ndarray | None = None
                  ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, float]:
    """The step dz, the weighted residuals r + J dz it predicts, those it predicts at the
    point's feasible projection, the step to that projection, and the chi-square fall
    from the projection that the quadratic model with `hessian` (the reduced Hessian in
    w, default Gauss-Newton's) predicts, -g'y with g its gradient."""
    red = red or reduce_linearisation(lin)
    ns = _null_space(red, hessian)
    base = red.r + red.JZ @ ns.dw0
    gradient = ns.N.T @ (red.JZ.T @ base)
    y = -(ns.inverse() @ gradient)
    to_projection = red.dz_p + red.Z @ ns.dw0
    return (to_projection + red.Z @ (ns.N @ y), base + red.JZ @ (ns.N @ y), base,
            to_projection, -float(gradient @ y))
