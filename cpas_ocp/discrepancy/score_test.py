"""Score (Lagrange multiplier) tests: would an effect the fit left out explain the data?

An effect E with parameters theta is *nested* in the fitted model when at
some null values theta_0 (`Effect.null_values`: no air mass, no lag, no
friction) the model with E predicts exactly what the fitted model predicts.
The fit is then the optimum of the extended model with theta held at
theta_0, and one Gauss-Newton step from there, with every parameter free,
gives the linearised estimate theta_hat and its covariance C (the KKT
parameter block of the extended model).  The score statistic

    LM = theta_hat' C^-1 theta_hat

is the chi-square decrease that step predicts along theta; under the null it
is chi-square with k degrees of freedom, k the number of theta the data
determine.  Where theta_0 sits on a bound (an added-mass factor cannot be
negative, a pressure recovery fraction cannot exceed 1), only one sign is an
alternative: the statistic is the decrease within that cone,

    LM+ = theta_hat' W theta_hat - min over the cone of (t - theta_hat)' W (t - theta_hat),

W = C^-1, and its law chi-bar-squared (`hypothesis_tests`).  No refit is
needed: one linearisation of the extended NLP at the fit.

An effect that adds states (an elastic riser) is not reached by copying the
fit: its stiffest, critically damped riser is not the rigid one, so the fit
is near, not at, the optimum of the extended model at theta_0.  The test is
then Neyman's C(alpha) test: the step is taken from the fit with the new
states integrated through it, where the nuisance parameters' gradient is not
zero.  The step's theta part is the efficient score (the theta gradient less
its projection on the nuisance parameters) times the inverse of the Schur
complement C_theta^-1, so the statistic above has the same chi-square law
to first order, without re-solving the null point.  That solve is the one
that failed: on `drogue` flown with added mass and fitted without it, the
stiff riser's Gauss-Newton steps opened its shooting gaps and 100 Ipopt
iterations (103 s) ended nowhere (`null_point="solve"` keeps that path).

Ranking many effects by p-value needs no correction for the ranking itself,
but reading "significant" off a list of m tests should use alpha / m
(`ScoreTest.significant` takes m).

The score statistic is local.  Where the effect's signature is partly
absorbed by large moves of the other parameters (a load-cell friction loss
moves the drag scale by many sigma), the chi-square surface is far from
quadratic over that distance and the Gauss-Newton curvature at the null
(from residuals that still hold the unexplained signal) overstates the
information: the statistic then undershoots the likelihood ratio, by a factor
of about three on the FBCP test.  `confirm` therefore refits the extended
model for the leading candidates, from the fit, and reports the
likelihood-ratio test, which ranks them by the chi-square they actually remove.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numpy as np

from cpas_ocp.errors import InputError, PluginError, SolverFailure
from cpas_ocp.estimation.estimator import POLISH_CONSTRAINT_TOL, STOP_CONSTRAINT_TOL, Estimator, Fit
from cpas_ocp.estimation.kkt_system import NonFiniteCurvature
from cpas_ocp.inference.hypothesis_tests import chi_bar_square_sf, cone_statistic
from cpas_ocp.inference.model_comparison import LikelihoodRatio, nested_start, nested_values
from cpas_ocp.inference.restarts import IMPROVEMENT_CHI2
from cpas_ocp.io.model_spec import RISER_MODELS, ModelSpec
from cpas_ocp.physics.effects.base import Effect
from cpas_ocp.physics.effects.registry import BUILTIN, EffectType
from cpas_ocp.process_memory import new_objects_only, release_freed_memory
from cpas_ocp.progress import progress_line

if TYPE_CHECKING:
    from cpas_ocp.physics.model import Model

# Relative chi-square mismatch above which the effect at its null values is taken not to
# reproduce the fit (its null point is then found by a restricted solve).
NESTED_CHI2_TOL = 1e-6
RESTRICTED_MAX_ITER = 100


@dataclass
class ScoreTest:
    """The score test of one effect at a fit.

    `estimate` holds the linearised estimates of the tested parameters (SI),
    `std` their standard deviations; `one_sided` the parameters whose null
    is a bound; `undetermined` those the data cannot determine in this test
    (left out of the statistic).  `note` says why an effect was not tested,
    or how its null point was reached.
    """

    effect: str
    source: str
    parameters: tuple[str, ...] = ()
    statistic: float = math.nan
    dof: int = 0
    p_value: float = math.nan
    null: dict[str, float] = field(default_factory=dict)
    estimate: dict[str, float] = field(default_factory=dict)
    std: dict[str, float] = field(default_factory=dict)
    one_sided: tuple[str, ...] = ()
    undetermined: tuple[str, ...] = ()
    note: str = ""
    # The refit with the effect (`confirm`): its likelihood ratio, estimates and outcome.
    refit: LikelihoodRatio | None = None
    refit_estimate: dict[str, float] = field(default_factory=dict)
    refit_note: str = ""
    spec: ModelSpec | None = field(default=None, repr=False)
    refitted: tuple[Estimator, Fit] | None = field(default=None, repr=False)
    # Which start the refit kept came from, once other starts were tried
    # (`discovery.from_other_starts`: "" where the nested refit stayed lowest); None before.
    start: str | None = None
    # Parameters whose linearised estimate lies beyond the bounds of the parameter: the
    # score step points there, but that is no value the model can take.
    beyond: tuple[str, ...] = ()

    @property
    def tested(self) -> bool:
        return not math.isnan(self.statistic)

    def significant(self, alpha: float = 0.01, tests: int = 1) -> bool:
        """p below alpha / tests (Bonferroni over `tests` effects tested together)."""
        return self.tested and self.p_value < alpha / max(tests, 1)

    def __str__(self) -> str:
        """One line: statistic, p-value and the estimates, or why it was not tested."""
        if not self.tested:
            return f"{self.effect:18s} not tested: {self.note}"
        shown = ", ".join(f"{n}: linearised step beyond its bounds (no estimate)"
                          if n in self.beyond else
                          f"{n} = {self.estimate[n]:.4g} +- {self.std[n]:.2g}"
                          for n in self.parameters if n in self.std)
        extra = f"; undetermined here: {', '.join(self.undetermined)}" if self.undetermined \
            else ""
        return (f"{self.effect:18s} LM = {self.statistic:10.2f} on {self.dof} "
                f"{'(one-sided) ' if self.one_sided else ''}p = {self.p_value:.2g}   "
                f"{shown}{extra}")

    def refit_text(self) -> str:
        """One line on the refit with the effect (empty when there was none)."""
        if self.refit is None:
            return f"{self.effect:18s} refit: {self.refit_note}" if self.refit_note else ""
        shown = ", ".join(f"{n} = {v:.4g}" for n, v in self.refit_estimate.items())
        how = f" ({self.refit_note})" if self.refit.lower_bound else ""
        return f"{self.effect:18s} refit: {self.refit}   {shown}{how}"

    def as_dict(self) -> dict:
        out = {}
        for f in dataclasses.fields(self):
            value = getattr(self, f.name)
            if f.name in ("spec", "refitted"):
                continue
            if f.name in ("estimate", "std"):  # an estimate beyond the bounds is none
                value = {n: None if n in self.beyond else v for n, v in value.items()}
            if f.name == "refit":
                value = None if value is None else value.as_dict()
            out[f.name] = None if isinstance(value, float) and math.isnan(value) else value
        return out


def candidate_effects(plugins: Mapping[str, EffectType] | None = None) -> dict[str, EffectType]:
    """The library's candidate effects (`EffectType.candidate`) and those of plug-in files,
    by name."""
    return {**{n: e for n, e in BUILTIN.items() if e.candidate}, **(plugins or {})}


def score_tests(fit: Fit, spec: ModelSpec,
                candidates: Mapping[str, EffectType] | None = None,
                progress: bool = False, exclude: frozenset[str] = frozenset()
                ) -> list[ScoreTest]:
    """Score-test every candidate effect the fit's model does not use (and `exclude` does
    not name); ranked, most significant first, then the effects that could not be tested.

    `spec` is the fitted model's spec; `candidates` defaults to the library
    (`candidate_effects`).
    """
    entries = {n: e for n, e in candidate_effects(candidates).items()
               if n not in spec.effect_names and n not in exclude}
    out = []
    with new_objects_only(), progress_line("score tests", len(entries), progress) as advance:
        for name, entry in entries.items():
            advance(name, done=0)
            out.append(score_test(fit, spec, entry))
            release_freed_memory()
            advance()
    return rank(out)


def rank(tests: list[ScoreTest]) -> list[ScoreTest]:
    """Tested effects by p-value (ties, including p = 0, by the larger statistic), then the
    untested ones."""
    return sorted(tests, key=lambda s: (not s.tested, s.p_value if s.tested else 0.0,
                                        -s.statistic if s.tested else 0.0))


def score_test(fit: Fit, spec: ModelSpec, entry: EffectType,
               null_point: str = "score") -> ScoreTest:
    """The score test of one effect (see the module docstring).

    Where the extended model at the null values does not reproduce the fit,
    `null_point` "score" takes the C(alpha) step from the fit; "solve" first
    re-solves the null point (at most `NULL_POINT_MAX_ITER` iterations).
    """
    if null_point not in ("score", "solve"):
        raise ValueError(f"null_point must be 'score' or 'solve', not {null_point!r}")
    result = ScoreTest(entry.name, entry.source)
    try:
        effect = entry.build({}, entry.source, entry.name)
    except InputError as exc:
        result.note = f"cannot be built with its default options ({exc})"
        return result
    null = effect.null_values(fit.test)
    if null is None:
        result.note = "not nested in the fitted model; compare by refitting (cpas-ocp compare)"
        return result
    if not null:
        result.note = "has no parameters in this test"
        return result
    try:
        extended = extended_spec(fit, spec, effect)
    except InputError as exc:
        result.note = f"does not apply to this test: {exc.expectation}"
        return result
    tested = tuple(null)
    result.parameters, result.null = tested, dict(null)
    model = extended.model(fit.test)
    free = [*fit.free, *tested]
    fixed = {n: fit.parameters[n] for n in model.parameter_names
             if n not in free and n in fit.parameters}
    # Only an effect with states brings a new NLP (its states, maybe a finer grid), worth
    # compiling for.
    settings = dataclasses.replace(fit.settings, free=free, fixed=fixed,
                                   compile=fit.settings.compile and bool(effect.states(fit.test)),
                                   guess={**(nested_values(fit, model, free) or {}), **null},
                                   limits={}, verbose=False)
    est = Estimator(fit.test, extended, settings)
    z, (chi2, violation) = est.extension_start(fit, null)
    if not _reproduces(chi2, violation, fit):
        if null_point == "solve":
            bounds = {n: (v, v) for n, v in null.items()}
            try:
                restricted = est.solve(start=z, bounds=bounds, max_iter=NULL_POINT_MAX_ITER,
                                       sensitivities=False)
            except SolverFailure as exc:
                result.note = f"its null point did not converge: {exc}"
                return result
            z = restricted.z
            result.note = (f"null point re-solved ({restricted.solver.iterations} iterations, "
                           f"chi-square {fit.chi_square:.1f} -> {restricted.chi_square:.1f})")
        elif not violation <= POLISH_CONSTRAINT_TOL:  # NaN too: the start blew up
            # A linearisation so far from feasible says nothing about the effect.
            result.note = (f"its null point is not near the fit (largest scaled shooting gap "
                           f"{violation:.2g}); compare by refitting (cpas-ocp compare)")
            return result
        else:
            result.note = (f"C(alpha) score from the fit with the effect's states added "
                           f"(chi-square {fit.chi_square:.1f} -> {chi2:.1f})")
    try:
        values, cov = est.gauss_newton_estimate(z, release=tested)
    except NonFiniteCurvature:
        # A Jacobian with inf or NaN in it: on `fbcp` with a GPS lag, the elastic riser at
        # its null (an all but rigid spring) integrated backwards over the lag blows up.
        result.note = ("its linearisation at the null is not finite (the extended model "
                       "overflows there); compare by refitting (cpas-ocp compare)")
        return result
    _statistic(result, model, values, cov)
    result.spec = extended
    return result


# Ipopt iterations a null point's solve gets: it starts next to the fit, so one that has
# not converged by then is reported as such (an elastic riser's on a misspecified `drogue`
# fit ran 500 iterations, almost six minutes, to no end).
NULL_POINT_MAX_ITER = 100


# Ipopt iterations a confirming refit gets.  It starts from the fit and the score test's
# step, so a refit the data support converges in tens; one that has not converged by then
# is reported as such rather than left to run to the fit's own limit (500 iterations,
# minutes on a long real flight).
CONFIRM_MAX_ITER = 150


def confirm(fit: Fit, result: ScoreTest, progress: bool = False,
            defaults_too: bool = False) -> None:
    """Refit the model with `result`'s effect, starting from `fit`, and record the
    likelihood-ratio test against `fit` (in place).  `defaults_too`: try the effect's
    defaults as well wherever the refit from the score step converged (below), and keep
    that fit where it is lower by more than IMPROVEMENT_CHI2.

    The effect's parameters start at their linearised estimates where those
    lie inside the bounds, else just inside the bound at the null value.
    The refit starts from that point or from a fraction of the score step,
    whichever is nearly feasible with the lowest chi-square (`_start_on_step`).
    Where it does not converge, or converges above the fit's chi-square, it is
    tried once more, for at most RETRY_MAX_ITER iterations, from the effect's own
    default values (`_retry_from_defaults`), and the lower of the two is kept.
    A refit above the fit has found a stationary point of the extended model
    that is not its optimum, or the extended model only approaches the fit
    (an elastic riser's stiffest is not rigid): on `drogue` flown with 6 Hz
    elastic risers, a refit finished by `feasible_descent` converged at
    chi-square 7,209.7 against the rigid fit's 7,187.7, and the verdict
    became "consistent with the noise".

    An effect brought in by continuation (`Effect.continuation`: an elastic
    riser, whose null is the singular stiff limit) whose linearised estimates
    all lie outside their bounds offers no step: its refit would start at the
    null, from where it does not converge (`_start_on_step`), so it starts from
    the effect's defaults alone (from the step where that try cannot be made).
    On `drogue` flown through a wind shear, the
    riser's score step (periods -0.14 and -0.12 s, damping ratios -2.6 and
    -1.6) sent the refit from the null through 150 iterations (41 s) to no end
    before the try from the defaults.
    """
    if not result.tested or result.spec is None:
        return
    model = result.spec.model(fit.test)
    null, target, start = {}, {}, {}
    for n in result.parameters:
        prm = model.parameter(n)
        inside = 0.01 * (prm.upper - prm.lower)
        null[n] = min(max(result.null[n], prm.lower + inside), prm.upper - inside)
        target[n] = min(max(result.estimate[n], prm.lower + inside), prm.upper - inside)
        start[n] = result.estimate[n] if target[n] == result.estimate[n] else null[n]
    nuisance = _nuisance(fit, model, result)
    est, z0, (chi2, violation) = nested_start(fit, result.spec,
                                              [*fit.free, *result.parameters, *nuisance],
                                              start, CONFIRM_MAX_ITER)
    dof = len(result.parameters) - len(result.undetermined)
    refitted: Fit | None = None
    failure: SolverFailure | None = None
    stepless, retry = _stepless(result, model, target), None
    if stepless:
        retry = _retry_from_defaults(est, fit, model, result, start, progress)
        stepless = retry[0] is not None or retry[2] is not None  # else no try was made
    if not stepless:
        z0 = _start_on_step(est, fit, null, target, (_start_chi2(chi2, violation), z0))
        try:
            refitted = est.solve(progress=progress, start=z0)
        except SolverFailure as exc:
            failure = exc
    origin = tried = ""
    if refitted is not None and defaults_too and retry is None \
            and refitted.chi_square <= fit.chi_square:
        # A full dose of the effect, beside the score step's small one.
        retry = _retry_from_defaults(est, fit, model, result, start, progress)
        if retry[0] is not None \
                and retry[0].chi_square < refitted.chi_square - IMPROVEMENT_CHI2:
            origin = (f" from the effect's defaults (the refit from the score step ended at "
                      f"chi-square {refitted.chi_square:.1f})")
            refitted = retry[0]
    if refitted is None or refitted.chi_square > fit.chi_square:
        # Not converged, or converged to a stationary point above the fit it extends.
        retried, tried, retry_failure = retry or _retry_from_defaults(est, fit, model, result,
                                                                      start, progress)
        failure = failure or retry_failure
        if retried is not None and (refitted is None
                                    or retried.chi_square < refitted.chi_square):
            first = ("offered no start: every linearised estimate lies outside its bounds"
                     if stepless else
                     f"did not converge: {failure.status} after {failure.iterations} "
                     f"iterations" if refitted is None else
                     f"ended above the fit, at chi-square {refitted.chi_square:.1f}")
            refitted = retried
            origin = f" from the effect's defaults (the score step {first})"
        elif refitted is None:
            result.refit_note = (
                f"the refit did not converge: {failure}{tried}" if not stepless else
                "its score step leaves every parameter's bounds, and the refit from the "
                f"effect's defaults did not converge: {failure}")
            _bound_from_last_iterate(fit, result, est, failure, dof)
            return
    result.refit = LikelihoodRatio(fit.chi_square - refitted.chi_square, dof,
                                   len(result.one_sided))
    result.refit_estimate = {n: refitted.parameters[n] for n in [*result.parameters,
                                                                  *nuisance]}
    result.refitted = (est, refitted)
    result.refit_note = (f"{refitted.solver.iterations} iterations{origin}, chi-square "
                         f"{fit.chi_square:.1f} -> {refitted.chi_square:.1f}")
    if refitted.chi_square > fit.chi_square:
        result.refit_note += (" (above the fit: a stationary point of the extended model "
                              f"that need not be its optimum{tried})")


def _nuisance(fit: Fit, model: Model, result: ScoreTest) -> list[str]:
    """The effect's parameters that its null leaves out but that are estimated by default:
    they change nothing under the null (a modulation's frequency where its amplitudes
    are zero) and start at their defaults.  The refit estimates them with the rest,
    as a fit of the extended model would; held at their defaults, a frequency read
    off a periodogram 2 % high left the refit of a 3 Hz drag-area modulation on
    `fbcp` at chi-square 2,998.9 against the model's optimum 2,635.8.  The
    likelihood ratio keeps the null's degrees of freedom: a parameter that exists
    only under the alternative makes its distribution non-standard (Davies 1977)
    and the p-value approximate (too small)."""
    return [n for n in model.parameter_names if n not in fit.parameters
            and n not in result.parameters and model.parameter(n).estimable
            and model.parameter(n).free_by_default]


# Iterations of a confirming refit's second try, from the effect's defaults.  On `drogue`
# flown with 6 Hz elastic risers, refits from 3-12 Hz converged in 22-50 iterations.
RETRY_MAX_ITER = 60


def _stepless(result: ScoreTest, model: Model, target: dict[str, float]) -> bool:
    """Whether `result`'s effect is one brought in by continuation (`Effect.continuation`)
    and its score step leaves the bounds of every parameter (`target`, the estimates
    moved inside the bounds, differs from each estimate): a refit from the step would
    start at the null."""
    effect = next((e for e in model.effects if e.name == result.effect), None)
    return effect is not None and effect.continuation and all(
        target[n] != result.estimate[n] for n in result.parameters)


def _retry_from_defaults(est: Estimator, fit: Fit, model: Model, result: ScoreTest,
                         tried: dict[str, float], progress: bool
                         ) -> tuple[Fit | None, str, SolverFailure | None]:
    """The refit from `fit` with the effect's parameters at their defaults (the model's
    typical values), where those differ from the start `tried` and start nearly
    feasible, and converge in RETRY_MAX_ITER iterations (else None); a note on a try
    that did not converge, for the refit's note ("" where none was made); and that
    try's failure (None where it converged or was not made).

    The score step extrapolates from the null, which for some effects is a
    singular limit (a rigid riser is an elastic one with zero period): there
    the refit's start is a matter of luck.  On `drogue` flown with 6 Hz
    elastic risers and fitted with rigid ones, the refit from the score step
    stopped at 150 iterations (LR >= 66.7 from its last iterate), and from the
    riser's defaults (8 Hz, zeta 0.3) converged in 24 (LR 90.3).
    """
    defaults = {n: model.parameter(n).default for n in result.parameters}
    if all(np.isclose(defaults[n], tried[n]) for n in defaults):
        return None, "", None
    z0, (chi2, violation) = est.extension_start(fit, defaults)
    if _start_chi2(chi2, violation) == np.inf:
        return None, "", None
    try:
        return est.solve(progress=progress, start=z0, max_iter=RETRY_MAX_ITER), "", None
    except SolverFailure as exc:
        return None, (f"; a second try from the effect's defaults stopped too ({exc.status} "
                      f"after {exc.iterations} iterations)"), exc


# Fractions of the score test's step at which a confirming refit's start is tried beside
# the linearised estimates.
START_FRACTIONS = (0.5, 0.25, 0.125)


def _start_chi2(chi2: float, violation: float) -> float:
    """A refit start's chi-square where the start is nearly feasible (its largest scaled
    gap within POLISH_CONSTRAINT_TOL) and chi-square a number; inf otherwise."""
    return chi2 if np.isfinite(chi2) and violation <= POLISH_CONSTRAINT_TOL else np.inf


def _start_on_step(est: Estimator, fit: Fit, null: dict[str, float],
                   target: dict[str, float], first: tuple[float, np.ndarray]) -> np.ndarray:
    """Of `first` (a start and its chi-square, inf where it is far from feasible) and the
    extended model's starts at `fit` (`Estimator.extension_start`) with the effect's
    parameters at null + a (target - null) for the a of START_FRACTIONS within
    POLISH_CONSTRAINT_TOL of feasible, the one with the lowest chi-square; `first`'s
    start where none is feasible.

    The linearised estimates themselves (`first`) may be feasible and still a
    poor start: on `drogue` flown with added mass and fitted without it, the
    elastic riser's estimated period started the refit at chi-square 17,363
    against the fit's 8,518, and its first watchdog steps diverged (1e40).

    The score step is linear; the effect may not be.  On `drogue` flown with
    6 Hz elastic risers (damping 0.3) and fitted with rigid ones, the full
    step (42 and 38 Hz, damping 0.49 and 0.11) starts at chi-square 1e10,
    gaps 0.08.  From an eighth of it (27 Hz, 7,194.0) the refit reached 6.4
    and 5.4 Hz, damping 0.42 and 0.24, in 128 iterations (LR 90).  The null
    values themselves are not tried: there the riser is all but rigid, the
    chi-square flat in its parameters, and refits from there did not
    converge in 150 iterations, on `drogue` or on `fbcp` (where a quarter or
    half of the step converged in 33-35).
    """
    best = first
    for a in START_FRACTIONS:
        values = {n: null[n] + a * (target[n] - null[n]) for n in target}
        z, (chi2, violation) = est.extension_start(fit, values)
        if _start_chi2(chi2, violation) < best[0]:
            best = (chi2, z)
    return best[1]


def _bound_from_last_iterate(fit: Fit, result: ScoreTest, est: Estimator,
                             failure: SolverFailure, dof: int) -> None:
    """After a refit that did not converge: where its last iterate or its best nearly
    feasible one (`Estimator.best_iterate`), integrated into a feasible point of the
    extended model (`Estimator.feasible_point`), has a lower chi-square than `fit`,
    record the likelihood ratio as the lower bound the lower of the two gives (in
    place), with the effect's values there.

    The extended model's optimum lies at or below any of its feasible points,
    so LR >= chi^2(fit) - chi^2(point) and the p-value of that bound is an
    upper bound on the test's: a refit that ran out of iterations far below
    the fit still confirms the effect, without a claim on its final estimates.
    """
    last = failure.last_iterate
    witnesses = {"last": last.z if last is not None else None,
                 "lowest nearly feasible": est.best_iterate}
    if witnesses["last"] is not None and witnesses["lowest nearly feasible"] is not None \
            and np.array_equal(*witnesses.values()):
        del witnesses["lowest nearly feasible"]  # one point, integrated once
    feasible = {label: est.feasible_point(z) for label, z in witnesses.items()
                if z is not None}
    found = {label: f for label, f in feasible.items() if f is not None}
    if not found:
        return
    label = min(found, key=lambda k: found[k][1])
    point, chi2 = found[label]
    if not fit.chi_square - chi2 > 0.0:
        return
    values = est.free_values(point)
    result.refit = LikelihoodRatio(fit.chi_square - chi2, dof, len(result.one_sided),
                                   lower_bound=True)
    result.refit_estimate = {n: values[n] for n in result.parameters}
    result.refit_note += (f"; its {label} iterate, integrated to a feasible point, has "
                          f"chi-square {chi2:.1f} against the fit's {fit.chi_square:.1f}")


def confirmed_ranking(tests: list[ScoreTest]) -> list[ScoreTest]:
    """Refitted effects first, by the likelihood-ratio p-value (ties, including underflow
    to 0, by the larger statistic); then the rest in score-test order."""
    done = [t for t in tests if t.refit is not None]
    rest = [t for t in tests if t.refit is None]
    done.sort(key=lambda t: (t.refit.p_value, -t.refit.statistic))  # type: ignore[union-attr]
    return done + rank(rest)


def extended_spec(fit: Fit, spec: ModelSpec, effect: Effect) -> ModelSpec:
    """`spec` with `effect` added where the composition accepts it (replacing the effect it
    `replaces`); when no position composes, the first PluginError (the plug-in's code failed
    where its place was right), else the first InputError."""
    effects = list(spec.effects)
    names = [e.name for e in effects]
    if effect.replaces in names:
        at = names.index(effect.replaces)
        trials = [[*effects[:at], effect, *effects[at + 1:]]]
    elif effect.name in RISER_MODELS and set(names) & set(RISER_MODELS):
        used = ", ".join(sorted(set(names) & set(RISER_MODELS)))
        raise InputError(spec.source, "model.effects",
                         f"one riser model; the fit uses {used}")
    else:
        trials = [[*effects[:k], effect, *effects[k:]] for k in range(len(effects), -1, -1)]
    errors: list[InputError | PluginError] = []
    for trial in trials:
        candidate = dataclasses.replace(spec, effects=tuple(trial))
        try:
            candidate.model(fit.test)
        except (InputError, PluginError) as exc:  # a plug-in's hook may fail at one place only
            errors.append(exc)
            continue
        return candidate
    # A plug-in's own failure where it composes says more than where it does not.
    raise next((e for e in errors if isinstance(e, PluginError)), errors[0])


def _reproduces(chi2: float, violation: float, fit: Fit) -> bool:
    """Whether the extended NLP at a point of chi-square `chi2` and largest scaled gap
    `violation` is feasible and has the fit's chi-square."""
    return (violation <= STOP_CONSTRAINT_TOL
            and abs(chi2 - fit.chi_square) <= NESTED_CHI2_TOL * max(fit.chi_square, 1.0))


