"""Forward simulation of a test phase and synthetic sensor data.

The simulator integrates the very same CasADi dynamics the estimator uses,
with classical Runge-Kutta 4 on a fine step (default 1 ms), stepping exactly
onto every inflation start time so that each stage's start airspeed V_i is
captured at its event.  Sensor samples are the model outputs at their sample
times plus Gaussian noise with the manifest's sigmas, drawn from a seeded
generator.  A test folder is written to a temporary directory and moved into
place only when complete.
"""

from __future__ import annotations

import json
import shutil
import tempfile
from dataclasses import dataclass
from pathlib import Path

import casadi as ca
import numpy as np
import pandas as pd

from cpas_ocp.errors import InputError
from cpas_ocp.io.flight_test import MANIFEST, flight_test_from_manifest, load_test
from cpas_ocp.io.model_spec import spec_from_block
from cpas_ocp.io.problems import Problem
from cpas_ocp.physics.effects import Effect
from cpas_ocp.physics.flight_test import SENSOR_COLUMNS, FlightTest
from cpas_ocp.physics.integration import rk4
from cpas_ocp.physics.model import Model
from cpas_ocp.physics.units import FACTORS


@dataclass
class Trajectory:
    """A simulated trajectory: times (s), states (n x nx), captured values by name."""

    t: np.ndarray
    x: np.ndarray
    captures: dict[str, float]


def rk4_step(model: Model) -> ca.Function:
    """One RK4 step x(t) -> x(t + h) of the model's dynamics, h symbolic."""
    x = ca.SX.sym("x", model.nx)
    t, h = ca.SX.sym("t"), ca.SX.sym("h")
    p = ca.SX.sym("p", len(model.parameters))
    c = ca.SX.sym("c", len(model.captures))
    return ca.Function("rk4", [x, t, h, p, c], [rk4(model.rhs, x, t, h, p, c)],
                       ["x", "t", "h", "p", "c"], ["xf"])


def simulate(model: Model, params: dict[str, float], x0: np.ndarray, t0: float, t1: float,
             step: float = 1e-3) -> Trajectory:
    """Integrate from t0 to t1 on a grid of `step`, stopping exactly at capture times."""
    pvec = model.parameter_vector(params)
    names = model.parameter_names
    pending = sorted(((cap.at_time if cap.at_time is not None
                       else pvec[names.index(cap.time_parameter)], i)
                      for i, cap in enumerate(model.captures)))
    cvec = np.zeros(len(model.captures))
    speed = float(ca.norm_2(x0[model.state_slice("velocity")]))
    cvec[:] = speed  # placeholder until each event happens; its stage is inactive before
    step_fn = rk4_step(model)
    n = round((t1 - t0) / step)
    times = t0 + step * np.arange(n + 1)
    xs = np.empty((n + 1, model.nx))
    x = np.asarray(x0, dtype=float)
    xs[0] = x
    k = 0
    while k < n:
        # Whole steps before the next capture run in one call (CasADi's mapaccum).
        clean = n if not pending else int(np.searchsorted(times, pending[0][0])) - 1
        if clean > k + 1:
            run = step_fn.mapaccum(clean - k)(x, times[k:clean], np.diff(times[k:clean + 1]),
                                              pvec, cvec)
            xs[k + 1:clean + 1] = np.asarray(run).T
            x, k = xs[clean], clean
            continue
        ta, tb = times[k], times[k + 1]
        while pending and pending[0][0] <= tb:
            tc, i = pending.pop(0)
            if tc > ta:
                x = np.asarray(step_fn(x, ta, tc - ta, pvec, cvec)).ravel()
                ta = tc
            cvec[i] = float(model.capture_function(model.captures[i].name)(x, ta, pvec, cvec))
        x = np.asarray(step_fn(x, ta, tb - ta, pvec, cvec)).ravel()
        xs[k + 1] = x
        k += 1
    return Trajectory(times, xs, {cap.name: float(cvec[i]) for i, cap in enumerate(model.captures)})


def model_outputs(model: Model, traj: Trajectory, params: dict[str, float], sensor: str,
                  times: np.ndarray) -> np.ndarray:
    """Noise-free outputs of `sensor` at `times` (which must lie on the trajectory grid)."""
    idx = np.rint((times - traj.t[0]) / (traj.t[1] - traj.t[0])).astype(int)
    if np.any(np.abs(traj.t[idx] - times) > 1e-9):
        raise ValueError("sample times must lie on the simulation grid")
    fn = model.outputs[sensor].map(len(times))
    return np.asarray(fn(traj.x[idx].T, times, model.parameter_vector(params),
                         model.capture_vector(traj.captures))).T


