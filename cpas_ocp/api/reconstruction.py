"""One test's reconstruction: the fit, its covariance and claim, and what follows from it."""

from __future__ import annotations

import dataclasses
import html
import shutil
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path

import matplotlib.pyplot as plt
import numpy as np
import pandas as pd

from cpas_ocp import interrupts
from cpas_ocp.api.kept_discovery import discover_kept, discovery_context
from cpas_ocp.discrepancy.diagnosis import ALPHA, CONFIRM_TOP, Diagnosis, diagnose
from cpas_ocp.discrepancy.discovery import (
    MAX_STEPS,
    Discovery,
    DiscoveryStep,
    discover,
)
from cpas_ocp.discrepancy.score_test import extended_spec
from cpas_ocp.errors import InputError, NotAResult, SolverFailure
from cpas_ocp.estimation.estimator import Estimator, Fit, Settings
from cpas_ocp.estimation.simulate import simulate_problem
from cpas_ocp.estimation.uncertainty import Covariance
from cpas_ocp.inference.diagnostics import window_statistics, worst_of
from cpas_ocp.inference.model_comparison import Comparison, Criteria, compare
from cpas_ocp.inference.phase_windows import phase_windows
from cpas_ocp.inference.process_intensity import IntensityChoice
from cpas_ocp.inference.profile_likelihood import Profile, profile, require_free
from cpas_ocp.inference.reconstruction import fit_and_claim
from cpas_ocp.inference.result_claim import (
    Claim,
    start_shifts,
    with_start_shifts,
)
from cpas_ocp.inference.whatif import WhatIfResult, parameter_bounds, parse_constraint
from cpas_ocp.inference.whatif import what_if as solve_what_if
from cpas_ocp.io.flight_test import load_test
from cpas_ocp.io.model_spec import ModelSpec, load_model_file, spec_of_test
from cpas_ocp.io.problems import load_problem
from cpas_ocp.physics.effects.registry import BUILTIN, EffectType, load_plugins
from cpas_ocp.physics.flight_test import FlightTest
from cpas_ocp.progress import SILENT, Narration
from cpas_ocp.reports.discrepancy_report import write_comparison, write_diagnosis
from cpas_ocp.reports.display_units import DisplayUnits, display_units
from cpas_ocp.reports.failure_report import write_failure_report
from cpas_ocp.reports.fit_text import claim_text, grid_text, intensity_text
from cpas_ocp.reports.plots import (
    correlation_axes,
    drag_area_axes,
    events_axes,
    profile_axes,
    sensor_axes,
)
from cpas_ocp.reports.report import fit_summary, parameter_table, write_report
from cpas_ocp.reports.report_data import bound_flag


@dataclass(frozen=True)
class FitOptions:
    """How a test phase is fitted, beyond the model.

    settings: the transcription's and Ipopt's (`estimation.fit.Settings`: a forced
    grid step in s, Ipopt's log, its iteration limit, ...; None: the defaults);
    hessian: the curvature the covariance inverts ("gauss-newton", or "exact": the
    Lagrangian's);
    rescale_sigmas: the sensor sigmas are not trusted: scale the covariance and the
    what-if tests by chi-square/dof;
    wind_intensities: multiples of the wind process's sigmas among which its
    intensity is chosen by the marginal likelihood, one fit each (none: the model's).
    """

    settings: Settings | None = None
    hessian: str = "gauss-newton"
    rescale_sigmas: bool = False
    wind_intensities: tuple[float, ...] = ()


def as_test(test: FlightTest | str | Path) -> FlightTest:
    """A loaded test as given, else the test in the folder `test`."""
    return test if isinstance(test, FlightTest) else load_test(test)


def model_of(test: FlightTest, model: ModelSpec | str | Path | None = None,
             plugins: Mapping[str, EffectType] | None = None,
             allow_external_plugins: bool = False) -> ModelSpec:
    """The model `model` names: a spec as given, a model file (whose effects may be
    `plugins`), or None for the test manifest's own; plug-in files named from outside
    their file's folder are refused unless `allow_external_plugins`."""
    if isinstance(model, ModelSpec):
        return model
    if model is None:
        return spec_of_test(test, allow_external_plugins)
    return load_model_file(model, dict(plugins or {}), allow_external_plugins)


