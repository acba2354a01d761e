"""Design of the next test: the sigma each parameter will have under a planned
instrumentation, and which single sensor change buys the most.

The planned test is simulated without sensor noise at its nominal parameters
theta_0, and the estimator of the test as it would be flown is built on those
data and linearised at theta_0 (its trajectory, its captured speeds).  The
covariance it gives is that of `Linearisations.covariance`, the parameter block of
the Gauss-Newton KKT system; with noise-free data it is the inverse of the
Fisher information

    F = J' J  (J the Jacobian of the sigma-weighted residuals, shooting states
               and constraints eliminated, as in `uncertainty`),

the Cramer-Rao bound of an unbiased estimate, in the units of the parameters
(SI).  A parameter in a direction of F whose curvature is below
`kkt_system.SINGULAR_RATIO` of the largest is not determined by the planned
data at all; it is named, with the combination, and given no sigma.

Summaries of a candidate, over the free parameters off their bounds, in units
of each parameter's typical magnitude (`Parameter.scale`, the NLP's scaling):
A = trace of the covariance (A-optimal: the mean variance), D = log det of the
covariance (D-optimal: the volume of the confidence ellipsoid); lower is better.

A change (add, upgrade or remove one sensor, time the events better) is
ranked by the mean fractional sigma it removes from the parameters of
interest, 1 - sigma_new / sigma_base: a parameter it makes determined counts
1, one it leaves undetermined counts as lost (minus infinity).

The linearisation is known to be optimistic in one tail where the residuals are far
from linear in a parameter: on `drogue` the start time of a disreef and the shapes n_p
and expopen of its stage trade against one another.  Their profile likelihood is
within a few percent of the parabola over both sides but reaches 12-15 % beyond it on
one (the shapes high, the start early), and over 150 seeds a few land 3-5 sigma out
along that line, so their spread is 5-11 % above the linearised sigma while the bulk
(the median absolute deviation) agrees (docs/validation.md).  Each such figure carries
its note (`linearisation_note`).
"""

from __future__ import annotations

import dataclasses
import json
import tempfile
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pandas as pd

from cpas_ocp.errors import InputError
from cpas_ocp.estimation.estimator import Estimator, Settings
from cpas_ocp.estimation.simulate import initial_state, simulate, simulate_problem
from cpas_ocp.estimation.uncertainty import Covariance
from cpas_ocp.io.flight_test_plan import (
    TIMED_EVENTS,
    Change,
    Instrumentation,
    PlannedSensor,
    TestPlan,
    problem_phases,
)
from cpas_ocp.io.model_spec import spec_of_test
from cpas_ocp.io.problems import Problem
from cpas_ocp.io.series_files import si_value
from cpas_ocp.physics.flight_test import SIGMA_GROUPS, FlightTest
from cpas_ocp.physics.parameters import split_name
from cpas_ocp.physics.units import FACTORS

# Factor on a sensor's sigma in the phases it does not record (`recorded_only`).
ABSENT_FACTOR = 1e8
# Eigenvalues of a covariance below this share of the largest are a constraint's, not noise.
RANK_TOLERANCE = 1e-9
# Relative sigma (of the nominal value) beyond which a linearised figure is doubtful.
NONLINEAR_SHARE = 0.1
# Parameters whose linearised sigma was measured optimistic in one tail (docs/validation.md:
# on `drogue` a disreef start trades against n_p and expopen; their profile reaches 12-15 %
# beyond the parabola on one side, and a few of 150 seeds land 3-5 sigma out).
OPTIMISTIC_SHAPES = ("n_p", "expopen")
OPTIMISTIC_NOTE = ("linearised sigma measured optimistic in one tail for this kind of "
                   "parameter: its profile reaches 12-15 % beyond it on one side, and a few "
                   "of 150 drogue seeds landed 3-5 sigma out (docs/validation.md)")


