"""A planned test and the instrumentations it may fly with (`cpas-ocp design PLAN`).

A plan file (``data_schemas/test_plan.schema.json``) names the planned test (a
built-in problem, or a problem file: a manifest without data, its simulation
set-up and the nominal parameter values) and the candidate instrumentations:
each sensor's kind, sample rate (Hz), noise sigma, the phases it records, and
the timing sigma of the observed events.  Reading it resolves every candidate
into whole manifest sensor entries, so that what is designed is exactly what
the simulator and the estimator would be given; every mistake is an
`InputError` naming the plan file, the field and what was expected.
"""

from __future__ import annotations

import copy
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from cpas_ocp.errors import InputError
from cpas_ocp.io.json_files import read_json, validate_block
from cpas_ocp.io.problems import Problem, load_problem
from cpas_ocp.physics.flight_test import SENSOR_COLUMNS, SIGMA_GROUPS
from cpas_ocp.physics.units import FACTORS

PLAN_SCHEMA = "test_plan.schema.json"
DEPLOYMENT = "deployment"  # the phase before the first canopy's first inflation
POPULATION_DRAWS = 8  # parameter sets a design over a population predicts at by default
# SI column units of a sensor kind the problem does not have, by dimension.
# Events the model times itself, which a plan may add to every canopy stage (a chase camera
# timing each canopy's peak: full open): unlike the deployment and disreef events, which
# only seed the start times' windows, their times enter the estimate as observations.
TIMED_EVENTS = ("full_open",)
SI_UNITS = {"time": "s", "length": "m", "velocity": "m/s", "force": "N",
            "load_factor": "g", "acceleration": "m/s^2"}


@dataclass(frozen=True)
class PlannedSensor:
    """One sensor as flown: its manifest entry (noise sigmas in their units), its
    sample rate (Hz), and the phases it records (None: the whole test)."""

    entry: dict[str, Any]
    rate_hz: float
    phases: tuple[str, ...] | None = None

    @property
    def name(self) -> str:
        return str(self.entry["name"])

    @property
    def kind(self) -> str:
        return str(self.entry["kind"])


@dataclass(frozen=True)
class Instrumentation:
    """A candidate instrumentation: its sensors and the timing sigma (s) of every observed
    event by event name (None: not observed; names absent keep the problem's)."""

    name: str
    sensors: tuple[PlannedSensor, ...]
    event_sigma: dict[str, float | None] = field(default_factory=dict)

    def sensor(self, name: str) -> PlannedSensor | None:
        return next((s for s in self.sensors if s.name == name), None)


@dataclass(frozen=True)
class Change:
    """A single change to an instrumentation: one sensor added or replaced (`sensor`), one
    removed (`removed`), or the events timed differently (`event_sigma`)."""

    label: str
    sensor: PlannedSensor | None = None
    removed: str | None = None
    event_sigma: dict[str, float | None] = field(default_factory=dict)

    def applied(self, base: Instrumentation) -> Instrumentation:
        """`base` with this change made."""
        new = self.sensor
        sensors = [new if new is not None and s.name == new.name else s
                   for s in base.sensors if s.name != self.removed]
        if new is not None and base.sensor(new.name) is None:
            sensors.append(new)
        return Instrumentation(f"{base.name}, {self.label}", tuple(sensors),
                               {**base.event_sigma, **self.event_sigma})


@dataclass(frozen=True)
class TestPlan:
    """A planned test (`problem`), the candidates, the changes to rank against the first
    candidate (removing each sensor is always among them), the parameters they are
    ranked by (empty: all), and whether to tabulate sensor failures."""

    path: str
    problem: Problem
    candidates: tuple[Instrumentation, ...]
    changes: tuple[Change, ...]
    interest: tuple[str, ...] = ()
    failures: bool = True
    # A folder of Monte Carlo cases (`cpas-ocp dispersions`) to predict over as well, and
    # the parameter sets to draw from it.
    population_cases: Path | None = None
    population_draws: int = POPULATION_DRAWS

    @property
    def phases(self) -> tuple[str, ...]:
        """The phases a sensor may record (`problem_phases`)."""
        return problem_phases(self.problem)


def problem_phases(problem: Problem) -> tuple[str, ...]:
    """The phases of a planned test a sensor may record: the deployment, then each stage."""
    stages: list[str] = []
    for chute in problem.manifest["parachutes"]:
        stages += [s for s in chute["stages"] if s not in stages]
    return (DEPLOYMENT, *stages)


