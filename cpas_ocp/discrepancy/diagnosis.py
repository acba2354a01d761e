"""Diagnosis of a fit: where the model fails, which known effect is missing, or what the
unexplained residual looks like.

1. Where: the residual chi-square per sensor channel and phase window
   (deployment, each stage's inflation and steady state, per canopy), and
   the one place where it exceeds the noise most (`diagnostics.worst_of`).
2. What is known: a score test of every library (and plug-in) effect the
   model does not use (`score_test`), ranked; the significant ones
   (p < alpha / m for m effects tested) are confirmed, up to `confirm_top`
   of them, by refitting the model with the effect and testing the
   likelihood ratio.  The confirmed effect with the smallest likelihood-ratio
   p-value is the diagnosis.  Where that effect is implausible (a stand-in),
   the other tested effects are refitted too, in score order, until a
   plausible one is confirmed better (`confirm_past_stand_ins`); where none is
   confirmed and the fit lies above the noise, the others are refitted in score
   order until one is (`confirm_at_misfit`: a score test is local, and can miss
   an effect a full dose of which removes much of the misfit).
3. The air's motion: where an altimeter and a GPS share a slow wander, the
   evidence of a wind process against still air (`wind_evidence`); the
   process is named where its Bayes factor is decisive.
4. What is not: the residual tests (whiteness, a periodic line, a lag,
   correlation with signatures of the fitted trajectory) per channel and
   window (`residual_diagnosis`).  When no effect is confirmed but the
   residuals carry significant structure, the report says so and describes
   that structure: sensor, window, frequency or lag, and what it correlates with.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field

from scipy.stats import chi2 as chi2_law
from scipy.stats import norm

from cpas_ocp.discrepancy.residual_diagnosis import Finding, diagnose_residuals, signature_text
from cpas_ocp.discrepancy.score_test import ScoreTest, confirm, confirmed_ranking, score_tests
from cpas_ocp.discrepancy.wind_evidence import WindEvidence, wind_evidence
from cpas_ocp.estimation.estimator import Fit
from cpas_ocp.estimation.kkt_system import NonFiniteCurvature
from cpas_ocp.inference.diagnostics import (
    MIN_TESTED_SAMPLES,
    WindowStatistic,
    departs,
    excess_removed,
    explained_share,
    window_statistics,
    worst_of,
)
from cpas_ocp.inference.noise_test import NoiseTest, noise_test
from cpas_ocp.inference.phase_windows import PhaseWindow, phase_windows
from cpas_ocp.io.model_spec import ModelSpec
from cpas_ocp.physics.effects.registry import EffectType
from cpas_ocp.process_memory import new_objects_only, release_freed_memory

ALPHA = 0.01  # family-wise level of the diagnosis's tests
CONFIRM_TOP = 3  # significant score tests confirmed by a refit
# A window a confirmed effect removes at least this share of the excess chi-square from is
# one it explains in part; if it still departs from the noise, the effect may be a stand-in.
PARTLY_EXPLAINED = 0.1


@dataclass
class Diagnosis:
    """What `diagnose` found at one fit; `effects` in their final ranking."""

    fit: Fit
    windows: list[PhaseWindow]
    statistics: list[WindowStatistic]
    effects: list[ScoreTest]
    findings: list[Finding]
    alpha: float = ALPHA
    notes: list[str] = field(default_factory=list)
    air: WindEvidence | None = None  # the air motion's evidence, where it was asked
    # The plug-in files `discover` wrote from this diagnosis's residual signature (names in
    # its proposed/ folder; empty where the signature asks for none); None where no chain
    # asked for them (a diagnosis on its own).
    proposed: list[str] | None = None
    _stand_in: dict[str, list[str]] = field(default_factory=dict, repr=False)
    _implausible: dict[str, list[str]] = field(default_factory=dict, repr=False)
    _noise: NoiseTest | None = field(default=None, repr=False)

    @property
    def worst(self) -> str:
        """One line naming the channel and window with the largest chi-square excess."""
        return worst_of(self.statistics)

    @property
    def tests_made(self) -> int:
        return sum(t.tested for t in self.effects)

    @property
    def family(self) -> int:
        """The number of tests the Bonferroni level alpha / m divides by (at least 1)."""
        return max(self.tests_made, 1)

    @property
    def explanation(self) -> ScoreTest | None:
        """The confirmed effect that explains the residual best, if any is significant."""
        m = self.family
        for t in self.effects:
            if t.refit is not None and t.refit.p_value < self.alpha / m:
                return t
        return None

    def confirmed(self) -> list[ScoreTest]:
        """The effects whose refit converged with a likelihood ratio significant at the
        family-wise level, in the ranking's order."""
        m = self.family
        return [t for t in self.effects if t.refit is not None and not t.refit.lower_bound
                and t.refitted is not None and t.spec is not None
                and t.refit.p_value < self.alpha / m]

    @property
    def structure(self) -> list[Finding]:
        """The residual findings that are significant after the multiple-test correction."""
        return [f for f in self.findings if f.significant]

    @property
    def noise(self) -> NoiseTest:
        """The fit's overall and per-window chi-square against the noise (`noise_test`)."""
        if self._noise is None:
            self._noise = noise_test(self.fit, self.statistics, self.alpha)
        return self._noise

    @property
    def consistent_with_noise(self) -> bool:
        """Nothing to add and nothing above the noise: no effect confirmed or left
        unresolved, no air motion named, and the fit's chi-square above the noise neither
        overall nor in any window tested (`NoiseTest.above`).  The total may lie below the
        noise (`NoiseTest.below`: the stated sigma too large), and the residuals may keep a
        shape within the noise's size (`structure`); neither is a misfit."""
        return (self.explanation is None and not (self.air is not None and self.air.decisive)
                and not self._unresolved(None) and not self.noise.above)

    @property
    def state(self) -> str:
        """How the diagnosis ends, in one word: "missing effect" (one is confirmed, or the
        air's motion is named), "undecided" (significant effects whose refits did not
        converge), "consistent" or "below the noise" (`consistent_with_noise`, the total
        within the noise or below it) or "misfit" (nothing found, and the chi-square above
        the noise)."""
        if (self.air is not None and self.air.decisive) or self.explanation is not None:
            return "missing effect"
        if self._unresolved(None):
            return "undecided"
        if not self.consistent_with_noise:
            return "misfit"
        return "below the noise" if self.noise.below else "consistent"

    def misfit_text(self) -> str:
        """What remains where nothing is found and the chi-square lies above the noise: the
        noise test, the signature, and the next move to try."""
        lines = [f"a misfit: {self.noise}"]
        if self.structure:
            lines.append("the residual's signature:\n" + signature_text(self.structure))
        lines.append("next: " + next_move(self.noise, self.statistics, bool(self.structure),
                                          self.proposed))
        return "\n".join(lines)

    def noise_text(self) -> str:
        """The verdict where nothing is found and the chi-square is not above the noise: the
        residuals consistent with it, or below it (the stated sigma too large by about
        1 / sqrt(chi2/dof), or the samples fewer than counted), and any shape they keep
        within the noise's size (their signature)."""
        noise = self.noise
        if noise.below:
            head = (f"the residuals are below the sensor noise: {noise}; the stated sigma are "
                    f"about {100 * (1.0 / noise.sigma_scale - 1.0):.0f} % too large, or the "
                    "samples fewer than counted (noise correlated in time, as a recorder's "
                    "filter makes it)")
        else:
            head = f"the residuals are consistent with the sensor noise: {noise}"
        head += f"; no effect is significant at the family-wise level {self.alpha:g}"
        if not self.structure:
            return head
        return (f"{head}; within the noise's size the residuals keep a shape no effect tested "
                "explains (noise correlated in time, or an effect smaller than the noise; "
                f"{proposal_hint(self.proposed)}): the residual's signature:\n"
                + signature_text(self.structure))

    @property
    def departure_level(self) -> float:
        """The z a window's chi-square excess must pass to depart from the noise: the normal
        quantile at the family-wise level over the windows."""
        return float(norm.isf(self.alpha / max(len(self.statistics), 1)))

    def stand_in(self, best: ScoreTest) -> list[str]:
        """Why the confirmed effect `best` may stand in for something it does not describe:
        an estimate outside its plausible range (`Effect.plausible`); each window it
        explains in part (at least PARTLY_EXPLAINED of the excess) that still departs
        from the noise after its refit; significant residual structure its refit leaves
        in such a window; and, where any of those holds, the strongest structure the
        refit leaves elsewhere.  Empty where none holds."""
        if best.effect not in self._stand_in:
            self._stand_in[best.effect] = self._stand_in_reasons(best)
        return self._stand_in[best.effect]

    def forget(self, effect: str) -> None:
        """Drop what was judged of `effect`'s refit (after the refit was replaced)."""
        self._stand_in.pop(effect, None)
        self._implausible.pop(effect, None)

    def implausible(self, best: ScoreTest) -> list[str]:
        """The refit estimates of `best`'s effect that its declared plausible ranges
        (`Effect.plausible`) exclude, each in words; empty where none does.

        An estimate outside its range by less than the two-sided normal quantile at the
        family-wise level times its standard error (from the refit's covariance) could
        lie inside: it is not called implausible.  A load-cell zero offset hidden at
        1 kN, at the edge of the 1,009 N that 2 % of the largest reading allows on
        `drogue`, came out at 1,013 N and was called a stand-in by the bare range.
        Without a refit (no covariance), the bare range decides."""
        if best.effect not in self._implausible:
            self._implausible[best.effect] = self._implausible_estimates(best)
        return self._implausible[best.effect]

    def _implausible_estimates(self, best: ScoreTest) -> list[str]:
        """`implausible`, computed."""
        effect = next((e for e in best.spec.effects if e.name == best.effect), None) \
            if best.spec is not None else None
        if effect is None:
            return []
        outside = {name: (value, lo, hi) for name, (lo, hi) in
                   effect.plausible(self.fit.test).items()
                   if (value := best.refit_estimate.get(name)) is not None
                   and not lo <= value <= hi}
        if outside and best.refitted is not None:
            est, refit = best.refitted
            try:
                std = est.covariance(refit).std
            except NonFiniteCurvature:  # no standard errors: the bare range decides
                std = {}
            z = float(norm.isf(self.alpha / 2.0))
            outside = {name: v for name, v in outside.items()
                       if min(abs(v[0] - v[1]), abs(v[0] - v[2])) > z * std.get(name, 0.0)}
        return [f"{name} = {value:.4g} lies outside its plausible range {lo:.4g} to {hi:.4g}"
                for name, (value, lo, hi) in outside.items()]

    def _stand_in_reasons(self, best: ScoreTest) -> list[str]:
        """`stand_in`, computed."""
        reasons = list(self.implausible(best))
        if best.refitted is not None:
            refit = best.refitted[1]
            level = self.departure_level
            after = window_statistics(refit, self.windows)
            acted = set()
            for w, now, share in excess_removed(self.statistics, after, level):
                if share < PARTLY_EXPLAINED:
                    continue
                acted.add((w.sensor, w.channel, w.window))
                if departs(now, level):
                    reasons.append(f"{w.sensor}.{w.channel} {w.window} still departs from the "
                                   f"noise (normalised RMS {now.normalised_rms:.2f}, "
                                   f"{100 * share:.0f} % of its excess removed)")
            # Structure the refit leaves in the windows the effect acts in; where the effect
            # is a stand-in, the strongest structure it leaves elsewhere too.
            left = [f for f in diagnose_residuals(refit, self.windows, self.alpha)
                    if f.significant]
            inside = [f for f in left if (f.sensor, f.channel, f.window) in acted]
            reasons += [f"structure in {f}" for f in inside]
            elsewhere = [f for f in left if f not in inside]
            if reasons and elsewhere:
                reasons.append(f"and elsewhere {elsewhere[0]}")
        return reasons

    def _unresolved(self, best: ScoreTest | None) -> list[ScoreTest]:
        """Significant score tests, other than `best`, whose refits did not converge: their
        likelihood ratio is unknown or only bounded below."""
        m = self.family
        return [t for t in self.effects if t is not best and t.significant(self.alpha, m)
                and t.refit_note and (t.refit is None or t.refit.lower_bound)]

    def verdict(self) -> str:
        """One paragraph: the effect that is missing, or the signature nobody explains."""
        best = self.explanation
        unresolved = self._unresolved(best)
        if self.air is not None and self.air.decisive:
            also = (f"; also confirmed: {best.effect} (likelihood ratio "
                    f"{best.refit.statistic:.1f}, p = {best.refit.p_value:.2g})"
                    if best is not None else "")
            return f"missing effect: {self.air.verdict()}{also}"
        if best is not None:
            lr = best.refit
            estimates = ", ".join(f"{n} = {v:.4g}" for n, v in best.refit_estimate.items())
            if lr.lower_bound:
                found = (f"likelihood ratio >= {lr.statistic:.1f}, p <= {lr.p_value:.2g}: its "
                         f"refit did not converge, and its last iterate made feasible has "
                         f"{estimates}")
            else:
                share = explained_share(self.fit.chi_square, self.fit.dof,
                                        self.fit.chi_square - lr.statistic)
                found = (f"likelihood ratio {lr.statistic:.1f}, p = {lr.p_value:.2g}, "
                         f"{100 * share:.0f} % of the excess chi-square; refit estimates "
                         f"{estimates}")
            rivals = "".join(
                f"; the refit of {t.effect} did not converge"
                + (f" (likelihood ratio >= {t.refit.statistic:.1f})" if t.refit else "")
                + ", so it may explain more" for t in unresolved)
            remains = self.stand_in(best)
            if remains:
                return (f"partly explained by {best.effect} ({found}){rivals}; what remains: "
                        + "; ".join(remains))
            return f"missing effect: {best.effect} ({found}){rivals}"
        if unresolved:
            signature = ("; the residual's signature:\n" + signature_text(self.structure)
                         if self.structure else "")
            return ("undecided: the score tests of " + ", ".join(t.effect for t in unresolved)
                    + f" are significant at the family-wise level {self.alpha:g}, but their "
                    "refits did not converge, so nothing is confirmed and nothing ruled out "
                    "(see the refits above)" + signature)
        if not self.consistent_with_noise:
            return ("no effect in the library explains the residual, " + self.misfit_text())
        return self.noise_text()


