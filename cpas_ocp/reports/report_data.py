"""A fit as the plain data its HTML report draws: sensor channels and parameter rows in
display units, phase windows as time spans.  No figures here; `html_page` draws them."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from cpas_ocp.estimation.estimator import EVENTS, Fit
from cpas_ocp.estimation.uncertainty import Covariance
from cpas_ocp.inference.phase_windows import PhaseWindow, windows_for_sensor
from cpas_ocp.precision import Z95, Measured, interval_text, rounded, sigma_text
from cpas_ocp.reports.display_units import DisplayUnits


@dataclass(frozen=True)
class ChannelSeries:
    """One sensor channel: sample times (s), measurement and model in `unit`, and the
    normalised residual (measured - model) / sigma."""

    sensor: str
    channel: str
    unit: str
    t: np.ndarray
    measured: np.ndarray
    model: np.ndarray
    normalised: np.ndarray


@dataclass(frozen=True)
class Span:
    """A time span to shade (s), of a kind (deployment, inflation, steady), named."""

    name: str
    kind: str
    t0: float
    t1: float


@dataclass(frozen=True)
class ParameterRow:
    """A free parameter's estimate in display units: value, 1 sigma and 95 % interval
    (None where the covariance gives none), initial guess, what is wrong with it, and the
    bounds within which the data leave it undetermined (`undetermined_window`; None
    where they determine it)."""

    name: str
    value: float
    std: float | None
    ci95: tuple[float, float] | None
    unit: str
    initial: float
    flag: str
    window: tuple[float, float] | None = None

    @property
    def interval(self) -> str:
        """The 95 % interval as printed: "[lo, hi]", "—" without one, or, where its sigma
        exceeds the width of its bounds, that it is undetermined within them (an interval
        of 11.461 ± 13.62 s, [-15.2, 38.2], inside a start window of 4 s is none)."""
        if self.window is not None:
            what = "window" if self.unit == "s" else "bounds"
            return (f"undetermined within its {what} "
                    f"[{self.window[0]:.4g}, {self.window[1]:.4g}]")
        return "—" if self.ci95 is None else interval_text(*self.ci95, self.std)

    @property
    def value_text(self) -> Measured:
        """The value to the decimal place of its sigma (`precision`)."""
        return rounded(self.value, self.std)

    @property
    def std_text(self) -> Measured:
        """The sigma to two significant digits, "—" without one."""
        return sigma_text(self.std)


def channel_series(fit: Fit, units: DisplayUnits) -> list[ChannelSeries]:
    """Every sensor channel of the fit (not events, priors or process innovations), in
    `units`."""
    out = []
    for r in fit.residuals:
        if r.sensor in fit.pseudo_sensors:
            continue
        unit, k = units.channel(r.channel)
        out.append(ChannelSeries(r.sensor, r.channel, unit, np.asarray(r.t),
                                 np.asarray(r.measured) * k, np.asarray(r.model) * k,
                                 np.asarray(r.normalised)))
    return out


def sensor_spans(fit: Fit, windows: Sequence[PhaseWindow]) -> dict[str, list[Span]]:
    """Per sensor, the phase windows that apply to it (its own canopy's for a load cell)."""
    return {s: [Span(w.name, w.kind, w.t0, w.t1)
                for w in windows_for_sensor(fit.test, s, windows)] for s in fit.sensors}


def bound_flag(fit: Fit, cov: Covariance | None, name: str) -> str:
    """Where a free parameter's estimate stands against its bounds, or '' where clear of them:
    "on its upper bound (6, guessed)" where the fit left it on a bound (within the solver's
    tolerance, `Parameter.held_side`, or held there by the covariance), "within 1σ of its
    lower bound (0.001, physical)" where its sigma reaches past the bound (a 6 ± 84 on an
    upper bound of 6: the interval means nothing there).  Bounds in SI."""
    prm, value = fit.model.parameter(name), fit.parameters[name]
    side = prm.held_side(value)
    if side is None and cov is not None and name in cov.at_bound:
        side = prm.nearer_bound(value)
    where = "on"
    if side is None:
        std = cov.std.get(name) if cov is not None else None
        near = prm.nearer_bound(value)
        if std is None or abs(value - (prm.lower if near == "lower" else prm.upper)) >= std:
            return ""
        side, where = near, "within 1σ of"
    kind = "physical" if prm.is_physical(side) else "guessed"
    return f"{where} its {side} bound ({prm.lower if side == 'lower' else prm.upper:.6g}, {kind})"


def undetermined_window(fit: Fit, cov: Covariance | None, name: str
                        ) -> tuple[float, float] | None:
    """The bounds (SI) of a free parameter whose standard deviation exceeds their width, so
    that its 95 % interval runs far past both: the data do not determine it within them
    (a start time 11.461 ± 13.62 s in a window of 4 s).  None where its sigma is smaller,
    it has none, or a bound is infinite."""
    std = cov.std.get(name) if cov is not None else None
    prm = fit.model.parameter(name)
    if std is None or not (np.isfinite(prm.lower) and np.isfinite(prm.upper)):
        return None
    return (prm.lower, prm.upper) if std > prm.upper - prm.lower else None


def parameter_flag(fit: Fit, cov: Covariance | None, name: str) -> str:
    """What is wrong with a free parameter's estimate (`bound_flag`, undetermined by the
    covariance, or outside its effect's plausible range), or ''."""
    flag = bound_flag(fit, cov, name)
    if not flag and cov is not None and name in cov.undetermined:
        return "undetermined"
    return flag or implausible_flag(fit, name)


def implausible_flag(fit: Fit, name: str) -> str:
    """"implausible (outside 0 to 0.5)" where the estimate lies outside the range its effect
    declares physically plausible (`Effect.plausible`: a sensor lag is positive), or ''.
    Bounds in SI."""
    for effect in fit.model.effects:
        low_high = effect.plausible(fit.test).get(name)
        if low_high is not None and not low_high[0] <= fit.parameters[name] <= low_high[1]:
            return f"implausible (outside {low_high[0]:.6g} to {low_high[1]:.6g})"
    return ""


def parameter_rows(fit: Fit, cov: Covariance | None, units: DisplayUnits
                   ) -> list[ParameterRow]:
    """The free parameters' estimates in `units`, in the fit's order."""
    std = cov.std if cov is not None else {}
    rows = []
    for name in fit.free:
        prm = fit.model.parameter(name)
        unit, k = units.of_si(prm.unit)
        v = fit.parameters[name] * k
        s = std[name] * k if name in std else None
        ci = None if s is None else (v - Z95 * s, v + Z95 * s)
        window = undetermined_window(fit, cov, name)
        rows.append(ParameterRow(name, v, s, ci, unit, fit.guess.get(name, prm.default) * k,
                                 parameter_flag(fit, cov, name),
                                 None if window is None else (window[0] * k, window[1] * k)))
    return rows


@dataclass(frozen=True)
class EventRow:
    """An observed event time against the model's (s), its sigma and the difference in
    sigmas."""

    event: str
    observed: float
    model: float
    sigma: float

    @property
    def z(self) -> float:
        return (self.observed - self.model) / self.sigma


def event_rows(fit: Fit) -> list[EventRow]:
    """The observed events the fit sees, in time order."""
    rows = [EventRow(r.channel, float(r.measured[0]), float(r.model[0]), float(r.sigma[0]))
            for r in fit.residuals if r.sensor == EVENTS]
    return sorted(rows, key=lambda e: e.observed)