def build(test: FlightTest, spec: ModelSpec, settings: Settings | None = None,
          tell: Narration = SILENT) -> Estimator:
    """The multiple-shooting NLP of a test phase under `spec`, its shooting grid said, and
    a warning for every sensor no effect of the model predicts (its data are not fitted).
    A forced grid step must be positive and shorter than the phase (InputError)."""
    step = None if settings is None else settings.grid_step
    if step is not None and not 0.0 < step < test.t_end - test.t_start:
        raise InputError("(options)", "grid_step", "a step in seconds, positive and shorter "
                         f"than the phase; got {step}")
    tell.say(f"building the multiple-shooting NLP of {test.name} "
             f"({test.t_end - test.t_start:.1f} s) ...")
    est = Estimator(test, spec, settings=settings)
    tell.say(f"  {grid_text(est.t)}")
    if est.unfitted:
        tell.warn(f"no effect of the model predicts sensor(s) {', '.join(est.unfitted)}: "
                  "their data are not fitted")
    return est


def fit_estimator(est: Estimator, options: FitOptions | None = None,
                  plugins: Mapping[str, EffectType] | None = None,
                  tell: Narration = SILENT) -> Reconstruction:
    """A reconstruction of `est` (`inference.reconstruction.fit_and_claim`, the one path
    every workflow that fits takes), with the plug-in effects its diagnosis may test; a
    warning for every parameter combination the data leave undetermined and every reason
    the fit is not yet a result.  Raises SolverFailure where no fit converges."""
    options = options or FitOptions()
    if options.wind_intensities:
        tell.say(f"choosing the wind process's intensity ({len(options.wind_intensities)} "
                 "fits) ...")
    if options.hessian == "exact":
        tell.say("the fit, then its exact-Hessian covariance ...")
    done = fit_and_claim(est, options.rescale_sigmas, options.hessian,
                         options.wind_intensities, tell.progress)
    rec = Reconstruction(done.estimator, done.fit, done.covariance, done.claim,
                         dict(plugins or {}), done.intensity_choice)
    if rec.intensity_choice is not None:
        tell.say(intensity_text(rec.intensity_choice))
    if rec.covariance.undetermined:
        tell.warn(f"the data do not determine {', '.join(rec.covariance.undetermined)} "
                  "(see the identifiability lines)")
    for problem in rec.problems:
        tell.warn(problem)
    return rec


def reconstruct(test: FlightTest | str | Path, model: ModelSpec | str | Path | None = None,
                plugins: Sequence[str | Path] | Mapping[str, EffectType] = (),
                options: FitOptions | None = None, out: str | Path | None = None,
                profiles: Sequence[str] = (), profile_span: float = 3.0,
                profile_points: int = 13, units: DisplayUnits | str | None = None,
                allow_external_plugins: bool = False, tell: Narration = SILENT
                ) -> Reconstruction:
    """Reconstruct a test (a loaded test or its folder) with `model` (a spec, a model file,
    or None for the manifest's, whose effects may be `plugins`: files or loaded effects):
    the fit from the offline reduction, what it may claim (`result_claim`), and its
    covariance (`fit_estimator`); the likelihood of each free parameter in `profiles`
    profiled over the estimate -+ `profile_span` sigma at `profile_points` values.

    With `out`, the report folder `cpas-ocp reconstruct` writes is written there, in
    `units` (display units, "si", "us", or None for the test's own); a fit that does not
    converge writes its failure report there instead.  Raises SolverFailure where no fit
    converges."""
    test = as_test(test)
    effects = plugins if isinstance(plugins, Mapping) else load_plugins(plugins)
    est = build(test, model_of(test, model, effects, allow_external_plugins),
                None if options is None else options.settings, tell)
    for name in profiles:
        require_free(est, name)
    tell.say(f"solving: {est.size_text()} ...")
    try:
        rec = fit_estimator(est, options, effects, tell)
    except SolverFailure as exc:
        if out is not None:
            folder = write_failure_report(exc, out)
            tell.warn(f"NOT CONVERGED: why is in {folder / 'failure.md'}")
        raise
    rec.profiles = [rec.profile(n, profile_span, profile_points, tell.progress)
                    for n in profiles]
    if out is not None:
        rec.units = units_of(test, units)
        rec.folder = rec.report(out, units=rec.units)
    return rec


def units_of(test: FlightTest, units: DisplayUnits | str | None) -> DisplayUnits:
    """Display units: as given, a system's name ("si", "us"), or None for those the
    test's manifest is written in."""
    return units if isinstance(units, DisplayUnits) else display_units(test, units)