def diagnose(fit: Fit, spec: ModelSpec, candidates: Mapping[str, EffectType] | None = None,
             confirm_top: int = CONFIRM_TOP, alpha: float = ALPHA,
             progress: bool = False, exclude: frozenset[str] = frozenset(),
             at_misfit: bool = True) -> Diagnosis:
    """Diagnose `fit` (made with `spec`): see the module docstring.  The effects named in
    `exclude` are not tested (ones a chain of models has already dropped).  `at_misfit`:
    refit every tested effect where nothing is confirmed and the fit is a misfit
    (`confirm_at_misfit`; a chain of models calls it itself, after cheaper moves)."""
    with new_objects_only():
        windows = phase_windows(fit)
        tests = score_tests(fit, spec, candidates, progress, exclude)
        m = max(sum(t.tested for t in tests), 1)
        leading = [t for t in tests if t.significant(alpha, m)][:confirm_top]
        for t in leading:
            confirm(fit, t, progress)
            release_freed_memory()
        air = wind_evidence(fit, spec, alpha, progress)
        release_freed_memory()
        diag = Diagnosis(fit, windows, window_statistics(fit, windows),
                         confirmed_ranking(tests), diagnose_residuals(fit, windows, alpha),
                         alpha, air=air)
        if confirm_top > 0:
            if at_misfit:
                confirm_at_misfit(diag, progress)
            confirm_past_stand_ins(diag, tests, progress)
    return diag


