"""Fits that bring stiff effects in by continuation when a direct start fails.

Some effects change the dynamics so much that a solve from the offline
reduction's guess can backtrack for hundreds of iterations: elastic risers
(a spring-damper per canopy whose states the reduction can only guess).  An
effect says so with `Effect.continuation`.  A model that has such effects is
fitted from the reduction with at most DIRECT_ITERATIONS iterations; if that
fails, in two steps:

1. the relaxed model: each such effect replaced by the one it stands in for
   (`Effect.replaces`: an elastic riser by the rigid one) or left out,
   fitted from the reduction;
2. the model itself, started from that fit (`Estimator.point_from`: the
   shared states and parameters from it, the effect's own states from its
   `state_guess` and its parameters at their defaults).

Where the relaxed fit fails too, the direct start's failure is reported.

Continuation is not tried first because it is not free: on `drogue_full`
(elastic risers and added mass, seed 1) the direct start converges in 28
iterations, while the rigid-riser fit takes 31 and the full fit from it 33
more (152 s against 67 s).  On `main3_full` the direct start does not
converge at all.
"""

from __future__ import annotations

import dataclasses
import sys
from collections.abc import Callable

import numpy as np

from cpas_ocp.errors import SolverFailure
from cpas_ocp.estimation.estimator import Estimator, Fit, Settings
from cpas_ocp.inference.restarts import IMPROVEMENT_CHI2, restart_start_times
from cpas_ocp.inference.result_claim import (
    MAX_WINDOW_MOVES,
    Claim,
    WindowMove,
    check_claim,
    moved_windows,
    start_shifts,
)
from cpas_ocp.inference.shape_restarts import restart_shapes
from cpas_ocp.io.model_spec import ModelSpec
from cpas_ocp.physics.effects import Effect
from cpas_ocp.physics.effects.registry import BUILTIN
from cpas_ocp.physics.flight_test import FlightTest


def relaxed_spec(spec: ModelSpec, test: FlightTest) -> ModelSpec | None:
    """`spec` without its continuation effects (each replaced by the effect it stands in
    for, if any), its fixed, freed and prior parameters restricted to what remains; None
    when `spec` has no continuation effect."""
    if not any(effect.continuation for effect in spec.effects):
        return None
    effects: list[Effect] = []
    for effect in spec.effects:
        if not effect.continuation:
            effects.append(effect)
        elif effect.replaces is not None:
            effects.append(BUILTIN[effect.replaces].build({}, spec.source, effect.replaces))
    relaxed = dataclasses.replace(spec, effects=tuple(effects), fix={}, free=(), priors={})
    names = set(relaxed.model(test).parameter_names)
    return dataclasses.replace(
        relaxed, fix={k: v for k, v in spec.fix.items() if k in names},
        free=tuple(n for n in spec.free if n in names),
        priors={k: v for k, v in spec.priors.items() if k in names})


def relaxed_settings(settings: Settings, names: set[str]) -> Settings:
    """`settings` with its free, fixed and guessed parameters restricted to `names`."""
    return dataclasses.replace(
        settings, free=None if settings.free is None else [n for n in settings.free
                                                          if n in names],
        fixed={k: v for k, v in settings.fixed.items() if k in names},
        guess={k: v for k, v in settings.guess.items() if k in names})


# Iterations a direct start of a model with continuation effects gets before the fit goes
# through the relaxed model instead; direct starts that converge take 28 (`drogue_full`).
DIRECT_ITERATIONS = 100


def solve(est: Estimator, progress: bool = False) -> Fit:
    """Fit `est`'s model from the reduction; where it has continuation effects and the
    direct start fails, through its relaxed model (see the module docstring); where
    that fails or leaves an opening's shape on a guessed bound, from the reduction
    with other shapes (`shape_restarts`); then restarted with the start times that
    misfit moved (`restarts`).  Raises SolverFailure as `Estimator.solve` does, for
    the first attempt where no other converges."""
    return _restarted(est, lambda: _solve_from_reduction(est, progress), progress)


