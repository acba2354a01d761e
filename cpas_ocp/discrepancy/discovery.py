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
3. where nothing library-made is confirmed but the residuals keep structure,
   write the plug-ins its signature asks for (`candidate_plugins.propose`: a
   periodic line, a load-cell residual that follows the load, one that
   follows altitude), load each from its file and test it as written, like a
   library effect (score test, confirming refit, likelihood ratio at the
   family-wise level over the plug-ins proposed); a confirmed one is the next
   step;
4. after each step, drop every earlier effect added as a stand-in that the
   model no longer needs (its removal refitted from the last fit, and
   keeping it not significant: `_drop_stand_ins`), a step of its own, and
   never test it again;
5. stop where the residuals are consistent with the noise, where nothing
   left is significant (the last diagnosis then describes what remains: its
   signature), where the refit that would add the effect did not converge
   (its likelihood ratio is only a bound, and a bound is not a step), or
   after `max_steps` steps.

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
import math
import tempfile
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from scipy.stats import norm

from cpas_ocp.discrepancy.candidate_plugins import Proposal, propose
from cpas_ocp.discrepancy.diagnosis import ALPHA, CONFIRM_TOP, Diagnosis, diagnose
from cpas_ocp.discrepancy.score_test import CONFIRM_MAX_ITER, ScoreTest, confirm, score_test
from cpas_ocp.errors import InputError, SolverFailure
from cpas_ocp.estimation.estimator import Estimator, Fit
from cpas_ocp.inference.continuation import solve as solve_with_continuation
from cpas_ocp.inference.diagnostics import (
    WindowStatistic,
    excess_removed,
    explained_share,
    window_statistics,
    worst_window,
)
from cpas_ocp.inference.model_comparison import Criteria, LikelihoodRatio, one_sided_count, refit
from cpas_ocp.io.model_spec import ModelSpec
from cpas_ocp.physics.effects.registry import EffectType, load_plugin

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

    @property
    def label(self) -> str:
        """What the step did: the effect it added, "without X" where it dropped X."""
        if self.dropped is not None:
            return f"without {self.dropped}"
        return self.added or "start"

    @property
    def criteria(self) -> Criteria:
        return Criteria.of(self.fit)

    @property
    def channel_rms(self) -> dict[str, float]:
        """Normalised RMS of each sensor channel ("sensor.channel"), pseudo-sensors left out."""
        return {f"{r.sensor}.{r.channel}": float(np.sqrt(np.mean(r.normalized**2)))
                for r in self.fit.residuals
                if r.sensor not in self.fit.pseudo_sensors and r.t.size}

    def explained_lines(self, shown: int = 3) -> list[str]:
        """How much of the step before's misfit this step explains: overall, and in the
        `shown` windows that departed from the noise most."""
        if self.dropped is not None:
            return [f"{self.dropped} dropped: with the effects added after it, {self.admitted_by}"]
        lines = [f"{self.added} removes {100 * self.explained:.0f} % of the excess "
                 "chi-square" + (", and only partly explains it (a stand-in?)" if self.stand_in
                                else "")]
        lines += [f"  {w.sensor}.{w.channel} {w.window}: {100 * share:.0f} % of its excess "
                  f"{w.excess:.1f}" for w, _, share in self.windows_explained[:shown]]
        lines += [f"  what remains: {reason}" for reason in self.stand_in]
        return lines

    @property
    def worst_window(self) -> tuple[str, float] | None:
        """The diagnosed window with the largest chi-square excess and its normalised RMS."""
        w = None if self.diagnosis is None else worst_window(self.diagnosis.statistics)
        return None if w is None else (f"{w.sensor}.{w.channel} {w.window}", w.normalized_rms)


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

    def text(self) -> str:
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

    @property
    def added(self) -> int:
        """Steps that added an effect."""
        return sum(s.dropped is None for s in self.steps[1:])

    @property
    def dropped(self) -> set[str]:
        """Effects a step dropped (as stand-ins no longer needed); never tested again."""
        return {s.dropped for s in self.steps if s.dropped is not None}

    def text(self) -> str:
        """The chain as a table, then why it stopped and the last verdict."""
        lines = [f"{'step':>4}  {'added':22s} {'chi-square':>11s} {'chi2/dof':>8s} "
                 f"{'AIC':>10s} {'BIC':>10s}  worst window (normalised RMS); admitted by"]
        for k, s in enumerate(self.steps):
            c = s.criteria
            worst = s.worst_window
            where = f"{worst[0]} ({worst[1]:.2f})" if worst else "not diagnosed"
            lines.append(f"{k:4d}  {s.label:22s} {c.chi_square:11.1f} "
                         f"{c.chi_square / s.fit.dof:8.3f} {c.aic:10.1f} {c.bic:10.1f}  "
                         f"{where}" + (f"; {s.admitted_by}" if s.admitted_by else ""))
        lines += [""] + [line for s in self.steps[1:] for line in s.explained_lines()]
        if self.proposals:
            lines += ["", "plug-ins proposed from the residual's signature, tested as written:"]
            lines += ["  " + t.text() for t in self.proposals]
        lines += ["", f"stopped: {self.stopped}"] + [f"note: {n}" for n in self.notes]
        last = self.steps[-1].diagnosis if self.steps else None
        if last is not None:
            lines += ["", "last diagnosis: " + last.verdict()]
        return "\n".join(lines)


