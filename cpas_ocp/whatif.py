"""What-if constraint studies: hold a parameter at a value or behind a limit, see what it costs.

A what-if re-solves the reconstruction with each constrained parameter's
bounds set to the constraint (``Ck[drogue1,stage1] == 1`` pins it;
``t_start[drogue2,stage2] >= 12.4`` moves its lower bound), starting from
the unconstrained fit, and reports

* the chi-square increase and its likelihood-ratio test: under the
  constraint's hypothesis the increase follows chi-square with one degree
  of freedom per active constraint (an inequality the fit does not touch
  costs nothing and counts none);
* each constraint's sensitivity d(chi^2)/d(value), twice its Lagrange
  multiplier: how hard the data push against it, per SI unit;
* how every other free parameter moved, in the unconstrained fit's sigmas;
* which sensor channels and which 0.5 s windows got worse.

Values are SI unless a unit follows the number (``== 12.4 s``, ``<= 30 ft^2``).
"""

from __future__ import annotations

import re
from dataclasses import dataclass

import numpy as np
from scipy.stats import chi2

from .errors import InputError
from .estimation import Estimator, Fit
from .uncertainty import Covariance
from .units import FACTORS

_EXPR = re.compile(r"^\s*(?P<name>[A-Za-z_][A-Za-z0-9_]*(\[[A-Za-z0-9_,]+\])?)\s*"
                   r"(?P<op>==|<=|>=)\s*(?P<value>[-+]?(\d+\.?\d*|\.\d+)([eE][-+]?\d+)?)"
                   r"\s*(?P<unit>\S+)?\s*$")
WINDOW_S = 0.5  # width of the time windows compared before and after (s)
# Distance to a limit, in units of the parameter's scale, within which an inequality is
# active (Ipopt relaxes bounds by about 1e-8 relative and stops near, not on, them).
ACTIVE_TOL = 1e-6


@dataclass(frozen=True)
class Constraint:
    """``name op value``: a free parameter held at (==) or behind (<=, >=) a value (SI)."""

    name: str
    op: str
    value: float
    text: str

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
    if name not in est.free:
        raise InputError(source, name, f"a free parameter of the fit ({', '.join(est.free)})")
    si = est.model.parameter(name).unit
    if unit is not None and unit != si:
        dims = [d for d, table in FACTORS.items() if unit in table and si in table]
        if not dims:
            raise InputError(source, f"{name} unit",
                             f"a unit of the same dimension as {si}; got {unit!r}")
        value *= FACTORS[dims[0]][unit] / FACTORS[dims[0]][si]
    prm = est.model.parameter(name)
    if not prm.lower <= value <= prm.upper:
        raise InputError(source, name, f"a value within its bounds [{prm.lower:g}, "
                                       f"{prm.upper:g}] {si}; got {value:g}")
    return Constraint(name, op, value, text.strip())


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
    def p_value(self) -> float:
        """Likelihood-ratio test of the constraints against the data (1 if none active)."""
        if not self.active:
            return 1.0
        return float(chi2.sf(max(self.delta_chi_square, 0.0), len(self.active)))

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
        before = {(r.sensor, r.channel): float(np.sum(r.normalized**2))
                  for r in self.free.residuals}
        after = {(r.sensor, r.channel): float(np.sum(r.normalized**2))
                 for r in self.constrained.residuals}
        changes = {f"{s}.{c}": after[(s, c)] - before[(s, c)] for s, c in before}
        return dict(sorted(changes.items(), key=lambda kv: -kv[1]))

    def window_changes(self, top: int = 3) -> list[tuple[str, float, float, float]]:
        """The `top` (channel, t0, t1, chi-square rise) windows of WINDOW_S that got worst."""
        rows = []
        for a, b in zip(self.free.residuals, self.constrained.residuals, strict=True):
            edges = np.arange(a.t[0], a.t[-1] + WINDOW_S, WINDOW_S)
            index = np.digitize(a.t, edges) - 1
            rise = np.bincount(index, b.normalized**2 - a.normalized**2, minlength=len(edges))
            for k in np.argsort(-rise)[:top]:
                rows.append((f"{a.sensor}.{a.channel}", float(edges[k]),
                             float(edges[k] + WINDOW_S), float(rise[k])))
        return sorted(rows, key=lambda r: -r[3])[:top]


def what_if(est: Estimator, fit: Fit, cov: Covariance | None,
            constraints: list[Constraint], progress: bool = False) -> WhatIfResult:
    """Re-solve `est` under `constraints`, from its unconstrained `fit`."""
    bounds = {}
    for con in constraints:
        prm = est.model.parameter(con.name)
        lo, hi = bounds.get(con.name, (prm.lower, prm.upper))
        bounds[con.name] = con.bounds(lo, hi)
    constrained = est.solve(progress=progress, start=fit, bounds=bounds)
    active = []
    for con in constraints:
        v = constrained.parameters[con.name]
        scale = est.model.parameter(con.name).scale
        if con.op == "==" or abs(v - con.value) <= ACTIVE_TOL * max(abs(con.value), scale):
            active.append(con.name)
    return WhatIfResult(constraints, fit, constrained, cov, active)


def whatif_text(result: WhatIfResult, top: int = 8) -> str:
    """The study in the terminal: cost, test, sensitivities, moved parameters, worse data."""
    lines = [f"constraint{'s' if len(result.constraints) > 1 else ''}: "
             + "; ".join(c.text for c in result.constraints)]
    dof = len(result.active)
    lines.append(f"chi-square {result.free.chi_square:.1f} -> {result.constrained.chi_square:.1f}"
                 f"  (increase {result.delta_chi_square:.2f}; likelihood-ratio p = "
                 f"{result.p_value:.3g} on {dof} active constraint{'s' if dof != 1 else ''})")
    for name, d in result.constrained.sensitivities.items():
        unit = result.constrained.model.parameter(name).unit
        state = "active" if name in result.active else "inactive"
        lines.append(f"  {name}: d(chi^2)/d(value) = {d:+.4g} per {unit} ({state})")
    lines.append("parameters that moved most (in sigma of the unconstrained fit):")
    moved = sorted(result.shifts().items(), key=lambda kv: -abs(np.nan_to_num(kv[1][2])))
    for name, (a, b, z) in moved[:top]:
        lines.append(f"  {name:30s} {a:12.6g} -> {b:12.6g}  ({z:+.2f} sigma)")
    lines.append("chi-square change per channel: " + ", ".join(
        f"{k} {v:+.1f}" for k, v in list(result.channel_changes().items())[:top]))
    lines.append("windows that got worse: " + "; ".join(
        f"{c} {t0:.1f}-{t1:.1f} s {r:+.1f}" for c, t0, t1, r in result.window_changes()))
    return "\n".join(lines)