@dataclass
class Prediction:
    """The predicted covariance of one instrumentation at the nominal parameters.

    `values`: nominal values (SI) of the free parameters; `scale`: their typical
    magnitudes; `units`: their SI units; `residuals`: the number of weighted residuals
    the plan gives.
    """

    instrumentation: Instrumentation
    covariance: Covariance
    values: dict[str, float]
    scale: dict[str, float]
    units: dict[str, str]
    residuals: int

    def sigma(self, name: str) -> float | None:
        """The predicted 1-sigma (SI) of `name`; None where undetermined or on a bound."""
        return self.covariance.std.get(name)

    def status(self, name: str) -> str:
        """'determined', 'poorly determined' (in a weak combination), 'undetermined', 'on a
        bound', or 'not estimated' (the instrumentation's model has no such parameter: the
        scale of a sensor it goes without)."""
        if name not in self.covariance.names:
            return "not estimated"
        if name in self.covariance.at_bound:
            return "on a bound"
        if name in self.covariance.undetermined:
            return "undetermined"
        if any(name in w.weights for w in self.covariance.weak):
            return "poorly determined"
        return "determined"

    def optimality(self, names: list[str] | None = None) -> tuple[float | None, float | None]:
        """(A, D) over `names` (default: every free parameter off its bounds), in units of
        the parameters' typical magnitudes: the trace of the covariance and its log
        determinant on its range (a combination the model's constraints fix, such as the
        load-cell scales' geometric mean, has no variance and is left out, eigenvalues
        below RANK_TOLERANCE of the largest); None where one of them is undetermined."""
        cov = self.covariance
        names = [n for n in (names or cov.names) if n not in cov.at_bound]
        if any(n in cov.undetermined for n in names) or not names:
            return None, None
        idx = [cov.names.index(n) for n in names]
        s = np.array([self.scale[n] for n in names])
        block = cov.matrix[np.ix_(idx, idx)] / np.outer(s, s)
        eig = np.linalg.eigvalsh(0.5 * (block + block.T))
        kept = eig[eig > RANK_TOLERANCE * max(eig.max(), 1e-300)]
        return float(np.trace(block)), float(np.sum(np.log(kept)))


@dataclass
class RankedChange:
    """A single change, its prediction, and the fraction of each parameter of interest's
    sigma it removes (1 - new/base; -inf where it loses the parameter)."""

    change: Change
    prediction: Prediction
    removed: dict[str, float]

    @property
    def score(self) -> float:
        """The mean fraction of sigma removed over the parameters of interest."""
        return float(np.mean(list(self.removed.values()))) if self.removed else 0.0


@dataclass
class TestDesign:
    """What `design` found: each candidate's prediction, the ranked single changes to the
    first candidate, its failure table, and the parameters of interest."""

    plan: TestPlan
    predictions: list[Prediction]
    ranking: list[RankedChange]
    failures: list[tuple[str, Prediction]]
    interest: list[str]
    notes: dict[str, str] = field(default_factory=dict)
    # The candidates' sigma over parameter sets drawn from a population (`predict_over`).
    spread: SpreadPrediction | None = None

    @property
    def baseline(self) -> Prediction:
        return self.predictions[0]

    def sigma_table(self) -> pd.DataFrame:
        """Parameter x candidate: the predicted sigma (SI), NaN where not determined."""
        rows = {}
        for p in self.predictions:
            rows[p.instrumentation.name] = {n: p.sigma(n) if p.sigma(n) is not None else np.nan
                                            for n in p.covariance.names}
        return pd.DataFrame(rows)


def design(plan: TestPlan) -> TestDesign:
    """Predict every candidate of `plan`, rank the single changes to its first candidate by
    the sigma they remove from the parameters of interest, and tabulate the failures."""
    planner = Planner(plan.problem)
    predictions = [planner.predict(c) for c in plan.candidates]
    base = predictions[0]
    interest = list(plan.interest) or [n for n in base.covariance.names
                                       if n not in base.covariance.at_bound]
    unknown = [n for n in interest if n not in base.covariance.names]
    if unknown:
        raise InputError(plan.path, "interest", f"free parameters of the planned test "
                         f"({', '.join(base.covariance.names)}); got {', '.join(unknown)}")
    removals = tuple(Change(f"without {s.name}", removed=s.name)
                     for s in base.instrumentation.sensors)
    ranking = [RankedChange(c, p, sigma_removed(base, p, interest)) for c, p in
               ((c, planner.predict(c.applied(base.instrumentation)))
                for c in plan.changes + removals)]
    ranking.sort(key=lambda r: -r.score)
    failures = ([(label, planner.predict(instr)) for label, instr in
                 failure_scenarios(base.instrumentation, plan.phases)]
                if plan.failures else [])
    notes = {n: note for n in base.covariance.names
             if (note := linearisation_note(n, base.values.get(n, 0.0), base.sigma(n),
                                            plan.problem))}
    return TestDesign(plan, predictions, ranking, failures, interest, notes)


