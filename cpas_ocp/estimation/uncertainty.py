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

from cpas_ocp.estimation.kkt_system import (
    SINGULAR_RATIO,
    Linearisation,
    NullSpace,
    null_space,
    reduce_linearisation,
)


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
    ns = null_space(reduce_linearisation(lin))
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
        ns = null_space(red)
    else:
        ns = null_space(red, red.Z.T @ np.asarray(hessian_product(red.Z)))
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


def _weak_combinations(ns: NullSpace, rows: list[int], at: list[int], names: list[str]
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
