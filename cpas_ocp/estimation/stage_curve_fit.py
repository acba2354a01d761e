"""Offline least-squares fit of one stage's drag-area curve (paper Eqs. 5, 6).

This is the legacy curve fit, done once per canopy stage on the reduced
riser drag area (Eq. 3, scaled to the IMU by the stage's factor), and used
only as the starting point of the single-shot estimation.  It fits the
shape of the stage's rise with the stage's steady drag area CdS_i and the
previous stage's CdS_{i-1} held at their steady-window values:

* infinite mass: start time t_i (s), over-inflation Ck, peak fill constant
  n_p, shape exponent expopen and settling time t_k (s);
* finite mass: t_i, fill constant n and expopen.

The fill time uses the reduction's airspeed at t_i (m/s) and the canopy's
fill length, exactly as the model does.  The fit minimises the sum of
squared drag-force differences, q (CdS - data) in N with q the reduction's
dynamic pressure (Pa), from a few starting shapes (expopen 1, 2 and 3) and
keeps the best; the start time starts where the curve first climbs a fifth
of the way from CdS_{i-1} to CdS_i.  The reduced drag area is a measured
force (or acceleration) divided by q, so its noise grows as 1/q: a rocket's
drogue opening at apogee, near zero airspeed, gives drag areas that are
noise alone until the vehicle has fallen fast enough, and weighted equally
they drove the fill constant and the shape exponent onto their 0.3 lower
bounds.  Weighted by q they count as little as they say.  The Jacobian is
CasADi's exact one, evaluated with the residual: forward differences cost one
more evaluation per parameter, and the reduction took twice as long
(`benchmarks/reduction_speed.py`).

Every value returned lies inside its bounds by BOUND_MARGIN: a start on a
bound is a start an interior-point solver leaves only slowly.  A stage whose
data do not show the rise (no samples, or no climb) is left to the caller's
defaults.  (Replacing a shape the fit left undetermined or on a bound by the
defaults was tried: on the `drogue` deployment-load fit it started a basin
28 sigma from the truth.)
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field

import casadi as ca
import numpy as np
from scipy.optimize import least_squares

from cpas_ocp.estimation.function_buffer import FunctionBuffer
from cpas_ocp.physics.flight_test import Parachute
from cpas_ocp.physics.inflation import (
    fill_length,
    finite_mass_cds,
    infinite_mass_cds,
    stage_started,
)
from cpas_ocp.physics.parameters import param_name

# Fraction of the climb from CdS_{i-1} to CdS_i at which the start-time search begins.
CLIMB_FRACTION = 0.2
# Longest stretch of data after the observed start used for one stage (s).
MAX_WINDOW_S = 4.0
STARTING_EXPOPEN = (1.0, 2.0, 3.0)
# A returned value keeps this fraction of its bounds' range from either bound (in log space
# for a positive shape parameter, whose range spans decades: 0.3-60 for a fill constant).
BOUND_MARGIN = 0.05


@dataclass(frozen=True)
class StageData:
    """The reduced drag-area history (m^2) around one stage and what the fit holds fixed.

    `t`, `cds` and `airspeed` (s, m^2, m/s) cover the stage's window only;
    `bounds` maps each fitted parameter name to the model's (lower, upper);
    `fixed` holds shape parameters the model keeps fixed (e.g. a Pilot's
    expopen = 1), which the fit keeps too.  `dynamic_pressure` (Pa, on `t`) weights
    each sample's drag area by the force it stands for (None: equal weights).
    """

    chute: Parachute
    stage: str
    t: np.ndarray
    cds: np.ndarray
    airspeed: np.ndarray
    cds_prev: float
    cds_steady: float
    cds_full_open: float
    bounds: dict[str, tuple[float, float]]
    fixed: dict[str, float] = field(default_factory=dict)
    dynamic_pressure: np.ndarray | None = None


def fitted_names(chute: Parachute, stage: str) -> list[str]:
    """Names of the parameters the curve fit returns for one stage, in its order."""
    shape = ("Ck", "n_p", "expopen", "t_k") if chute.inflation == "infinite_mass" \
        else ("n", "expopen")
    return [param_name(b, chute.name, stage) for b in ("t_start", *shape)]


def fit_stage_curve(data: StageData) -> dict[str, float] | None:
    """Least-squares shape of one stage's drag-area curve, or None where the data show no rise."""
    names = fitted_names(data.chute, data.stage)
    climb = data.cds_steady - data.cds_prev
    if data.t.size < 10 or climb <= 0:
        return None
    smooth = np.convolve(data.cds, np.ones(5) / 5.0, mode="same")
    above = np.flatnonzero(smooth > data.cds_prev + CLIMB_FRACTION * climb)
    if above.size == 0:
        return None
    t_cross = float(data.t[above[0]])
    i_peak = int(np.argmax(smooth))
    free = np.array([n not in data.fixed for n in names])
    held = np.array([data.fixed.get(n, np.nan) for n in names])
    lower = np.array([data.bounds[n][0] for n in names])[free]
    upper = np.array([data.bounds[n][1] for n in names])[free]

    def full(theta: np.ndarray) -> np.ndarray:
        out = held.copy()
        out[free] = theta
        return out

    q = np.ones_like(data.t) if data.dynamic_pressure is None else data.dynamic_pressure
    weight = q / max(float(np.max(q)), 1e-12)  # drag force per unit of the largest q
    residual = _WeightedResidual(curve_and_jacobian(data), data, weight, full, free)

    if not free.any():
        return dict(zip(names, (float(v) for v in held), strict=True))
    expopen_name = param_name("expopen", data.chute.name, data.stage)
    starting = (data.fixed[expopen_name],) if expopen_name in data.fixed else STARTING_EXPOPEN
    best = None
    for expopen in starting:
        theta0 = _starting_point(data, t_cross, i_peak, expopen)[free]
        theta0 = np.clip(theta0, lower + 1e-9 * (upper - lower), upper - 1e-9 * (upper - lower))
        sol = least_squares(residual, theta0, jac=residual.jacobian, bounds=(lower, upper),
                            x_scale="jac")
        if best is None or sol.cost < best.cost:
            best = sol
    fitted = dict(zip(names, (float(v) for v in full(best.x)), strict=True))
    for name in names[1:]:
        if name not in data.fixed:
            fitted[name] = inside_bounds(fitted[name], *data.bounds[name])
    return fitted


