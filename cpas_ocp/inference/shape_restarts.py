"""Restarts from the offline reduction where a fit ends with an opening's shape on a guessed
bound, or does not converge.

A canopy's fill constant n (n_p) and shape exponent expopen (and an infinite-mass
stage's settling time t_k) have bounds that are guesses of a plausible range
(`Parameter.physical_lower`/`physical_upper` False).  Where the data barely
determine an opening (a rocket's drogue opening at apogee, near zero airspeed,
where the fill time n D / V changes with the start time as fast as with n;
an altimeter alone, which sees the opening only through the descent it leaves),
a fit from one start can run onto such a bound, or wander for its iteration
limit between bound and interior.  On a 20 Hz altimeter-only rocket log whose
reduction started the drogue at n = expopen = 0.3, the lower bounds, Ipopt
stopped at its 500 iterations.

So the fit is started again from the reduction with every shape parameter of
each such stage (all stages' where the fit failed) at its default times each of
SHAPE_START_FACTORS, moved inside its bounds (`stage_curve_fit.inside_bounds`),
and the converged fit of least chi-square is kept: a restart replaces the
first fit where it lowers chi-square by more than IMPROVEMENT_CHI2 (or where
the first did not converge).  A fit whose shapes lie inside their bounds costs
nothing more.

A start that is the reduction's own (the reduction left every restarted shape at
its default, as it does for a stage an altimeter alone barely sees, and the factor
is 1) is not solved again where the first fit was solved from it: the solve is
deterministic and would repeat the first fit iteration for iteration (to rounding,
where one of the two ran in CasADi's virtual machine and the other in native code).
On the NDRT 2020 log (`problems/ndrt_2020.json`), whose main's fill constant ends on
its guessed upper bound, that restart repeated the first fit's 51 iterations.  The same
holds where the first attempt failed from the reduction's point (its last iterate records
where it started): there the repeat had run the whole 500 iterations of the failure
again, 75 s, before the starts at other shapes converged.
"""

from __future__ import annotations

import sys
from collections.abc import Callable

import numpy as np

from cpas_ocp.errors import SolverFailure
from cpas_ocp.estimation.estimator import Estimator, Fit
from cpas_ocp.estimation.fit import FROM_REDUCTION
from cpas_ocp.estimation.stage_curve_fit import inside_bounds
from cpas_ocp.inference.restarts import IMPROVEMENT_CHI2
from cpas_ocp.physics.parameters import split_name

SHAPE_PARAMETERS = ("n", "n_p", "expopen", "t_k")  # an opening's shape, per canopy stage
# Starts tried, as factors on each shape parameter's default (fill constant 8: 8, 4, 16).
SHAPE_START_FACTORS = (1.0, 0.5, 2.0)


def shapes_on_guessed_bounds(est: Estimator, values: dict[str, float]) -> list[str]:
    """The free shape parameters whose `values` lie within the curve fit's margin
    (`stage_curve_fit.BOUND_MARGIN`) of a bound that is a guess."""
    out = []
    for name in est.free:
        if split_name(name)[0] not in SHAPE_PARAMETERS:
            continue
        prm = est.model.parameter(name)
        value = values[name]
        moved = inside_bounds(value, prm.lower, prm.upper)
        if (moved > value and not prm.physical_lower) or (moved < value
                                                          and not prm.physical_upper):
            out.append(name)
    return out


def _solved_from_reduction(est: Estimator, fit: Fit | None,
                           failure: SolverFailure | None) -> bool:
    """Whether the first fit, or the first attempt that failed, was solved from the
    reduction's own point with the estimator's whole iteration limit: solving that start
    again would repeat it (a failure stopped short of the limit, a direct start of a model
    with continuation effects, is not repeated by a full solve)."""
    if fit is not None:
        return fit.solver.start == FROM_REDUCTION
    last = failure.last_iterate if failure is not None else None
    if last is None or last.solver.start != FROM_REDUCTION:
        return False
    return not (failure.status == "Maximum_Iterations_Exceeded"
                and failure.iterations < est.settings.max_iter)


def restart_shapes(est: Estimator, first: Callable[[], Fit], progress: bool = False) -> Fit:
    """`first()`, or the best fit from the reduction with the shapes of the stages it left
    on guessed bounds (of every stage, where it failed) restarted (module docstring).
    Raises the first fit's SolverFailure where no restart converges either."""
    failure: SolverFailure | None = None
    fit: Fit | None = None
    try:
        fit = first()
    except SolverFailure as exc:
        failure = exc
    stuck = (shapes_on_guessed_bounds(est, fit.parameters) if fit is not None else
             [n for n in est.free if split_name(n)[0] in SHAPE_PARAMETERS])
    if not stuck:
        if fit is None:
            assert failure is not None
            raise failure
        return fit
    stages = {split_name(n)[1] for n in stuck}
    names = [n for n in est.free
             if split_name(n)[0] in SHAPE_PARAMETERS and split_name(n)[1] in stages]
    start = est.initial_point()
    best, how = fit, ""
    for factor in SHAPE_START_FACTORS:
        z = start
        for name in names:
            prm = est.model.parameter(name)
            z = est.with_value(z, name, inside_bounds(factor * prm.default, prm.lower,
                                                      prm.upper))
        if np.array_equal(z, start) and _solved_from_reduction(est, fit, failure):
            continue  # the reduction's own start, from which the first fit was solved
        if progress:
            print(f"{', '.join(stuck)} on a guessed bound: fitting again from the reduction "
                  f"with {', '.join(names)} at {factor:g} x their defaults ...",
                  file=sys.stderr, flush=True)
        try:
            trial = est.solve(progress=progress, start=z)
        except SolverFailure:
            continue
        if best is None or trial.chi_square < best.chi_square - IMPROVEMENT_CHI2:
            best, how = trial, f"{factor:g} x their defaults"
    if best is None:
        assert failure is not None
        raise failure
    if best is not fit:
        before = (f"chi-square {fit.chi_square:.2f}" if fit is not None else
                  f"{failure.status if failure else ''}")
        best.solver.start += (f"; restarted from the reduction with {', '.join(names)} at "
                              f"{how} ({', '.join(stuck)} ended on a guessed bound or the fit "
                              f"failed: {before} -> chi-square {best.chi_square:.2f})")
    return best