def confirm_at_misfit(diag: Diagnosis, progress: bool = False) -> bool:
    """Where no score test leads to a confirmed effect and the fit lies above the noise,
    refit the other tested effects too, in score-test order and whatever their score
    statistic, until one is confirmed with plausible estimates (as
    `confirm_past_stand_ins` does past an implausible one; in place: `diag`'s ranking is
    made again, and what was judged of it forgotten).  Whether any was refitted.

    The score test is local: it asks how chi-square falls for an infinitesimal dose
    of the effect, after the model's other parameters have taken up what they can of
    it.  An effect whose first-order signature the fill constants mimic scores low
    even where a full dose removes much of the misfit, and a refit from the score
    step can stop near the null.  Each is therefore refitted from its defaults too
    (a full dose, `confirm`'s `defaults_too`), the lower kept.  On `drogue` flown
    with an added mass growing as D^6 (k_A 1.4), the library's D^3 law scored 2.1
    on 2 (p 0.16); its refit from the score step stopped at k_A 0.02 and 0.00
    (likelihood ratio 2.2), and its refit from k_A = 1 removed 547 of the 1,078
    excess chi-square.  Refitting costs no family-wise level (each is admitted by
    its likelihood ratio at alpha / m over every effect tested), only time, so it
    is spent where the fit is a misfit that nothing named.  Not done where the
    air's motion is named."""
    if diag.explanation is not None or (diag.air is not None and diag.air.decisive) \
            or not diag.noise.above:
        return False
    refitted = False
    for t in [t for t in diag.effects if t.tested and t.refit is None and not t.refit_note]:
        confirm(diag.fit, t, progress, defaults_too=True)
        release_freed_memory()
        refitted = True
        diag.effects = confirmed_ranking(diag.effects)
        diag._stand_in.clear()
        diag._implausible.clear()
        best = diag.explanation
        if best is not None and not diag.implausible(best):
            break
    return refitted


