"""Discovery: diagnose, add what the diagnosis confirms, refit from the nested fit, and again.

One diagnosis names at most one missing effect, and a test may lack several:
drogue data flown with added mass and a GPS latency are explained by neither
alone.  `discover` repeats the diagnosis on the model each step ends with:

1. diagnose the fit (`diagnosis.diagnose`: score tests of every library or
   plug-in effect the model does not use, the leading ones confirmed by a
   refit and a likelihood-ratio test, and the air's motion where the altitude
   sensors share their residual);
2. where it names a missing effect, take the confirming refit (started from
   the fit before, so each step is nested in the last) as the next step's
   fit and model;
3. where nothing is named, go past the library's effects as they are
   (`_beyond_the_library`), cheapest and most specific first:
   * refine the effects the chain added, each once (within the noise too: a
     wrong form can hide in the total's spread): free a structural constant
     of each (an exponent, a start time: `refinement.refine`), kept by its
     likelihood ratio at the family-wise level over the refinements tried
     (an added effect whose own windows stay off the noise is refined at
     once, before anything else is asked to take up the rest);
   * where the residuals keep structure, write the plug-ins the signature
     asks for (`candidate_plugins.propose`: a periodic line, a load-cell
     residual that follows the load, one that follows altitude), load each
     from its file and test it as written, like a library effect (score
     test, confirming refit, likelihood ratio at the family-wise level over
     the plug-ins proposed);
   * at a misfit, refit every tested effect whatever its score, from its
     score step and its defaults (`diagnosis.confirm_at_misfit`: the score
     test is local);
   * at a misfit, once per chain, a drag law by sparse regression
     (`sparse_terms.select`: every term against none, then backward
     elimination at alpha over the terms);
   the first that makes a step is the next step;
4. after each step, drop every earlier effect added as a stand-in that the
   model no longer needs (its removal refitted from the last fit, and
   keeping it not significant: `_drop_stand_ins`), a step of its own, and
   never test it again;
5. where a confirming refit (nested in the fit before) looks like a wrong
   basin (far above the noise, implausible estimates, identical canopies
   given different constants), fit the same model from other starts too and
   keep the lowest (`from_other_starts`); before the verdict, the same for
   the last model, then every effect added tested again against the last
   model and dropped where not significant (`_drop_unneeded`);
6. end in one of four states (`Discovery.state`): consistent with the
   noise (the last fit's chi-square above it neither overall nor in any
   window, `noise_test`; a shape the residuals keep within the noise's size
   is described, not called a misfit), below the noise (the total in the
   chi-square's lower tail: the stated sigma too large, or fewer independent
   samples than counted), a misfit nothing tested explains (the chi-square
   above the noise; the last diagnosis describes what remains: its signature
   and the next move), or stopped early (the step limit, or a refit that
   would add the effect did not converge: its likelihood ratio is only a
   bound, and a bound is not a step).

Every step keeps its fit, so each fall in chi-square is the likelihood ratio
of one nested pair, tested at the diagnosis's family-wise level.  Each step
also says how much of the misfit before it removes (the share of the excess
chi-square, overall and per window that departed from the noise) and, where
the diagnosis found the effect only partly explains the residual
(`Diagnosis.stand_in`: an implausible estimate, or windows it acts in that
stay off the noise), what remains.
"""

from __future__ import annotations

import dataclasses
import itertools
import math
import tempfile
import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from scipy.stats import chi2, norm

from cpas_ocp.discrepancy.candidate_plugins import Proposal, propose
from cpas_ocp.discrepancy.diagnosis import (
    ALPHA,
    CONFIRM_TOP,
    Diagnosis,
    confirm_at_misfit,
    diagnose,
)
from cpas_ocp.discrepancy.refinement import RefinementTrial, best_kept, refine
from cpas_ocp.discrepancy.score_test import CONFIRM_MAX_ITER, ScoreTest, confirm, score_test
from cpas_ocp.discrepancy.sparse_terms import TermSelection, select
from cpas_ocp.errors import InputError, SolverFailure
from cpas_ocp.estimation.estimator import Estimator, Fit, Settings
from cpas_ocp.estimation.fit import FROM_REDUCTION
from cpas_ocp.estimation.kkt_system import NonFiniteCurvature
from cpas_ocp.inference.continuation import solve as solve_with_continuation
from cpas_ocp.inference.diagnostics import (
    WindowStatistic,
    excess_removed,
    explained_share,
    window_statistics,
    worst_window,
)
from cpas_ocp.inference.model_comparison import Criteria, LikelihoodRatio, one_sided_count, refit
from cpas_ocp.inference.noise_test import NoiseTest, noise_test
from cpas_ocp.inference.phase_windows import phase_windows
from cpas_ocp.inference.restarts import IMPROVEMENT_CHI2, restart_start_times
from cpas_ocp.interrupts import Interrupted
from cpas_ocp.io.model_spec import ModelSpec
from cpas_ocp.physics.effects.registry import EffectType, load_plugin
from cpas_ocp.physics.flight_test import FlightTest
from cpas_ocp.physics.parameters import split_name
from cpas_ocp.precision import with_sigma

MAX_STEPS = 4  # effects added at most, by default