def _restarted(est: Estimator, first: Callable[[], Fit], progress: bool) -> Fit:
    """`first()` with its shapes and then its misfitting start times restarted."""
    fit = restart_shapes(est, first, progress)
    return restart_start_times(est, fit, progress)[0]


def solve_checked(est: Estimator, progress: bool = False
                  ) -> tuple[Estimator, Fit, Claim]:
    """`solve`, then what the fit may claim (`result_claim`).

    Where the fit is not a plain result and start times sit at their windows'
    edges, those windows are centred on the edges and the phase fitted again from
    the reduction (`result_claim.moved_windows`), up to MAX_WINDOW_MOVES times,
    while the refit lowers chi-square.  Returns the estimator of the fit kept (a
    moved model's own), the fit and its claim, which lists the moves.

    A first fit from the reduction that converges with start times at their edges
    has its windows moved before any restart: the restarts search the same windows,
    and where the events that seeded them are off, each ends at the same edges (events
    1.5 s late on `drogue`: three shape restarts of 95-124 iterations each, 26 s, all
    pressed at chi-square 363,203, before a move reached the noise in 6 iterations).
    Where that first move does not lower chi-square, the fit is restarted and judged
    as if no move had been tried.

    A first fit that fails with start times at their windows' edges at its last
    iterate has its windows moved before any restart too, and the moved fit is kept at
    once where it is a result at the noise: the same 1.5 s late events stall from the
    reduction on some installs (Stalled_Without_Progress after 95 iterations, chi-square
    363,605, with numpy 2.4 and scipy 1.17), and moving from the stalled iterate saves
    the restarts that would end at the same edges (`benchmarks/events_offset.py
    --against REV` times both orders).
    Otherwise the failed fit is judged at its last iterate the same way as a converged
    one, after its restarts (a failed run is never a plain result); the first failure
    is raised where no window moves or no moved model converges.
    """
    claim: Claim | None = None
    tried = False
    try:
        first: Fit | SolverFailure = _solve_from_reduction(est, progress)
    except SolverFailure as exc:
        first, claim = exc, _judged(est, exc)  # its last iterate's, judged once
        from_stall = _moved_from_failure(est, exc, claim, progress)
        if from_stall is not None:
            return _with_moves(*from_stall)
    if isinstance(first, Fit):
        claim = check_claim(est, first)
        tried = moved_windows(claim, est, first) is not None
        if tried:
            moved = _moved(est, first, claim, None, progress)
            if moved[3]:
                return _with_moves(*moved)
    fit, claim, failure = _restarted_claim(est, first, claim, progress)
    if tried and fit is first:  # the same move from the same fit: tried already
        return _with_moves(est, fit, claim, [], None)
    return _with_moves(*_moved(est, fit, claim, failure, progress))


def _judged(est: Estimator, failure: SolverFailure) -> Claim | None:
    """What a failed run's last iterate may claim (`check_claim`); None where it has no
    iterate or that iterate cannot be linearised (a NaN there)."""
    if not isinstance(failure.last_iterate, Fit):
        return None
    try:
        return check_claim(est, failure.last_iterate)
    except (ValueError, np.linalg.LinAlgError):
        return None


def _moved_from_failure(est: Estimator, failure: SolverFailure, claim: Claim | None,
                        progress: bool
                        ) -> tuple[Estimator, Fit, Claim, list[WindowMove], None] | None:
    """The windows moved from a failed first fit's last iterate (`_moved`), whose claim
    is `claim` (`_judged`), where its start times sit at their windows' edges, kept where
    the moves end in a converged result at the noise; None otherwise (the restarts then
    go first)."""
    if claim is None or moved_windows(claim, est, failure.last_iterate) is None:
        return None
    est, fit, claim, moves, still = _moved(est, failure.last_iterate, claim, failure,
                                           progress)
    if still is not None or not moves or not (claim.is_result and claim.fits_noise):
        return None
    return est, fit, claim, moves, None


