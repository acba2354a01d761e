"""The Python interface for notebooks and scripts: the command line's steps as functions.

    import cpas_ocp as co

    test = co.simulate("drogue", "drogue-test", seed=1)   # or co.load_test(folder)
    rec = co.reconstruct(test)        # solve, judge the fit, covariance
    rec.parameters                    # value, sigma, 95 % interval, unit (SI)
    rec.worst                         # where the model fits worst, one line
    rec.report("report")              # the folder `cpas-ocp reconstruct` writes
    diag = rec.diagnose()             # which effect is missing, or the residual's signature
    chain = rec.discover()            # diagnose, add, refit, ... until the residual is noise
    comp = rec.compare("model.json")  # this model against another, nested or not

A fit that did not converge raises `SolverFailure` (its status and iteration
count), never a result; a fit that converged but is not a result (a guessed bound
pressed, chi-square/dof beyond 10, a process beyond its prior, a drag area
undetermined: `result_claim`) is returned with `rec.is_result` False and
`rec.problems` saying why.
"""

from __future__ import annotations

import dataclasses
import html
import shutil
import sys
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import matplotlib.pyplot as plt
import numpy as np
import pandas as pd

from cpas_ocp import interrupts
from cpas_ocp.campaign.campaign import (
    TestOutcome,
    campaign_text,
    find_tests,
    run_campaign,
    write_campaign,
)
from cpas_ocp.campaign.dispersion_study import (
    DispersionModel,
    dispersion_models,
    read_parameter_table,
    read_stage_table,
)
from cpas_ocp.campaign.peak_load_study import MARKER as MONTE_CARLO_MARKER
from cpas_ocp.campaign.peak_load_study import (
    StageLoads,
    check_columns,
    match_cases,
    run_monte_carlo,
    summary_text,
)
from cpas_ocp.campaign.population_study import (
    PopulationGroup,
    population_dispersions,
    population_groups,
    read_covariance_table,
    with_line_length_ratio,
)
from cpas_ocp.discrepancy.diagnosis import ALPHA, CONFIRM_TOP, Diagnosis, diagnose
from cpas_ocp.discrepancy.discovery import (
    MAX_STEPS,
    Discovery,
    DiscoveryStep,
    InterruptedDiscovery,
    discover,
)
from cpas_ocp.discrepancy.discovery_checkpoint import (
    checkpoint_context,
    read_checkpoint,
    write_checkpoint,
)
from cpas_ocp.discrepancy.score_test import extended_spec
from cpas_ocp.errors import InputError, NotAResult, PluginError
from cpas_ocp.estimation.estimator import Estimator, Fit, Settings
from cpas_ocp.estimation.simulate import simulate_problem
from cpas_ocp.estimation.uncertainty import Covariance
from cpas_ocp.inference.diagnostics import window_statistics, worst_of
from cpas_ocp.inference.joint_fit import JointFit, SharingError, joint_fit
from cpas_ocp.inference.model_comparison import Comparison, Criteria, compare
from cpas_ocp.inference.phase_windows import phase_windows
from cpas_ocp.inference.process_intensity import IntensityChoice
from cpas_ocp.inference.profile_likelihood import Profile, profile
from cpas_ocp.inference.reconstruction import fit_and_claim
from cpas_ocp.inference.result_claim import (
    Claim,
    start_shifts,
    with_start_shifts,
)
from cpas_ocp.inference.test_design import TestDesign
from cpas_ocp.inference.test_design import design as design_test
from cpas_ocp.inference.whatif import WhatIfResult, parameter_bounds, parse_constraint, what_if
from cpas_ocp.io.flight_card import FlightCard, card_reading, load_card
from cpas_ocp.io.flight_log import import_flight
from cpas_ocp.io.flight_test import load_test
from cpas_ocp.io.import_reports import ImportSummary
from cpas_ocp.io.log_formats import read_flight_log
from cpas_ocp.io.model_spec import ModelSpec, load_model_file, spec_of_test
from cpas_ocp.io.output_folder import atomic_folder, check_output
from cpas_ocp.io.problems import load_problem
from cpas_ocp.io.test_plan import load_plan
from cpas_ocp.physics.effects.base import Effect
from cpas_ocp.physics.effects.registry import BUILTIN, EffectType, load_plugins
from cpas_ocp.physics.flight_test import FlightTest
from cpas_ocp.reports.design_report import write_design
from cpas_ocp.reports.discrepancy_report import write_comparison, write_diagnosis, write_discovery
from cpas_ocp.reports.display_units import DisplayUnits, display_units
from cpas_ocp.reports.joint_report import joint_frame, joint_text, write_joint
from cpas_ocp.reports.plots import (
    correlation_axes,
    drag_area_axes,
    events_axes,
    profile_axes,
    sensor_axes,
)
from cpas_ocp.reports.population_report import (
    parameter_frame,
    population_text,
    write_population,
)
from cpas_ocp.reports.report import fit_summary, parameter_table, write_report
from cpas_ocp.reports.report_data import bound_flag
from cpas_ocp.reports.study_reports import write_dispersions, write_monte_carlo

