"""Gauss-Newton descent through feasible points: the finish of a run Ipopt cannot end.

On a misspecified model the weighted residuals are large, and the
Gauss-Newton Hessian Ipopt is given leaves out both their curvature and the
shooting gaps'.  Near the optimum Ipopt's full steps then open the gaps
(second order in the step), its filter cuts them, and the run creeps: on
`drogue` flown with added mass and refitted with elastic risers instead,
chi-square stood within 8,034-8,042 from iteration 20 to the 150-iteration cap
while the Gauss-Newton decrement stayed at 10-25.

Here every iterate is a feasible point (`Estimator.feasible_point`: the
states integrated through the grid with the parameters held, so the gaps are
closed exactly), and a step is accepted only where the feasible chi-square
falls.  Each step is the Gauss-Newton step of the linearised problem,
shortened to the minimum of chi-square along it as measured by one residual
evaluation at its end (`uncertainty.measured_decrement`: a = D / c), and halved
where the feasible point there is not lower.  A free parameter on a bound is
held there while the step would carry it outside, and released once the
step points inside; the other parameters are clipped to their bounds before
the states are integrated.  The descent ends when the measured decrement is
below the statistical test's tolerance (`Settings.chi2_step_tol`), which is
the test that ends an Ipopt run; so it finishes a fit at the same kind of
point, never a better-looking one.

The states are integrated over the whole phase at once (single shooting),
which is why this is a finish and not the engine: from a poor start the
integrated trajectory of a stiff or unstable model is far from the data,
where multiple shooting keeps every interval near it.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, replace

import numpy as np

from cpas_ocp.estimation.gauss_newton import GaussNewtonStep, gauss_newton, measured_decrement
from cpas_ocp.estimation.kkt_system import Linearisation, ReducedProblem, reduce_linearisation
from cpas_ocp.estimation.structured_secant import StructuredSecant

# Halvings of a step whose feasible end is not lower before the descent gives up.
HALVINGS = 4
# A free parameter within this fraction of its bounds' span of a bound sits on it.
ON_BOUND = 1e-6


@dataclass(frozen=True)
class DescentEnd:
    """Where a descent ended: the feasible point `z` (scaled decision vector), its
    chi-square, the measured Gauss-Newton decrement there, the steps taken, and
    whether the decrement fell below the tolerance."""

    z: np.ndarray
    chi2: float
    decrement: float
    steps: int
    converged: bool


@dataclass(frozen=True)
class DescentProblem:
    """What the descent needs of an estimator: its linearisation at a point, a feasible
    point near a point with that point's chi-square (None where none is found), the
    weighted residuals at a point (for the curvature along a step), and where the free
    parameters lie in the decision vector with their scaled bounds."""

    linearise: Callable[[np.ndarray], Linearisation]
    feasible_point: Callable[[np.ndarray], tuple[np.ndarray, float] | None]
    residual_value: Callable[[np.ndarray], np.ndarray]
    param_index: np.ndarray
    lower: np.ndarray
    upper: np.ndarray


# A step with parameters held on their bounds takes its reduction from the free one's
# columns (`ReducedProblem.holding`) rather than a forward substitution of its own; False
# is the earlier path (`benchmarks/descent_reductions.py`).
HELD_FROM_FREE_REDUCTION = True


def bounded_step(lin: Linearisation, problem: DescentProblem,
                 curvature: tuple[np.ndarray, np.ndarray] | None = None,
                 red: ReducedProblem | None = None) -> GaussNewtonStep:
    """The Gauss-Newton step at `lin` with each free parameter that sits on a bound held
    there where the unconstrained step would carry it outside (and every parameter
    whose bounds coincide held); with `curvature` (columns, S), S added to the
    Gauss-Newton Hessian over those columns (`gauss_newton.gauss_newton`).  `red`: `lin`
    already reduced with only its states held (`free_reduction`)."""
    idx = problem.param_index
    states_held = np.setdiff1d(lin.held, idx)
    unheld = replace(lin, held=states_held)
    red = red or reduce_linearisation(unheld)
    free = gauss_newton(unheld, red, curvature)
    values, span = lin.z[idx], problem.upper - problem.lower
    move = free.step[idx]
    hold = ((values <= problem.lower + ON_BOUND * span) & (move < 0.0)) \
        | ((values >= problem.upper - ON_BOUND * span) & (move > 0.0)) \
        | (span <= 0.0)
    if not hold.any():
        return free
    return gauss_newton(replace(lin, held=np.union1d(states_held, idx[hold])),
                        red.holding(idx[hold]) if HELD_FROM_FREE_REDUCTION else None,
                        curvature)


def free_reduction(lin: Linearisation, problem: DescentProblem) -> ReducedProblem:
    """`lin` reduced with only its states held, the free parameters all free: the
    coordinates the learnt curvature lives in, and the first reduction of `bounded_step`."""
    return reduce_linearisation(replace(lin, held=np.setdiff1d(lin.held, problem.param_index)))


def descend(z: np.ndarray, chi2: float, problem: DescentProblem, tol: float,
            max_steps: int, learn: bool = True,
            step_taken: Callable[[int, float], None] | None = None) -> DescentEnd:
    """Gauss-Newton steps from the feasible point `z` (chi-square `chi2`) through feasible
    points, for at most `max_steps` steps, until the measured decrement is below `tol`.

    With `learn`, each step may be taken with the residuals' curvature learnt from the
    steps before (`structured_secant`), where that measures more on offer along it (the
    test for the end stays Gauss-Newton's, that of an Ipopt run), and a trial that does
    not fall sets the next from the feasible curve's parabola (`feasible_curvature`),
    two trials on one parabola whose least value lies within `tol` below the point
    ending the descent there; without, Gauss-Newton steps are halved where they fail
    (the earlier path).  `step_taken(k, chi2)` is told of every step taken (progress)."""
    idx = problem.param_index
    decrement = np.inf
    secant = StructuredSecant() if learn else None
    for k in range(max_steps + 1):
        lin = problem.linearise(z)
        red = free_reduction(lin, problem)
        gn = bounded_step(lin, problem, red=red)
        decrement = measured_decrement(problem.residual_value, lin, gn)
        if decrement < tol and abs(gn.restoration) <= tol:
            return DescentEnd(z, chi2, decrement, k, True)
        if k == max_steps:
            break
        on_offer = decrement
        if secant is not None:
            # The learnt step where it measures more on offer along it than Gauss-Newton's
            # (NL2SOL likewise switches between the two models by their record): a
            # curvature learnt on the way can point the step where the valley does not go.
            secant.observe(lin.z, red.free, red.JZ, lin.r)
            learnt = bounded_step(lin, problem, (secant.columns, secant.S), red)
            measured = measured_decrement(problem.residual_value, lin, learnt)
            if measured > decrement:
                gn, on_offer = learnt, measured
        length = min(1.0, on_offer / gn.decrement) \
            if np.isfinite(on_offer) and gn.decrement > 0.0 else 1.0
        parabola: tuple[float, float] | None = None  # (c, D^2/c) of the last failed trial
        for _ in range(HALVINGS + 1):
            trial = z + length * gn.step
            trial[idx] = np.clip(trial[idx], problem.lower, problem.upper)
            found = problem.feasible_point(trial)
            if found is not None and found[1] < chi2:
                z, chi2 = found
                if step_taken is not None:
                    step_taken(k + 1, chi2)
                break
            if not learn:
                length *= 0.5
                continue
            if parabola is not None and found is not None and parabola[1] < tol and abs(
                    found[1] - (chi2 - 2.0 * gn.decrement * length + parabola[0] * length**2)
            ) <= tol:
                # Two trials on one parabola, whose least value lies less than the test's
                # tolerance below this point: along the feasible curve the step's
                # direction offers no more, and the point is as far down as a
                # Gauss-Newton step can take it.
                return DescentEnd(z, chi2, parabola[1], k, True)
            curvature = feasible_curvature(chi2, found, gn.decrement, length)
            if curvature is None:
                parabola = None
                length *= 0.5
                continue
            parabola = (curvature, gn.decrement**2 / curvature)
            # The parabola's minimum, cut to a tenth at most (a trial that rose lies at
            # least twice as far out).
            length = max(gn.decrement / curvature, 0.1 * length)
        else:
            return DescentEnd(z, chi2, decrement, k, False)
    return DescentEnd(z, chi2, decrement, max_steps, False)


def feasible_curvature(chi2: float, found: tuple[np.ndarray, float] | None,
                       decrement: float, length: float) -> float | None:
    """The curvature c of chi-square along a Gauss-Newton step through feasible points,
    from one trial `length` along it (`found`: its feasible point and chi-square), or None
    where there is no trial or the parabola does not open upwards.

    Closing the gaps moves a trial point only to second order in the step, so the
    feasible chi-square starts down the step with the Gauss-Newton slope, -2 D per unit
    length (D the step's `decrement`), and chi^2(a) = chi^2(0) - 2 D a + c a^2 through
    the trial gives c; the least chi-square along the step then lies D^2 / c below
    chi^2(0), at a = D / c.  Where the gaps' own curvature dominates (a held fill
    exponent on the Prometheus TeleMega log, in still air), a trial at 0.77 of the
    step rose by 50 where the linearisation promised a fall of 0.026: c = 84, and
    what the step can still give is 1e-5, where the residuals' curvature alone
    (`uncertainty.measured_decrement`) said 0.020 and the descent kept trying.
    """
    if found is None or not np.isfinite(found[1]) or length <= 0.0:
        return None
    curvature = (found[1] - chi2 + 2.0 * decrement * length) / length**2
    return curvature if curvature > 0.0 else None
