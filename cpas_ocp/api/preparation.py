"""Before a fit: a simulated test folder, a model file, the design of a test to fly."""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path

from cpas_ocp.api.reconstruction import as_test, model_of, units_of
from cpas_ocp.campaign.population_design import design_over_population
from cpas_ocp.errors import InputError
from cpas_ocp.estimation.simulate import simulate_problem
from cpas_ocp.inference.flight_test_design import TestDesign
from cpas_ocp.inference.flight_test_design import design as design_test
from cpas_ocp.io.flight_test_plan import load_plan
from cpas_ocp.io.model_spec import ModelSpec, load_model_file
from cpas_ocp.io.problems import load_problem
from cpas_ocp.physics.effects.base import Effect
from cpas_ocp.physics.effects.registry import BUILTIN, load_plugins
from cpas_ocp.physics.flight_test import FlightTest
from cpas_ocp.physics.model import Model
from cpas_ocp.reports.design_report import write_design
from cpas_ocp.reports.display_units import DisplayUnits
from cpas_ocp.reports.reduction_report import guess_table, write_reduction


def effect(name: str, plugins: Sequence[str | Path] = (), **options: object) -> Effect:
    """The library's (or the plug-in files' `plugins`) effect `name`, as a model block
    names it (`cpas-ocp effects` lists them), with `options` over its preset; for a
    simulation with an effect the test folder's model lacks (`simulate(..., effects=)`)."""
    registry = {**BUILTIN, **load_plugins(plugins)}
    if name not in registry:
        raise InputError("(effect)", "name", f"one of {', '.join(sorted(registry))}; got "
                         f"{name!r}")
    return registry[name].build(dict(options), "(effect)", name)


def simulate(problem: str, out: str | Path, seed: int, effects: Sequence[Effect] | None = None,
             truth: Mapping[str, float] | None = None) -> FlightTest:
    """Simulate the built-in problem `problem` (drogue, fbcp, main2, ...) with sensor noise
    drawn from `seed` into the test folder `out`, and load it.  `effects` is the model
    that makes the data (default: the problem's), e.g. ``[*co.baseline_effects(),
    co.effect("added_mass")]`` for an effect the test folder's model lacks; `truth`
    overrides or adds true parameter values (SI), such as those of that effect."""
    base = load_problem(problem)
    if truth:
        base = dataclasses.replace(base, truth={**base.truth, **truth})
    return simulate_problem(base, out, seed, effects=None if effects is None else list(effects))


def design(plan: str | Path, out: str | Path | None = None,
           progress: Callable[[str], None] | None = None) -> TestDesign:
    """The design of the next test from the plan file `plan` (`inference.flight_test_design`): each
    candidate instrumentation's predicted sigma, the single changes ranked by the sigma they
    remove from the plan's parameters of interest, the failure table, and where the plan
    names a population's cases, each candidate's sigma over parameter sets drawn from them
    (`campaign.population_design`); the folder `cpas-ocp design` writes is written to `out`
    where given."""
    planned = load_plan(plan)
    found = design_test(planned)
    if planned.population_cases is not None:
        found.spread = design_over_population(planned, progress)
    if out is not None:
        write_design(found, out)
    return found


def load_model(path: str | Path, plugins: Sequence[str | Path] = ()) -> ModelSpec:
    """A model file (a JSON model block), with the plug-in files its effects may name."""
    return load_model_file(path, load_plugins(plugins))


@dataclass
class InitialGuess:
    """A test's offline reduction (Eqs. 2-3) and the initial guess it gives the fit of
    `model`, in SI; the folder written (reduction.csv, initial_guess.json, reduction.png)
    and the units its table is shown in."""

    model: Model
    guess: dict[str, float]
    out: Path
    units: DisplayUnits

    def summary(self) -> str:
        """What `cpas-ocp reduce` prints: each estimable parameter's initial value."""
        return guess_table(self.model, self.guess, self.units)


def reduce(test: FlightTest | str | Path, out: str | Path,
           model: ModelSpec | str | Path | None = None, plugins: Sequence[str | Path] = (),
           units: DisplayUnits | str | None = None, allow_external_plugins: bool = False
           ) -> InitialGuess:
    """Reduce `test` offline and write its reduction and the initial guess of `model` (a
    spec, a model file whose effects may be those of the plug-in files `plugins`, or None
    for the manifest's) to `out` (`cpas-ocp reduce`)."""
    test = as_test(test)
    spec = model_of(test, model, load_plugins(plugins), allow_external_plugins)
    shown = units_of(test, units)
    written, built, guess = write_reduction(test, out, spec, shown)
    return InitialGuess(built, guess, written, shown)