def confirm_past_stand_ins(diag: Diagnosis, tests: list[ScoreTest], progress: bool = False
                           ) -> None:
    """Where the effect the likelihood ratio confirms best is implausible (a stand-in),
    refit the other tested effects too, in score-test order, whatever their score
    statistic, until a plausible one is confirmed better than every stand-in (a smaller
    likelihood-ratio p-value: it explains more of the signal the stand-in fits in
    part), or none is left (in place: `diag`'s ranking is made again).

    A confirmed stand-in says the data ask for something the model lacks; the score
    test, being local, may rank the effect that describes it low.  The fit without
    the effect bends its other parameters to make up for it, and what is left of its
    signature at that fit, after projecting out those parameters, can be small: on
    `drogue` flown with added mass (k_A 1.4) and a 0.1 s GPS latency, once the lag
    was added, added mass scored 7.0 on 2 (p 0.012, k_A 0.03 and 0.11) while a
    fairlead friction of the wrong sign was confirmed (likelihood ratio 78.6); the
    refit with added mass removed 1,455.8 of chi-square (k_A 1.38 and 1.43).
    Refitting more candidates costs no family-wise level: each is still admitted by
    its likelihood ratio at alpha / m, m counting every effect tested, as if all had
    been refitted.  Not done where the air's motion is named (that is the step)."""
    if diag.air is not None and diag.air.decisive:
        return
    for t in tests:
        best = diag.explanation
        if best is None or best.refit is None or best.refit.lower_bound \
                or not diag.implausible(best):
            return
        if not t.tested or t.refit is not None or t.refit_note:
            continue
        confirm(diag.fit, t, progress)
        release_freed_memory()
        diag.effects = confirmed_ranking(tests)