@dataclass
class DiscoveryStep:
    """One model of the chain: the effect it added to the one before (None for the first),
    its spec and fit, the test that admitted the effect (a likelihood ratio, or 2 ln B
    for the air's motion), and the diagnosis of its fit (None where none was made)."""

    added: str | None
    spec: ModelSpec
    fit: Fit
    admitted_by: str = ""
    diagnosis: Diagnosis | None = None
    # The share of the step before's excess chi-square this step removed, overall and in
    # each window of it that departed from the noise (`diagnostics.excess_removed`).
    explained: float = float("nan")
    windows_explained: list[tuple[WindowStatistic, WindowStatistic, float]] = field(
        default_factory=list)
    # Why the effect added may be only a stand-in (`Diagnosis.stand_in`); empty where not.
    stand_in: list[str] = field(default_factory=list)
    # The stand-in this step drops from the model before it (None where it adds one).
    dropped: str | None = None
    # The effect this step refines (`Refinement`: a structural constant freed), and how;
    # None where it adds or drops one.
    refined: str | None = None
    refinement: str = ""
    # The estimator of `fit` (for its covariance), where the chain kept it.
    estimator: Estimator | None = field(default=None, repr=False)
    # Which start the step's fit came from, where more than one was tried (`best_start`).
    start: str = ""
    searched: bool = False  # whether other starts were tried for `fit`
    # Wall-clock seconds spent finding this step (the diagnosis before it, its refits and
    # starts) and diagnosing it.
    found_s: float = 0.0
    diagnosed_s: float = 0.0
    # The verdict and worst window of a diagnosis made before the chain was read back from
    # its folder (`discovery_checkpoint`), where the diagnosis itself is not kept.
    recorded_verdict: str | None = None
    recorded_worst: tuple[str, float] | None = None

    @property
    def label(self) -> str:
        """What the step did: the effect it added, "without X" where it dropped X."""
        if self.dropped is not None:
            return f"without {self.dropped}"
        if self.refined is not None:
            return f"{self.refined} refined"
        return self.added or "start"

    @property
    def criteria(self) -> Criteria:
        return Criteria.of(self.fit)

    @property
    def channel_rms(self) -> dict[str, float]:
        """Normalised RMS of each sensor channel ("sensor.channel"), pseudo-sensors left out."""
        return {f"{r.sensor}.{r.channel}": float(np.sqrt(np.mean(r.normalised**2)))
                for r in self.fit.residuals
                if r.sensor not in self.fit.pseudo_sensors and r.t.size}

    def explained_lines(self, shown: int = 3) -> list[str]:
        """How much of the step before's misfit this step explains: overall, and in the
        `shown` windows that departed from the noise most."""
        if self.dropped is not None:
            return [f"{self.dropped} dropped: with the effects added after it, {self.admitted_by}"]
        what = (self.added if self.refined is None
                else f"{self.refined} refined ({self.refinement})")
        lines = [f"{what} removes {100 * self.explained:.0f} % of the excess "
                 "chi-square" + (", and only partly explains it (a stand-in?)" if self.stand_in
                                else "")]
        lines += [f"  {w.sensor}.{w.channel} {w.window}: {100 * share:.0f} % of its excess "
                  f"{w.excess:.1f}" for w, _, share in self.windows_explained[:shown]]
        lines += [f"  what remains: {reason}" for reason in self.stand_in]
        return lines

    @property
    def verdict(self) -> str | None:
        """The verdict of the step's diagnosis (None where none was made)."""
        return self.recorded_verdict if self.diagnosis is None else self.diagnosis.verdict()

    @property
    def worst_window(self) -> tuple[str, float] | None:
        """The diagnosed window with the largest chi-square excess and its normalised RMS."""
        if self.diagnosis is None:
            return self.recorded_worst
        w = worst_window(self.diagnosis.statistics)
        return None if w is None else (f"{w.sensor}.{w.channel} {w.window}", w.normalised_rms)


@dataclass
class ProposalTrial:
    """A plug-in proposed from a signature at step `step`, and its test as written: the
    score test at that step's fit with its confirming refit (`score_test.confirm`), and
    whether the refit's likelihood ratio passed the family-wise level over the `tried`
    plug-ins proposed there."""

    step: int
    proposal: Proposal
    test: ScoreTest
    tried: int
    confirmed: bool = False

    def __str__(self) -> str:
        """One line: the plug-in, why it was proposed, and what its test found."""
        lr = self.test.refit
        if lr is None:
            found = (self.test.refit_note or self.test.note
                     or f"not significant (score statistic {self.test.statistic:.1f}, "
                        f"p = {self.test.p_value:.2g})")
        else:
            estimates = ", ".join(f"{n} = {v:.4g}" for n, v in self.test.refit_estimate.items())
            verdict = "confirmed" if self.confirmed else "not confirmed"
            found = (f"likelihood ratio {'>= ' if lr.lower_bound else ''}{lr.statistic:.1f} on "
                     f"{lr.dof}, p = {lr.p_value:.2g} ({verdict} over {self.tried} plug-in(s) "
                     f"proposed); {estimates}")
        return (f"step {self.step}: proposed/{self.proposal.file_name} for "
                f"{self.proposal.reason}: {found}")


