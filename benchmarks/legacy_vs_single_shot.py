"""Benchmark: the legacy sequential reconstruction against the single-shot NLP.

What is compared
----------------
One synthetic test of the built-in ``drogue`` problem (two Drogues, three
infinite-mass stages each) is simulated with sensor noise drawn from
``--seed``.  Two methods reconstruct it from the test folder alone; the truth
(``truth.json``) is read only at the end to score them.

* Single-shot: ``cpas_ocp.estimation.estimator.Estimator(test).solve()``, the whole
  phase as one multiple-shooting NLP (build + solve timed).
* Legacy (paper sections II and IV), built from the package's own pieces:

  a. offline reduction (``cpas_ocp.estimation.reduction.reduce``) with the start times
     the single-shot initial guess takes from the observed events: riser drag
     areas (Eq. 3), IMU drag area (Eq. 2) and per-stage scale factors;
  b. for each canopy and stage, the riser drag area times its stage scale is
     fitted by Nelder-Mead (CdS, Ck, n_p, expopen, t_k) with the infinite-mass
     curve ``cpas_ocp.physics.inflation.infinite_mass_cds`` (start time held at the
     observed event, V_i = reduced airspeed at that start, the previous
     stage's fitted CdS as the stage's initial drag area);
  c. stage by stage, a bisection on one multiplier of both canopies' CdS of
     that stage, simulating (``cpas_ocp.estimation.simulate.simulate``) from the first
     GPS state to the stage's end until the simulated altitude equals the GPS
     altitude there;
  d. simultaneous peak-load matching of every canopy and stage: Ck is scaled
     by target / simulated peak riser load, n_p by target / simulated peak
     fill time, for a fixed number of iterations or until all are within
     0.5 %.  Targets are the load-cell readings times the stage scale factor
     of step a (the "scaled riser loads"); simulated loads are the model's
     true riser tension ``tension[P]``.

  The legacy estimate of ``drag_scale[S]`` (trajectory drag over load-cell
  drag) is the reduction's stage scale times the bisection multiplier; its
  start times are the observed event times.

How they are scored
-------------------
For every parameter both methods produce (CdS, Ck, n_p, expopen, t_k per
canopy and stage, and the stage drag scales) the table lists truth, both
estimates and both relative errors; the summary gives both wall times (same
process), their ratio, the RMS relative error of each method over those
parameters and the largest absolute start-time error of each.

The only random draw is the sensor and event noise of ``simulate_problem``,
seeded by ``--seed``; everything else is deterministic.

Usage: ``python benchmarks/legacy_vs_single_shot.py --seed 1 [--step 0.005]``
"""

from __future__ import annotations

import json
import math
import sys
import tempfile
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import casadi as ca
import harness
import numpy as np
from scipy.optimize import minimize

from cpas_ocp.estimation.estimator import Estimator
from cpas_ocp.estimation.kinematic_track import kinematic_track
from cpas_ocp.estimation.reduction import reduce_and_guess, stage_starts
from cpas_ocp.estimation.simulate import Trajectory, simulate, simulate_problem
from cpas_ocp.io.problems import load_problem
from cpas_ocp.physics.effects import baseline_effects
from cpas_ocp.physics.flight_test import FlightTest, Parachute
from cpas_ocp.physics.inflation import fill_length, infinite_mass_cds
from cpas_ocp.physics.model import Model
from cpas_ocp.physics.parameters import param_name

INFLATION_PARAMETERS = ("CdS", "Ck", "n_p", "expopen", "t_k")
PEAK_WINDOW_S = 3.0  # the inflation peak is searched in [start, start + this] (and before
# the canopy's next stage)
PEAK_TOLERANCE = 0.005  # peak load and peak time matched to 0.5 %
SMOOTH_SAMPLES = 5  # centred moving average applied to measured AND simulated loads
BISECTION_BRACKET = (0.7, 1.4)  # initial bracket of the stage drag multiplier
BISECTION_TOL = 1e-4  # bracket width at which the bisection stops
ALTITUDE_TOL_M = 0.01  # or stop when the altitude matches to this


def log(msg: str) -> None:
    print(msg, flush=True)


# ----------------------------------------------------------------------------- legacy, step b
def _curve_function() -> ca.Function:
    """`infinite_mass_cds` wrapped once as a numeric CasADi Function (t may be a row vector)."""
    names = ("t", "t_start", "cds_prev", "cds", "ck", "n_p", "expopen", "t_k", "length",
             "v_start")
    sym = [ca.SX.sym(n) for n in names]
    return ca.Function("infinite_mass_cds", sym, [infinite_mass_cds(*sym)], list(names), ["cds_t"])


