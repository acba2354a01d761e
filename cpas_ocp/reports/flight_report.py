"""What a real flight's reconstruction says about its parachutes, against the published
nominal values and the measured descent.

* Drag areas: each fitted steady CdS with its sigma (or that it sits on its
  bound, where the data give it none) against the card's nominal value, the
  difference in sigmas, the descent rate the nominal value would give at the
  same altitude against the rate measured there, and the drag area the
  measured rate needs, 2 W / (rho v^2) less the other drag areas open.
  A nominal drag area is a design number (Cd on the canopy's nominal area);
  the measured rate is what the canopy did.
* Steady descent rates: under each canopy phase, in a steady window away
  from its deployment, the rate the fitted drag areas imply,
  v = sqrt(2 W / (rho(h) sum CdS)), against the rate measured by the
  altimeter (a straight-line fit to its geometric altitude).  The implied
  rate's sigma comes from the drag areas' covariance; the measured rate's
  from the line fit's residuals with the sample count reduced for their
  lag-one autocorrelation (Bartlett's effective sample size).
* Opening of the last canopy: its inflation parameters with the fit's sigma
  and that sigma times sqrt(chi2/dof) (the residuals wander, so the white-noise
  sigma is too small by about that factor), held and bounded ones named; the
  fill time; and the accelerometer's largest axial specific force after the
  deployment against the model's peak load factor in the same window.  The
  axial reading is a lower bound of the load factor (the axis hangs at an
  angle to the riser) and at 10 Hz may miss the peak.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from cpas_ocp.discrepancy.common_residual import BLOCK_S, combined_p_value, common_residuals
from cpas_ocp.discrepancy.diagnosis import ALPHA, Diagnosis
from cpas_ocp.estimation.estimator import Fit
from cpas_ocp.estimation.kinematic_track import altimeter_altitude
from cpas_ocp.estimation.uncertainty import Covariance
from cpas_ocp.inference.model_comparison import channel_rms
from cpas_ocp.inference.phase_windows import DEPLOYMENT_EVENTS
from cpas_ocp.inference.profile_likelihood import THRESHOLD, Profile, held_profile
from cpas_ocp.io.import_events import EJECTION_EXCLUDE_S
from cpas_ocp.io.import_reports import import_snatches, nominal_area
from cpas_ocp.io.model_spec import ModelSpec
from cpas_ocp.io.opening_loads import OPENING_WINDOW_S, descent_load_factor_peak
from cpas_ocp.physics.atmosphere import density_at
from cpas_ocp.physics.effects.canopy_inflation import BAND_BLEND_M
from cpas_ocp.physics.effects.wind_process import WindProcess
from cpas_ocp.physics.flight_test import Event, Parachute
from cpas_ocp.physics.parameters import param_name, split_name
from cpas_ocp.physics.units import G0
from cpas_ocp.precision import with_sigma
from cpas_ocp.reports.display_units import DisplayUnits, pretty

STEADY_AFTER_S = 10.0  # a canopy phase counts as steady this long after its deployment (s)
STEADY_BEFORE_S = 2.0  # ... and until this long before the next deployment (s)
# A held inflation parameter is profiled at these multiples of its held value (expopen held
# at 1: from a slow start to a late, sudden growth).
HELD_PROFILE_FACTORS = (0.5, 0.75, 1.5, 2.0, 3.0, 4.0, 6.0)
HELD_PROFILE_MAX_ITER = 100  # Ipopt iterations of a held-profile point (held_opening_profiles)


@dataclass(frozen=True)
class DescentRate:
    """Steady descent under the canopies open in [t0, t1] (s): rates in m/s (positive down);
    `band` names the altitude band of a canopy open at the start whose drag area applies
    (empty without bands)."""

    canopies: tuple[str, ...]
    t0: float
    t1: float
    altitude_m: float
    measured: float
    measured_sigma: float
    implied: float
    implied_sigma: float
    band: str = ""

    @property
    def z(self) -> float:
        """Implied minus measured, in the combined sigma."""
        return (self.implied - self.measured) / float(np.hypot(self.measured_sigma,
                                                               self.implied_sigma))


@dataclass(frozen=True)
class NominalComparison:
    """A fitted drag area (m^2) against its published nominal value; `needed` the drag area
    the measured descent rate needs (`needed_cds`), `at_bound` whether the fit left it on
    a bound (its `sigma` then 0: the data give it none)."""

    name: str
    fitted: float
    sigma: float
    nominal: float
    source: str
    rate_nominal: float
    rate_measured: DescentRate
    sigma_rate: float
    needed: float = float("nan")
    at_bound: bool = False

    @property
    def z(self) -> float:
        """Fitted minus nominal in the sigma the measured descent rate allows: the fit's own
        sigma assumes white sensor noise and is far smaller than the descent's wander."""
        sigma = max(self.sigma, self.sigma_rate)
        return (self.fitted - self.nominal) / sigma if sigma > 0 else float("inf")


def _phases(fit: Fit) -> list[tuple[tuple[str, ...], float, float]]:
    """(canopies open, steady start, steady end) of each canopy phase, in deployment order.

    Canopies open at the phase's start make the first phase, steady from the start; a
    canopy deployed in the phase counts as steady STEADY_AFTER_S after its start."""
    test = fit.test
    starts = sorted((test.t_start - STEADY_AFTER_S if c.open_at_start
                     else fit.parameters[param_name("t_start", c.name, c.stages[0])], c.name)
                    for c in test.parachutes)
    out = []
    for k, (t0, _) in enumerate(starts):
        if k + 1 < len(starts) and starts[k + 1][0] == t0:
            continue  # opened together (at the phase's start): one phase
        t1 = starts[k + 1][0] - STEADY_BEFORE_S if k + 1 < len(starts) else test.t_end
        out.append((tuple(name for _, name in starts[:k + 1]), t0 + STEADY_AFTER_S, t1))
    return out


