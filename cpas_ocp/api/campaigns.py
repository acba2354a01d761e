"""Many tests: a campaign's reconstructions, each canopy type's population, a joint fit of
tests that share hardware, Monte Carlo dispersions and peak loads."""

from __future__ import annotations

import sys
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path

import pandas as pd

from cpas_ocp.api.reconstruction import as_test, fit_estimator
from cpas_ocp.campaign.campaign import (
    TestOutcome,
    find_tests,
    run_campaign,
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
)
from cpas_ocp.campaign.population_study import (
    PopulationGroup,
    covariate_of,
    population_dispersions,
    population_groups,
    read_covariance_table,
    with_line_length_ratio,
)
from cpas_ocp.errors import InputError, NotAResult
from cpas_ocp.estimation.estimator import Estimator, Fit, Settings
from cpas_ocp.inference.hierarchical_fit import HierarchicalFit, hierarchical_fit
from cpas_ocp.inference.joint_fit import JointFit, SharingError, joint_fit
from cpas_ocp.io.flight_test import load_test
from cpas_ocp.io.model_spec import spec_of_test
from cpas_ocp.io.output_folder import atomic_folder
from cpas_ocp.physics.flight_test import FlightTest
from cpas_ocp.progress import SILENT, Narration, terminal
from cpas_ocp.reports.campaign_text import campaign_text, monte_carlo_text
from cpas_ocp.reports.hierarchical_report import (
    hierarchical_text,
    population_frame,
    write_hierarchical,
)
from cpas_ocp.reports.joint_report import joint_frame, joint_text, write_joint
from cpas_ocp.reports.population_report import (
    parameter_frame,
    population_text,
    write_population,
)
from cpas_ocp.reports.study_reports import write_campaign, write_dispersions, write_monte_carlo


def population(campaign: str | Path, parameters: Sequence[str] | None = None,
               covariates: Sequence[str] = (), pool: Sequence[Sequence[tuple[str, str]]] = (),
               full_omega: bool = True, alpha: float = 0.05, seed: int = 0,
               by_position: bool = True) -> Population:
    """The population of each canopy type and stage of a campaign folder (`cpas-ocp
    campaign`): mu with the `covariates`' effects (any column of the campaign's table,
    the manifests' covariates among them), Omega, each opening's shrunken estimate and
    pull, the share of the between-test variance each covariate explains, and the
    grouping tests (`campaign.population_study`; their bootstrap drawn with `seed`).
    Each list in `pool` names (type, stage) pairs fitted as one population.  With
    `by_position`, a type flown in two or more positions of its cluster takes the
    position as a covariate."""
    table = with_line_length_ratio(read_parameter_table(campaign), read_stage_table(campaign))
    covariances = read_covariance_table(campaign)
    groups, skipped = population_groups(table, covariances, str(campaign), parameters,
                                        covariates, pool, full_omega, alpha, seed,
                                        by_position)
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
    loaded, labels, say = _several(tests, "to fit jointly", progress)
    try:
        return Joint(joint_fit(loaded, share, settings, labels, say))
    except SharingError as exc:
        raise InputError("(tests)", "share", str(exc)) from None


def _several(tests: Sequence[FlightTest | str | Path], why: str, progress: bool
             ) -> tuple[list[FlightTest], list[str], Callable[[str], None] | None]:
    """Two or more tests loaded (InputError saying `why` they are needed otherwise), their
    labels (folder or name), and where their fits' progress goes (stderr, or nowhere)."""
    loaded = [t if isinstance(t, FlightTest) else load_test(t) for t in tests]
    if len(loaded) < 2:
        raise InputError("(tests)", "tests", f"at least two test folders {why}")
    labels = [str(t) if not isinstance(t, FlightTest) else t.name for t in tests]
    return loaded, labels, (lambda line: print(line, file=sys.stderr, flush=True)) \
        if progress else None


def hierarchical(tests: Sequence[FlightTest | str | Path], populations: Mapping[str, str],
                 share: Mapping[str, str] | None = None, settings: Settings | None = None,
                 progress: bool = False) -> Hierarchical:
    """Reconstruct several tests and the populations of the parameters named in
    `populations` ({base name: "type" | "vehicle"}) in one NLP: each test's copy drawn from
    a log-normal population whose median and spread tau are estimated with it, tau by the
    Laplace approximation to the marginal likelihood (`inference.hierarchical_fit`); those
    named in `share` held equal across the tests as `joint` holds them."""
    loaded, labels, say = _several(tests, "for a population", progress)
    try:
        return Hierarchical(hierarchical_fit(loaded, populations, share, settings, labels,
                                             progress=say))
    except SharingError as exc:
        raise InputError("(tests)", "population", str(exc)) from None


