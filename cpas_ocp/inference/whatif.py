"""What-if constraint studies: hold a parameter at a value or behind a limit, see what it costs.

A what-if re-solves the reconstruction with each constrained parameter's
bounds set to the constraint (``Ck[drogue1,stage1] == 1`` pins it;
``t_start[drogue2,stage2] >= 12.4`` moves its lower bound), or with a
derived quantity's peak limited at every shooting node
(``peak_load[drogue1] <= 30000 lbf``: riser tension; ``peak_dynamic_pressure``,
``peak_load_factor``, ``peak_airspeed``, ``peak_cds[P]``), starting from the
unconstrained fit, and reports

* the chi-square increase and its likelihood-ratio test.  Under the
  constraint's hypothesis the increase follows chi-square with one degree of
  freedom per active equality; an active inequality puts the truth on the
  boundary of what is allowed, where the increase is zero half of the time,
  so k active inequalities add the chi-bar-squared mixture
  sum_j C(k, j) 2^-k chi2_j (Self and Liang 1987; exact when the
  inequalities' directions are uncorrelated, conservative-ish otherwise).
  An inequality the fit does not touch costs nothing and counts none.  With
  sigmas that are not trusted (a covariance scaled by chi^2/dof) the
  increase is divided by chi^2/dof first;
* each constraint's sensitivity d(chi^2)/d(value), twice its Lagrange
  multiplier: how hard the data push against it, per SI unit;
* how every other free parameter moved, in the unconstrained fit's sigmas;
* which sensor channels and which 0.5 s windows got worse.

Values are SI unless a unit follows the number (``== 12.4 s``, ``<= 30 ft^2``).
"""

from __future__ import annotations

import re
from dataclasses import dataclass, replace

import numpy as np

from cpas_ocp.errors import InputError
from cpas_ocp.estimation.estimator import Estimator, Fit
from cpas_ocp.estimation.uncertainty import Covariance
from cpas_ocp.inference.hypothesis_tests import chi_bar_square_sf
from cpas_ocp.physics.units import conversion

_EXPR = re.compile(r"^\s*(?P<name>[A-Za-z_][A-Za-z0-9_]*(\[[A-Za-z0-9_,]+\])?)\s*"
                   r"(?P<op>==|<=|>=)\s*(?P<value>[-+]?(\d+\.?\d*|\.\d+)([eE][-+]?\d+)?)"
                   r"\s*(?P<unit>\S+)?\s*$")
WINDOW_S = 0.5  # width of the time windows compared before and after (s)
# Distance to a limit, in the parameter's sigma, within which an inequality is active:
# Ipopt's interior point stops near, not on, a bound (1e-3 sigma inside was seen at
# "acceptable" convergence); an inequality that close costs (0.01)^2 in chi-square
# at most if it is in fact not active, so counting it does not change the test.
ACTIVE_SIGMA = 0.01
# Without a covariance: the distance in units of the parameter's scale.
ACTIVE_TOL = 1e-6
# The same for a peak limit, relative to the limit: the peak is read from the fitted
# trajectory, whose interior-point solution sits a few 1e-6 inside a limit that binds.
PEAK_ACTIVE_TOL = 1e-4


# Derived quantities a what-if may limit: name after ``peak_`` -> (model quantity, SI unit).
PEAKS = {"load": ("tension", "N"), "tension": ("tension", "N"),
         "dynamic_pressure": ("dynamic_pressure", "Pa"), "load_factor": ("load_factor", "g"),
         "airspeed": ("airspeed", "m/s"), "cds": ("cds", "m^2")}


@dataclass(frozen=True)
class Constraint:
    """``name op value``: a free parameter held at (==) or behind (<=, >=) a value (SI, in
    `unit`), or the peak of a model quantity (`quantity`, e.g. ``tension[drogue1]``) held
    below one."""

    name: str
    op: str
    value: float
    text: str
    unit: str
    quantity: str | None = None

    def bounds(self, lower: float, upper: float) -> tuple[float, float]:
        """The parameter's bounds under this constraint, from its own (lower, upper)."""
        if self.op == "==":
            return self.value, self.value
        return (lower, min(upper, self.value)) if self.op == "<=" else \
            (max(lower, self.value), upper)