@dataclass
class Discovery:
    """The chain of models and why it ended; the plug-ins proposed from signatures on the
    way (`proposals`, with their tests) and their effect types by name (`plugins`)."""

    steps: list[DiscoveryStep] = field(default_factory=list)
    stopped: str = ""
    # What the reader must know about the chain's start (a first fit that is not a result).
    notes: list[str] = field(default_factory=list)
    proposals: list[ProposalTrial] = field(default_factory=list)
    plugins: dict[str, EffectType] = field(default_factory=dict)
    # The refinements tried of effects the chain added, with their tests (`refinement`).
    refinements: list[RefinementTrial] = field(default_factory=list)
    # The sparse regressions of a drag law tried (`sparse_terms`), at most one per chain.
    regressions: list[TermSelection] = field(default_factory=list)
    # How the chain ended: "consistent" (the last fit's chi-square not above the noise),
    # "below the noise" (in its lower tail), "misfit" (nothing left is confirmed and the
    # chi-square lies above the noise) or "stopped early" (the step limit, or a refit that
    # did not converge); "in progress" while it runs.
    state: str = ""
    alpha: float = ALPHA

    @property
    def noise(self) -> NoiseTest:
        """The last fit's chi-square, overall and per window, against the noise."""
        last = self.steps[-1]
        diag = last.diagnosis
        if diag is not None and diag.fit is last.fit:
            return diag.noise
        windows = phase_windows(last.fit)
        return noise_test(last.fit, window_statistics(last.fit, windows), self.alpha)

    @property
    def seconds(self) -> float:
        """Wall-clock seconds of the whole chain."""
        return sum(s.found_s + s.diagnosed_s for s in self.steps)

    def ending(self) -> str:
        """How the chain ended, in words: its state, the last fit's noise test (with its
        p-value), and why it stopped."""
        noise = self.noise
        if self.state == "consistent":
            head = "consistent with the noise"
        elif self.state == "below the noise":
            head = (f"below the noise (the stated sigma about "
                    f"{100 * (1.0 / noise.sigma_scale - 1.0):.0f} % too large, or fewer "
                    "independent samples than counted)")
        elif self.state == "misfit":
            head = "a misfit nothing tested explains"
        elif self.state == "in progress":
            head = "in progress (the chain goes on)"
        else:
            head = "stopped early"
        return (f"{head}: {noise}; {self.stopped} ({len(self.steps) - 1} step(s), "
                f"{self.seconds:.0f} s)")

    def index(self, step: DiscoveryStep) -> int:
        """The position of `step` in the chain (by identity: steps hold fits)."""
        return next(k for k, s in enumerate(self.steps) if s is step)

    @property
    def added(self) -> int:
        """Steps that added an effect."""
        return sum(s.dropped is None for s in self.steps[1:])

    @property
    def dropped(self) -> set[str]:
        """Effects a step dropped (as stand-ins no longer needed); never tested again."""
        return {s.dropped for s in self.steps if s.dropped is not None}


class InterruptedDiscovery(Interrupted):
    """A signal that stopped `discover`, with the chain of the steps it had finished
    (`partial`: each step's fit, the diagnoses made; its state "stopped early")."""

    def __init__(self, signum: int, partial: Discovery) -> None:
        super().__init__(signum)
        self.partial = partial


def next_step(diag: Diagnosis, progress: bool = False) -> DiscoveryStep | str:
    """The step the diagnosis `diag` confirms, or why there is none."""
    air = diag.air
    if air is not None and air.decisive and air.best_spec is not None \
            and air.best_fit is not None:
        return DiscoveryStep("wind_process", air.best_spec, air.best_fit,
                             f"2 ln B = {air.two_ln_b:.1f} over still air")
    best = diag.explanation
    if best is None:
        if not diag.consistent_with_noise:
            return "nothing left is confirmed: the last diagnosis says what remains"
        return ("the residuals lie below the noise" if diag.noise.below
                else "the residuals are consistent with the noise")
    if best.refit is not None and best.spec is not None:
        from_other_starts(diag, best, progress)
    if _unconverged(best):
        return (f"the refit that would add {best.effect} did not converge, nor its fit from "
                "the offline reduction: its likelihood ratio is only a bound")
    implausible = diag.implausible(best)
    if implausible:
        # The next confirmed effect whose estimates are plausible, if any (the diagnosis
        # refits candidates past the score tests' leaders to find one where it must:
        # `confirm_past_stand_ins`).
        for other in diag.confirmed():
            if other is best:
                continue
            from_other_starts(diag, other, progress)
            if not diag.implausible(other):
                return _step_of(diag, other, f"{other.refit}; {best.effect}, ranked "
                                             "above it, is implausible")
        return (f"{best.effect} fits part of the residual only with an implausible estimate "
                f"({'; '.join(implausible)}): a stand-in, not added")
    return _step_of(diag, best, str(best.refit))


def _unconverged(best: ScoreTest) -> bool:
    """Whether no refit adding `best`'s effect converged: its likelihood ratio is at most a
    bound, and the chain cannot take the step."""
    return best.refit is None or best.refit.lower_bound or best.refitted is None \
        or best.spec is None


def _ending_state(diag: Diagnosis) -> str:
    """The state of a chain that stops at the diagnosis `diag` with no step to take:
    "consistent" or "below the noise" (`Diagnosis.consistent_with_noise`, `NoiseTest.below`),
    "stopped early" where the effect it confirms could not be added (no refit converged),
    else "misfit"."""
    if diag.consistent_with_noise:
        return "below the noise" if diag.noise.below else "consistent"
    best = diag.explanation
    return "stopped early" if best is not None and _unconverged(best) else "misfit"