def inside_bounds(value: float, lower: float, upper: float) -> float:
    """`value` moved inside [lower, upper] by BOUND_MARGIN of the range (of its logarithm
    where both bounds are positive): a start for a fit, off its bounds."""
    if lower > 0.0:
        span = np.log(upper / lower)
        lo, hi = lower * np.exp(BOUND_MARGIN * span), upper * np.exp(-BOUND_MARGIN * span)
    else:
        lo, hi = lower + BOUND_MARGIN * (upper - lower), upper - BOUND_MARGIN * (upper - lower)
    return float(np.clip(value, lo, hi))


def _starting_point(data: StageData, t_cross: float, i_peak: int, expopen: float) -> np.ndarray:
    length = float(fill_length(data.chute.fill_length, data.chute.diameter, data.cds_prev,
                               data.cds_steady, data.cds_full_open))
    v_i = float(np.interp(t_cross, data.t, data.airspeed))
    # The curve has climbed CLIMB_FRACTION of its rise at t_cross; with
    # expopen e that is CLIMB_FRACTION^(1/e) of the rise time after t_i.
    rise = max(float(data.t[i_peak]) - t_cross, 0.05)
    lead = CLIMB_FRACTION ** (1.0 / expopen)
    t_fill = rise / (1.0 - lead)
    t_i = t_cross - lead * t_fill
    n_fill = t_fill * v_i / length
    if data.chute.inflation == "infinite_mass":
        ck = max(float(data.cds[i_peak]) / data.cds_steady, 1.05)
        return np.array([t_i, ck, n_fill, expopen, 0.3])
    return np.array([t_i, n_fill, expopen])