def next_step(diag: Diagnosis) -> DiscoveryStep | str:
    """The step the diagnosis `diag` confirms, or why there is none."""
    air = diag.air
    if air is not None and air.decisive and air.best_spec is not None \
            and air.best_fit is not None:
        return DiscoveryStep("wind_process", air.best_spec, air.best_fit,
                             f"2 ln B = {air.two_ln_b:.1f} over still air")
    best = diag.explanation
    if best is None:
        return ("the residuals are consistent with the noise" if diag.consistent_with_noise
                else "nothing left is confirmed: the last diagnosis says what remains")
    if best.refit is None or best.refit.lower_bound or best.refitted is None \
            or best.spec is None:
        return (f"the refit that would add {best.effect} did not converge: its likelihood "
                "ratio is only a bound")
    from_reduction(diag, best)
    implausible = diag.implausible(best)
    if implausible:
        # The next confirmed effect whose estimates are plausible, if any (the diagnosis
        # refits candidates past the score tests' leaders to find one where it must:
        # `confirm_past_stand_ins`).
        for other in diag.confirmed():
            if other is best:
                continue
            from_reduction(diag, other)
            if not diag.implausible(other):
                return DiscoveryStep(other.effect, other.spec, other.refitted[1],
                                     f"{other.refit.text()}; {best.effect}, ranked above it, "
                                     "is implausible", stand_in=diag.stand_in(other))
        return (f"{best.effect} fits part of the residual only with an implausible estimate "
                f"({'; '.join(implausible)}): a stand-in, not added")
    return DiscoveryStep(best.effect, best.spec, best.refitted[1], best.refit.text(),
                         stand_in=diag.stand_in(best))


def from_reduction(diag: Diagnosis, best: ScoreTest, progress: bool = False) -> None:
    """Where the confirming refit of `best` (nested, from the diagnosed fit) still misfits
    beyond the noise (chi-square above its dof by more than the family-wise normal
    quantile times sqrt(2 dof)), fit the same model from the offline reduction too, and
    keep that fit where its chi-square is lower by more than 1 (in place: the refit,
    its likelihood ratio, estimates and note; the diagnosis's judgements of `best` are
    made again).

    A fit of a model that lacks an effect bends its other parameters to make up for
    it, and the refit that adds the effect starts there.  On `drogue` flown with a
    2,000 lbf deployment load, the refit from the baseline fit (chi-square/dof 17.6)
    stopped at 8.99 with the load at 11,058 N (truth 8,896 N), and a load-cell offset
    was then confirmed to take up the rest."""
    assert best.refitted is not None and best.refit is not None and best.spec is not None
    fit = best.refitted[1]
    if fit.chi_square <= fit.dof + norm.isf(diag.alpha) * math.sqrt(2.0 * fit.dof):
        return
    # The diagnosed fit's own iteration limit: a fit from the reduction is a fit, not a
    # refit from next door (on the deployment load above it took more than 150).
    settings = dataclasses.replace(fit.settings, nodes=None, guess={}, free=None, fixed={},
                                   limits={}, max_iter=diag.fit.settings.max_iter)
    try:
        est = Estimator(fit.test, best.spec, settings)
        fresh = solve_with_continuation(est, progress)
    except (SolverFailure, InputError):
        return
    if fresh.chi_square >= fit.chi_square - 1.0:
        return
    best.refit = dataclasses.replace(best.refit,
                                     statistic=diag.fit.chi_square - fresh.chi_square)
    best.refitted = (est, fresh)
    best.refit_estimate = {n: fresh.parameters[n] for n in best.refit_estimate}
    best.refit_note += (f"; fitted from the offline reduction too: chi-square "
                        f"{fresh.chi_square:.1f} against the nested refit's {fit.chi_square:.1f}")
    diag.forget(best.effect)