@dataclass
class StageFit:
    """Nelder-Mead fit of one canopy stage's drag-area curve."""

    values: dict[str, float]
    rms_m2: float
    evaluations: int
    samples: int


def fit_stage_curve(curve_fn: ca.Function, model: Model, chute: Parachute, stage: str,
                    t: np.ndarray, cds: np.ndarray, t0: float, cds_prev: float, v_i: float,
                    start: dict[str, float], cds_full_open: float) -> StageFit:
    """Least-squares fit of (CdS, Ck, n_p, expopen, t_k) to drag-area samples `cds` at `t`.

    Nelder-Mead in parameters divided by their model scales, within the model's
    bounds, restarted from its own result until the cost stops improving (the
    legacy "fminsearch used iteratively").
    """
    names = [param_name(b, chute.name, stage) for b in INFLATION_PARAMETERS]
    prms = [model.parameter(n) for n in names]
    scale = np.array([p.scale for p in prms])
    bounds = [(p.lower / s, p.upper / s) for p, s in zip(prms, scale, strict=True)]
    norm = float(np.mean(cds**2))
    trow = t[None, :]
    mapped = curve_fn.map(t.size)  # one evaluation over all samples

    def values_of(z: np.ndarray) -> np.ndarray:
        return np.asarray(z) * scale

    def cost(z: np.ndarray) -> float:
        c_s, ck, n_p, expo, t_k = values_of(z)
        length = float(fill_length(chute.fill_length, chute.diameter, cds_prev, c_s,
                                   cds_full_open))
        model_cds = np.asarray(mapped(trow, t0, cds_prev, c_s, ck, n_p, expo, t_k, length,
                                      v_i)).ravel()
        return float(np.mean((model_cds - cds) ** 2) / norm)

    z = np.array([start[n] for n in names]) / scale
    z = np.clip(z, [b[0] for b in bounds], [b[1] for b in bounds])
    best = cost(z)
    evaluations = 0
    for _ in range(6):
        res = minimize(cost, z, method="Nelder-Mead", bounds=bounds,
                       options={"xatol": 1e-6, "fatol": 1e-12, "maxiter": 4000,
                                "maxfev": 8000, "adaptive": True})
        evaluations += int(res.nfev)
        improved = best - float(res.fun) > 1e-9 * max(best, 1e-30)
        if float(res.fun) <= best:
            z, best = np.asarray(res.x), float(res.fun)
        if not improved:
            break
    vals = values_of(z)
    return StageFit(dict(zip(names, map(float, vals), strict=True)),
                    math.sqrt(best * norm), evaluations, int(t.size))


# ----------------------------------------------------------------------------- legacy, c and d
def initial_state(test: FlightTest, model: Model) -> np.ndarray:
    """Simulation initial state from the first GPS sample (position and velocity)."""
    gps = test.sensors_of("gps")[0]
    t_first = float(gps.time[gps.time >= test.t_start - 1e-9][0])
    first = kinematic_track(test, np.array([t_first]))
    pos, vel = first.position, first.velocity
    x0 = np.zeros(model.nx)
    x0[model.state_slice("position")] = pos[0]
    x0[model.state_slice("velocity")] = vel[0]
    return x0


def quantity_series(model: Model, traj: Trajectory, params: dict[str, float],
                    name: str) -> np.ndarray:
    """One scalar model quantity (e.g. ``tension[drogue1]``) on the trajectory grid."""
    return model.quantities_along(traj.t, traj.x, params, traj.captures)[name]


def smooth(y: np.ndarray, width: int = SMOOTH_SAMPLES) -> np.ndarray:
    """Centred moving average (edges use the available samples)."""
    kernel = np.ones(width)
    return np.convolve(y, kernel, "same") / np.convolve(np.ones_like(y), kernel, "same")


def peak_of(t: np.ndarray, y: np.ndarray, a: float, b: float) -> tuple[float, float]:
    """(time, value) of the maximum of the smoothed series `y` in [a, b]."""
    ys = smooth(y)
    sel = np.flatnonzero((t >= a) & (t <= b))
    i = sel[int(np.argmax(ys[sel]))]
    return float(t[i]), float(ys[i])


@dataclass
class Legacy:
    """Legacy estimates and a record of what each step did."""

    parameters: dict[str, float]
    wall_s: float
    timings: dict[str, float] = field(default_factory=dict)
    multipliers: dict[str, float] = field(default_factory=dict)
    simulations: int = 0