def _measured_rate(fit: Fit, t0: float, t1: float) -> tuple[float, float, float]:
    """Measured descent rate (m/s, positive down), its sigma and the mean altitude (m)."""
    t, h = altimeter_altitude(fit.test)
    sel = (t >= t0) & (t <= t1)
    if sel.sum() < 10:
        raise ValueError(f"too few altimeter samples in [{t0:.1f}, {t1:.1f}] s")
    tt, hh = t[sel], h[sel]
    coef, cov = np.polyfit(tt - tt.mean(), hh, 1, cov=True)
    r = hh - np.polyval(coef, tt - tt.mean())
    rho1 = float(np.corrcoef(r[:-1], r[1:])[0, 1])
    inflation = (1.0 + rho1) / (1.0 - rho1) if rho1 > 0 else 1.0
    return -float(coef[0]), float(np.sqrt(cov[0, 0] * inflation)), float(hh.mean())


def needed_cds(fit: Fit, rate: DescentRate, canopy: str) -> float:
    """The drag area of `canopy` (m^2) that the measured descent `rate` needs: drag equal
    to weight at the window's mean altitude, 2 W / (rho(h) v^2), with v the measured rate
    through the fitted air (the rate over the ground plus the mean updraft there), less
    the fitted drag areas of the other canopies open and of the forebody.  Computed from
    the measurement, not the fit: where the fitted drag area sits on a bound, the two
    differ."""
    rho = float(density_at(fit.test.atmosphere, rate.altitude_m)[0])
    v = rate.measured + mean_updraft(fit, rate.t0, rate.t1)
    return 2.0 * fit.test.weight / (rho * v**2) - _other_cds(fit, rate, canopy)


def _other_cds(fit: Fit, rate: DescentRate, canopy: str) -> float:
    """The fitted drag areas (m^2) open in `rate`'s window besides `canopy`'s: the other
    canopies' (in the window's band) and the forebody's."""
    return sum(fit.parameters[_steady_cds(fit, c, rate.band)] for c in rate.canopies
               if c != canopy) + fit.parameters.get("CdS_V", 0.0)


def steady_rate(fit: Fit, cds: float, altitude: float) -> float:
    """Steady descent rate (m/s) with total drag area `cds` (m^2) at `altitude` (m):
    drag equals weight, v = sqrt(2 W / (rho(h) CdS))."""
    rho = float(density_at(fit.test.atmosphere, altitude)[0])
    return float(np.sqrt(2.0 * fit.test.weight / (rho * cds)))


def _steady_cds(fit: Fit, canopy: str, band: str = "") -> str:
    """Name of the steady drag area of `canopy` (its last stage; in altitude `band` for a
    canopy with bands)."""
    chute = fit.test.parachute(canopy)
    if chute.band_names:
        return param_name("CdS", canopy, chute.stages[-1], band or chute.band_names[0])
    return param_name("CdS", canopy, chute.stages[-1])


def updraft_weights(fit: Fit, t0: float, t1: float) -> dict[str, float]:
    """The fitted air's mean vertical velocity over [t0, t1] (s) as weights of the wind
    process's knots (`WindProcess.mean_weights`); empty in still air."""
    for effect in fit.model.effects:
        if isinstance(effect, WindProcess) and "up" in effect.components:
            return effect.mean_weights(fit.test, "up", t0, t1)
    return {}


def mean_updraft(fit: Fit, t0: float, t1: float) -> float:
    """The fitted air's mean vertical velocity over [t0, t1] (m/s, up positive; 0 in still
    air)."""
    return sum(w * fit.parameters[k] for k, w in updraft_weights(fit, t0, t1).items())


def _implied_rate(fit: Fit, cov: Covariance, canopies: tuple[str, ...], t0: float, t1: float,
                  altitude: float, band: str = "") -> tuple[float, float]:
    """Steady rate (m/s, down) over the ground the fitted drag areas give at `altitude` (m)
    in [t0, t1] (s), and its sigma: the rate through the air less the fitted mean updraft
    there, which the drag areas trade against (their covariance counted).  `band`: the
    altitude band whose drag area a banded canopy among them has there."""
    names = [_steady_cds(fit, c, band) for c in canopies]
    cds = sum(fit.parameters[n] for n in names) + fit.parameters.get("CdS_V", 0.0)
    v = steady_rate(fit, cds, altitude)
    weights = updraft_weights(fit, t0, t1)
    gradient = {**{n: -0.5 * v / cds for n in names}, **{k: -w for k, w in weights.items()}}
    idx = [cov.names.index(n) for n in gradient if n in cov.names]
    g = np.array([gradient[cov.names[i]] for i in idx])
    var = float(g @ cov.matrix[np.ix_(idx, idx)] @ g) if idx else 0.0
    return v - mean_updraft(fit, t0, t1), float(np.sqrt(max(var, 0.0)))