@dataclass
class SpreadPrediction:
    """Each candidate's predicted sigma at several parameter sets (drawn from a population
    of the planned canopies) besides the nominal one.

    The Fisher information depends on where it is evaluated: a draggier canopy opens
    faster and loads its riser harder, and a fill time drawn long spreads the opening's
    information over more samples.  A plan flown with canopies the population has not
    yet seen gets, for each parameter, the root-mean-square of its sigma over the draws
    (the sigma of the estimate averaged over the population, as its variance averages),
    the smallest and largest, and how many draws leave it undetermined.

    `sigma`: candidate name -> parameter x draw predicted sigma (SI), NaN where that draw
    leaves the parameter undetermined or on a bound; `source` says where the draws came
    from, `notes` what was held at its nominal value."""

    sigma: dict[str, pd.DataFrame]
    source: str
    notes: list[str] = field(default_factory=list)

    @property
    def draws(self) -> int:
        return next(iter(self.sigma.values())).shape[1] if self.sigma else 0

    def summary(self) -> pd.DataFrame:
        """One row per candidate and parameter: rms, lowest and highest sigma over the draws
        that determine it (SI), and the draws that do not."""
        rows = []
        for candidate, frame in self.sigma.items():
            for name, values in frame.iterrows():
                v = values.to_numpy(dtype=float)
                ok = np.isfinite(v)
                rows.append({"candidate": candidate, "parameter": name,
                             "rms": float(np.sqrt(np.mean(v[ok] ** 2))) if ok.any() else np.nan,
                             "lowest": float(v[ok].min()) if ok.any() else np.nan,
                             "highest": float(v[ok].max()) if ok.any() else np.nan,
                             "undetermined": int((~ok).sum())})
        return pd.DataFrame(rows)


def predict_over(plan: TestPlan, draws: list[dict[str, float]], source: str,
                 notes: list[str] | None = None,
                 progress: Callable[[str], None] | None = None) -> SpreadPrediction:
    """Every candidate of `plan` predicted at each parameter set of `draws` (name -> SI value,
    taking the place of the problem's nominal value): the planned test simulated and
    linearised there as at the nominal values (`predicted_covariance`)."""
    say = progress or (lambda _: None)
    columns: dict[str, dict[int, dict[str, float]]] = {c.name: {} for c in plan.candidates}
    for k, draw in enumerate(draws):
        say(f"predicting at parameter set {k + 1} of {len(draws)}")
        planner = Planner(dataclasses.replace(plan.problem,
                                              truth={**plan.problem.truth, **draw}))
        for c in plan.candidates:
            p = planner.predict(c)
            unknown = [n for n in draw if n not in plan.problem.truth and n not in p.values]
            if unknown:  # a name the model would ignore, silently predicting at its default
                raise ValueError(f"parameter set {k}: not parameters of the planned test: "
                                 f"{', '.join(unknown)}")
            columns[c.name][k] = {n: (np.nan if p.sigma(n) is None else float(p.sigma(n)))
                                  for n in p.covariance.names}
    return SpreadPrediction({c: pd.DataFrame(d) for c, d in columns.items()}, source,
                            list(notes or []))


def sigma_removed(base: Prediction, new: Prediction, names: list[str]) -> dict[str, float]:
    """Per name, the fraction of `base`'s sigma that `new` removes: 1 - new/base; 1 where
    `new` determines what `base` did not, -inf where it loses what `base` determined, 0
    where neither determines it.  A name `new` does not hold at all (the scale of a load
    cell the change removes) is left out: it leaves with its instrument, it is not lost."""
    out = {}
    for n in names:
        if n not in new.covariance.names:
            continue
        a, b = base.sigma(n), new.sigma(n)
        if a is None:
            out[n] = 1.0 if b is not None else 0.0
        else:
            out[n] = -np.inf if b is None else 1.0 - b / a
    return out


def failure_scenarios(base: Instrumentation, phases: tuple[str, ...]
                      ) -> list[tuple[str, Instrumentation]]:
    """One load cell lost (each in turn), and the GPS lost in each phase it records."""
    out = []
    for s in base.sensors:
        if s.kind == "load_cell":
            out.append((f"{s.name} lost", Change(f"{s.name} lost", removed=s.name).applied(base)))
    for s in base.sensors:
        if s.kind != "gps":
            continue
        recorded = s.phases if s.phases is not None else phases
        for phase in recorded:
            kept = tuple(p for p in recorded if p != phase)
            label = f"{s.name} lost in {phase}"
            out.append((label, Change(label, PlannedSensor(s.entry, s.rate_hz, kept))
                        .applied(base)))
    return out