def load_plan(path: str | Path) -> TestPlan:
    """Read and check the plan file at `path` (InputError naming the field on any mistake)."""
    path = Path(path)
    file = str(path)
    raw = read_json(path, "a test plan (JSON, format cpas-ocp/test-plan/1)")
    validate_block(raw, PLAN_SCHEMA, file)
    problem = _planned_problem(raw, path)
    own = Instrumentation("as planned", tuple(
        PlannedSensor(copy.deepcopy(s), _problem_rate(problem, s["name"], file))
        for s in problem.manifest["sensors"]))
    candidates = tuple(_instrumentation(c, own, problem, file, f"candidates[{i}]")
                       for i, c in enumerate(raw.get("candidates", []))) or (own,)
    changes = tuple(_change(c, candidates[0], problem, file, f"changes[{i}]")
                    for i, c in enumerate(raw["changes"])) if "changes" in raw \
        else default_changes(candidates[0])
    population = raw.get("population", {})
    cases = path.parent / population["cases"] if population else None
    if cases is not None and not cases.is_dir():
        raise InputError(file, "population.cases", f"a folder of Monte Carlo cases written by "
                         f"cpas-ocp dispersions; {cases} is not a folder")
    plan = TestPlan(file, problem, candidates, changes, tuple(raw.get("interest", [])),
                    bool(raw.get("failures", True)), cases,
                    int(population.get("draws", POPULATION_DRAWS)))
    for i, c in enumerate(raw.get("candidates", [])):
        for j, s in enumerate(c.get("sensors", [])):
            _check_phases(plan, s, file, f"candidates[{i}].sensors[{j}].phases")
    for i, c in enumerate(raw.get("changes", [])):
        _check_phases(plan, c.get("sensor", {}), file, f"changes[{i}].sensor.phases")
    return plan


def default_changes(base: Instrumentation) -> tuple[Change, ...]:
    """Each sensor of `base` sampled twice as fast, and with half its noise sigma."""
    out = []
    for s in base.sensors:
        out.append(Change(f"{s.name} at {2 * s.rate_hz:g} Hz",
                          PlannedSensor(s.entry, 2.0 * s.rate_hz, s.phases)))
        entry = copy.deepcopy(s.entry)
        for q in entry["sigma"].values():
            q["value"] = 0.5 * q["value"]
        if "sigma_relative" in entry:
            entry["sigma_relative"] = 0.5 * entry["sigma_relative"]
        out.append(Change(f"{s.name} sigma halved", PlannedSensor(entry, s.rate_hz, s.phases)))
    return tuple(out)


def _planned_problem(raw: dict[str, Any], path: Path) -> Problem:
    """The built-in problem the plan names, or its problem file read as one."""
    if "problem" in raw:
        try:
            return load_problem(raw["problem"])
        except InputError as exc:
            raise InputError(str(path), "problem", exc.expectation) from None
    where = path.parent / raw["problem_file"]
    body = read_json(where, "a problem file (manifest, simulation, truth)")
    validate_block(body, "problem.schema.json", str(where))
    truth = body["truth"]["parameters"]
    return Problem(str(body.get("name", where.stem)), str(body.get("title", where.stem)),
                   str(body.get("label", "")), body["manifest"], body["simulation"], truth)


def _problem_rate(problem: Problem, name: str, file: str) -> float:
    rate = problem.simulation.get("rates_hz", {}).get(name)
    if not isinstance(rate, int | float) or rate <= 0:
        raise InputError(file, f"simulation.rates_hz.{name}",
                         f"the sample rate (Hz, > 0) of the problem's sensor {name!r}")
    return float(rate)


def _instrumentation(raw: dict[str, Any], own: Instrumentation, problem: Problem, file: str,
                     where: str) -> Instrumentation:
    """A candidate from its plan entry: sensors merged with the problem's of the same name."""
    entries = raw.get("sensors")
    if entries is None:
        sensors = own.sensors
    else:
        sensors = tuple(_sensor(s, own, problem, file, f"{where}.sensors[{j}]")
                        for j, s in enumerate(entries))
        names = [s.name for s in sensors]
        if len(set(names)) != len(names):
            raise InputError(file, f"{where}.sensors", "sensor names that are unique")
    return Instrumentation(raw["name"], sensors,
                           _event_sigma(raw.get("event_sigma", {}), problem, file,
                                        f"{where}.event_sigma"))