def _band_windows(fit: Fit, canopies: tuple[str, ...], t0: float, t1: float
                  ) -> list[tuple[str, float, float]]:
    """(band, start, end) (s) of [t0, t1] split where the altimeter crosses the altitude
    bands of a banded canopy among `canopies` (away from each edge by BAND_BLEND_M, where
    the drag area is that band's), in time order; [("", t0, t1)] without bands."""
    chute = next((fit.test.parachute(c) for c in canopies if fit.test.parachute(c).band_names),
                 None)
    if chute is None:
        return [("", t0, t1)]
    t, h = altimeter_altitude(fit.test)
    sel = (t >= t0) & (t <= t1)
    out = []
    for band in chute.band_names:
        lo, hi = chute.band_range(band)
        inside = t[sel][(h[sel] > lo + BAND_BLEND_M) & (h[sel] < hi - BAND_BLEND_M)]
        if inside.size:
            out.append((band, float(inside[0]), float(inside[-1])))
    return sorted(out, key=lambda w: w[1])


def descent_rates(fit: Fit, cov: Covariance) -> list[DescentRate]:
    """Implied against measured steady descent rate under each canopy phase (and in each
    altitude band of a canopy open at the start that has bands), over windows of at least
    5 s."""
    out = []
    for canopies, start, end in _phases(fit):
        for band, t0, t1 in _band_windows(fit, canopies, start, end):
            if t1 - t0 < 5.0:
                continue
            measured, m_sigma, altitude = _measured_rate(fit, t0, t1)
            implied, i_sigma = _implied_rate(fit, cov, canopies, t0, t1, altitude, band)
            out.append(DescentRate(canopies, t0, t1, altitude, measured, m_sigma, implied,
                                   i_sigma, band))
    return out


def steady_descent_text(fit: Fit, cov: Covariance, units: DisplayUnits | None = None) -> str:
    """The markdown section on a steady descent (a test with a canopy open at its start):
    each canopy's steady drag area (per altitude band where it has bands) with the fit's
    sigma and that sigma times sqrt(chi2/dof) (where the residuals exceed their stated
    noise the fit's sigma is too small by that factor), and the descent rates they imply
    against the altimeter's (`descent_rates`); in `units` (default SI)."""
    units = units or DisplayUnits("si")
    area, k_area = pretty(units.unit("area")), units.factor("area")
    length, k_length = units.unit("length"), units.factor("length")
    speed, k_speed = units.unit("velocity"), units.factor("velocity")
    excess = float(np.sqrt(max(1.0, fit.chi_square / fit.dof)))
    lines = ["## Drag areas and steady descent rates", "",
             f"| canopy | parameter | altitudes ({length} MSL) | fitted ({area}) | "
             f"fit's σ ({area}) | σ × √(χ²/dof) = σ × {excess:.2f} |",
             "|---|---|---|---|---|---|"]
    for chute in fit.test.parachutes:
        for band in chute.band_names or ("",):
            name = _steady_cds(fit, chute.name, band)
            lo, hi = (k_length * h for h in chute.band_range(band)) if band else (
                -np.inf, np.inf)
            span = ("all" if not band else f"below {hi:.0f}" if lo == -np.inf
                    else f"above {lo:.0f}" if hi == np.inf else f"{lo:.0f}-{hi:.0f}")
            sd = k_area * cov.std.get(name, float("nan"))
            sds = ("held fixed | " if name not in fit.free else "on a bound | "
                   if name in cov.at_bound else f"{sd:.2g} | {excess * sd:.2g}")
            lines.append(f"| {chute.name} | {name} | {span} | "
                         f"{k_area * fit.parameters[name]:.4f} | {sds} |")
    lines += ["", f"| canopies open | band | window (s) | mean altitude ({length} MSL) | "
              f"measured ({speed}) | implied v = √(2W/(ρ CdS)) ({speed}) | difference (σ) |",
              "|---|---|---|---|---|---|---|"]
    try:
        rates = descent_rates(fit, cov)
    except ValueError as exc:  # an altimeter too sparse for a window's line fit
        rates = []
        lines.append(f"| no descent rate: {exc} | | | | | | |")
    for r in rates:
        lines.append(f"| {' + '.join(r.canopies)} | {r.band or '-'} | {r.t0:.1f}-{r.t1:.1f} | "
                     f"{k_length * r.altitude_m:.0f} | "
                     f"{with_sigma(k_speed * r.measured, k_speed * r.measured_sigma)} | "
                     f"{with_sigma(k_speed * r.implied, k_speed * r.implied_sigma)} | "
                     f"{r.z:+.1f} |")
    lines += ["", "The implied rate is drag equal to weight at the window's mean altitude, "
              "its σ from the drag areas' covariance; the measured one a straight line "
              "through the altimeter's geometric altitude, its σ counting the residuals' "
              "autocorrelation. Falling into denser air the vehicle slows, so drag "
              "exceeds weight and the measured rate exceeds the steady one by about "
              "v³ |d ln ρ/dh| / (4 g) (0.06 m/s at 28 m/s near 2 km).", ""]
    return "\n".join(lines)


def rate_sigmas(fit: Fit, rates: list[DescentRate]) -> dict[str, float]:
    """Sigma (m^2) of each canopy's steady drag area from the measured descent rates alone.

    Drag equals weight, so a phase's total drag area is 2 W / (rho v^2) and its
    relative sigma is twice the measured rate's (whose sigma counts the
    residuals' autocorrelation: the descent's slow wander, which the fit's
    white-noise sigma leaves out).  A canopy opened after others gets its
    phase's total less theirs, so their sigmas add in quadrature.  A canopy with
    altitude bands has one drag area, and one sigma, per band (the rate's `band`).
    """
    out: dict[str, float] = {}
    for r in rates:
        canopy = r.canopies[-1]
        total = sum(fit.parameters[_steady_cds(fit, c, r.band)] for c in r.canopies)
        total += fit.parameters.get("CdS_V", 0.0)
        var = (2.0 * total * r.measured_sigma / r.measured) ** 2
        var += sum(out.get(_steady_cds(fit, c, r.band), 0.0) ** 2 for c in r.canopies[:-1])
        out[_steady_cds(fit, canopy, r.band)] = float(np.sqrt(var))
    return out