def linearisation_note(name: str, value: float, sigma: float | None, problem: Problem) -> str:
    """Where the linearised sigma of `name` is known to be optimistic, the note that says
    so: a disreef's start time, an inflation shape (n_p, expopen), or a sigma beyond
    NONLINEAR_SHARE of the nominal value; '' where none applies."""
    base, index = split_name(name)
    notes = []
    if base == "t_start" and len(index) == 2:
        chute = next((p for p in problem.manifest["parachutes"] if p["name"] == index[0]), None)
        if chute is not None and chute["stages"] and index[1] != chute["stages"][0]:
            notes.append("disreef start time: " + OPTIMISTIC_NOTE)
    if base in OPTIMISTIC_SHAPES:
        notes.append(OPTIMISTIC_NOTE)
    if sigma is not None and value and sigma > NONLINEAR_SHARE * abs(value):
        notes.append(f"sigma is {sigma / abs(value):.0%} of the value: beyond the "
                     f"linearisation's reach, a profile or a simulation tells more")
    return "; ".join(notes)


class Planner:
    """Predictions for instrumentations of one planned test, each made once."""

    def __init__(self, problem: Problem) -> None:
        self.problem = problem
        self._made: dict[str, Prediction] = {}
        self._grid: tuple[float, ...] | None = None

    def predict(self, instr: Instrumentation) -> Prediction:
        """The predicted covariance of `instr` (`predicted_covariance`), made once per
        distinct instrumentation."""
        key = _key(instr)
        if key not in self._made:
            self._made[key] = predicted_covariance(self.problem, instr, self.grid)
        return dataclasses.replace(self._made[key], instrumentation=instr)

    def grid(self) -> tuple[float, ...]:
        """The shooting grid of the problem's own instrumentation (`shooting_grid`)."""
        if self._grid is None:
            self._grid = shooting_grid(self.problem)
        return self._grid


def _key(instr: Instrumentation) -> str:
    return json.dumps([sorted(([s.entry, s.rate_hz, s.phases] for s in instr.sensors),
                              key=lambda e: e[0]["name"]), sorted(instr.event_sigma.items())],
                      sort_keys=True, default=str)


def shooting_grid(problem: Problem) -> tuple[float, ...]:
    """The nodes (s) of the estimator of `problem` as planned, from its dynamics at the
    nominal parameters (`estimation.shooting_grid`)."""
    with tempfile.TemporaryDirectory(prefix=".cpas-design-") as tmp:
        test = simulate_planned(problem, None, Path(tmp) / "test", seed=0, noise=False)
        spec = spec_of_test(test)
        est = Estimator(test, spec, Settings(guess=nominal_values(problem, test)))
        return tuple(est.t)


def nominal_values(problem: Problem, test: FlightTest) -> dict[str, float]:
    """Every parameter of the test's model at the problem's nominal (true) value, the
    model's default where the problem gives none (SI)."""
    model = spec_of_test(test).model(test)
    return dict(zip(model.parameter_names, map(float, model.parameter_vector(problem.truth)),
                    strict=True))


def predicted_covariance(problem: Problem, instr: Instrumentation,
                         grid: Callable[[], tuple[float, ...]]) -> Prediction:
    """The Gauss-Newton covariance (inverse Fisher information) of the free parameters of
    the test `problem` flown with `instr`, at the nominal parameters, on the shooting grid
    the estimator chooses from the planned data, or (where it has no kinematic track to
    choose one from) on the nodes `grid()` gives (s)."""
    with tempfile.TemporaryDirectory(prefix=".cpas-design-") as tmp:
        test = simulate_planned(problem, instr, Path(tmp) / "test", seed=0, noise=False)
        spec = spec_of_test(test)
        values = nominal_values(problem, test)
        try:  # its own grid, as the estimator would choose it from the planned data
            est = Estimator(test, spec, Settings(guess=values))
        except InputError:  # no kinematic track to choose it from (no GPS, no altimeter)
            est = Estimator(test, spec, Settings(guess=values, nodes=grid()))
        cov = est.covariance_at(nominal_point(est, problem, values))
        model = est.model
        residuals = sum(len(s.time) * len(s.channels) for s in test.sensors)
        return Prediction(instr, cov, {n: values[n] for n in est.free},
                          {n: model.parameter(n).scale for n in est.free},
                          {n: model.parameter(n).unit for n in est.free},
                          residuals + len(test.events))