def _step_of(diag: Diagnosis, best: ScoreTest, admitted_by: str) -> DiscoveryStep:
    """The step that adds `best`'s effect with its refit (the lowest start kept)."""
    assert best.spec is not None and best.refitted is not None
    est, fit = best.refitted
    return DiscoveryStep(best.effect, best.spec, fit, admitted_by,
                         stand_in=diag.stand_in(best), estimator=est, start=best.start or "",
                         searched=best.start is not None)


def far_from_noise(fit: Fit, alpha: float) -> bool:
    """Whether `fit`'s chi-square lies above its dof by more than the normal quantile at
    `alpha` times its spread sqrt(2 dof): a misfit the noise does not give."""
    return fit.chi_square > fit.dof + norm.isf(alpha) * math.sqrt(2.0 * fit.dof)


def twins_apart(est: Estimator, fit: Fit, names: Sequence[str], alpha: float) -> list[str]:
    """The parameters among `names` of identical canopies (the same type, size, mass,
    inflation law and stages) whose estimates differ by more than the two-sided normal
    quantile at `alpha` times the standard error of their difference, each pair in words.

    An effect's constant of a canopy design (an added-mass factor, a fill constant's
    correction) is the same for two canopies of that design; a fit that gives them
    factors of 1.26 and 0.98 has bent one to stand in for something else, a sign of
    a wrong basin."""
    canopies = {c.name: c for c in fit.test.parachutes}
    groups: dict[tuple, list[str]] = {}
    for name in names:
        if name not in fit.free:
            continue
        base, index = split_name(name)
        design = [dataclasses.replace(canopies[i], name="") for i in index if i in canopies]
        if len(design) != 1:
            continue
        rest = tuple(i for i in index if i not in canopies)
        groups.setdefault((base, rest, repr(design[0])), []).append(name)
    pairs = [(a, b) for group in groups.values() for a, b in itertools.pairwise(group)]
    if not pairs:
        return []
    try:
        cov = est.covariance(fit)
    except NonFiniteCurvature:
        return []
    z = float(norm.isf(alpha / 2.0))
    out = []
    for a, b in pairs:
        if a not in cov.names or b not in cov.names:
            continue
        i, j = cov.names.index(a), cov.names.index(b)
        var = cov.matrix[i, i] + cov.matrix[j, j] - 2.0 * cov.matrix[i, j]
        gap = fit.parameters[a] - fit.parameters[b]
        if var > 0 and abs(gap) > z * math.sqrt(var):
            out.append(f"{a} = {fit.parameters[a]:.4g} and {b} = {fit.parameters[b]:.4g} "
                       f"differ by {abs(gap) / math.sqrt(var):.1f} sigma for identical canopies")
    return out


def fresh_fit(test: FlightTest, spec: ModelSpec, settings: Settings, max_iter: int,
              progress: bool = False) -> tuple[Estimator, Fit] | None:
    """`spec` fitted to `test` from its offline reduction (`continuation.solve`, with its
    own shape and start-time restarts), on `settings` without the nested fit's grid,
    guesses, freed or held parameters and limits, with the iteration limit `max_iter`;
    None where it does not converge."""
    settings = dataclasses.replace(settings, nodes=None, interval_steps=None, guess={},
                                   free=None, fixed={}, limits={}, max_iter=max_iter)
    try:
        est = Estimator(test, spec, settings)
        return est, solve_with_continuation(est, progress)
    except (SolverFailure, InputError):
        return None


def best_start(est: Estimator, fit: Fit, max_iter: int, progress: bool = False
               ) -> tuple[Estimator, Fit, str] | None:
    """The same model as `fit` (of `est`) from other starts, where one ends lower by more
    than IMPROVEMENT_CHI2: the fit with the start times whose windows misfit moved
    (`restarts.restart_start_times`), and a fit from the offline reduction
    (`fresh_fit`) with the iteration limit `max_iter`.  The lowest, with which start it
    came from, or None where `fit` stays lowest."""
    tried: list[tuple[Estimator, Fit, str]] = []
    moved, restarts = restart_start_times(est, fit, progress)
    if restarts:
        tried.append((est, moved, "; ".join(str(r) for r in restarts)))
    fresh = fresh_fit(fit.test, est.spec, fit.settings, max_iter, progress)
    if fresh is not None:
        tried.append((*fresh, FROM_REDUCTION))
    best = min(tried, key=lambda t: t[1].chi_square, default=None)
    if best is None or best[1].chi_square >= fit.chi_square - IMPROVEMENT_CHI2:
        return None
    return (best[0], best[1], f"{best[2]} (chi-square {best[1].chi_square:.1f} against "
                              f"{fit.chi_square:.1f} from the fit before)")