@dataclass(frozen=True)
class SteadyDragArea:
    """A fitted steady drag area (m^2) against the one its steady window's descent gives,
    2 W / (rho v^2) less the other canopies' fitted drag areas and the forebody's; its
    sigma counts the measured rate's and the vertical air's (`air_sigma`, m/s: the airspeed
    is v - w, and the air's mean w over the window is 0 to that sigma)."""

    name: str
    fitted: float
    fitted_sigma: float
    steady: float
    steady_sigma: float
    air_sigma: float
    rate: DescentRate

    @property
    def z(self) -> float:
        """Fitted minus steady-descent drag area, in the combined sigma."""
        sigma = float(np.hypot(self.fitted_sigma, self.steady_sigma))
        return (self.fitted - self.steady) / sigma if sigma > 0 else float("inf")


def air_sigma(fit: Fit, t0: float, t1: float) -> float:
    """Sigma (m/s) of the vertical air's mean over [t0, t1] (s) as the prior of the model's
    wind process has it (`WindProcess.mean_sigma`); for a model in still air, as the rocket
    default's (`WindProcess.vertical_thermals`) has it: the air moves whatever the model
    says."""
    wind = next((e for e in fit.model.effects
                 if isinstance(e, WindProcess) and "up" in e.components),
                WindProcess.vertical_thermals())
    return wind.mean_sigma(fit.test, t0, t1)


def steady_drag_areas(fit: Fit, cov: Covariance, rates: list[DescentRate]
                      ) -> list[SteadyDragArea]:
    """Each steady window's drag area for its last-opened canopy from the descent rate
    alone (drag equals weight), against the fit's: sigma^2 = (2 CdS_total / v)^2
    (sigma_v^2 + sigma_w^2) plus the other canopies' fitted variances."""
    out = []
    for r in rates:
        name = _steady_cds(fit, r.canopies[-1], r.band)
        rho = float(density_at(fit.test.atmosphere, r.altitude_m)[0])
        total = 2.0 * fit.test.weight / (rho * r.measured**2)
        others = [_steady_cds(fit, c, r.band) for c in r.canopies[:-1]]
        w_sigma = air_sigma(fit, r.t0, r.t1)
        var = (2.0 * total / r.measured) ** 2 * (r.measured_sigma**2 + w_sigma**2)
        var += sum(cov.std.get(n, 0.0) ** 2 for n in others)
        steady = total - sum(fit.parameters[n] for n in others) - fit.parameters.get("CdS_V",
                                                                                     0.0)
        out.append(SteadyDragArea(name, fit.parameters[name], cov.std.get(name, 0.0), steady,
                                  float(np.sqrt(var)), w_sigma, r))
    return out


def window_residuals(fit: Fit, t0: float, t1: float) -> dict[str, tuple[int, float, float]]:
    """Each sensor channel's residuals in [t0, t1] (s): (samples, chi-square, mean of the
    normalised residuals); the pseudo-sensors (events, priors, processes) left out."""
    out = {}
    for r in fit.residuals:
        sel = (r.t >= t0) & (r.t <= t1)
        if r.sensor in fit.pseudo_sensors or not sel.any():
            continue
        n = r.normalised[sel]
        out[f"{r.sensor}.{r.channel}"] = (int(sel.sum()), float(np.sum(n**2)),
                                          float(np.mean(n)))
    return out


STEADY_HEADER = ["parameter", "window (s)", "fitted (m²)", "2W/(ρ v²) (m²)",
                 "σ of the air's mean (m/s)", "difference (σ)"]


def steady_drag_area_section(fit: Fit, cov: Covariance, rates: list[DescentRate]
                             ) -> TableSection:
    """Each fitted drag area beside its steady descent's (`steady_drag_areas`), flagged
    where they differ by more than two sigma; for those, which channel's residuals are
    worst in the steady window (`window_residuals`), and the fitted air's mean there
    against its prior."""
    areas = steady_drag_areas(fit, cov, rates)
    rows = [[a.name, f"{a.rate.t0:.1f}-{a.rate.t1:.1f}", with_sigma(a.fitted, a.fitted_sigma),
             with_sigma(a.steady, a.steady_sigma),
             f"{a.air_sigma:.2f}", f"{a.z:+.1f}"] for a in areas]
    note = ("The steady descent's drag area is drag equal to weight at the measured rate and "
            "the window's mean altitude; its σ counts the rate's and the vertical air's (the "
            "airspeed is v - w, and the air's mean over the window is zero to the σ its prior "
            "gives), 2 CdS √(σ_v² + σ_w²) / v.")
    sentences = []
    for a in areas:
        if abs(a.z) <= 2.0:
            continue
        chans = window_residuals(fit, a.rate.t0, a.rate.t1)
        if not chans:
            continue
        worst = max(chans, key=lambda c: chans[c][1] / chans[c][0])
        n, chi2, mean = chans[worst]
        rest = "; ".join(f"{c} {np.sqrt(v[1] / v[0]):.2f} over {v[0]}" for c, v in chans.items()
                         if c != worst)
        updraft = mean_updraft(fit, a.rate.t0, a.rate.t1)
        sentences.append(
            f"{a.name}: the fit lies {a.z:+.1f} σ from the steady descent's. In "
            f"{a.rate.t0:.1f}-{a.rate.t1:.1f} s the worst residuals are the {worst}'s "
            f"(normalised RMS {np.sqrt(chi2 / n):.2f} over {n} samples, mean {mean:+.2f}, "
            f"chi-square {chi2:.0f}" + (f"; {rest}" if rest else "")
            + f"): {worst} drives the fit away from the descent rate"
            + (f", and the fitted air there moves at {updraft:+.2f} m/s on average against "
               f"the {a.air_sigma:.2f} m/s its prior allows." if updraft else "."))
    return TableSection(rows, [abs(a.z) > 2.0 for a in areas], note, sentences)