def nominal_point(est: Estimator, problem: Problem, values: dict[str, float]) -> np.ndarray:
    """The estimator's decision vector at the nominal parameters `values` (SI): the shooting
    states of the simulated trajectory at its nodes, the parameters, the captured speeds."""
    sim = problem.simulation
    traj = simulate(est.model, values, initial_state(est.model, sim), float(sim["t_begin"]),
                    float(sim["t_end"]), float(sim["step"]))
    states = np.array([np.interp(est.t, traj.t, col) for col in traj.x.T])
    return est.decision_vector(states, values, traj.captures)


def planned_problem(problem: Problem, instr: Instrumentation | None) -> Problem:
    """`problem` flown with `instr` (None: as it is): its sensors, their rates, the events'
    timing sigmas (unobserved events left out), the manifest's own model making the data."""
    manifest = json.loads(json.dumps(problem.manifest))
    sim = {k: v for k, v in problem.simulation.items() if k != "model"}
    if instr is None:
        return dataclasses.replace(problem, simulation=sim)
    manifest["sensors"] = [recorded_only(s.entry, s.phases, problem) for s in instr.sensors]
    sim["rates_hz"] = {s.name: s.rate_hz for s in instr.sensors}
    events = []
    for e in sim.get("events", []):
        sigma = instr.event_sigma.get(e["name"], e["sigma"])
        if sigma is not None:
            events.append({**e, "sigma": sigma})
    for name in TIMED_EVENTS:
        sigma = instr.event_sigma.get(name)
        if sigma is not None and not any(e["name"] == name for e in events):
            events += [{"name": name, "parachute": c["name"], "stage": stage,
                        "from_model": True, "sigma": sigma}
                       for c in problem.manifest["parachutes"] for stage in c["stages"]]
    sim["events"] = events
    return dataclasses.replace(problem, manifest=manifest, simulation=sim)


def phase_spans(problem: Problem, phases: tuple[str, ...]) -> dict[str, tuple[float, float]]:
    """Each phase's time span (s): the deployment from the start to the first canopy's first
    inflation, each stage from the first canopy's start of it to the next stage's."""
    sim = problem.simulation
    starts = [float(sim["t_begin"])]
    for stage in phases[1:]:
        times = [v for k, v in problem.truth.items()
                 if split_name(k)[0] == "t_start" and split_name(k)[1][-1:] == (stage,)]
        starts.append(min(times) if times else starts[-1])
    ends = [*starts[1:], float(sim["t_end"]) + 1.0]
    return dict(zip(phases, zip(starts, ends, strict=True), strict=True))


def simulate_planned(problem: Problem, instr: Instrumentation | None, out: Path, seed: int,
                     noise: bool = True) -> FlightTest:
    """The test `problem` flown with `instr`, simulated into `out` with noise from `seed`
    (`simulate_problem`)."""
    return simulate_problem(planned_problem(problem, instr), out, seed, noise=noise,
                            known_only=True)


def recorded_only(entry: dict, phases: tuple[str, ...] | None, problem: Problem) -> dict:
    """The manifest entry of a sensor that records only in `phases` (None: all): outside
    them its noise sigma is ABSENT_FACTOR times its own (`sigma_after`), so its samples
    there carry 1 / ABSENT_FACTOR^2 of their information, below what the covariance
    tells from none (`kkt_system.SINGULAR_RATIO`).  The samples stay, because every
    sensor must span the phase the estimator reconstructs."""
    if phases is None:
        return entry
    spans = phase_spans(problem, problem_phases(problem))
    absent = {}
    for group, q in entry["sigma"].items():
        dim = SIGMA_GROUPS[entry["kind"]][group][0]
        unit = max(FACTORS[dim], key=lambda u: FACTORS[dim][u])
        absent[group] = {"value": ABSENT_FACTOR * si_value(q, dim) / FACTORS[dim][unit],
                         "unit": unit}
    changes = []
    for name, (t0, t1) in spans.items():
        if name not in phases:
            changes += [{"time": {"value": t0, "unit": "s"}, "sigma": absent},
                        {"time": {"value": t1, "unit": "s"}, "sigma": entry["sigma"]}]
    return {**entry, "sigma_after": sorted(changes, key=lambda c: c["time"]["value"])}