__all__ = ["Campaign", "Dispersions", "Joint", "MonteCarlo", "Population", "Reconstruction",
           "campaign", "design", "dispersions", "fit_estimator", "import_log", "joint",
           "load_model", "load_test", "monte_carlo", "population", "reconstruct", "simulate"]


def simulate(problem: str, out: str | Path, seed: int, effects: Sequence[Effect] | None = None,
             truth: Mapping[str, float] | None = None) -> FlightTest:
    """Simulate the built-in problem `problem` (drogue, fbcp, main2, ...) with sensor noise
    drawn from `seed` into the test folder `out`, and load it.  `effects` is the model
    that makes the data (default: the problem's); `truth` overrides or adds true
    parameter values (SI), such as those of an effect hidden from the fit."""
    base = load_problem(problem)
    if truth:
        base = dataclasses.replace(base, truth={**base.truth, **truth})
    return simulate_problem(base, out, seed, effects=None if effects is None else list(effects))


def design(plan: str | Path, out: str | Path | None = None) -> TestDesign:
    """The design of the next test from the plan file `plan` (`inference.test_design`): each
    candidate instrumentation's predicted sigma, the single changes ranked by the sigma they
    remove from the plan's parameters of interest, the failure table; the folder
    `cpas-ocp design` writes is written to `out` where given."""
    found = design_test(load_plan(plan))
    if out is not None:
        write_design(found, out)
    return found


def load_model(path: str | Path, plugins: Sequence[str | Path] = ()) -> ModelSpec:
    """A model file (a JSON model block), with the plug-in files its effects may name."""
    return load_model_file(path, load_plugins(plugins))


def reconstruct(test: FlightTest | str | Path, model: ModelSpec | str | Path | None = None,
                plugins: Sequence[str | Path] = (), rescale_sigmas: bool = False,
                settings: Settings | None = None, hessian: str = "gauss-newton",
                wind_intensities: Sequence[float] = (), progress: bool = False
                ) -> Reconstruction:
    """Reconstruct a test (a loaded test or its folder) with `model` (a spec, a model file,
    or None for the manifest's) and the estimator's `settings`: the fit from the offline
    reduction, what it may claim (`result_claim`), and its covariance (`fit_estimator`).
    Raises SolverFailure where it does not converge."""
    if not isinstance(test, FlightTest):
        test = load_test(test)
    effects = load_plugins(plugins)
    spec = model if isinstance(model, ModelSpec) else (
        spec_of_test(test) if model is None else load_model_file(model, effects))
    return fit_estimator(Estimator(test, spec, settings=settings), rescale_sigmas, hessian,
                         wind_intensities, progress, effects)


def fit_estimator(est: Estimator, rescale_sigmas: bool = False, hessian: str = "gauss-newton",
                  wind_intensities: Sequence[float] = (), progress: bool = False,
                  plugins: Mapping[str, EffectType] | None = None) -> Reconstruction:
    """A reconstruction of `est` (`inference.reconstruction.fit_and_claim`, the one path
    every workflow that fits takes), with the plug-in effects its diagnosis may test.
    Raises SolverFailure where no fit converges."""
    done = fit_and_claim(est, rescale_sigmas, hessian, wind_intensities, progress)
    return Reconstruction(done.estimator, done.fit, done.covariance, done.claim,
                          dict(plugins or {}), done.intensity_choice)


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
                             fit_summary(self.fit, units), self.claim.text()])

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
        return what_if(self.estimator, self.fit, self.covariance, parsed, progress)

    @property
    def worst(self) -> str:
        """One line: the sensor channel and phase window that depart from the noise most."""
        return worst_of(window_statistics(self.fit, phase_windows(self.fit)))

    def report(self, out: str | Path, profiles: Sequence[Profile] = (),
               units: DisplayUnits | None = None) -> Path:
        """Write the report folder `cpas-ocp reconstruct` writes (result.json,
        parameters.csv, report.md, report.html, figures) to `out`, with `profiles`, tables
        and figures in `units` (default the test's own)."""
        return write_report(self.fit, self.covariance, out, list(profiles), self.claim, units)

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


