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

from .uncertainty import GaussNewtonStep, Linearization, gauss_newton, measured_decrement

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

    linearize: Callable[[np.ndarray], Linearization]
    feasible_point: Callable[[np.ndarray], tuple[np.ndarray, float] | None]
    residual_value: Callable[[np.ndarray], np.ndarray]
    param_index: np.ndarray
    lower: np.ndarray
    upper: np.ndarray


def bounded_step(lin: Linearization, problem: DescentProblem) -> GaussNewtonStep:
    """The Gauss-Newton step at `lin` with each free parameter that sits on a bound held
    there where the unconstrained step would carry it outside (and every parameter
    whose bounds coincide held)."""
    idx = problem.param_index
    states_held = np.setdiff1d(lin.held, idx)
    free = gauss_newton(replace(lin, held=states_held))
    values, span = lin.z[idx], problem.upper - problem.lower
    move = free.step[idx]
    hold = ((values <= problem.lower + ON_BOUND * span) & (move < 0.0)) \
        | ((values >= problem.upper - ON_BOUND * span) & (move > 0.0)) \
        | (span <= 0.0)
    if not hold.any():
        return free
    return gauss_newton(replace(lin, held=np.union1d(states_held, idx[hold])))


def descend(z: np.ndarray, chi2: float, problem: DescentProblem, tol: float,
            max_steps: int) -> DescentEnd:
    """Gauss-Newton steps from the feasible point `z` (chi-square `chi2`) through feasible
    points, for at most `max_steps` steps, until the measured decrement is below `tol`."""
    idx = problem.param_index
    decrement = np.inf
    for k in range(max_steps + 1):
        lin = problem.linearize(z)
        gn = bounded_step(lin, problem)
        decrement = measured_decrement(problem.residual_value, lin, gn)
        if decrement < tol and abs(gn.restoration) <= tol:
            return DescentEnd(z, chi2, decrement, k, True)
        if k == max_steps:
            break
        length = min(1.0, decrement / gn.decrement) \
            if np.isfinite(decrement) and gn.decrement > 0.0 else 1.0
        for _ in range(HALVINGS + 1):
            trial = z + length * gn.step
            trial[idx] = np.clip(trial[idx], problem.lower, problem.upper)
            found = problem.feasible_point(trial)
            if found is not None and found[1] < chi2:
                z, chi2 = found
                break
            length *= 0.5
        else:
            return DescentEnd(z, chi2, decrement, k, False)
    return DescentEnd(z, chi2, decrement, max_steps, False)