def say_written(rec: Reconstruction, tell: Narration) -> None:
    """Say a reconstruction whose report was written (`reconstruct` with `out`): its
    parameter table, statistics and claim, its profiles, and where the report is."""
    tell.say("")
    tell.say(rec.summary(rec.units))
    for prof in rec.profiles:
        tell.say(f"profile likelihood, {prof}")
    tell.say(f"\nreport written to {rec.folder} (result.json, parameters.csv, report.md, "
             "figures)")
    tell.say(f"interactive report: {rec.folder / 'report.html'}")  # type: ignore[operator]


def require_result(rec: Reconstruction) -> None:
    """NotAResult where the fit converged but may not be read as a result (after its report
    is written, which says why)."""
    if not rec.is_result:
        where = f" (see the claim in {rec.folder / 'report.md'})" if rec.folder else ""
        raise NotAResult(f"the fit converged but is not a result{where}: {rec.problems[0]}")


def what_if(test: FlightTest | str | Path, constraints: Sequence[str],
            model: ModelSpec | str | Path | None = None,
            plugins: Sequence[str | Path] = (), options: FitOptions | None = None,
            allow_external_plugins: bool = False, tell: Narration = SILENT) -> WhatIfResult:
    """The fit of `test` re-solved under `constraints` (`Reconstruction.what_if`; `cpas-ocp
    whatif`): the constraints are read and their contradictions refused before any fit,
    and a first fit that is not a result is refused (NotAResult), since a what-if from it
    means nothing."""
    test = as_test(test)
    effects = load_plugins(plugins)
    est = build(test, model_of(test, model, effects, allow_external_plugins),
                None if options is None else options.settings, tell)
    parameter_bounds([parse_constraint(text, est) for text in constraints], est)
    tell.say(f"solving without the constraints: {est.size_text()} ...")
    rec = fit_estimator(est, options, effects, tell)
    if not rec.is_result:
        raise NotAResult("the fit without the constraints is not a result, so a what-if from "
                         "it means nothing: " + "; ".join(rec.problems))
    tell.say("solving with them ...")
    return rec.what_if(*constraints, progress=tell.progress)


def demo(out: str | Path, seed: int = 1, options: FitOptions | None = None,
         units: DisplayUnits | str | None = None, tell: Narration = SILENT
         ) -> Reconstruction:
    """The built-in Drogue test simulated with noise from `seed` into out/test and
    reconstructed into out/report (`cpas-ocp demo`).  A folder out/test that is not an
    earlier demo's (no truth.json) is refused; an interrupted demo leaves no test folder."""
    test_dir = Path(out) / "test"
    if test_dir.is_symlink() or (test_dir.exists() and not (test_dir / "truth.json").is_file()):
        raise InputError(str(test_dir), "(folder)", "no such folder, or a test simulated by an "
                         "earlier demo (holding truth.json) to replace")
    if test_dir.exists():
        shutil.rmtree(test_dir)
    tell.say(f"simulating the built-in 'drogue' problem (seed {seed}) into {test_dir}")
    test = simulate_problem(load_problem("drogue"), test_dir, seed)
    try:
        return reconstruct(test, options=options, out=Path(out) / "report",
                           units=units_of(test, units), tell=tell)
    except (interrupts.Interrupted, KeyboardInterrupt):
        shutil.rmtree(test_dir, ignore_errors=True)
        raise