def population(campaign: str | Path, parameters: Sequence[str] | None = None,
               covariates: Sequence[str] = (), pool: Sequence[Sequence[tuple[str, str]]] = (),
               full_omega: bool = True, alpha: float = 0.05, seed: int = 0) -> Population:
    """The population of each canopy type and stage of a campaign folder (`cpas-ocp
    campaign`): mu with the `covariates`' effects, Omega, each opening's shrunken
    estimate and pull, and the grouping tests (`campaign.population_study`; their
    bootstrap drawn with `seed`).  Each list in `pool` names (type, stage) pairs fitted as
    one population."""
    table = with_line_length_ratio(read_parameter_table(campaign), read_stage_table(campaign))
    covariances = read_covariance_table(campaign)
    groups, skipped = population_groups(table, covariances, str(campaign), parameters,
                                        covariates, pool, full_omega, alpha, seed)
    if not groups:
        raise InputError(str(campaign), "(table)", "a canopy type and stage with enough "
                         "openings for a population; " + "; ".join(skipped or ["none"]))
    return Population(str(campaign), groups, skipped)


@dataclass
class Population:
    """The populations of a campaign: one fitted `PopulationGroup` per canopy type and stage
    (or pooled set), and a note per one left out."""

    campaign: str
    groups: list[PopulationGroup]
    skipped: list[str]

    @property
    def table(self) -> pd.DataFrame:
        """Per population and parameter: median with its interval, tau with its interval,
        I^2 and the point-estimate spread."""
        return pd.concat([parameter_frame(g) for g in self.groups], ignore_index=True)

    def summary(self) -> str:
        """What `cpas-ocp population` prints."""
        return population_text(self.groups, self.skipped)

    def report(self, out: str | Path) -> Path:
        """The folder `cpas-ocp population` writes."""
        return write_population(self.groups, self.skipped, out,
                                f"Populations of {Path(self.campaign).name}")

    def __repr__(self) -> str:
        return (f"<Population of {self.campaign}: "
                f"{', '.join(g.label for g in self.groups)}>")

    def _repr_html_(self) -> str:
        return self.table.to_html(float_format=lambda v: f"{v:.4g}", index=False)


def joint(tests: Sequence[FlightTest | str | Path], share: Mapping[str, str],
          settings: Settings | None = None, progress: bool = False) -> Joint:
    """Reconstruct several tests in one NLP with the parameters named in `share` held equal
    across them: {base name: "type" | "vehicle"}, e.g. {"CdS": "type", "prf": "vehicle"}
    for one drag area per canopy type and stage and one PRF per forebody
    (`inference.joint_fit`).  Each test is fitted alone first, as its start."""
    loaded = [t if isinstance(t, FlightTest) else load_test(t) for t in tests]
    if len(loaded) < 2:
        raise InputError("(tests)", "tests", "at least two test folders to fit jointly")
    labels = [str(t) if not isinstance(t, FlightTest) else t.name for t in tests]
    say = (lambda line: print(line, file=sys.stderr, flush=True)) if progress else None
    try:
        return Joint(joint_fit(loaded, share, settings, labels, say))
    except SharingError as exc:
        raise InputError("(tests)", "share", str(exc)) from None


@dataclass
class Joint:
    """A joint fit of several tests (`inference.joint_fit.JointFit` as `fit`): the shared
    parameters beside each test's own estimates, a summary, and its report folder."""

    fit: JointFit

    @property
    def table(self) -> pd.DataFrame:
        """Per shared parameter and copy: the joint estimate and sigma, the copy's own."""
        return joint_frame(self.fit)

    def summary(self) -> str:
        """What `cpas-ocp joint` prints."""
        return joint_text(self.fit)

    def report(self, out: str | Path) -> Path:
        """joint.md, joint.csv, parameters.csv and joint.json in `out`."""
        write_joint(self.fit, Path(out))
        return Path(out)

    def __repr__(self) -> str:
        return f"<Joint {self.fit!r}>"

    def _repr_html_(self) -> str:
        return self.table.to_html(float_format=lambda v: f"{v:.5g}", index=False)


@dataclass
class Dispersions:
    """A campaign's Monte Carlo input: a model per canopy type and stage, the types and
    stages left out, notes, whether drag-area envelopes were drawn, and the folder."""

    models: list[DispersionModel]
    skipped: list[str]
    notes: list[str]
    envelopes: bool
    out: Path