def from_other_starts(diag: Diagnosis, best: ScoreTest, progress: bool = False) -> None:
    """Where the confirming refit of `best` (nested, from the diagnosed fit) did not
    converge or looks like a wrong basin, fit the same model from other starts and keep
    the lowest (in place: the refit, its likelihood ratio, estimates, note and `start`;
    the diagnosis's judgements of `best` are made again).  A wrong basin shows as a
    chi-square far above the noise (`far_from_noise`), an estimate outside its
    plausible range (`Diagnosis.implausible`), or identical canopies given different
    constants (`twins_apart`); the other starts are then `best_start`'s.  A refit that
    did not converge is fitted from the offline reduction (`fresh_fit`), which
    replaces it where it converges.  Tried once per effect and diagnosis.

    A fit of a model that lacks an effect bends its other parameters to make up for
    it, and the refit that adds the effect starts there.  On `drogue` flown with a
    2,000 lbf deployment load, the refit from the baseline fit (chi-square/dof 17.6)
    stopped at 8.99 with the load at 11,058 N (truth 8,896 N), and a load-cell offset
    was then confirmed to take up the rest; with the observed inflation starts 0.3 s
    off the truth too, the refit did not converge at all.  On a two-Drogue test
    flown with added mass, the nested refit reported "Solved" at chi-square 7,056.8
    on about 5,720 dof, with one disreef's start 0.3 s early and added-mass factors
    1.26 and 0.98 for two identical canopies."""
    assert best.refit is not None and best.spec is not None
    if best.start is not None:
        return
    best.start = ""
    # The diagnosed fit's own iteration limit: a fit from the reduction is a fit, not a
    # refit from next door (on the deployment load above it took more than 150).
    max_iter = diag.fit.settings.max_iter
    if best.refit.lower_bound or best.refitted is None:
        fresh = fresh_fit(diag.fit.test, best.spec, diag.fit.settings, max_iter, progress)
        if fresh is None or (best.refitted is not None
                             and fresh[1].chi_square > best.refitted[1].chi_square):
            return
        found = (*fresh, "the offline reduction, after the nested refit did not converge")
    else:
        est, fit = best.refitted
        suspect = far_from_noise(fit, diag.alpha) or diag.implausible(best) \
            or twins_apart(est, fit, list(best.refit_estimate), diag.alpha)
        if not suspect:
            return
        found = best_start(est, fit, max_iter, progress)
        if found is None:
            return
    fresh_est, fit, how = found
    best.refit = dataclasses.replace(best.refit, statistic=diag.fit.chi_square - fit.chi_square,
                                     lower_bound=False)
    best.refitted = (fresh_est, fit)
    best.refit_estimate = {n: fit.parameters[n] for n in
                           best.refit_estimate or best.parameters}
    best.refit_note += f"; fitted from other starts too, kept: {how}"
    best.start = how
    diag.forget(best.effect)


def discover(fit: Fit, spec: ModelSpec, candidates: Mapping[str, EffectType] | None = None,
             max_steps: int = MAX_STEPS, alpha: float = ALPHA, confirm_top: int = CONFIRM_TOP,
             progress: bool = False,
             on_step: Callable[[DiscoveryStep], None] | None = None,
             estimator: Estimator | None = None,
             on_whole: Callable[[Discovery], None] | None = None,
             resume: Discovery | None = None) -> Discovery:
    """The chain from `fit` (of `spec`, by `estimator` where given): see the module
    docstring.  `candidates` are the plug-in effects tested beside the library's;
    `on_step` is called with each step once it is diagnosed (progress for a caller
    that prints), `on_whole` with the chain wherever it is whole (a step appended and
    the stand-ins it frees dropped, or a step diagnosed: for a caller that keeps it on
    disk, `discovery_checkpoint`).  `resume`: a chain read back from disk, to go on
    from its last step (`fit` and `spec` are then its first).  A signal
    (`interrupts.Interrupted`) raises `InterruptedDiscovery` with the steps finished
    so far, for the caller to keep."""
    out = resume if resume is not None else Discovery(
        [DiscoveryStep(None, spec, fit, estimator=estimator)], alpha=alpha)
    out.state, out.stopped = "in progress", ""
    try:
        return _chain(out, candidates, max_steps, alpha, confirm_top, progress, on_step,
                      on_whole)
    except Interrupted as exc:
        # Every step in the chain is a finished fit; what was under way is lost.
        out.state = "stopped early"
        diagnosed = sum(s.diagnosis is not None for s in out.steps)
        out.stopped = (f"interrupted ({exc}) after {len(out.steps)} fit(s), {diagnosed} of "
                       "them diagnosed; the work under way was lost")
        raise InterruptedDiscovery(exc.signum, out) from None