def legacy_reconstruction(test: FlightTest, step: float, peak_iterations: int) -> Legacy:
    """The paper's sequence: reduction, curve fits, drag-scale bisection, peak matching."""
    timer = harness.Timer()  # each step's time runs from the end of the one before
    timings: dict[str, float] = {}
    n_sims = 0

    # a. offline reduction with the observed start times.
    model = Model(test, baseline_effects())
    chutes = list(test.parachutes)
    for chute in chutes:
        if chute.inflation != "infinite_mass":
            raise ValueError(f"{chute.name}: this benchmark's legacy path handles infinite-mass "
                             "canopies only")
    guess, red = reduce_and_guess(test, model)
    # The legacy sequence keeps the observed event times (the model's defaults),
    # not the start times the library's own curve fit finds.
    starts = stage_starts(test, {p.name: p.default for p in model.parameters})
    stages = list(dict.fromkeys(s for c in chutes for s in c.stages))
    log("[legacy] a. reduction: stage scale factors "
        + ", ".join(f"{s} {red.drag_scale(s):.4f}" for s in stages))
    timings["a. reduction"] = timer.split("a. reduction")

    # b. Nelder-Mead fit of every canopy stage's drag-area curve.
    curve_fn = _curve_function()
    params: dict[str, float] = {p.name: p.default for p in model.parameters}
    params.update({param_name("t_start", c, s): t for (c, s), t in starts.items()})
    for s in stages:
        params[param_name("drag_scale", s)] = red.drag_scale(s)
    for chute in chutes:
        riser = red.cds_riser[chute.name]
        cds_prev = 0.0
        last = param_name("CdS", chute.name, chute.stages[-1])
        cds_full_open = guess[last]
        for k, stage in enumerate(chute.stages):
            t0 = starts[(chute.name, stage)]
            t1 = (starts[(chute.name, chute.stages[k + 1])] if k + 1 < len(chute.stages)
                  else test.t_end)
            sel = (red.t >= t0) & (red.t < t1)
            v_i = float(np.interp(t0, red.t, red.airspeed))
            fit = fit_stage_curve(curve_fn, model, chute, stage, red.t[sel],
                                  red.group_of(chute.name, stage).scale * riser[sel], t0,
                                  cds_prev, v_i, guess, cds_full_open)
            params.update(fit.values)
            cds_prev = fit.values[param_name("CdS", chute.name, stage)]
            if k + 1 == len(chute.stages):
                cds_full_open = cds_prev
            log(f"[legacy] b. {chute.name} {stage}: fit of {fit.samples} samples, "
                f"{fit.evaluations} evaluations, rms {fit.rms_m2:.3f} m^2: "
                + ", ".join(f"{b} {fit.values[param_name(b, chute.name, stage)]:.4g}"
                            for b in INFLATION_PARAMETERS))
    timings["b. curve fits"] = timer.split("b. curve fits")

    # c. per-stage drag scale by bisection on the end-of-stage altitude.
    x0 = initial_state(test, model)
    gps = test.sensors_of("gps")[0]
    t_sim0 = test.t_start
    multipliers: dict[str, float] = {}
    for k, stage in enumerate(stages):
        later = [t for (c, s), t in starts.items() if s in stages[k + 1:]]
        end = min(later) if later else test.t_end
        # The last GPS sample in the stage, moved onto the simulation grid.
        t_gps = float(gps.time[gps.time <= end + 1e-9][-1])
        t_end = t_sim0 + step * round((t_gps - t_sim0) / step)
        h_gps = float(kinematic_track(test, np.array([t_end])).position[0, 2])
        fitted = {c.name: params[param_name("CdS", c.name, stage)] for c in chutes
                  if stage in c.stages}

        def altitude_error(m: float, stage: str = stage, fitted: dict[str, float] = fitted,
                           t_end: float = t_end, h_gps: float = h_gps) -> float:
            nonlocal n_sims
            trial = dict(params)
            for c, v in fitted.items():
                trial[param_name("CdS", c, stage)] = m * v
            traj = simulate(model, trial, x0, t_sim0, t_end, step)
            n_sims += 1
            return float(traj.x[-1, model.state_slice("position")][2]) - h_gps

        m_star, n_iter = bisect(altitude_error, *BISECTION_BRACKET)
        multipliers[stage] = m_star
        for c, v in fitted.items():
            params[param_name("CdS", c, stage)] = m_star * v
        params[param_name("drag_scale", stage)] = red.drag_scale(stage) * m_star
        log(f"[legacy] c. {stage}: multiplier {m_star:.5f} after {n_iter} simulations to "
            f"t = {t_end:.2f} s (GPS altitude {h_gps:.1f} m)")
    timings["c. drag-scale bisection"] = timer.split("c. drag-scale bisection")

    # d. iterative Ck / n_p peak-load matching, all canopies and stages at once.
    windows: dict[tuple[str, str], tuple[float, float]] = {}
    targets: dict[tuple[str, str], tuple[float, float]] = {}
    for chute in chutes:
        cell = next(s for s in test.sensors_of("load_cell") if s.parachute == chute.name)
        tc = cell.time
        reading = cell.data["tension"].to_numpy()
        for k, stage in enumerate(chute.stages):
            t0 = starts[(chute.name, stage)]
            nxt = (starts[(chute.name, chute.stages[k + 1])] if k + 1 < len(chute.stages)
                   else test.t_end)
            win = (t0, min(t0 + PEAK_WINDOW_S, nxt - 1e-6))
            windows[(chute.name, stage)] = win
            scaled = reading * red.group_of(chute.name, stage).scale
            targets[(chute.name, stage)] = peak_of(tc, scaled, *win)
    t_sim1 = min(test.t_end, max(b for _, b in windows.values()) + 0.1)
    t_sim1 = t_sim0 + step * math.ceil((t_sim1 - t_sim0) / step - 1e-9)
    cells = {c.name: next(s for s in test.sensors_of("load_cell") if s.parachute == c.name)
             for c in chutes}
    for it in range(peak_iterations + 1):
        traj = simulate(model, params, x0, t_sim0, t_sim1, step)
        n_sims += 1
        worst = 0.0
        updates: dict[str, float] = {}
        for chute in chutes:
            tension = quantity_series(model, traj, params, param_name("tension", chute.name))
            tc = cells[chute.name].time
            tc = tc[(tc >= traj.t[0]) & (tc <= traj.t[-1])]
            sim_at_cells = np.interp(tc, traj.t, tension)
            for stage in chute.stages:
                key = (chute.name, stage)
                t0 = starts[key]
                t_target, f_target = targets[key]
                t_sim, f_sim = peak_of(tc, sim_at_cells, *windows[key])
                load_ratio = f_target / f_sim
                time_ratio = max(t_target - t0, 1e-3) / max(t_sim - t0, 1e-3)
                worst = max(worst, abs(load_ratio - 1.0), abs(time_ratio - 1.0))
                ck, n_p = param_name("Ck", *key), param_name("n_p", *key)
                updates[ck] = float(np.clip(params[ck] * load_ratio,
                                            model.parameter(ck).lower, model.parameter(ck).upper))
                updates[n_p] = float(np.clip(params[n_p] * time_ratio,
                                             model.parameter(n_p).lower,
                                             model.parameter(n_p).upper))
        log(f"[legacy] d. peak matching, simulation {it + 1}: worst peak-load / peak-time "
            f"mismatch {100 * worst:.2f} %")
        if worst < PEAK_TOLERANCE or it == peak_iterations:
            break
        params.update(updates)
    timings["d. peak matching"] = timer.split("d. peak matching")

    wall = timer.elapsed()
    return Legacy(params, wall, timings, multipliers, n_sims)