def steady_drag_area_text(fit: Fit, cov: Covariance, rates: list[DescentRate]) -> str:
    """The markdown section of `steady_drag_area_section`."""
    return steady_drag_area_section(fit, cov, rates).markdown(
        "Drag areas from the steady descent", STEADY_HEADER)


def nominal_comparisons(fit: Fit, cov: Covariance, nominal: dict[str, dict[str, Any]],
                        rates: list[DescentRate]) -> list[NominalComparison]:
    """Each nominal drag area against the fit, with the descent rate it would give; a
    nominal value whose canopy has no steady window among `rates` (none of 5 s or more) is
    left out (`uncompared` names it)."""
    out = []
    by_rate = rate_sigmas(fit, rates)
    for name, spec in nominal.items():
        if name not in fit.parameters:
            continue
        value = nominal_area(spec)
        canopy = split_name(name)[1][0]
        band = split_name(name)[1][-1] if fit.test.parachute(canopy).band_names else ""
        rate = next((r for r in rates if r.canopies[-1] == canopy and band in ("", r.band)),
                    None)
        if rate is None:
            continue
        v_nom = steady_rate(fit, value + _other_cds(fit, rate, canopy), rate.altitude_m) \
            - mean_updraft(fit, rate.t0, rate.t1)
        out.append(NominalComparison(name, fit.parameters[name], cov.std.get(name, 0.0), value,
                                     spec.get("source", ""), v_nom, rate,
                                     by_rate.get(name, 0.0), needed_cds(fit, rate, canopy),
                                     name in cov.at_bound))
    return out


def uncompared(fit: Fit, nominal: dict[str, dict[str, Any]],
               comparisons: list[NominalComparison]) -> list[str]:
    """The fitted nominal drag areas that `nominal_comparisons` could not compare."""
    done = {c.name for c in comparisons}
    return [n for n in nominal if n in fit.parameters and n not in done]


def opening_shock(fit: Fit, t_deploy: float, load_factor: np.ndarray
                  ) -> tuple[float, float, float] | None:
    """(measured axial peak (g), its time (s), model peak load factor (g)) after the
    deployment at `t_deploy` (s), the model's `load_factor` (g) given on the fit's grid; None
    without an accelerometer."""
    accel = fit.test.sensors_of("axial_accelerometer")
    if not accel:
        return None
    lo, hi = t_deploy + EJECTION_EXCLUDE_S, t_deploy + OPENING_WINDOW_S
    peak, t_peak = descent_load_factor_peak(accel[0].data, lo, hi)
    sel = (fit.t >= lo) & (fit.t <= hi)
    return peak, t_peak, float(np.max(load_factor[sel]))


def last_opening(fit: Fit) -> tuple[Event, Parachute, list[str]]:
    """The last canopy to deploy: its deployment event, the canopy, and its first stage's
    inflation parameters (n and expopen, or n_p, Ck, expopen and t_k), then its start."""
    last = max((e for e in fit.test.events if e.name in DEPLOYMENT_EVENTS), key=lambda e: e.time)
    chute = fit.test.parachute(last.parachute)
    stage = chute.stages[0]
    inflation = [n for n in fit.model.parameter_names if split_name(n)[1] == (chute.name, stage)
                 and split_name(n)[0] not in ("CdS", "t_start")]
    return last, chute, [*inflation, param_name("t_start", chute.name, stage)]


def held_opening_profiles(fit: Fit, spec: ModelSpec, progress: bool = False
                          ) -> dict[str, Profile]:
    """The profile (`held_profile`) of each inflation parameter of the last canopy's opening
    that the model holds fixed, over HELD_PROFILE_FACTORS times its held value (within its
    bounds; none for a parameter held at 0), each point given HELD_PROFILE_MAX_ITER
    iterations, then reported as not converged.  With the wind process every point of
    both Prometheus logs converges since stalled runs' descent learns the curvature
    (`feasible_descent`; 87 s for the TeleMetrum log's seven points); before,
    every TeleMetrum point ran the full 500 iterations (110 s each), Ipopt cycling
    within about one of chi-square where the opening's start and fill trade."""
    out = {}
    for name in last_opening(fit)[2]:
        if name in fit.free:
            continue
        prm = fit.model.parameter(name)
        grid = np.clip(fit.parameters[name] * np.asarray(HELD_PROFILE_FACTORS), prm.lower,
                       prm.upper)
        if np.all(grid == fit.parameters[name]):
            continue  # held at 0 (no multiple differs): nothing to profile
        out[name] = held_profile(fit, spec, name, grid, progress, HELD_PROFILE_MAX_ITER)
    return out