def _chain(out: Discovery, candidates: Mapping[str, EffectType] | None, max_steps: int,
           alpha: float, confirm_top: int, progress: bool,
           on_step: Callable[[DiscoveryStep], None] | None,
           on_whole: Callable[[Discovery], None] | None = None) -> Discovery:
    """`discover`'s loop on the chain `out`, which it extends in place."""
    clock = time.perf_counter()
    with tempfile.TemporaryDirectory(prefix="cpas-ocp-proposed-") as folder:
        while True:
            step = out.steps[-1]
            if step.diagnosis is None or step.diagnosis.fit is not step.fit:
                if on_whole is not None:
                    on_whole(out)
                began = time.perf_counter()
                step.diagnosis = diagnose(step.fit, step.spec, candidates, confirm_top, alpha,
                                          progress, frozenset(out.dropped), at_misfit=False)
                step.diagnosed_s += time.perf_counter() - began
                clock = time.perf_counter()
                if on_step is not None:
                    on_step(step)
                if on_whole is not None:
                    on_whole(out)
            found = next_step(step.diagnosis, progress)
            if isinstance(found, str) and out.added < max_steps:
                found = _beyond_the_library(out, step, found, Path(folder), alpha,
                                            confirm_top, progress)
            elif isinstance(found, DiscoveryStep) and found.stand_in and confirm_top > 0 \
                    and not out.regressions and out.added < max_steps:
                found = _against_a_drag_law(out, step, found, alpha, progress)
            if isinstance(found, str):
                # Before the verdict: the last model from other starts, where its fit is
                # not at the noise, then every effect the chain added tested again
                # against the last model; either change is diagnosed again.
                if _restarted_last(out, step, progress) or _drop_unneeded(out, alpha,
                                                                          progress):
                    continue
                out.stopped = found
                out.state = _ending_state(step.diagnosis)
                return out
            found.found_s = time.perf_counter() - clock
            if not _extend(out, step, found, max_steps):
                # At the step limit too, every effect added earns its place or goes; a
                # model that changes is diagnosed again (and adds nothing: the limit).
                if _drop_unneeded(out, alpha, progress):
                    continue
                out.state = "stopped early"
                return out
            if found.stand_in and found.added is not None and out.added < max_steps:
                # An effect that leaves its own windows off the noise: its other forms
                # first, before anything else is asked to take up the rest.
                began = time.perf_counter()
                refined = _refined_step(out, found, [found.added], alpha, progress)
                if refined is not None:
                    refined.found_s = time.perf_counter() - began
                    _extend(out, found, refined, max_steps)
            _drop_stand_ins(out, alpha, progress)


def _beyond_the_library(out: Discovery, step: DiscoveryStep, found: str, folder: Path,
                        alpha: float, confirm_top: int, progress: bool
                        ) -> DiscoveryStep | str:
    """Where the diagnosis of `step` names nothing (`found` says why), the moves past the
    library's effects as they are, cheapest and most specific first: the effects the
    chain added in other forms (`_refined_step`, each effect once); where the residual
    keeps structure nothing explains, the plug-ins its signature asks for
    (`_proposed_step`); where the fit is a misfit, every tested effect refitted whatever
    its score (`diagnosis.confirm_at_misfit`), then a drag law by sparse regression
    (`_regressed_step`, once per chain).  The first step one of them makes, or why
    there is none.

    The refinements are tried even where the fit lies within the noise: the total
    chi-square on some 7,000 degrees of freedom moves by its spread of 120 before the
    test sees a misfit, and a wrong form can hide inside it.  On `drogue` flown with
    an added mass growing as D^4.5, the chain added an elastic riser (a stand-in),
    then the D^3 law, and stood at chi-square/dof 1.026 (p = 0.063): "consistent",
    with the riser kept and the form wrong."""
    diag = step.diagnosis
    assert diag is not None
    misfit = not diag.consistent_with_noise
    refined = _refined_step(out, step, _unrefined(out), alpha, progress)
    if refined is not None:
        return refined
    note = ""
    if _unexplained(diag):
        tried = len(out.proposals)
        proposed = _proposed_step(out, step, folder, alpha, progress)
        if proposed is not None:
            return proposed
        if len(out.proposals) > tried:
            note = "; no plug-in proposed from its signature is confirmed (see proposed/)"
    if misfit and confirm_top > 0 and confirm_at_misfit(diag, progress):
        again = next_step(diag, progress)
        if not isinstance(again, str):
            return again
        found = again
    if misfit and confirm_top > 0 and not out.regressions:
        regressed = _regressed_step(out, step, alpha, progress)
        if regressed is not None:
            return regressed
    return found + note


def _against_a_drag_law(out: Discovery, step: DiscoveryStep, found: DiscoveryStep,
                        alpha: float, progress: bool) -> DiscoveryStep:
    """`found`, an effect that only partly explains the misfit at `step` (a stand-in), or
    the drag law a sparse regression selects there (`_regressed_step`, once per chain)
    where that leaves the fit within the noise's reach (not `far_from_noise`) and is
    the more significant step: the smaller p-value of its likelihood ratio against
    `step`'s fit, chi-square on the parameters each adds.

    A misfit the library does not describe is partly taken up by effects it does: on
    `drogue` flown with every drag area times (q / 1 kPa)^-0.1, an IMU bias, then added
    mass, then its refinement were each confirmed (likelihood ratios of about 43, 14
    and 14) and used up the chain's steps, while the drag law the regression selects
    at the first fit removes 1,008 of chi-square with one term."""
    regressed = _regressed_step(out, step, alpha, progress)
    if regressed is None:
        return found

    def p_value(s: DiscoveryStep) -> float:
        gain = step.fit.chi_square - s.fit.chi_square
        return float(chi2.sf(max(gain, 0.0), max(len(s.fit.free) - len(step.fit.free), 1)))

    # A drag law that leaves the fit a misfit is one more stand-in: on `fbcp` flown
    # through a wind shear layer it took the place of a GPS lag, and the wind profile
    # the residual's altitude signature asks for was never written.
    if far_from_noise(regressed.fit, alpha):
        out.regressions[-1].note = (f"not taken in place of {found.added}: it leaves the fit "
                                    "far from the noise")
        return found
    if p_value(regressed) >= p_value(found):
        out.regressions[-1].note = f"not taken: {found.added} is the more significant step"
        return found
    return regressed