def parse_constraint(text: str, est: Estimator, source: str = "--constrain") -> Constraint:
    """A what-if expression; InputError naming what is wrong with it."""
    m = _EXPR.match(text)
    if m is None:
        raise InputError(source, text, "NAME == VALUE [UNIT], NAME <= VALUE or NAME >= VALUE, "
                                       "e.g. 'Ck[drogue1,stage1] == 1'")
    name, op, value, unit = m["name"], m["op"], float(m["value"]), m["unit"]
    if name.startswith("peak_"):
        return _peak_constraint(name, op, value, unit, text, est, source)
    if name not in est.free:
        raise InputError(source, name, f"a free parameter of the fit ({', '.join(est.free)}) "
                                       f"or a peak ({', '.join('peak_' + k for k in PEAKS)})")
    prm = est.model.parameter(name)
    value = _to_si(value, unit, prm.unit, source, name)
    if not prm.lower <= value <= prm.upper:
        raise InputError(source, name, f"a value within its bounds [{prm.lower:g}, "
                                       f"{prm.upper:g}] {prm.unit}; got {value:g}")
    return Constraint(name, op, value, text.strip(), prm.unit)


def parameter_bounds(constraints: list[Constraint], est: Estimator,
                     source: str = "--constrain") -> dict[str, tuple[float, float]]:
    """The free parameters' bounds (SI) under `constraints` (peak limits aside); InputError
    where a parameter held with '==' is constrained again, or where the constraints on one
    parameter leave no value.  Without this, the last of two '==' on a parameter was the
    one applied while the test counted both."""
    bounds: dict[str, tuple[float, float]] = {}
    given: dict[str, Constraint] = {}
    for con in constraints:
        if con.quantity is not None:
            continue
        earlier = given.get(con.name)
        if earlier is not None and "==" in (earlier.op, con.op):
            raise InputError(source, con.text, f"one constraint on {con.name} where one holds "
                             f"it with '=='; {earlier.text!r} constrains it already")
        prm = est.model.parameter(con.name)
        lo, hi = con.bounds(*bounds.get(con.name, (prm.lower, prm.upper)))
        if lo > hi:
            raise InputError(source, con.text, f"constraints on {con.name} that some value "
                             f"meets; with {earlier.text if earlier else ''!r} none does")
        bounds[con.name], given[con.name] = (lo, hi), con
    return bounds


def _peak_constraint(name: str, op: str, value: float, unit: str | None, text: str,
                     est: Estimator, source: str) -> Constraint:
    """``peak_load[drogue1] <= 30000 lbf``: the largest riser tension over the phase."""
    base, _, index = name.removeprefix("peak_").partition("[")
    if base not in PEAKS:
        raise InputError(source, name, f"a peak of {', '.join('peak_' + k for k in PEAKS)}")
    quantity, si = PEAKS[base]
    quantity += f"[{index}" if index else ""
    if quantity not in est.model.quantity_names:
        known = [q for q in est.model.quantity_names if q.split("[")[0] == PEAKS[base][0]]
        raise InputError(source, name, f"a quantity of this model ({', '.join(known) or 'none'})")
    if op != "<=":
        raise InputError(source, name, "'<=': a peak is limited from above (every node below "
                                       "the value); '==' and '>=' do not say where it occurs")
    return Constraint(name, op, _to_si(value, unit, si, source, name), text.strip(), si,
                      quantity)


def _to_si(value: float, unit: str | None, si: str, source: str, name: str) -> float:
    """`value` in `unit` converted to `si` (same dimension); no unit means SI already."""
    if unit is None or unit == si:
        return value
    factor = conversion(unit, si)
    if factor is None:
        raise InputError(source, f"{name} unit", f"a unit of the same dimension as {si}; "
                                                 f"got {unit!r}")
    return value * factor