def bisect(f: Callable[[float], float], lo: float, hi: float) -> tuple[float, int]:
    """Root of the increasing function f in [lo, hi] (bracket widened if needed)."""
    calls = 0
    f_lo, f_hi = f(lo), f(hi)
    calls += 2
    while f_lo > 0 and lo > 0.2:
        lo, hi, f_hi = lo * 0.8, lo, f_lo
        f_lo = f(lo)
        calls += 1
    while f_hi < 0 and hi < 5.0:
        lo, f_lo, hi = hi, f_hi, hi * 1.25
        f_hi = f(hi)
        calls += 1
    if f_lo > 0 or f_hi < 0:
        raise RuntimeError(f"bisection: no sign change in [{lo:.3f}, {hi:.3f}]")
    while hi - lo > BISECTION_TOL:
        mid = 0.5 * (lo + hi)
        f_mid = f(mid)
        calls += 1
        if abs(f_mid) < ALTITUDE_TOL_M:
            return mid, calls
        if f_mid < 0:
            lo = mid
        else:
            hi = mid
    return 0.5 * (lo + hi), calls


# ----------------------------------------------------------------------------- report
def relative_error(estimate: float, truth: float) -> float:
    return (estimate - truth) / truth


def report(truth: dict[str, float], single: dict[str, float], free: list[str],
           legacy: Legacy, single_wall: float, step: float) -> dict:
    """Print the parameter table and the summary; return the summary's figures."""
    legacy_names = {n for n in legacy.parameters
                    if n.split("[")[0] in (*INFLATION_PARAMETERS, "drag_scale")}
    common = [n for n in free if n in legacy_names]
    width = max(len(n) for n in common)
    head = (f"{'parameter':<{width}}  {'truth':>10}  {'single-shot':>11}  {'legacy':>10}  "
            f"{'err single':>10}  {'err legacy':>10}")
    print()
    print(head)
    print("-" * len(head))
    err_s, err_l = [], []
    for n in common:
        es = relative_error(single[n], truth[n])
        el = relative_error(legacy.parameters[n], truth[n])
        err_s.append(es)
        err_l.append(el)
        print(f"{n:<{width}}  {truth[n]:>10.4f}  {single[n]:>11.4f}  {legacy.parameters[n]:>10.4f}"
              f"  {100 * es:>9.2f}%  {100 * el:>9.2f}%")
    starts = [n for n in truth if n.startswith("t_start[")]
    dt_single = max(abs(single[n] - truth[n]) for n in starts)
    dt_legacy = max(abs(legacy.parameters[n] - truth[n]) for n in starts)
    rms_s = math.sqrt(float(np.mean(np.square(err_s))))
    rms_l = math.sqrt(float(np.mean(np.square(err_l))))
    print()
    print("summary")
    print(f"  common parameters                {len(common)}")
    print(f"  wall time, single-shot           {single_wall:8.1f} s   (NLP build + solve)")
    print(f"  wall time, legacy                {legacy.wall_s:8.1f} s   "
          f"({legacy.simulations} simulations at step {step:g} s)")
    for k, v in legacy.timings.items():
        print(f"    {k:<30} {v:8.1f} s")
    print(f"  ratio legacy / single-shot       "
          f"{harness.ratio_text(legacy.wall_s, single_wall, '8.3f')}")
    print(f"  RMS relative error, single-shot  {100 * rms_s:8.2f} %")
    print(f"  RMS relative error, legacy       {100 * rms_l:8.2f} %")
    print(f"  max |start-time error|, single   {1000 * dt_single:8.1f} ms")
    print(f"  max |start-time error|, legacy   {1000 * dt_legacy:8.1f} ms   "
          "(observed event times)")
    comparison = harness.table(
        ["", "single-shot", "legacy"],
        [[f"wall time (s), legacy step {1000 * step:g} ms", single_wall, legacy.wall_s],
         [f"RMS relative error over {len(common)} common parameters (%)", 100 * rms_s,
          100 * rms_l],
         ["largest start-time error (ms)", 1000 * dt_single, 1000 * dt_legacy]])
    return {"comparison": comparison, "common_parameters": len(common),
            "single_shot_s": single_wall,
            "legacy_s": legacy.wall_s, "legacy_steps_s": legacy.timings,
            "legacy_simulations": legacy.simulations,
            "legacy_over_single_shot": harness.ratio(legacy.wall_s, single_wall),
            "rms_relative_error": {"single_shot": rms_s, "legacy": rms_l},
            "max_start_time_error_s": {"single_shot": dt_single, "legacy": dt_legacy}}