def simulate_problem(problem: Problem, out: str | Path, seed: int,
                     effects: list[Effect] | None = None, noise: bool = True,
                     known_only: bool = False) -> FlightTest:
    """Simulate `problem` with sensor noise drawn from `seed`; write a test folder at `out`.

    The truth model is `effects` if given, else the problem's ``simulation.model``
    block (a hidden effect the manifest's model lacks), else the manifest's.

    `noise=False` writes the noise-free outputs (event times stay noisy), for
    checking a transcription against the simulator.  `known_only` leaves out true values
    of parameters the model lacks (the scale of a sensor a planned test goes without)
    rather than refusing them.

    Writes manifest.json, one CSV per sensor (in the manifest's units) and
    truth.json (``{"parameters": {name: value}}``, SI).  Nothing is left
    behind if anything fails.
    """
    out = Path(out)
    if out.exists() and any(out.iterdir()):
        raise InputError(str(out), "(folder)", "an empty or new folder for the test")
    rng = np.random.default_rng(seed)
    sim = problem.simulation
    truth = dict(problem.truth)
    manifest = json.loads(json.dumps(problem.manifest))
    manifest["name"] = f"{problem.name}-seed{seed}"
    # Timing noise of every event, drawn first and in the listed order.
    timing_noise = rng.standard_normal(len(sim["events"]))
    derived = sim.get("start_at_crossing", {})
    manifest["events"] = _observed_events(sim["events"], truth, timing_noise,
                                          skip=set(derived))

    t0, t1, step = float(sim["t_begin"]), float(sim["t_end"]), float(sim["step"])
    sample_times = {}
    for s in manifest["sensors"]:
        rate = float(sim["rates_hz"][s["name"]])
        sample_times[s["name"]] = t0 + np.arange(round((t1 - t0) * rate) + 1) / rate
    planned = {name: pd.DataFrame({"time": t}) for name, t in sample_times.items()}
    test = flight_test_from_manifest(manifest, out, series=planned)
    model = _truth_model(problem, test, effects)
    # Effects whose parameters are a random process (`simulation.drawn`: the air's
    # motion) take them from a stream of their own, so that the sensor noise of a seed
    # is the same with and without them.
    for name in sim.get("drawn", []):
        effect = next(e for e in model.effects if e.name == name)
        truth.update(effect.draw(test, np.random.default_rng([seed, 1])))
    unknown = sorted(set(truth) - set(model.parameter_names))
    if known_only:
        truth = {k: v for k, v in truth.items() if k not in unknown}
    elif unknown:
        raise ValueError(f"problem {problem.name}: truth names unknown parameters {unknown}")
    x0 = initial_state(model, sim)
    for name, quantity in derived.items():
        truth[name] = first_crossing(model, simulate(model, {**truth, name: t1}, x0, t0, t1,
                                                      step), {**truth, name: t1}, quantity)
    traj = simulate(model, truth, x0, t0, t1, step)
    manifest["events"] = _observed_events(sim["events"], truth, timing_noise,
                                          model_times=_true_event_times(model, traj, truth))

    tmp = Path(tempfile.mkdtemp(prefix=".cpas-sim-", dir=out.parent if out.parent.exists()
                                else None))
    try:
        for s in manifest["sensors"]:
            _sensor_series(model, test, s, traj, truth, sample_times[s["name"]], (t0, step),
                           rng if noise else None).to_csv(tmp / s["file"], index=False,
                                                         float_format="%.9g")
        full_truth = {p.name: float(v) for p, v in
                      zip(model.parameters, model.parameter_vector(truth), strict=True)}
        (tmp / MANIFEST).write_text(json.dumps(manifest, indent=2))
        (tmp / "truth.json").write_text(json.dumps(
            {"problem": problem.name, "seed": seed, "label": problem.label,
             "parameters": full_truth, "captures": traj.captures}, indent=2))
        out.mkdir(parents=True, exist_ok=True)
        for f in tmp.iterdir():
            shutil.move(str(f), out / f.name)
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    return load_test(out)


def _truth_model(problem: Problem, test: FlightTest, effects: list[Effect] | None) -> Model:
    """The model that makes the data: `effects` if given, else the problem's
    ``simulation.model`` block, else the manifest's model."""
    if effects is not None:
        return Model(test, effects)
    block = problem.simulation.get("model", test.manifest.get("model"))
    return spec_from_block(block, f"problem {problem.name}", Path()).model(test)