def dispersions(campaign: str | Path, out: str | Path, cases: int, seed: int,
                from_population: bool = False) -> Dispersions:
    """`cases` Monte Carlo cases per canopy type and stage of a campaign (`cpas-ocp
    dispersions`), from the point estimates' dispersions within the grown hulls, or with
    `from_population` from each type and stage's fitted population (`population`); the
    folder written to `out`."""
    table = read_parameter_table(campaign)
    stages = read_stage_table(campaign)
    models, skipped = dispersion_models(table)
    if not models:
        raise InputError(str(campaign), "(table)",
                         "a canopy type and stage with enough tests to disperse; "
                         + ("; ".join(skipped) or "the table has no canopy's "
                            "CdS, Ck, n_p, n, expopen or t_k"))
    notes: list[str] = []
    if from_population:
        pop = population(campaign)
        models, notes = population_dispersions(models, pop.groups)
        notes += [f"no population: {s}" for s in pop.skipped]
    written = write_dispersions(models, skipped, cases, seed, out, table, stages)
    return Dispersions(models, skipped, notes, stages is not None, written)


@dataclass
class MonteCarlo:
    """Dispersed cases flown through a reconstruction: its `fit` and each stage's peak
    loads (`campaign.peak_load_study.StageLoads`); the folder written to `out`."""

    fit: Fit
    results: list[StageLoads]
    out: Path

    def summary(self) -> str:
        """What `cpas-ocp montecarlo` prints: the fit's status and each stage's quantiles."""
        return summary_text(self.fit, self.results)


def monte_carlo(test: FlightTest | str | Path, cases: str | Path, out: str | Path,
                limit: int | None = None, workers: int = 2, scheduler: str | None = None,
                progress: bool = False) -> MonteCarlo:
    """Reconstruct `test` and fly the dispersed cases in the folder `cases` (`cpas-ocp
    dispersions`) through its fit, on `workers` local processes or the Dask `scheduler`;
    peak-load quantiles and figures written to `out`, whole or not at all.

    The cases are matched to the test's canopies and their columns checked against its
    model before the NLP is built; a fit that is not a result flies no case
    (NotAResult)."""
    test = test if isinstance(test, FlightTest) else load_test(test)
    stages = match_cases(test, cases, limit)
    spec = spec_of_test(test)
    check_columns(spec.model(test), stages)
    say = (lambda line: print(line, flush=True)) if progress else (lambda _: None)
    with atomic_folder(out, MONTE_CARLO_MARKER) as tmp:
        est = Estimator(test, spec)
        say(f"reconstructing {test.name}: {est.size_text()} ...")
        rec = fit_estimator(est, progress=progress)
        if not rec.is_result:  # no cases are flown through a fit that is not a result
            raise NotAResult(f"the fit of {test.name} is not a result: {rec.problems[0]}")
        say(f"flying {sum(len(s.cases) for s in stages):,} cases of "
            f"{', '.join(s.label for s in stages)} on {_where(workers, scheduler)} ...")
        results = run_monte_carlo(rec.fit, stages, workers, scheduler, progress=progress)
        write_monte_carlo(rec.fit, results, tmp)
    return MonteCarlo(rec.fit, results, Path(out))


def _where(workers: int, scheduler: str | None) -> str:
    """Where a campaign's or a Monte Carlo's tasks run, in words."""
    return f"Dask scheduler {scheduler}" if scheduler else f"{workers} local processes"


@dataclass
class Campaign:
    """Every test folder under a folder reconstructed (`campaign.campaign.TestOutcome` per
    test, in path order), and the folder the tables were written to."""

    outcomes: list[TestOutcome]
    out: Path

    @property
    def failed(self) -> int:
        """How many tests gave no table rows (why is in failures.csv)."""
        return sum(not o.ok for o in self.outcomes)

    def summary(self) -> str:
        """What `cpas-ocp campaign` prints: a line per test."""
        return campaign_text(self.outcomes)


def campaign(tests_dir: str | Path, out: str | Path, workers: int = 2,
             scheduler: str | None = None, progress: bool = False) -> Campaign:
    """Reconstruct every test folder under `tests_dir` on `workers` local processes or the
    Dask `scheduler`, and write the campaign's tables to `out` (`cpas-ocp campaign`)."""
    folders = find_tests(tests_dir)
    if progress:
        print(f"reconstructing {len(folders)} test folders on {_where(workers, scheduler)} "
              "...", flush=True)
    outcomes = run_campaign(folders, workers, scheduler, progress=progress)
    return Campaign(outcomes, write_campaign(outcomes, out))


