"""Forward Monte Carlo of one canopy stage through the reconstruction's own model: the
distribution of its peak riser load.

A fitted test supplies the model (its effects), the state at the stage's
inflation start and every parameter not dispersed.  Each Monte Carlo case
replaces the stage's inflation parameters (``CdS``, ``Ck``, ``n_p`` or ``n``,
``expopen``, ``t_k``: the columns of a `dispersion_study` draw) and the
stage is flown forward with the model's RK4 step, all cases at once: the
step and the quantities function are CasADi Functions mapped over the cases
(`Function.map`, two threads), so one call advances every case by one step.
The peak of ``tension[P]`` (N) and of the system load factor over the window
are kept per case.

The window runs from the stage's fitted start t_i to the next stage's start
(or t_i + `duration`), and the start state is the fit's shooting node at or
before t_i, integrated forward to t_i; the stage's start airspeed is the
fit's captured value, the same for every case (t_i is not dispersed).
"""

from __future__ import annotations

from dataclasses import dataclass

import casadi as ca
import numpy as np
import pandas as pd

from cpas_ocp.estimation.estimator import Fit
from cpas_ocp.estimation.simulate import rk4_step
from cpas_ocp.physics.model import Model
from cpas_ocp.physics.parameters import param_name
from cpas_ocp.progress import progress_line

# RK4 step (s): on the Drogue's disreef stage the peak load at 4 ms is 0.03 % below the
# 1 ms value (50,477 against 50,490 N), far inside any dispersion.
DEFAULT_STEP_S = 0.004
DEFAULT_DURATION_S = 2.0


@dataclass
class PeakLoads:
    """Per case: peak riser tension (N) of the canopy and peak load factor (g) of the system."""

    parachute: str
    stage: str
    t0: float
    t1: float
    tension: np.ndarray
    load_factor: np.ndarray

    def table(self) -> pd.DataFrame:
        return pd.DataFrame({"peak_tension": self.tension, "peak_load_factor": self.load_factor})

    def quantiles(self, q: tuple[float, ...] = (0.5, 0.9, 0.99, 0.999, 1.0)) -> dict[float, float]:
        """Quantiles of the peak tension (N)."""
        return {p: float(np.quantile(self.tension, p)) for p in q}


def _flight_step(model: Model, step_fn: ca.Function, parachute: str) -> ca.Function:
    """(x, t, h, p, c) -> (x after one RK4 step, tension[P] and load factor at x): one call
    per step for every case, with only the two quantities kept (CasADi drops the rest)."""
    x = ca.SX.sym("x", model.nx)
    t, h = ca.SX.sym("t"), ca.SX.sym("h")
    p = ca.SX.sym("p", len(model.parameters))
    c = ca.SX.sym("c", len(model.captures))
    q = model.quantities(x, t, p, c)
    names = model.quantity_names
    return ca.Function("flight", [x, t, h, p, c],
                       [step_fn(x, t, h, p, c), q[names.index(param_name("tension", parachute))],
                        q[names.index("load_factor")]])


@dataclass(frozen=True)
class StageStart:
    """Where the Monte Carlo of one canopy stage starts: the fitted state `x0` at the stage's
    start time `t0` (s), the window end `t1` (s), and the fit's parameter and captured values
    (SI, by name) that every case shares.  Plain numbers only, so it travels to worker
    processes and Dask workers, which rebuild the model from the test folder."""

    parachute: str
    stage: str
    t0: float
    t1: float
    x0: np.ndarray
    parameters: dict[str, float]
    captures: dict[str, float]


def stage_start(fit: Fit, parachute: str, stage: str,
                duration: float = DEFAULT_DURATION_S) -> StageStart:
    """The fit's state at the stage's start t_i (the shooting node at or before t_i carried
    forward by one partial RK4 step) and the window [t_i, min(next start, t_i + duration,
    end of the fit)]."""
    chute = fit.test.parachute(parachute)
    if stage not in chute.stages:
        raise ValueError(f"{parachute} has no stage {stage!r} ({', '.join(chute.stages)})")
    model = fit.model
    t_i = fit.parameters[param_name("t_start", parachute, stage)]
    k = chute.stages.index(stage)
    t_next = (fit.parameters[param_name("t_start", parachute, chute.stages[k + 1])]
              if k + 1 < len(chute.stages) else np.inf)
    t1 = float(min(t_next, t_i + duration, fit.t[-1]))
    node = int(np.searchsorted(fit.t, t_i, side="right") - 1)
    x = np.asarray(rk4_step(model)(fit.x[node], fit.t[node], t_i - fit.t[node],
                                   model.parameter_vector(fit.parameters),
                                   model.capture_vector(fit.captures))).ravel()
    return StageStart(parachute, stage, float(t_i), t1, x, dict(fit.parameters),
                      dict(fit.captures))


def stage_peak_loads(fit: Fit, parachute: str, stage: str, cases: pd.DataFrame,
                     step: float = DEFAULT_STEP_S, duration: float = DEFAULT_DURATION_S,
                     progress: bool = False) -> PeakLoads:
    """Fly the stage once per row of `cases` (columns: parameter base names, SI)."""
    return fly_stage(fit.model, stage_start(fit, parachute, stage, duration), cases, step,
                     progress)


def fly_stage(model: Model, start: StageStart, cases: pd.DataFrame,
              step: float = DEFAULT_STEP_S, progress: bool = False) -> PeakLoads:
    """Fly every row of `cases` (columns: the stage's parameter base names, SI) from `start`
    through `model` with RK4 steps of at most `step` s; peak tension and load factor per case.
    ValueError names a column that is not a parameter of the stage."""
    parachute, stage, t_i, t1 = start.parachute, start.stage, start.t0, start.t1
    names = model.parameter_names
    columns = {}
    for base in cases.columns:
        name = param_name(base, parachute, stage)
        if name not in names:
            raise ValueError(f"the model has no parameter {name}")
        columns[names.index(name)] = cases[base].to_numpy(dtype=float)
    n = len(cases)
    p = np.repeat(model.parameter_vector(start.parameters)[:, None], n, axis=1)
    for row, values in columns.items():
        p[row] = values
    c = np.repeat(model.capture_vector(start.captures)[:, None], n, axis=1)
    flight = _flight_step(model, rk4_step(model), parachute).map(n, "thread", 2)
    X = np.repeat(np.asarray(start.x0, dtype=float)[:, None], n, axis=1)
    peak_t = np.full(n, -np.inf)
    peak_g = np.full(n, -np.inf)
    steps = max(1, int(np.ceil((t1 - t_i) / step)))
    h = (t1 - t_i) / steps
    with progress_line(f"{parachute} {stage}: steps flown", steps + 1, progress) as advance:
        for j in range(steps + 1):
            t = t_i + j * h
            X_next, tension, factor = flight(X, t, h, p, c)
            np.maximum(peak_t, np.asarray(tension).ravel(), out=peak_t)
            np.maximum(peak_g, np.asarray(factor).ravel(), out=peak_g)
            X = np.asarray(X_next)
            advance(f"t = {t - t_i:.2f} of {t1 - t_i:.2f} s")
    return PeakLoads(parachute, stage, float(t_i), t1, peak_t, peak_g)