def held_lines(profile: Profile, scale: float, related: list[str]) -> list[str]:
    """What the profile of a held parameter says, its chi-square changes divided by `scale`
    (chi2/dof where the residuals are not white): the values within the 95 % level of the
    best one studied (chi2_1 quantile 3.84), whether that is all of them, and the range the
    `related` parameters run through over those values (what holding it hides from their
    sigmas).  Where no refit away from the held value converged there is no profile, and
    the lines say so instead."""
    failures = ("Points that failed: " + ", ".join(f"{v:g} ({status})"
                                                   for v, status in profile.failures))
    if profile.values.size < 2:
        return [f"- {profile.name} is held at {profile.estimate:g}; its profile could not be "
                "made, as no refit with it held elsewhere converged, so whether the data "
                f"determine it is not known. {failures}"]
    delta = profile.delta_chi_square
    within = (delta - delta.min()) / scale <= THRESHOLD
    inside = profile.values[within]
    studied = ", ".join(f"{v:g}" for v in profile.values)
    line = (f"- {profile.name} is held at {profile.estimate:g}. Held instead at each of "
            f"{studied} with everything else refitted, χ² changes by {delta.min():+.1f} to "
            f"{delta.max():+.1f} ({delta.min() / scale:+.2f} to {delta.max() / scale:+.2f} "
            f"after dividing by χ²/dof = {scale:.2f}); ")
    if inside.size == profile.values.size:
        line += ("every value studied lies within the 95 % level of the best (3.84): these "
                 "data do not determine it, and holding it costs nothing.")
    else:
        line += (f"the values within the 95 % level of the best (3.84) run from "
                 f"{inside.min():g} to {inside.max():g}.")
    ranges = []
    for name in related:
        along = [p[name] for p, ok in zip(profile.parameters, within, strict=True) if ok]
        if along:
            ranges.append(f"{name} from {min(along):.5g} to {max(along):.5g}")
    if ranges:
        line += (" Over those values " + ", ".join(ranges) + ": the spread that holding "
                 f"{profile.name} keeps out of their σ.")
    return [line, f"  {failures}"] if profile.failures else [line]


def opening_lines(fit: Fit, cov: Covariance, held: dict[str, Profile] | None = None
                  ) -> list[str]:
    """The markdown section on the last canopy's opening: its inflation parameters as fitted
    (each with the fit's sigma and that sigma times sqrt(chi2/dof), the honest one while
    the residuals are not white; held and bounded ones said so, with the profiles `held` of
    held ones where given), the fill time, the observed full-open time, and the
    accelerometer's axial peak against the model's and against the most the drag can
    pull, and the samples above that ceiling the import left out (`import_snatches`)."""
    last, chute, inflation = last_opening(fit)
    stage = chute.stages[0]
    start = inflation[-1]
    cds_name = param_name("CdS", chute.name, chute.stages[-1])
    scale = max(1.0, fit.chi_square / fit.dof)
    excess = float(np.sqrt(scale))
    lines = ["", "## Opening of the " + chute.name, "",
             f"| parameter | fitted | fit's σ | σ × √(χ²/dof) = σ × {excess:.2f} | |",
             "|---|---|---|---|---|"]
    for name in inflation:
        value = fit.parameters[name]
        if name not in fit.free:
            lines.append(f"| {name} | {value:.5g} | | | held fixed |")
        elif name in cov.at_bound:
            side = fit.model.parameter(name).nearer_bound(value)
            lines.append(f"| {name} | {value:.5g} | | | on its {side} bound |")
        else:
            sd = cov.std[name]
            lines.append(f"| {name} | {value:.5g} | {sd:.2g} | {excess * sd:.2g} | |")
    for prof in (held or {}).values():
        lines += ["", *held_lines(prof, scale, [n for n in inflation if n in fit.free])]
    v_start = fit.captures[param_name("V_start", chute.name, stage)]
    q = fit.quantities()
    t_start = fit.parameters[start]
    rise = float(q[param_name("rise_end", chute.name, stage)][0])
    lines += ["", f"- fill time {rise - t_start:.2f} s, from {t_start:.2f} s at "
              f"{v_start:.1f} m/s."]
    full = fit.test.event("full_open", chute.name, stage)
    if full is not None:
        lines.append(f"- full open observed at {with_sigma(full.time, full.sigma)} s (the "
                     "accelerometer's opening peak, `full_open`), the model's at "
                     f"{rise:.2f} s ({(rise - full.time) / full.sigma:+.1f} σ); with the "
                     "altimeter it fixes the start and the fill constant together.")
    if start in cov.at_bound and t_start <= last.time - last.sigma + 1e-6:
        lines.append(f"- the start sits on its lower bound, the {chute.name}'s deployment "
                     f"({last.time:.2f} s, less its {last.sigma:.2f} s timing sigma): the "
                     "altimeter would have the descent slow earlier still, so the fill time "
                     "counts the deployment and line stretch as well as the inflation.")
    shock = opening_shock(fit, last.time, q["load_factor"])
    if shock is not None:
        peak, t_peak, model_peak = shock
        # The most the canopy's drag can pull: full area at the start speed (g).
        at_start = {k: float(np.interp(t_start, fit.t, q[k])) for k in ("density", "mass")}
        ceiling = (0.5 * at_start["density"] * v_start**2 * fit.parameters[cds_name]
                   / (at_start["mass"] * G0))
        lines += [f"- accelerometer: largest axial specific force {peak:.2f} g at "
                  f"{t_peak:.2f} s (a lower bound of the load factor: the axis is not along "
                  "the riser, and the log samples at about 10 Hz);",
                  f"- model: peak load factor {model_peak:.2f} g in the same window; the "
                  f"{chute.name}'s full drag area at the start speed would pull "
                  f"{ceiling:.1f} g."]
        snatch = import_snatches(fit.test.path).get(chute.name)
        if snatch is not None and snatch.largest_m_s2 is not None:
            lines.append(
                f"- the import left out {snatch.samples_left_out} accelerometer sample(s) of "
                f"the opening above {snatch.ceiling_m_s2 / G0:.1f} g, the most the canopies' "
                "drag can pull at the speed of the charge (from the altimeter's rates; "
                f"the largest {snatch.largest_m_s2 / G0:.1f} g at {snatch.at_s:.2f} s): that "
                "is not the drag but the riser's snatch (an elastic shock cord stretched by "
                "the canopy stopping ahead of the vehicle, then recoiling), which a rigid "
                "riser cannot make"
                + ("; the time of the peak is the full-open event." if full is not None
                   else "."))
    return lines