def main(argv: list[str] | None = None) -> int:
    ap = harness.parser(__doc__, seed=1, seed_help="noise seed of the simulated test")
    ap.add_argument("--step", type=float, default=0.005,
                    help="legacy simulation step (s); the test itself is simulated at 1 ms")
    ap.add_argument("--peak-iterations", type=int, default=5,
                    help="maximum Ck / n_p updates of the peak matching")
    args = ap.parse_args(argv)

    with tempfile.TemporaryDirectory(prefix="legacy-vs-single-") as tmp:
        folder = Path(tmp) / "test"
        log(f"simulating problem 'drogue' with seed {args.seed} into {folder}")
        test = simulate_problem(load_problem("drogue"), folder, args.seed)

        log("single-shot: building and solving the NLP ...")
        timer = harness.Timer()
        with timer("single-shot"):
            fit = Estimator(test).solve()
        single_wall = timer["single-shot"]
        log(f"single-shot: {fit.solver.status} after {fit.solver.iterations} iterations, "
            f"{single_wall:.1f} s")

        log(f"legacy: sequential reconstruction (simulation step {args.step:g} s) ...")
        legacy = legacy_reconstruction(test, args.step, args.peak_iterations)
        log(f"legacy: done in {legacy.wall_s:.1f} s")

        # The truth is read only now, to score both methods.
        truth = json.loads((folder / "truth.json").read_text())["parameters"]
    summary = report(truth, fit.parameters, fit.free, legacy, single_wall, args.step)
    harness.report("legacy_vs_single_shot", step_s=args.step, **summary)
    return 0


if __name__ == "__main__":
    sys.exit(main())