def _restarted_last(out: Discovery, step: DiscoveryStep, progress: bool) -> bool:
    """Where the last step's fit is far from the noise and has not been tried from other
    starts: try them (`best_start`), and where one is lower, make it the step's fit (its
    diagnosis to be made again).  Whether the fit changed."""
    if step.searched or step.estimator is None or not far_from_noise(step.fit, out.alpha):
        return False
    step.searched = True
    began = time.perf_counter()
    # The first fit's iteration limit: a step's refit carries the confirming refit's.
    found = best_start(step.estimator, step.fit, out.steps[0].fit.settings.max_iter, progress)
    step.found_s += time.perf_counter() - began
    if found is None:
        return False
    step.estimator, step.fit, step.start = found
    return True


def _unrefined(out: Discovery) -> list[str]:
    """The effects the chain added that its last model holds and no refinement was tried of."""
    last = out.steps[-1].spec.effect_names
    tried = {t.effect for t in out.refinements}
    return [s.added for s in out.steps[1:] if s.added is not None and s.added in last
            and s.added not in tried and s.added not in out.dropped]


def _refined_step(out: Discovery, step: DiscoveryStep, names: list[str], alpha: float,
                  progress: bool) -> DiscoveryStep | None:
    """The step that refines one of the effects `names` of `step`'s model: every refinement
    of them tried (`refinement.refine`, recorded in `out`), the most significant kept at
    the family-wise level; None where none is kept."""
    if not names:
        return None
    index = out.index(step)
    trials = refine(step.fit, step.spec, names, index, alpha, progress)
    out.refinements += trials
    best = best_kept(trials)
    if best is None or best.refitted is None or best.spec is None:
        return None
    est, fit = best.refitted
    return DiscoveryStep(None, best.spec, fit, str(best.lr), estimator=est,
                         refined=best.effect, refinement=best.change)


def _regressed_step(out: Discovery, step: DiscoveryStep, alpha: float, progress: bool
                    ) -> DiscoveryStep | None:
    """The step that adds the drag law a sparse regression selects at `step`'s fit
    (`sparse_terms.select`, recorded in `out`), or None where it selects no term."""
    index = out.index(step)
    found = select(step.fit, step.spec, index, alpha, progress)
    out.regressions.append(found)
    if not found.found or found.spec is None or found.refitted is None:
        return None
    est, fit = found.refitted
    terms = ", ".join(f"{n} = {with_sigma(v, s)}" for n, (v, s) in found.selected.items())
    return DiscoveryStep("drag_law_terms", found.spec, fit,
                         f"every term against none: {found.gate}; selected {terms}: "
                         f"{found.lr}", estimator=est)


def _unexplained(diag: Diagnosis) -> bool:
    """Whether the residual of the diagnosed fit keeps significant structure that no library
    effect explains with a plausible estimate (and the air's motion is not named)."""
    best = diag.explanation
    return bool(diag.structure) and not (diag.air is not None and diag.air.decisive) \
        and (best is None or bool(diag.implausible(best)))


def _extend(out: Discovery, step: DiscoveryStep, found: DiscoveryStep, max_steps: int
            ) -> bool:
    """Append `found` after `step` with the share of the misfit it explains; False (and the
    reason recorded) where the chain already holds `max_steps` added effects."""
    if out.added >= max_steps:
        out.stopped = (f"{max_steps} effects added, the most asked for; the last "
                       f"diagnosis confirms {found.added} too")
        return False
    found.explained = explained_share(step.fit.chi_square, step.fit.dof, found.fit.chi_square)
    diag = step.diagnosis
    windows = diag.windows if diag is not None else phase_windows(step.fit)
    before = diag.statistics if diag is not None else window_statistics(step.fit, windows)
    found.windows_explained = excess_removed(before, window_statistics(found.fit, windows))
    out.steps.append(found)
    return True


def _proposed_step(out: Discovery, step: DiscoveryStep, folder: Path, alpha: float,
                   progress: bool) -> DiscoveryStep | None:
    """Where the diagnosis of `step` confirms nothing but leaves structure: the plug-ins its
    signature asks for that this chain has not tried, each written to `folder`, loaded
    from there and tested as written (score test and confirming refit at `step`'s
    fit), recorded in `out`; the step the most significant confirmed one makes, or None."""
    diag = step.diagnosis
    assert diag is not None
    asked = propose(diag, step.spec)
    fresh = [p for p in asked if p.name not in out.plugins]
    trials = []
    for proposal in fresh:
        path = folder / proposal.file_name
        path.write_text(proposal.source)
        entry = load_plugin(path)[proposal.name]
        out.plugins[proposal.name] = entry
        result = score_test(step.fit, step.spec, entry)
        if result.significant(alpha, len(fresh)):
            confirm(step.fit, result, progress)
        lr = result.refit
        trial = ProposalTrial(len(out.steps) - 1, proposal, result, len(fresh))
        trial.confirmed = (lr is not None and not lr.lower_bound and result.refitted is not None
                           and lr.p_value < alpha / len(fresh))
        trials.append(trial)
    out.proposals += trials
    # What the diagnosis's text may say was written: the proposals the chain holds (this
    # step's, and those an earlier step wrote from the same signature).
    written = {t.proposal.name for t in out.proposals}
    diag.proposed = [p.file_name for p in asked if p.name in written]
    confirmed = sorted((t for t in trials if t.confirmed), key=lambda t: (
        t.test.refit.p_value, -t.test.refit.statistic))
    if not confirmed:
        return None
    best = confirmed[0].test
    assert best.spec is not None and best.refitted is not None and best.refit is not None
    from_other_starts(diag, best, progress)
    return _step_of(diag, best, f"{best.refit}; proposed/"
                                f"{confirmed[0].proposal.file_name}, written from the "
                                "residual's signature")