def missing_text(fit: Fit, diagnosis: Diagnosis | None) -> str:
    """The markdown section on what the model misses: the worst-fitting window, the
    diagnosis's verdict on the library's effects and the residual's structure, and whether
    the altitude sensors share their residual (`common_residual`), which names the effect."""
    rms = ", ".join(f"{name} {value:.2f}" for name, value in channel_rms(fit).items()
                    if name.split(".")[0] not in fit.pseudo_sensors)
    lines = ["## What the model misses", "",
             f"- chi-square per degree of freedom {fit.chi_square / fit.dof:.2f}; normalised "
             f"RMS by channel: {rms}."]
    alpha = diagnosis.alpha if diagnosis is not None else ALPHA
    if diagnosis is not None:
        verdict = diagnosis.verdict().split("\n")
        lines += [f"- worst fit: {diagnosis.worst}.",
                  "- the diagnosis (score tests of every library effect the model does not use, "
                  "residual tests per channel and window; the diagnosis folder beside this "
                  "report): " + verdict[0]]
        lines += [f"  {line}" for line in verdict[1:]]
    common = common_residuals(fit)
    p = combined_p_value(common)
    if common:
        lines.append("- the altitude sensors against each other:")
    lines += [f"  - {c};" for c in common]
    if common and p < alpha:
        size = max(max(c.rms) for c in common)
        lines += ["", f"The altitude sensors share their residual (Fisher's combined p = {p:.2g}, "
                  f"below {alpha:g}): the vehicle's own altitude wanders about the model, by up "
                  f"to {size:.0f} m RMS in {BLOCK_S:g} s means, and the two sensors see it alike. "
                  "The effect that remains is therefore physical, not a sensor's: no bias, lag "
                  "or scale of one sensor can remove what both see. The descent rate varies "
                  "along the descent in a way the model lacks: vertical air motion (rising and "
                  "sinking air of a fraction of a metre per second shifts a steady descent by "
                  "tens of metres over a minute) or a density profile off the site "
                  "atmosphere's constant lapse rate. Neither is in the model; the drag areas "
                  "carry each canopy phase's mean descent rate."]
    elif common:
        lines += ["", f"The test does not show the altitude sensors sharing their residual at "
                  f"the {alpha:g} level (Fisher's combined p = {p:.2g}). That is no evidence "
                  "that they do not: short stretches give few effective samples. Whether "
                  "what remains is physical or each sensor's own is left open."]
    return "\n".join(lines) + "\n"


DESCENT_RATE_HEADER = ("canopies open", "window (s)", "mean altitude (m MSL)", "measured (m/s)",
                       "implied by the fitted CdS (m/s)", "difference (σ)")


def descent_rate_rows(rates: list[DescentRate]) -> list[list[str]]:
    """One row per steady window (`DESCENT_RATE_HEADER`): the measured descent rate against
    the one the fitted drag areas imply there."""
    return [[" + ".join(r.canopies), f"{r.t0:.1f}-{r.t1:.1f}", f"{r.altitude_m:.0f}",
             with_sigma(r.measured, r.measured_sigma),
             with_sigma(r.implied, r.implied_sigma), f"{r.z:+.1f}"] for r in rates]


def descent_rate_text(rates: list[DescentRate]) -> str:
    """The markdown table of `descent_rate_rows`."""
    return "\n".join(["## Steady descent rates", "", f"| {' | '.join(DESCENT_RATE_HEADER)} |",
                      "|---|---|---|---|---|---|",
                      *(f"| {' | '.join(row)} |" for row in descent_rate_rows(rates))])


NOMINAL_HEADER = ("parameter", "fitted (m²)", "σ from the measured rate (m²)", "nominal (m²)",
                  "fitted / nominal", "difference (σ)", "rate with the nominal CdS (m/s)",
                  "measured rate (m/s)")


@dataclass(frozen=True)
class TableSection:
    """A report section as plain data for report.md and the page alike: its table's rows,
    which rows are flagged, a note on the table, and its sentences."""

    rows: list[list[str]]
    flagged: list[bool]
    note: str
    sentences: list[str]

    def markdown(self, title: str, header: list[str]) -> str:
        """The section as markdown: a heading, the table, the note and the sentences."""
        return "\n".join([f"## {title}", "", f"| {' | '.join(header)} |",
                          "|---" * len(header) + "|",
                          *(f"| {' | '.join(row)} |" for row in self.rows),
                          "", self.note, "", *(f"- {line}" for line in self.sentences)])


