"""The Gauss-Newton step of the linearised problem and the chi-square fall it predicts:
the linear algebra of the statistical stopping rule (`solve`) and of the score test
(`gauss_newton_step`)."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from cpas_ocp.estimation.kkt_system import (
    Linearisation,
    ReducedProblem,
    null_space,
    reduce_linearisation,
)


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


def bound_reached(lin: Linearisation, gn: GaussNewtonStep, lower: np.ndarray,
                  upper: np.ndarray, tol: float, coordinates: np.ndarray
                  ) -> tuple[int, float] | None:
    """The coordinate among `coordinates` of the scaled decision vector (those the
    linearisation holds on a bound: the free parameters) that the step `gn` carries
    soonest through a bound (within `lower`/`upper`) so near that less than `tol` of
    chi-square is to be had before it, and that bound; None if there is none.

    Along the step chi-square falls by D a (2 - a) to the fraction a of it (the
    Gauss-Newton model, D the decrement), so a coordinate that meets its bound at a
    fraction a of the step gives at most that much by moving to it.  Ipopt keeps such a
    coordinate a little inside its bound (its barrier), where the step, which knows no
    bounds, promises the decrease beyond it: on a rocket log whose main's start time sat
    4e-5 s above the phase's start, the decrement stayed at 112, then 0.044, and Ipopt
    crept on for 446 iterations.  Placed on its bound, the coordinate is held there
    (`kkt_system.linearise`), and the decrement is what the data offer on that face.
    One coordinate only: with two correlated coordinates held at once, the optimum on
    the box can move one of them inward (the multiplier's sign is then wrong), and the
    decrement on the face can miss a fall of any size."""
    free = np.zeros(lin.z.size, dtype=bool)
    free[coordinates] = True
    free[lin.held] = False
    room = np.where(free, _rooms(lin.z, gn.step, lower, upper), np.inf)
    i = int(np.argmin(room))
    a = room[i]
    if not (a < 1.0 and gn.decrement * a * (2.0 - a) < tol):
        return None
    return i, float(lower[i] if gn.step[i] < 0.0 else upper[i])


DECREMENT_FLOOR = 1e-4  # chi-square: below it the decrement is taken as the model gives it


def measured_decrement(residual_value: Callable[[np.ndarray], np.ndarray],
                       lin: Linearisation, gn: GaussNewtonStep,
                       bounds: tuple[np.ndarray, np.ndarray] | None = None) -> float:
    """The chi-square decrease still to be had along the Gauss-Newton step `gn` from
    `lin.z` (within `bounds`, the scaled decision vector's, where given), with the step's
    curvature measured rather than taken from the Gauss-Newton model.

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

    A step that leaves the bounds is measured where it meets the first of them, at the
    fraction b of it: the model beyond a bound is no measure of what is to be had (on an
    imported rocket log a step of the drogue's shape exponent 6.5 scales long, through its
    bounds, ended at a chi-square of 4e8 and measured a decrease of 0 where Ipopt went on
    to find 0.7).  Where the minimum along the step, D / c, lies within the bounds the
    decrease is D^2 / c as without them; where it lies beyond, the decrement D itself."""
    decrement = gn.decrement
    if decrement < DECREMENT_FLOOR:
        return decrement
    room = np.inf if bounds is None else _room(lin.z, gn.step, *bounds)
    reach = min(room, 1.0)
    if reach <= 0.0:
        return decrement
    r1 = residual_value(lin.z + reach * gn.step)
    if not np.all(np.isfinite(r1)):  # the step left the model's domain: no measurement
        return decrement
    curvature = (float(r1 @ r1 - lin.r @ lin.r) + 2.0 * decrement * reach) / reach**2
    if curvature <= 0.0:
        return np.inf
    if decrement / curvature > room:
        # The minimum along the step lies beyond a bound: what the other coordinates
        # offer past it is not measured, and the model's decrement stands.
        return decrement
    return decrement**2 / curvature


def _rooms(z: np.ndarray, dz: np.ndarray, lower: np.ndarray, upper: np.ndarray
           ) -> np.ndarray:
    """Per coordinate, the fraction of the step `dz` from `z` at which it meets its bound
    (infinity where it meets none)."""
    with np.errstate(divide="ignore", invalid="ignore"):
        room = np.where(dz < 0.0, (lower - z) / dz, np.where(dz > 0.0, (upper - z) / dz, np.inf))
    return np.maximum(np.nan_to_num(room, nan=np.inf), 0.0)


def _room(z: np.ndarray, dz: np.ndarray, lower: np.ndarray, upper: np.ndarray) -> float:
    """The largest fraction of the step `dz` from `z` that stays within the bounds."""
    return float(np.min(_rooms(z, dz, lower, upper), initial=np.inf))


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
    ns = null_space(red, hessian)
    base = red.r + red.JZ @ ns.dw0
    gradient = ns.N.T @ (red.JZ.T @ base)
    y = -(ns.inverse() @ gradient)
    to_projection = red.dz_p + red.Z @ ns.dw0
    return (to_projection + red.Z @ (ns.N @ y), base + red.JZ @ (ns.N @ y), base,
            to_projection, -float(gradient @ y))