def discover(fit: Fit, spec: ModelSpec, candidates: Mapping[str, EffectType] | None = None,
             max_steps: int = MAX_STEPS, alpha: float = ALPHA, confirm_top: int = CONFIRM_TOP,
             progress: bool = False,
             on_step: Callable[[DiscoveryStep], None] | None = None) -> Discovery:
    """The chain from `fit` (of `spec`): see the module docstring.  `candidates` are the
    plug-in effects tested beside the library's; `on_step` is called with each step once
    it is diagnosed (progress for a caller that prints)."""
    out = Discovery([DiscoveryStep(None, spec, fit)])
    with tempfile.TemporaryDirectory(prefix="cpas-ocp-proposed-") as folder:
        while True:
            step = out.steps[-1]
            step.diagnosis = diagnose(step.fit, step.spec, candidates, confirm_top, alpha,
                                      progress, frozenset(out.dropped))
            if on_step is not None:
                on_step(step)
            found = next_step(step.diagnosis)
            if isinstance(found, str) and _unexplained(step.diagnosis) \
                    and out.added < max_steps:
                tried = len(out.proposals)
                found = _proposed_step(out, step, Path(folder), alpha, progress) or (
                    found + ("; no plug-in proposed from its signature is confirmed (see "
                             "proposed/)" if len(out.proposals) > tried else ""))
            if isinstance(found, str):
                out.stopped = found
                return out
            if not _extend(out, step, found, max_steps):
                return out
            _drop_stand_ins(out, alpha, progress)


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
    found.windows_explained = excess_removed(
        step.diagnosis.statistics, window_statistics(found.fit, step.diagnosis.windows))
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
    fresh = [p for p in propose(diag, step.spec) if p.name not in out.plugins]
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
    confirmed = sorted((t for t in trials if t.confirmed), key=lambda t: (
        t.test.refit.p_value, -t.test.refit.statistic))
    if not confirmed:
        return None
    best = confirmed[0].test
    assert best.spec is not None and best.refitted is not None and best.refit is not None
    from_reduction(diag, best, progress)
    return DiscoveryStep(best.effect, best.spec, best.refitted[1],
                         f"{best.refit.text()}; proposed/{confirmed[0].proposal.file_name}, "
                         "written from the residual's signature",
                         stand_in=diag.stand_in(best))


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
            step = _without(last, name, alpha, progress)
            if step is not None:
                step.explained = explained_share(last.fit.chi_square, last.fit.dof,
                                                 step.fit.chi_square)
                out.steps.append(step)
                break
        else:
            return


def _without(last: DiscoveryStep, name: str, alpha: float, progress: bool
             ) -> DiscoveryStep | None:
    """The step that drops effect `name` from `last`'s model: its refit from `last`'s fit
    where it converges and keeping the effect is not significant at `alpha` (the
    likelihood ratio of `last` against it, on the effect's parameters); else None.
    An effect that replaced another (an elastic riser) is not dropped."""
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
        _, fit = refit(last.fit, smaller, progress=progress, max_iter=CONFIRM_MAX_ITER)
    except (SolverFailure, InputError):
        return None
    null = effect.null_values(last.fit.test) or {}
    lr = LikelihoodRatio(fit.chi_square - last.fit.chi_square,
                         len(last.fit.free) - len(fit.free),
                         one_sided_count(last.spec, last.fit, null))
    if lr.dof < 1 or lr.p_value < alpha:
        return None
    return DiscoveryStep(None, smaller, fit, f"keeping it is not significant ({lr.text()})",
                         dropped=name)