@dataclass
class WhatIfResult:
    """An unconstrained fit, the constrained one, and what the constraints cost."""

    constraints: list[Constraint]
    free: Fit
    constrained: Fit
    covariance: Covariance | None
    active: list[str]

    @property
    def delta_chi_square(self) -> float:
        return self.constrained.chi_square - self.free.chi_square

    @property
    def statistic(self) -> float:
        """The likelihood-ratio statistic: the chi-square increase, divided by chi^2/dof
        where the covariance was scaled because the sigmas are not trusted."""
        cov = self.covariance
        scale = cov.residual_variance if cov is not None and cov.scaled else 1.0
        return max(self.delta_chi_square, 0.0) / scale

    @property
    def p_value(self) -> float:
        """Likelihood-ratio test of the active constraints against the data (1 if none):
        chi-square on the equalities, chi-bar-squared on the inequalities."""
        if not self.active:
            return 1.0
        ops = {c.name: c.op for c in self.constraints}
        k_eq = sum(ops[n] == "==" for n in self.active)
        k_in = len(self.active) - k_eq
        return chi_bar_square_sf(self.statistic, k_eq, k_in)

    def shifts(self) -> dict[str, tuple[float, float, float]]:
        """Every free parameter: (unconstrained value, constrained value, shift in sigma)."""
        std = self.covariance.std if self.covariance is not None else {}
        out = {}
        for n in self.free.free:
            a, b = self.free.parameters[n], self.constrained.parameters[n]
            out[n] = (a, b, (b - a) / std[n] if std.get(n) else float("nan"))
        return out

    def channel_changes(self) -> dict[str, float]:
        """Chi-square change per sensor channel (``sensor.channel``), largest rise first."""
        before = {(r.sensor, r.channel): float(np.sum(r.normalised**2))
                  for r in self.free.residuals}
        after = {(r.sensor, r.channel): float(np.sum(r.normalised**2))
                 for r in self.constrained.residuals}
        changes = {f"{s}.{c}": after[(s, c)] - before[(s, c)] for s, c in before}
        return dict(sorted(changes.items(), key=lambda kv: -kv[1]))

    def window_changes(self, top: int = 3) -> list[tuple[str, float, float, float]]:
        """The `top` (channel, t0, t1, chi-square rise) windows of WINDOW_S that got worst."""
        rows = []
        for a, b in zip(self.free.residuals, self.constrained.residuals, strict=True):
            edges = np.arange(a.t[0], a.t[-1] + WINDOW_S, WINDOW_S)
            index = np.digitize(a.t, edges) - 1
            rise = np.bincount(index, b.normalised**2 - a.normalised**2, minlength=len(edges))
            for k in np.argsort(-rise)[:top]:
                rows.append((f"{a.sensor}.{a.channel}", float(edges[k]),
                             float(edges[k] + WINDOW_S), float(rise[k])))
        return sorted(rows, key=lambda r: -r[3])[:top]


def what_if(est: Estimator, fit: Fit, cov: Covariance | None,
            constraints: list[Constraint], progress: bool = False) -> WhatIfResult:
    """Re-solve `est` under `constraints`, from its unconstrained `fit`.

    Peak limits add constraints to the NLP, so they are solved by a second
    estimator of the same test, model and grid (its decision vector is laid
    out alike, so it starts from `fit`).
    """
    bounds = parameter_bounds(constraints, est)
    limits: dict[str, tuple[float, float]] = {}
    for con in constraints:
        if con.quantity is not None:
            lo, hi = limits.get(con.quantity, (-np.inf, np.inf))
            limits[con.quantity] = (lo, min(hi, con.value))
    solver = est
    if limits:
        solver = Estimator(est.test, est.spec, replace(est.settings, free=list(est.free),
                                                       limits=limits))
    constrained = solver.solve(progress=progress, start=fit, bounds=bounds)
    peaks = constrained.quantities() if limits else {}
    active = []
    for con in constraints:
        if con.quantity is not None:
            v = float(np.max(peaks[con.quantity]))
            rows, qscale = solver.transcription.limit_rows[con.quantity]
            constrained.sensitivities[con.name] = float(
                -2.0 * np.sum(constrained.multipliers[rows]) / qscale)
            if v >= con.value - PEAK_ACTIVE_TOL * abs(con.value):
                active.append(con.name)
            continue
        v = constrained.parameters[con.name]
        sigma = cov.std.get(con.name) if cov is not None else None
        near = (ACTIVE_SIGMA * sigma if sigma else
                ACTIVE_TOL * max(abs(con.value), est.model.parameter(con.name).scale))
        if con.op == "==" or abs(v - con.value) <= near:
            active.append(con.name)
    return WhatIfResult(constraints, fit, constrained, cov, active)