def _sensor_series(model: Model, test: FlightTest, entry: dict, traj: Trajectory,
                   truth: dict[str, float], t: np.ndarray, lattice: tuple[float, float],
                   rng: np.random.Generator | None) -> pd.DataFrame:
    """One sensor's samples at the times `t` (s) in its manifest `entry`'s column units: the
    model's outputs along `traj` (on the simulation's `lattice`, its start and step),
    plus noise of the sensor's sigma drawn from `rng` (none without it)."""
    sensor = next(x for x in test.sensors if x.name == entry["name"])
    clean = model_outputs(model, traj, truth, entry["name"], _on_grid(t, *lattice))
    cols = {"time": t}
    for j, ch in enumerate(model.sensor_channels[entry["name"]]):
        sigma = sensor.noise_sigma(ch, clean[:, j])
        dim = SENSOR_COLUMNS[entry["kind"]][ch]
        draw = rng.standard_normal(len(t)) if rng is not None else np.zeros(len(t))
        cols[ch] = (clean[:, j] + sigma * draw) / FACTORS[dim][entry["columns"][ch]]
    return pd.DataFrame(cols)


def initial_state(model: Model, simulation: dict) -> np.ndarray:
    """The state vector at the start of a problem's simulation (SI).

    States the problem's ``initial_state`` names take its values; the others
    (those effects add) start at their declared `State.initial`.
    """
    given = simulation["initial_state"]
    return np.concatenate([np.broadcast_to(given.get(s.name, s.initial), s.size)
                           for s in model.states])


def _on_grid(t: np.ndarray, t0: float, step: float) -> np.ndarray:
    return t0 + step * np.rint((t - t0) / step)


def _observed_events(spec: list[dict], truth: dict[str, float], noise: np.ndarray,
                     skip: set[str] | None = None,
                     model_times: dict[tuple[str, str, str | None], float] | None = None
                     ) -> list[dict]:
    """Events as a video or pyro log would report them: true times plus timing noise.

    A true time is given (``time``), follows a truth parameter (``from_parameter``
    plus ``offset``), or is the model's own event (``from_model``: a Pilot's
    Main bag lift), taken from `model_times` by (event, parachute, stage).  Events that
    depend on parameters in `skip`, or on the model while `model_times` is not
    yet known, are left out.  `noise` holds one standard normal draw per
    listed event.
    """
    events = []
    for e, draw in zip(spec, noise, strict=True):
        if "from_parameter" in e:
            if e["from_parameter"] in (skip or set()):
                continue
            base = truth[e["from_parameter"]] + e["offset"]
        elif e.get("from_model"):
            if model_times is None:
                continue
            base = model_times[(e["name"], e["parachute"], e.get("stage"))]
        else:
            base = e["time"]
        t = base + e["sigma"] * draw
        ev = {"name": e["name"], "parachute": e["parachute"],
              "time": {"value": round(float(t), 4), "unit": "s"},
              "sigma": {"value": e["sigma"], "unit": "s"}}
        if "stage" in e:
            ev["stage"] = e["stage"]
        events.append(ev)
    return events


def first_crossing(model: Model, traj: Trajectory, params: dict[str, float],
                    quantity: str) -> float:
    """The time (s) a quantity first rises through zero, interpolated between steps."""
    g = model.quantities_along(traj.t, traj.x, params, traj.captures)[quantity]
    up = np.flatnonzero((g[:-1] < 0.0) & (g[1:] >= 0.0))
    if up.size == 0:
        raise ValueError(f"{quantity} never rises through zero in the simulation")
    k = int(up[0])
    return float(traj.t[k] + (traj.t[k + 1] - traj.t[k]) * -g[k] / (g[k + 1] - g[k]))


def _true_event_times(model: Model, traj: Trajectory,
                      params: dict[str, float]) -> dict[tuple[str, str, str | None], float]:
    """The true time of every event the model's effects predict, by (event, parachute,
    stage)."""
    out = {}
    at_end = model.quantities_along(traj.t[-1:], traj.x[-1:], params, traj.captures)
    for effect in model.effects:
        for timing in effect.event_timings(model.test):
            key = (timing.event, timing.parachute, timing.stage)
            out[key] = (float(at_end[timing.time][0]) if timing.time is not None
                        else first_crossing(model, traj, params, timing.crossing))
    return out