def _restarted_claim(est: Estimator, first: Fit | SolverFailure, claim: Claim | None,
                     progress: bool) -> tuple[Fit, Claim, SolverFailure | None]:
    """The first fit restarted (`_restarted`) and its claim (`claim`, the first's, where
    no restart replaced it; a failed first's is its last iterate's, `_judged`); where
    every start fails, the failure's last iterate and its claim with the failure, which
    is raised where its last iterate cannot be judged."""
    def given() -> Fit:
        if isinstance(first, SolverFailure):
            raise first
        return first

    try:
        fit = _restarted(est, given, progress)
        return (fit, claim if fit is first and claim is not None else check_claim(est, fit),
                None)
    except SolverFailure as exc:
        judged = claim if exc is first else _judged(est, exc)
        if judged is None:  # no last iterate, or one unfit to linearise: the failure stands
            raise exc from None
        return exc.last_iterate, judged, exc


def _moved(est: Estimator, fit: Fit, claim: Claim, failure: SolverFailure | None,
           progress: bool
           ) -> tuple[Estimator, Fit, Claim, list[WindowMove], SolverFailure | None]:
    """The windows moved from `fit` while each move's refit (`solve`) lowers chi-square:
    the estimator, fit and claim kept, the moves and the failure still standing."""
    moves: list[WindowMove] = []
    for _ in range(MAX_WINDOW_MOVES):
        spec = moved_windows(claim, est, fit)
        if spec is None:
            break
        base = start_shifts(est.spec)
        shifted = {n: v for n, v in start_shifts(spec).items() if base.get(n) != v}
        if progress:
            print(f"start times at their windows' edges ({', '.join(shifted)}) in a fit that "
                  f"is not a plain result: moving the windows and fitting again ...",
                  file=sys.stderr, flush=True)
        # The grid follows the windows: its fine intervals cover each start time's window.
        moved = Estimator(est.test, spec, dataclasses.replace(est.settings, nodes=None,
                                                                     interval_steps=None))
        try:
            refit = solve(moved, progress)
        except SolverFailure:
            break
        # A failed first fit's last iterate is no optimum to improve on: any converged
        # refit replaces it.
        if failure is None and refit.chi_square > fit.chi_square - IMPROVEMENT_CHI2:
            break
        moves += [WindowMove(n, v - base.get(n, 0.0), fit.chi_square, refit.chi_square)
                  for n, v in shifted.items()]
        est, fit, failure = moved, refit, None
        claim = check_claim(est, fit)
    return est, fit, claim, moves, failure


def _with_moves(est: Estimator, fit: Fit, claim: Claim, moves: list[WindowMove],
                failure: SolverFailure | None) -> tuple[Estimator, Fit, Claim]:
    """The outcome of `solve_checked`: the failure raised where it stands, else the
    estimator, fit and claim with the moves recorded."""
    if failure is not None:
        raise failure
    claim.moves = moves
    if moves:
        fit.solver.start += "; " + "; ".join(f"{m.parameter}'s window moved "
                                            f"{m.shift_s:+.2f} s" for m in moves)
    return est, fit, claim


def _solve_from_reduction(est: Estimator, progress: bool) -> Fit:
    relaxed = relaxed_spec(est.spec, est.test)
    if relaxed is None:
        return est.solve(progress=progress)
    try:
        return est.solve(progress=progress, max_iter=min(DIRECT_ITERATIONS,
                                                         est.settings.max_iter))
    except SolverFailure as exc:
        direct = exc
    failed = f"{direct.status} after {direct.iterations} iterations"
    names = set(relaxed.model(est.test).parameter_names)
    try:
        first = Estimator(est.test, relaxed, relaxed_settings(est.settings, names)).solve(
            progress=progress)
    except SolverFailure:
        raise direct from None  # the user's model's own failure, not the relaxed one's
    fit = est.solve(progress=progress, start=est.point_from(first))
    fit.solver.start = (f"a fit with {relaxation_text(est.spec)} ({first.solver.iterations} "
                        f"iterations), after a start from the offline reduction failed "
                        f"({failed})")
    return fit


def relaxation_text(spec: ModelSpec) -> str:
    """What the relaxed model changes: "rigid_riser in place of elastic_riser", "no X"."""
    return ", ".join(f"{e.replaces} in place of {e.name}" if e.replaces else f"no {e.name}"
                     for e in spec.effects if e.continuation)