@dataclass
class Hierarchical:
    """A hierarchical fit of several tests (`inference.hierarchical_fit.HierarchicalFit` as
    `fit`): each population's median, interval and tau, every copy beside its test's own
    estimate, a summary and its report folder."""

    fit: HierarchicalFit

    @property
    def table(self) -> pd.DataFrame:
        """Per population: the median with its interval, tau, the copies (SI)."""
        return population_frame(self.fit)

    def summary(self) -> str:
        """What `cpas-ocp hierarchical` prints."""
        return hierarchical_text(self.fit)

    def report(self, out: str | Path) -> Path:
        """hierarchical.md, hierarchical.csv, copies.csv and hierarchical.json in `out`."""
        return write_hierarchical(self.fit, Path(out))

    def __repr__(self) -> str:
        return (f"<Hierarchical fit of {len(self.fit.fits)} tests: "
                f"{', '.join(p.name for p in self.fit.populations)}>")


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
                from_population: bool = False, at: Mapping[str, str] | None = None
                ) -> Dispersions:
    """`cases` Monte Carlo cases per canopy type and stage of a campaign (`cpas-ocp
    dispersions`), from the point estimates' dispersions within the grown hulls, or with
    `from_population` from each type and stage's fitted population (`population`), at the
    configuration `at` (covariate -> value: a position, a line length; the covariates'
    reference where not given); the folder written to `out`."""
    if at and not from_population:
        raise InputError("(command line)", "--at", "a configuration to draw a population "
                         "at: give --population too")
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
        in_mean = {covariate_of(c) for g in pop.groups for c in g.data.columns[1:]}
        unknown = [c for c in (at or {}) if c not in in_mean]
        if unknown:
            raise InputError(str(campaign), f"--at {unknown[0]}", "a covariate of a "
                             f"population's mean: {', '.join(sorted(in_mean)) or 'none'}")
        models, notes = population_dispersions(models, pop.groups, at, str(campaign))
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
        return monte_carlo_text(self.fit, self.results)


def monte_carlo(test: FlightTest | str | Path, cases: str | Path, out: str | Path,
                limit: int | None = None, workers: int = 2, scheduler: str | None = None,
                progress: bool = False) -> MonteCarlo:
    """Reconstruct `test` and fly the dispersed cases in the folder `cases` (`cpas-ocp
    dispersions`) through its fit, on `workers` local processes or the Dask `scheduler`;
    peak-load quantiles and figures written to `out`, whole or not at all.

    The cases are matched to the test's canopies and their columns checked against its
    model before the NLP is built; a fit that is not a result flies no case
    (NotAResult)."""
    test = as_test(test)
    stages = match_cases(test, cases, limit)
    spec = spec_of_test(test)
    check_columns(spec.model(test), stages)
    tell = _steps(progress)
    with atomic_folder(out, MONTE_CARLO_MARKER) as tmp:
        est = Estimator(test, spec)
        tell.say(f"reconstructing {test.name}: {est.size_text()} ...")
        rec = fit_estimator(est, tell=tell)
        if not rec.is_result:  # no cases are flown through a fit that is not a result
            raise NotAResult(f"the fit of {test.name} is not a result: {rec.problems[0]}")
        tell.say(f"flying {sum(len(s.cases) for s in stages):,} cases of "
                 f"{', '.join(s.label for s in stages)} on {_where(workers, scheduler)} ...")
        results = run_monte_carlo(rec.fit, stages, workers, scheduler, progress=progress)
        write_monte_carlo(rec.fit, results, tmp)
    return MonteCarlo(rec.fit, results, Path(out))


def _steps(progress: bool) -> Narration:
    """With `progress`, the steps said on the terminal and progress lines drawn; never the
    fit's warnings (a fit that is not a result ends the run in one line)."""
    return Narration(terminal().say, progress=True) if progress else SILENT


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


def reconstruct_campaign(tests_dir: str | Path, out: str | Path, workers: int = 2,
                         scheduler: str | None = None, progress: bool = False) -> Campaign:
    """Reconstruct every test folder under `tests_dir` on `workers` local processes or the
    Dask `scheduler`, and write the campaign's tables to `out` (`cpas-ocp campaign`)."""
    folders = find_tests(tests_dir)
    _steps(progress).say(f"reconstructing {len(folders)} test folders on "
                         f"{_where(workers, scheduler)} ...")
    outcomes = run_campaign(folders, workers, scheduler, progress=progress)
    return Campaign(outcomes, write_campaign(outcomes, out))