def proposal_hint(proposed: list[str] | None) -> str:
    """What `discover` did with a residual signature: the plug-in files it wrote from it
    (`Diagnosis.proposed`), that it wrote none, or, for a diagnosis no chain asked (None),
    which signatures it writes one for."""
    if proposed is None:
        return ("`discover` writes and tests one where the signature is a periodic line of "
                "three cycles or more, a load cell that follows the load, or a residual that "
                "follows altitude")
    if not proposed:
        return ("`discover` wrote none: a plug-in is written for a periodic line of three "
                "cycles or more in its window, a load cell that follows the load, or a "
                "residual that follows altitude")
    return ("`discover` wrote " + ", ".join(f"proposed/{name}" for name in proposed)
            + " from it and tested each as written")


def next_move(noise: NoiseTest, statistics: list[WindowStatistic], structure: bool,
              proposed: list[str] | None = None) -> str:
    """The next thing to try on a misfit nothing tested explains (a chi-square above the
    noise), read from where it sits; `proposed` as `Diagnosis.proposed`.

    Where every window tested passes once its chi-square is divided by the fit's
    chi^2/dof (phi), the excess is uniform: the sensors' sigma are about sqrt(phi)
    too small, or an effect acts everywhere alike.  Otherwise the misfit sits in the
    windows that still fail so scaled, which are named."""
    phi = noise.sigma_scale**2
    tested = [w for w in statistics if w.samples >= MIN_TESTED_SAMPLES]
    level = noise.alpha / max(len(tested), 1)
    local = [w for w in tested if chi2_law.sf(w.chi_square / max(phi, 1.0), w.samples) < level]
    if not local:
        return (f"the excess is spread evenly (every window passes once scaled by chi2/dof "
                f"{phi:.3f}): either the sensors' stated sigma are about "
                f"{100 * (noise.sigma_scale - 1):.0f} % too small (check each sensor's sigma "
                "against its settled residual), or a small effect acts everywhere alike (a "
                "plug-in; see docs/plugins.md)")
    local.sort(key=lambda w: chi2_law.sf(w.chi_square / max(phi, 1.0), w.samples))
    channels = list(dict.fromkeys(f"{w.sensor}.{w.channel}" for w in local))
    windows = list(dict.fromkeys(w.window for w in local))
    where = (channels[0] if len(channels) == 1 else
             f"{len(channels)} channels ({', '.join(channels[:4])})") \
        + f" in {', '.join(windows[:4])}"
    hint = (f"write an effect that acts there as a plug-in (docs/plugins.md; "
            f"{proposal_hint(proposed)})" if structure else
            "look at that sensor's residual plot there: an effect acting on it (a plug-in, "
            "docs/plugins.md), a wrong sigma, or a start the fit did not reach")
    return f"the misfit sits in {where}; {hint}; `--confirm N` refits more candidates"