def import_log(log: str | Path, card: str | FlightCard, out: str | Path,
               log_format: str | None = None, columns: str | Path | None = None,
               still_air: bool = False) -> ImportSummary:
    """A flight log, as it came off the recorder, into a test folder at `out` under the
    flight `card` (a built-in name, a card file or a loaded card): read as `log_format` (a
    built-in format: altus, cats) or through the column map `columns`, else as the card's
    ``data`` block says (`cpas-ocp import`)."""
    card = card if isinstance(card, FlightCard) else load_card(str(card))
    if log_format is None and columns is None:  # the card says how its logs are read
        if card.data_format is None and card.data_columns is None:
            raise InputError(card.source, "data.format/data.columns", "one of the two, "
                             "saying how the card's logs are read (a built-in format, or a "
                             "column map), or --format/--columns on the command line")
        log_format, columns = card_reading(card)
    record = read_flight_log(log, log_format, columns, f"{card.source}: data.columns")
    return import_flight(record, card, out, still_air)


def discovery_context(test_dir: str | Path, plugin_files: Sequence[str | Path], max_steps: int,
                      alpha: float, confirm: int, units: str | None) -> dict:
    """What a kept discovery stores to be resumed: the test folder, the plug-in files and
    the options, paths absolute."""
    return {"test_dir": str(Path(test_dir).resolve()),
            "plugin": [str(Path(f).resolve()) for f in plugin_files],
            "max_steps": max_steps, "alpha": alpha, "confirm": confirm, "units": units}


def discover_kept(out: str | Path, fit: Fit, spec: ModelSpec, plugins: Mapping[str, EffectType],
                  context: Mapping[str, Any], units: DisplayUnits | None = None, *,
                  estimator: Estimator | None = None, resume: Discovery | None = None,
                  progress: bool = False,
                  on_step: Callable[[DiscoveryStep], None] | None = None) -> Discovery:
    """`discover` from `fit` (of `spec`) with the folder `out` written whole, with signals
    held off, at every point the chain is whole: the report so far and what resuming
    needs (`discovery_checkpoint`; `context` from `discovery_context`, its "first_fit"
    a note the report keeps).  The options are the context's.  On a signal the finished
    steps are written, marked stopped with how to go on, and `InterruptedDiscovery` is
    raised again; a user's mistake (a plug-in that fails) leaves no folder it created."""
    out = Path(out)
    whole = [len(resume.steps) if resume is not None else 0]  # steps last written whole
    note = context.get("first_fit")

    def kept(chain: Discovery, figures: bool = False) -> Path:
        if note and note not in chain.notes:
            chain.notes.append(note)
        with interrupts.deferred():
            return write_discovery(chain, out, {**plugins, **chain.plugins}, units,
                                   figures=figures,
                                   extra=lambda tmp: write_checkpoint(chain, tmp, context))

    def checkpoint(chain: Discovery) -> None:
        kept(chain)
        whole[0] = len(chain.steps)

    new_folder = not out.exists() or not any(out.iterdir())
    try:
        found = discover(fit, spec, plugins, context["max_steps"], context["alpha"],
                         context["confirm"], progress=progress, on_step=on_step,
                         estimator=estimator, on_whole=checkpoint, resume=resume)
    except (InputError, PluginError):
        if new_folder:
            shutil.rmtree(out, ignore_errors=True)
        raise
    except InterruptedDiscovery as exc:
        # The chain as it last was whole (a step under way may have been appended since).
        exc.partial.steps = exc.partial.steps[:max(whole[0], 1)]
        exc.partial.stopped += f"; `cpas-ocp discover --resume {out}` goes on from here"
        kept(exc.partial)
        raise
    kept(found, figures=True)
    return found


def resume_discovery(folder: str | Path, progress: bool = False,
                     on_step: Callable[[DiscoveryStep], None] | None = None,
                     on_read: Callable[[Discovery], None] | None = None) -> Discovery:
    """Go on with the discovery kept in `folder` (`discover_kept`) from its last finished
    step, with its test folder, plug-in files and options; `on_read` is called with the
    chain read back, before the discovery goes on."""
    folder = Path(folder)
    context = checkpoint_context(folder)
    check_output(folder)
    test = load_test(context["test_dir"])
    plugins = load_plugins(context["plugin"])
    chain = read_checkpoint(folder, test, plugins)
    if on_read is not None:
        on_read(chain)
    return discover_kept(folder, chain.steps[0].fit, chain.steps[0].spec, plugins, context,
                         display_units(test, context["units"]), resume=chain,
                         progress=progress, on_step=on_step)