def _statistic(result: ScoreTest, model, values: dict[str, float], cov) -> None:
    """Fill in the statistic, its degrees of freedom and p-value (one-sided where the null
    is a bound of the parameter)."""
    undetermined = set(cov.undetermined)
    names = [n for n in result.parameters if n not in undetermined]
    result.undetermined = tuple(n for n in result.parameters if n in undetermined)
    result.estimate = {n: values[n] for n in result.parameters}
    result.beyond = tuple(n for n in result.parameters
                          if not model.parameter(n).lower <= values[n]
                          <= model.parameter(n).upper)
    std = cov.std
    result.std = {n: std[n] for n in names}
    if not names:
        result.note = "the data do not determine its parameters in this test"
        return
    index = [cov.names.index(n) for n in names]
    C = cov.matrix[np.ix_(index, index)]
    theta = np.array([values[n] - result.null[n] for n in names])
    lower = np.full(len(names), -np.inf)
    upper = np.full(len(names), np.inf)
    sided = []
    for j, n in enumerate(names):
        prm = model.parameter(n)
        if prm.on_bound(result.null[n]):
            # The alternative lies on the side of the bound the null value is not.
            if result.null[n] <= prm.lower:
                lower[j] = 0.0
            else:
                upper[j] = 0.0
            sided.append(n)
    statistic = cone_statistic(theta, C, lower, upper)
    result.statistic = statistic
    result.dof = len(names)
    result.one_sided = tuple(sided)
    result.p_value = chi_bar_square_sf(statistic, len(names) - len(sided), len(sided))