def _drop_stand_ins(out: Discovery, alpha: float, progress: bool) -> None:
    """After a step, drop each earlier effect that was added as a stand-in (`stand_in`) and
    that the model no longer needs: the most recent first, each refitted away from the
    last model (`_without`) and appended as a step of its own, until none can go.

    A stand-in fits part of a signal it does not describe; once the effect that does
    describe it is in, the stand-in's share is gone.  On `fbcp` flown through a
    shear layer, a GPS lag and an accelerometer bias were added as partial steps
    before the wind profile proposed from the residual's altitude signature.

    Only effects added before the newest are candidates: the newest was just
    admitted by its likelihood ratio against the model without it, so dropping it
    would undo the step.  Once a drop had made it an earlier step, it was tried
    too, and on `drogue` flown through a wind shear two refits (21 s) found the
    wind profile still needed."""
    newest = max(k for k, s in enumerate(out.steps) if s.dropped is None)
    while True:
        last = out.steps[-1]
        names = [s.added for s in out.steps[1:newest] if s.stand_in and s.added is not None
                 and s.added in last.spec.effect_names and s.added not in out.dropped]
        for name in reversed(names):
            began = time.perf_counter()
            step = _without(last, name, alpha, progress)
            if step is not None:
                step.found_s = time.perf_counter() - began
                step.explained = explained_share(last.fit.chi_square, last.fit.dof,
                                                 step.fit.chi_square)
                out.steps.append(step)
                break
        else:
            return


def _drop_unneeded(out: Discovery, alpha: float, progress: bool) -> bool:
    """Test every effect the chain added (stand-in or not) again against the last model,
    and drop the one whose keeping is least significant where it is not significant at
    alpha / k over the k effects tested (a step of its own, `_without`); again on the
    model that leaves, until every effect left earns its place.  Whether one was dropped.

    Each effect was admitted by its likelihood ratio against the model before it; the
    effects added after it may explain the same residual better.  On a two-Drogue test
    with a GPS latency and added mass hidden, an IMU bias admitted after both removed
    2 % of the excess and was kept.  Where the last fit is itself above the noise
    (chi^2/dof = phi > 1), each likelihood ratio is divided by phi (the
    quasi-likelihood test of a dispersion the model does not explain), so that a
    misfit left by something else does not keep an effect.  The air's motion, admitted
    by its evidence rather than a likelihood ratio, is not tested here."""
    dropped = False
    while True:
        began = time.perf_counter()
        last = out.steps[-1]
        names = [s.added for s in out.steps[1:] if s.added is not None and s.dropped is None
                 and s.added != "wind_process" and s.added in last.spec.effect_names
                 and s.added not in out.dropped]
        if not names:
            return dropped
        phi = max(1.0, last.fit.chi_square / last.fit.dof) if last.fit.dof > 0 else 1.0
        trials = [t for name in names
                  if (t := _without(last, name, alpha / len(names), progress, phi)) is not None]
        if not trials:
            return dropped
        step = min(trials, key=lambda t: t.fit.chi_square)  # the least needed
        step.explained = explained_share(last.fit.chi_square, last.fit.dof,
                                         step.fit.chi_square)
        step.admitted_by += (f", tested again against the last model with the "
                             f"{len(names)} effect(s) added")
        step.found_s = time.perf_counter() - began
        out.steps.append(step)
        dropped = True


def _without(last: DiscoveryStep, name: str, alpha: float, progress: bool,
             dispersion: float = 1.0) -> DiscoveryStep | None:
    """The step that drops effect `name` from `last`'s model: its refit from `last`'s fit
    where it converges and keeping the effect is not significant at `alpha` (the
    likelihood ratio of `last` against it, on the effect's parameters, divided by
    `dispersion`: see `_drop_unneeded`); else None.  An effect that replaced another
    (an elastic riser) is not dropped."""
    effect = next(e for e in last.spec.effects if e.name == name)
    if effect.replaces is not None:
        return None
    own = {p.name for p in effect.parameters(last.fit.test)}
    smaller = dataclasses.replace(
        last.spec, effects=tuple(e for e in last.spec.effects if e.name != name),
        fix={n: v for n, v in last.spec.fix.items() if n not in own},
        free=tuple(n for n in last.spec.free if n not in own),
        priors={n: v for n, v in last.spec.priors.items() if n not in own})
    try:
        est, fit = refit(last.fit, smaller, progress=progress, max_iter=CONFIRM_MAX_ITER)
    except (SolverFailure, InputError):
        return None
    null = effect.null_values(last.fit.test) or {}
    lr = LikelihoodRatio((fit.chi_square - last.fit.chi_square) / dispersion,
                         len(last.fit.free) - len(fit.free),
                         one_sided_count(last.spec, last.fit, null))
    if lr.dof < 1 or lr.p_value < alpha:
        return None
    scaled = f", divided by the last fit's chi2/dof {dispersion:.3f}" if dispersion > 1 else ""
    return DiscoveryStep(None, smaller, fit, f"keeping it is not significant ({lr}"
                                             f"{scaled})", dropped=name, estimator=est)