@dataclass
class Reconstruction:
    """One reconstruction: the estimator that made it, the fit, its covariance and claim,
    and the plug-in effects its model may use or its diagnosis test."""

    estimator: Estimator
    fit: Fit
    covariance: Covariance
    claim: Claim
    plugins: dict[str, EffectType]
    intensity_choice: IntensityChoice | None = None  # where the wind's intensity was chosen
    profiles: list[Profile] = dataclasses.field(default_factory=list)  # those asked for
    folder: Path | None = None  # where its report was written
    units: DisplayUnits | None = None  # its report's units

    @property
    def spec(self) -> ModelSpec:
        return self.estimator.spec

    @property
    def is_result(self) -> bool:
        """Whether the fit may be read as a result (`result_claim.Claim.is_result`)."""
        return self.claim.is_result

    @property
    def problems(self) -> list[str]:
        """Why the fit is not yet a result (empty where it is)."""
        return self.claim.problems()

    @property
    def parameters(self) -> pd.DataFrame:
        """The free parameters: value, 1 sigma, 95 % interval (value -+ 1.96 sigma), unit and
        where the value stands against its bounds (`report_data.bound_flag`, '' where
        clear), SI, indexed by name."""
        model = self.estimator.model
        rows = []
        for name in self.fit.free:
            value = self.fit.parameters[name]
            sigma = self.covariance.std.get(name, np.nan)
            rows.append({"parameter": name, "value": value, "sigma": sigma,
                         "low_95": value - 1.96 * sigma, "high_95": value + 1.96 * sigma,
                         "unit": model.parameter(name).unit,
                         "bound": bound_flag(self.fit, self.covariance, name)})
        return pd.DataFrame(rows).set_index("parameter")

    @property
    def chi_square_per_dof(self) -> float:
        return self.fit.chi_square / self.fit.dof

    @property
    def criteria(self) -> Criteria:
        """Chi-square, AIC and BIC with the sensors' sigmas known (only differences between
        fits of the same data mean anything)."""
        return Criteria.of(self.fit)

    def summary(self, units: DisplayUnits | None = None) -> str:
        """The parameter table with sigmas and intervals, the fit's statistics and what it
        may claim, as `cpas-ocp reconstruct` prints them."""
        return "\n\n".join([parameter_table(self.fit, self.covariance, units),
                             fit_summary(self.fit, units), claim_text(self.claim)])

    def __repr__(self) -> str:
        state = "a result" if self.is_result else "not a result"
        return (f"<Reconstruction of {self.fit.test.name}: {len(self.fit.free)} parameters, "
                f"chi-square/dof {self.chi_square_per_dof:.3f}, {state}>")

    def _repr_html_(self) -> str:
        """What a notebook shows: the claim in one line, the fit's statistics, and the
        parameter table."""
        state = ("a result" if self.is_result else
                 "<b>not a result</b>: " + html.escape("; ".join(self.problems)))
        head = (f"<p><b>{html.escape(self.fit.test.name)}</b>: chi-square/dof "
                f"{self.chi_square_per_dof:.3f} ({self.fit.dof} dof), {state}</p>")
        return head + self.parameters.to_html(float_format=lambda v: f"{v:.6g}")

    def plot(self, sensor: str, axes: Sequence[plt.Axes] | None = None, windows: bool = True
             ) -> list[plt.Axes]:
        """Model against measurement of `sensor`, each channel over its normalised residuals
        (two axes per channel, into `axes` where given), the phase windows shaded unless
        `windows` is False; returns the axes (`plots.sensor_axes`)."""
        shown = phase_windows(self.fit) if windows else ()
        return sensor_axes(self.fit, sensor, shown, axes=axes)

    def plot_drag_areas(self, axes: Sequence[plt.Axes] | None = None) -> list[plt.Axes]:
        """Each canopy's reconstructed drag area CdS(t) against its load cell's offline
        reduction, the inflation start times dashed (one axis per canopy); the axes."""
        return drag_area_axes(self.fit, axes=axes)

    def plot_events(self, ax: plt.Axes | None = None) -> plt.Axes | None:
        """The observed event times with their sigmas against the model's; the axis (None
        where the test has no observed events)."""
        return events_axes(self.fit, ax)

    def plot_correlation(self, ax: plt.Axes | None = None) -> plt.Axes | None:
        """The free parameters' correlation map; the axis (None with fewer than two
        determined parameters off their bounds)."""
        return correlation_axes(self.covariance, ax)

    def plot_profile(self, prof: Profile, ax: plt.Axes | None = None) -> plt.Axes:
        """A profile (`profile`) against the covariance's parabola, both 95 % intervals
        marked; the axis."""
        return profile_axes(prof, ax)

    def spec_with(self, *effects: str) -> ModelSpec:
        """This fit's model with the library's or the plug-ins' `effects` added where the
        composition accepts them (for `compare`: the two models are then nested)."""
        registry = {**BUILTIN, **self.plugins}
        spec = self.spec
        for name in effects:
            if name not in registry:
                raise ValueError(f"no effect {name!r}; the library's and the plug-ins': "
                                 f"{', '.join(sorted(registry))}")
            spec = extended_spec(self.fit, spec, registry[name].build({}, "(spec_with)", name))
        return spec

    def profile(self, name: str, span: float = 3.0, points: int = 13,
                progress: bool = False) -> Profile:
        """The profile likelihood of free parameter `name` over the estimate -+ `span`
        sigma at `points` values (`cpas-ocp reconstruct --profile`)."""
        return profile(self.estimator, self.fit, self.covariance, name, span, points, progress)

    def what_if(self, *constraints: str, progress: bool = False) -> WhatIfResult:
        """The fit re-solved under `constraints` ('NAME == VALUE [UNIT]', 'NAME <= VALUE',
        a peak limit such as 'peak_load[drogue1] <= 30000 lbf'): what each costs in
        chi-square, its test, and how far it pushes the rest (`cpas-ocp whatif`)."""
        parsed = [parse_constraint(text, self.estimator) for text in constraints]
        parameter_bounds(parsed, self.estimator)  # contradictions refused before the fits
        return solve_what_if(self.estimator, self.fit, self.covariance, parsed, progress)

    @property
    def worst(self) -> str:
        """One line: the sensor channel and phase window that depart from the noise most."""
        return worst_of(window_statistics(self.fit, phase_windows(self.fit)))

    def report(self, out: str | Path, profiles: Sequence[Profile] | None = None,
               units: DisplayUnits | None = None) -> Path:
        """Write the report folder `cpas-ocp reconstruct` writes (result.json,
        parameters.csv, report.md, report.html, figures) to `out`, with `profiles` (default
        those made with the fit), tables and figures in `units` (default the test's own)."""
        shown = self.profiles if profiles is None else list(profiles)
        return write_report(self.fit, self.covariance, out, shown, self.claim, units)

    def diagnose(self, out: str | Path | None = None, confirm: int = CONFIRM_TOP,
                 alpha: float = ALPHA, progress: bool = False,
                 units: DisplayUnits | None = None) -> Diagnosis:
        """Where the model fails and which effect it lacks (`cpas-ocp diagnose`): every
        library and plug-in effect the model leaves out tested at family-wise level
        `alpha`, the `confirm` leading ones refitted; the folder written to `out` where
        given."""
        diag = diagnose(self.fit, self.spec, self.plugins, confirm, alpha, progress=progress)
        if out is not None:
            write_diagnosis(diag, self.covariance, out, units)
        return diag

    def discover(self, out: str | Path | None = None, max_steps: int = MAX_STEPS,
                 alpha: float = ALPHA, confirm: int = CONFIRM_TOP, progress: bool = False,
                 on_step: Callable[[DiscoveryStep], None] | None = None,
                 units: DisplayUnits | None = None,
                 plugin_files: Sequence[str | Path] = ()) -> Discovery:
        """Diagnose, add the confirmed effect, refit, and again, at most `max_steps` times,
        from this fit (`cpas-ocp discover`; `on_step` is called as each step ends).  With
        `out`, the folder is written whole at every point the chain is whole, so a run
        stopped keeps its finished steps and `resume_discovery(out)` goes on from them
        (`discover_kept`; `plugin_files` are the files of this fit's plug-in effects,
        which a resumed run loads again)."""
        if out is None:
            return discover(self.fit, self.spec, self.plugins, max_steps, alpha, confirm,
                            progress=progress, on_step=on_step, estimator=self.estimator)
        if self.fit.test.path is None:
            raise InputError("(test)", "path", "a test read from a folder, for a discovery "
                             "kept on disk")
        context = discovery_context(self.fit.test.path, plugin_files, max_steps, alpha,
                                    confirm, None if units is None else units.system)
        if not self.is_result:
            context["first_fit"] = f"the first fit is not a result: {self.problems[0]}"
        return discover_kept(out, self.fit, self.spec, self.plugins, context, units,
                             estimator=self.estimator, progress=progress, on_step=on_step)

    def compare(self, model: ModelSpec | str | Path, out: str | Path | None = None,
                labels: tuple[str, str] = ("this", "other"), progress: bool = False,
                units: DisplayUnits | None = None) -> Comparison:
        """This model against `model` (a spec or a model file), the second started from
        this fit, with the start windows this fit had to move moved in it too
        (`cpas-ocp compare`); the folder written to `out` where given."""
        other = model if isinstance(model, ModelSpec) else load_model_file(model, self.plugins)
        other = with_start_shifts(other, start_shifts(self.spec))
        comparison = compare(self.fit, self.covariance, self.spec, other, labels, progress)
        if out is not None:
            write_comparison(comparison, out, units)
        return comparison