def nominal_section(fit: Fit, cov: Covariance, nominal: dict[str, dict[str, Any]],
                    rates: list[DescentRate] | None = None) -> TableSection:
    """Each fitted drag area against its published nominal value (`nominal_comparisons`),
    with the descent rate the nominal would give and the drag area the measured rate
    needs; `rates` the fit's `descent_rates` where already computed."""
    rates = descent_rates(fit, cov) if rates is None else rates
    comps = nominal_comparisons(fit, cov, nominal, rates)
    left = uncompared(fit, nominal, comps)
    rows = [[name, "no steady window of 5 s or more under its canopy: not compared",
             *[""] * (len(NOMINAL_HEADER) - 2)] for name in left]
    for c in comps:
        fitted = (f"{c.fitted:.4f} on its bound" if c.at_bound
                  else with_sigma(c.fitted, c.sigma))
        rows.append([c.name, fitted, f"{c.sigma_rate:.2g}", f"{c.nominal:.3f}",
                     f"{c.fitted / c.nominal:.2f}", f"{c.z:+.1f}", f"{c.rate_nominal:.2f}",
                     with_sigma(c.rate_measured.measured, c.rate_measured.measured_sigma)])
    if any(isinstance(e, WindProcess) for e in fit.model.effects):
        note = ("The fit's σ count the air's vertical motion (`wind_process`) as well as the "
                "sensors' noise; the σ that the measured rate's scatter allows is given beside "
                "them, and the difference from the nominal value is given in the larger of the "
                "two.")
    else:
        note = ("The fit's σ treat the sensor noise as white. The descent wanders about the "
                "model over tens of seconds (see below), so the σ that the measured rate's "
                "scatter allows, with the residuals' autocorrelation counted, is the honest "
                "one; the difference from the nominal value is given in the larger of the two.")
    sentences = []
    for c in comps:
        faster = "faster" if c.rate_nominal > c.rate_measured.measured else "slower"
        r = c.rate_measured
        updraft = mean_updraft(fit, r.t0, r.t1)
        air = (f" through air rising at {updraft:+.2f} m/s on average there (the fitted "
               "wind process)" if updraft else "")
        bound = (f" (the fit left it on its bound, at {c.fitted:.3f} m²)" if c.at_bound
                 else "")
        sentences.append(
            f"{c.name}: with the nominal {c.nominal:.3f} m² ({c.source}) the rocket would have "
            f"come down at {c.rate_nominal:.2f} m/s near {r.altitude_m:.0f} m{air}, {faster} "
            f"than the {r.measured:.2f} m/s measured there; the measured rate needs "
            f"{c.needed:.3f} m² (2 W / (ρ v²) with the other drag areas open taken away)"
            f"{bound}. A fitted drag area is the system's: it carries the drag of the body "
            "hanging beneath (the card fixes the forebody drag area at "
            f"{fit.parameters.get('CdS_V', 0.0):.3f} m²) and, for a later canopy, whatever "
            "the canopies opened before it lose or add to the wake.")
    return TableSection(rows, [False] * len(left) + [abs(c.z) > 3.0 for c in comps], note,
                          sentences)


def nominal_text(fit: Fit, cov: Covariance, nominal: dict[str, dict[str, Any]],
                 rates: list[DescentRate] | None = None) -> str:
    """The markdown section of `nominal_section`: its table, note and sentences."""
    return nominal_section(fit, cov, nominal, rates).markdown(
        "Drag areas against the published nominal values", NOMINAL_HEADER)


def flight_text(fit: Fit, cov: Covariance, nominal: dict[str, dict[str, Any]],
                diagnosis: Diagnosis | None = None,
                held: dict[str, Profile] | None = None) -> str:
    """The markdown sections comparing the reconstruction with nominal values and the data,
    and saying what the model misses (with `diagnosis`, its verdict too; with `held`, the
    profiles of the opening's held parameters, `held_opening_profiles`)."""
    rates = descent_rates(fit, cov)
    lines = [descent_rate_text(rates), "", steady_drag_area_text(fit, cov, rates), "",
             nominal_text(fit, cov, nominal, rates)]
    lines += opening_lines(fit, cov, held)
    return "\n".join(lines) + "\n\n" + missing_text(fit, diagnosis)


def air_motion_text(still: Fit, still_cov: Covariance, wind: Fit, wind_cov: Covariance,
                    figure: str) -> str:
    """The markdown section comparing the fit that estimates the air's vertical motion
    (`wind_process`) with the same model in still air: chi-square/dof, each sensor's
    normalised RMS, the drag areas and start times with their sigmas, and the wind figure."""
    lines = ["## Air motion", "",
             "The model estimates the air's vertical motion with the trajectory "
             "(`wind_process`: a Gauss-Markov process whose innovations join chi-square), so "
             "its σ count the air's motion as well as the sensors' noise. Beside it, the same "
             "model in still air (report in `report_still`):", "",
             "| | still air | with the air's motion |", "|---|---|---|",
             f"| χ²/dof | {still.chi_square / still.dof:.2f} | "
             f"{wind.chi_square / wind.dof:.2f} |"]
    rms_still, rms_wind = channel_rms(still), channel_rms(wind)
    for name, value in rms_still.items():
        if name.split(".")[0] in still.pseudo_sensors or name not in rms_wind:
            continue
        lines.append(f"| {name}, normalised RMS | {value:.2f} | {rms_wind[name]:.2f} |")
    for name in still.free:
        if name in wind.parameters and split_name(name)[0] in ("CdS", "t_start"):
            lines.append(f"| {name} | "
                         f"{with_sigma(still.parameters[name], still_cov.std.get(name))} | "
                         f"{with_sigma(wind.parameters[name], wind_cov.std.get(name))} |")
    lines += ["", f"![the air's vertical motion]({figure})", ""]
    return "\n".join(lines)