def curve_and_jacobian(data: StageData) -> ca.Function:
    """The stage's curve and its exact derivatives over a vector of times: (t, theta, V_i)
    -> (CdS (m^2), dCdS/d(theta, V_i)), theta the `fitted_names` in their order; the
    derivatives of each time's CdS are consecutive (dense, so that they can be read
    straight from the function's buffer).  theta and V_i are shared by every time."""
    t = ca.SX.sym("t")
    v_i = ca.SX.sym("V_i")
    theta = ca.SX.sym("theta", len(fitted_names(data.chute, data.stage)))
    cds = _curve(data, t, ca.vertsplit(theta), v_i)
    fn = ca.Function("stage_curve_jacobian", [t, theta, v_i],
                     [cds, ca.densify(ca.jacobian(cds, ca.vertcat(theta, v_i)))])
    return fn.map(data.t.size, [False, True, True], [False, False])


class _WeightedResidual:
    """The curve fit's residual, the weighted drag-area misfit weight (CdS - data), and its
    Jacobian in the free parameters, both from one evaluation per parameter vector
    (least_squares asks for the Jacobian where it has just asked for the residual).

    The airspeed at the start time, V_i, is the reduction's, interpolated linearly: its
    slope there carries the start time's effect on the fill time into the Jacobian."""

    def __init__(self, fn: ca.Function, data: StageData, weight: np.ndarray,
                 full: Callable[[np.ndarray], np.ndarray], free: np.ndarray) -> None:
        self._fn = FunctionBuffer(fn)
        self._data, self._weight, self._full, self._free = data, weight, full, free
        self._at: bytes | None = None
        self._r = self._J = np.empty(0)

    def __call__(self, theta: np.ndarray) -> np.ndarray:
        self._evaluate(theta)
        return self._r

    def jacobian(self, theta: np.ndarray) -> np.ndarray:
        self._evaluate(theta)
        return self._J

    def _evaluate(self, theta: np.ndarray) -> None:
        if self._at == theta.tobytes():
            return
        data = self._data
        values = self._full(theta)
        v_i, dv_dt = _interpolated(values[0], data.t, data.airspeed)
        cds, jac = self._fn.nonzeros(data.t, values, v_i)
        jac = jac.reshape(data.t.size, values.size + 1)
        d_values = jac[:, :-1].copy()
        d_values[:, 0] += jac[:, -1] * dv_dt
        self._r = self._weight * (cds - data.cds)
        self._J = self._weight[:, None] * d_values[:, self._free]
        self._at = theta.tobytes()


def _interpolated(x: float, t: np.ndarray, y: np.ndarray) -> tuple[float, float]:
    """y linearly interpolated at x (held at its ends, as np.interp) and its slope there."""
    if not t[0] <= x < t[-1]:
        return float(np.interp(x, t, y)), 0.0
    i = int(np.searchsorted(t, x, side="right")) - 1
    slope = (y[i + 1] - y[i]) / (t[i + 1] - t[i])
    return float(y[i] + slope * (x - t[i])), float(slope)


def _curve(data: StageData, t: ca.SX, theta: list[ca.SX], v_i: ca.SX) -> ca.SX:
    """The stage's drag area (m^2) at time t (s) for the fitted parameters `theta` (in
    `fitted_names` order) and the airspeed V_i (m/s) at its start."""
    length = fill_length(data.chute.fill_length, data.chute.diameter, data.cds_prev,
                         data.cds_steady, data.cds_full_open)
    if data.chute.inflation == "infinite_mass":
        ck, n_p, expopen, t_k = theta[1:]
        rise = infinite_mass_cds(t, theta[0], data.cds_prev, data.cds_steady, ck, n_p, expopen,
                                 t_k, length, v_i)
    else:
        n_fill, expopen = theta[1:]
        rise = finite_mass_cds(t, theta[0], data.cds_prev, data.cds_steady, n_fill, expopen,
                               length, v_i)
    return ca.if_else(stage_started(t, theta[0]), rise, data.cds_prev)