def _change(raw: dict[str, Any], base: Instrumentation, problem: Problem, file: str,
            where: str) -> Change:
    sensor = (_sensor(raw["sensor"], base, problem, file, f"{where}.sensor")
              if "sensor" in raw else None)
    return Change(raw["label"], sensor, None,
                  _event_sigma(raw.get("event_sigma", {}), problem, file, f"{where}.event_sigma"))


def _sensor(raw: dict[str, Any], base: Instrumentation, problem: Problem, file: str,
            where: str) -> PlannedSensor:
    """A planned sensor: the problem's (or `base`'s) sensor of that name with the fields
    `raw` gives replaced, or a new sensor, which must give its kind, rate and sigma."""
    known = base.sensor(raw["name"]) or next(
        (PlannedSensor(s, _problem_rate(problem, s["name"], file))
         for s in problem.manifest["sensors"] if s["name"] == raw["name"]), None)
    if known is None:
        for key in ("kind", "rate_hz", "sigma"):
            if key not in raw:
                raise InputError(file, f"{where}.{key}", f"required for a sensor the problem "
                                 f"does not have ({raw['name']!r})")
        entry = {"name": raw["name"], "kind": raw["kind"], "file": f"{raw['name']}.csv",
                 "columns": _columns(problem, raw["kind"])}
        rate = float(raw["rate_hz"])
    else:
        entry = copy.deepcopy(known.entry)
        if raw.get("kind", entry["kind"]) != entry["kind"]:
            raise InputError(file, f"{where}.kind", f"{entry['kind']!r}, the kind of the "
                             f"problem's sensor {raw['name']!r} (a new sensor takes a new name)")
        rate = float(raw.get("rate_hz", known.rate_hz))
    for key in ("sigma", "sigma_relative", "parachute"):
        if key in raw:
            entry[key] = copy.deepcopy(raw[key])
    _check_sensor(entry, problem, file, where)
    phases = raw.get("phases", known.phases if known is not None else None)
    return PlannedSensor(entry, rate, None if phases is None else tuple(phases))


def _columns(problem: Problem, kind: str) -> dict[str, str]:
    """Column units of a new sensor: those of the problem's first sensor of the kind, else SI."""
    same = next((s for s in problem.manifest["sensors"] if s["kind"] == kind), None)
    if same is not None:
        return dict(same["columns"])
    return {c: SI_UNITS[dim] for c, dim in SENSOR_COLUMNS[kind].items()}


def _check_sensor(entry: dict[str, Any], problem: Problem, file: str, where: str) -> None:
    """The sensor's noise groups and units, and a load cell's canopy."""
    groups = SIGMA_GROUPS[entry["kind"]]
    for group, q in entry["sigma"].items():
        if group not in groups:
            raise InputError(file, f"{where}.sigma.{group}", f"a noise group of a "
                             f"{entry['kind']} sensor: {', '.join(groups)}")
        dim = groups[group][0]
        if q["unit"] not in FACTORS[dim]:
            raise InputError(file, f"{where}.sigma.{group}.unit",
                             f"a unit of {dim}: {', '.join(FACTORS[dim])}")
    chutes = [p["name"] for p in problem.manifest["parachutes"]]
    if entry["kind"] == "load_cell" and entry.get("parachute") not in chutes:
        raise InputError(file, f"{where}.parachute",
                         f"the canopy a load cell measures: one of {', '.join(chutes)}")


def _event_sigma(raw: dict[str, Any], problem: Problem, file: str, where: str
                 ) -> dict[str, float | None]:
    """Event name -> timing sigma (s), None where the event goes unobserved."""
    names = sorted({e["name"] for e in problem.simulation.get("events", [])} | set(TIMED_EVENTS))
    out: dict[str, float | None] = {}
    for name, q in raw.items():
        if name not in names:
            raise InputError(file, f"{where}.{name}", f"an event the problem observes: "
                             f"{', '.join(names) or '(none)'}")
        if q is not None and q["unit"] not in FACTORS["time"]:
            raise InputError(file, f"{where}.{name}.unit",
                             f"a unit of time: {', '.join(FACTORS['time'])}")
        out[name] = None if q is None else q["value"] * FACTORS["time"][q["unit"]]
    return out


def _check_phases(plan: TestPlan, raw: dict[str, Any], file: str, where: str) -> None:
    for phase in raw.get("phases", []):
        if phase not in plan.phases:
            raise InputError(file, where, f"phases of the planned test: "
                             f"{', '.join(plan.phases)}; got {phase!r}")
