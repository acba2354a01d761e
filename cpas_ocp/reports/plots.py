"""Figures of a fit: model against measurement per sensor (also with the phase windows
shaded), canopy drag areas, event times, parameter correlations and profile likelihoods;
of a campaign's Monte Carlo dispersions (hull projections with the caps, histograms,
drag-area envelopes against the flight curves); and of Monte Carlo peak loads."""

from __future__ import annotations

import itertools
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np
from scipy.spatial import ConvexHull

from cpas_ocp.estimation.estimator import Fit, SensorResidual
from cpas_ocp.estimation.reduction import reduce, stage_starts
from cpas_ocp.estimation.uncertainty import Covariance
from cpas_ocp.inference.phase_windows import PhaseWindow, windows_for_sensor
from cpas_ocp.inference.profile_likelihood import THRESHOLD, Profile
from cpas_ocp.physics.effects.wind_process import WindProcess
from cpas_ocp.physics.parameters import param_name, split_name
from cpas_ocp.physics.units import FT, LBF
from cpas_ocp.reports.display_units import DisplayUnits, display_units, pretty
from cpas_ocp.reports.figure_files import write_figure
from cpas_ocp.reports.report_data import event_rows

if TYPE_CHECKING:
    import pandas as pd

    from cpas_ocp.campaign.dispersion_study import DispersionModel
    from cpas_ocp.campaign.drag_area_envelope import DragAreaEnvelope
    from cpas_ocp.campaign.peak_load_study import StageLoads



def sensor_axes(fit: Fit, sensor: str, windows: Sequence[PhaseWindow] = (),
                units: DisplayUnits | None = None, axes: Sequence[plt.Axes] | None = None
                ) -> list[plt.Axes]:
    """Draw one sensor of a fit: for each channel the model over the measurement (in
    `units`, default the test's own) and beneath it the normalised residuals with the +-1
    and +-3 sigma bands; the phase `windows` that apply to the sensor (its own canopy's
    for a load cell) shaded by kind.  Into `axes` (two per channel: value, residual),
    else a new figure's; returns the axes drawn."""
    units = units or display_units(fit.test)
    rows = [r for r in fit.residuals if r.sensor == sensor]
    if not rows:
        raise ValueError(f"no residuals of a sensor {sensor!r} in this fit; its sensors: "
                         f"{', '.join(dict.fromkeys(r.sensor for r in fit.residuals))}")
    if axes is None:
        _, grid = plt.subplots(2 * len(rows), 1, figsize=(10, 2.8 * len(rows) + 1.5),
                               sharex=True, gridspec_kw={"height_ratios": [3, 1.4] * len(rows)})
        axes = list(grid)
    if len(axes) != 2 * len(rows):
        raise ValueError(f"{sensor} has {len(rows)} channels: give {2 * len(rows)} axes")
    shown = windows_for_sensor(fit.test, sensor, windows) if windows else []
    for i, r in enumerate(rows):
        unit, k = units.channel(r.channel)
        ax, axr = axes[2 * i], axes[2 * i + 1]
        _shade_windows([ax, axr], shown, legend=i == 0)
        ax.plot(r.t, r.measured * k, ".", ms=1.5, color="0.55", label="measured")
        ax.plot(r.t, r.model * k, "-", lw=1.0, color="C3", label="model")
        ax.set_ylabel(f"{r.channel} [{pretty(unit)}]")
        ax.legend(loc="best", fontsize=7, ncol=2)
        _plot_normalised(axr, r)
    axes[-1].set_xlabel("time [s]")
    return list(axes)


def plot_sensors(fit: Fit, folder: Path, units: DisplayUnits | None = None) -> list[Path]:
    """One figure per sensor (``sensor_<sensor>.png``, `sensor_axes` without windows)."""
    return [write_figure(sensor_axes(fit, sensor, (), units)[0].figure,
                         f"{fit.test.name}: {sensor}, model vs measurement",
                         folder / f"sensor_{sensor}.png") for sensor in fit.sensors]


def events_axes(fit: Fit, ax: plt.Axes | None = None) -> plt.Axes | None:
    """Observed event times (with their 1 and 2 sigma) against the model's, one row each,
    into `ax` (else a new figure's); None where the test has no observed events."""
    rows = event_rows(fit)
    if not rows:
        return None
    ax = ax if ax is not None else plt.subplots(figsize=(10, 0.6 * len(rows) + 1.6))[1]
    for i, e in enumerate(rows):
        ax.errorbar(e.observed, i, xerr=2 * e.sigma, fmt="none", ecolor="0.75", elinewidth=6)
        ax.errorbar(e.observed, i, xerr=e.sigma, fmt="o", color="0.35", ms=4, elinewidth=6,
                    label="observed ±1σ, ±2σ" if i == 0 else None)
        ax.plot(e.model, i, "|", color="C3", ms=18, mew=2, label="model" if i == 0 else None)
        ax.annotate(f"{e.z:+.2f}σ", (e.observed + 2.5 * e.sigma, i), va="center", fontsize=8)
    ax.set_yticks(range(len(rows)), [e.event for e in rows])
    ax.set_ylim(-0.7, len(rows) - 0.3)
    ax.set_xlabel("time [s]")
    ax.legend(loc="lower right", fontsize=8)
    return ax


def plot_events(fit: Fit, folder: Path) -> Path | None:
    """``events.png`` (`events_axes`); None without observed events."""
    ax = events_axes(fit)
    return None if ax is None else write_figure(
        ax.figure, f"{fit.test.name}: observed event times against the model",
        folder / "events.png")


@dataclass(frozen=True)
class DragAreaCurves:
    """A canopy's drag area (SI, m^2): the reconstruction on the fit's grid, the riser
    load cell's offline (Eq. 3) reduction mapped to the trajectory frame (divided by the
    fitted load-cell gain; None without a load cell), and its stages' start times (s)."""

    canopy: str
    t: np.ndarray
    cds: np.ndarray
    data_t: np.ndarray | None
    data_cds: np.ndarray | None
    starts: dict[str, float]


def drag_area_curves(fit: Fit) -> list[DragAreaCurves]:
    """Each canopy's reconstructed drag area against its offline reduction, as data."""
    q = fit.quantities()
    starts = stage_starts(fit.test, fit.parameters)
    red = reduce(fit.test, starts)
    curves = []
    for chute in fit.test.parachutes:
        data_t = data_cds = None
        if chute.name in red.cds_riser:
            # Load-cell drag area mapped to the trajectory frame: divided by the fitted gain.
            gain = q.get(param_name("loadcell_gain", chute.name))
            factor = 1.0 if gain is None else 1.0 / np.interp(red.t, fit.t, gain)
            data_t, data_cds = np.asarray(red.t), red.cds_riser[chute.name] * factor
        curves.append(DragAreaCurves(chute.name, fit.t, q[param_name("cds", chute.name)],
                                     data_t, data_cds,
                                     {s: starts[(chute.name, s)] for s in chute.stages}))
    return curves


def drag_area_axes(fit: Fit, units: DisplayUnits | None = None,
                   curves: Sequence[DragAreaCurves] | None = None,
                   axes: Sequence[plt.Axes] | None = None) -> list[plt.Axes]:
    """Each canopy's reconstructed drag area against its offline (Eq. 3) reduction
    (`curves`, `drag_area_curves` of the fit where not given), in `units`, one axis per
    canopy (`axes`, else a new figure's); returns the axes."""
    units = units or display_units(fit.test)
    k, unit = units.factor("area"), pretty(units.unit("area"))
    curves = drag_area_curves(fit) if curves is None else curves
    if axes is None:
        axes = list(plt.subplots(len(curves), 1, figsize=(10, 3.2 * len(curves)), sharex=True,
                                 squeeze=False)[1][:, 0])
    if len(axes) != len(curves):
        raise ValueError(f"{len(curves)} canopies: give {len(curves)} axes")
    for ax, c in zip(axes, curves, strict=True):
        if c.data_t is not None and c.data_cds is not None:
            ax.plot(c.data_t, c.data_cds * k, ".", ms=1.2, color="0.6",
                    label="riser data, Eq. 3, with fitted scales")
        ax.plot(c.t, c.cds * k, color="C3", lw=1.2, label="reconstructed CdS(t)")
        for t0 in c.starts.values():
            ax.axvline(t0, color="C2", lw=0.6, ls="--")
        ax.set_ylabel(f"{c.canopy} CdS [{unit}]")
        ax.legend(loc="best", fontsize=8)
    axes[-1].set_xlabel("time [s]  (dashed: reconstructed inflation start times)")
    return list(axes)


def plot_drag_areas(fit: Fit, folder: Path, units: DisplayUnits | None = None,
                    curves: Sequence[DragAreaCurves] | None = None) -> Path:
    """``drag_areas.png`` (`drag_area_axes`)."""
    return write_figure(drag_area_axes(fit, units, curves)[0].figure,
                        f"{fit.test.name}: canopy drag areas", folder / "drag_areas.png")


def plot_wind(fit: Fit, cov: Covariance | None, folder: Path,
              units: DisplayUnits | None = None) -> Path | None:
    """``wind.png`` (`wind_axes`); None where the model has no process knots."""
    axes = wind_axes(fit, cov, units)
    if axes is None:
        return None
    return write_figure(axes[0, 0].figure, f"{fit.test.name}: air motion (wind process)",
                        folder / "wind.png")


@dataclass(frozen=True)
class WindCurve:
    """One component of the wind process's estimate in display units: the knot times (s),
    the air velocity there and its 95 % half-band (+-1.96 sigma, NaN without a sigma), and
    the vehicle's altitude at each knot."""

    component: str
    t: np.ndarray
    velocity: np.ndarray
    band: np.ndarray
    altitude: np.ndarray


def wind_curves(fit: Fit, cov: Covariance | None, units: DisplayUnits
                ) -> list[WindCurve]:
    """Each component of the wind process's estimate (`wind_process`) at its knots, in
    `units`; empty where the model has no process knots."""
    components: dict[str, list[tuple[int, str]]] = {}
    for name in fit.free:
        base, index = split_name(name)
        if fit.model.parameter(name).process_knot and base.startswith("wind_"):
            components.setdefault(base.removeprefix("wind_"), []).append((int(index[0]), name))
    if not components:
        return []
    kv, kh = units.factor("velocity"), units.factor("length")
    std = cov.std if cov is not None else {}
    q = fit.quantities()
    wind = next(e for e in fit.model.effects if isinstance(e, WindProcess))
    knot_times = wind.knot_times(fit.test)
    out = []
    for component, knots in components.items():
        names = [n for _, n in sorted(knots)]
        t = np.asarray(knot_times[:len(names)], dtype=float)
        out.append(WindCurve(component, t, kv * np.array([fit.parameters[n] for n in names]),
                             kv * 1.96 * np.array([std.get(n, np.nan) for n in names]),
                             kh * np.interp(t, fit.t, q["altitude"])))
    return out


def wind_axes(fit: Fit, cov: Covariance | None, units: DisplayUnits | None = None,
              axes: np.ndarray | None = None) -> np.ndarray | None:
    """The wind process's estimate (`wind_curves`): each component's air velocity at its
    knots with the 95 % band (+-1.96 sigma), against time (left) and against altitude
    (right); into `axes` (a row of two per component, else a new figure's); the axes, or
    None where the model has no process knots."""
    units = units or display_units(fit.test)
    curves = wind_curves(fit, cov, units)
    if not curves:
        return None
    speed, length = pretty(units.unit("velocity")), pretty(units.unit("length"))
    if axes is None:
        axes = plt.subplots(len(curves), 2, figsize=(12, 2.8 * len(curves) + 1.0),
                            squeeze=False, gridspec_kw={"width_ratios": [3, 1]})[1]
    for row, c in enumerate(curves):
        t, u, band = c.t, c.velocity, c.band
        ax = axes[row, 0]
        ax.fill_between(t, u - band, u + band, color="C0", alpha=0.25, label="95 % band")
        ax.plot(t, u, "-o", ms=2.5, color="C0", label="estimate at the knots")
        ax.axhline(0.0, color="k", lw=0.5)
        ax.set_ylabel(f"{c.component} air velocity [{speed}]")
        ax.legend(loc="best", fontsize=8)
        ax = axes[row, 1]
        ax.fill_betweenx(c.altitude, u - band, u + band, color="C0", alpha=0.25)
        ax.plot(u, c.altitude, "-o", ms=2.5, color="C0")
        ax.axvline(0.0, color="k", lw=0.5)
        ax.set_xlabel(f"{c.component} [{speed}]")
        ax.set_ylabel(f"altitude [{length}]")
    axes[-1, 0].set_xlabel("time [s]")
    return axes


def correlation_axes(cov: Covariance, ax: plt.Axes | None = None) -> plt.Axes | None:
    """The parameters' correlation matrix as a map, into `ax` (else a new figure's);
    undetermined parameters and those on a bound left out; None where fewer than two
    remain."""
    keep = [i for i, n in enumerate(cov.names) if n not in cov.undetermined
            and n not in cov.at_bound]
    if len(keep) < 2:
        return None
    rho = cov.correlation()[np.ix_(keep, keep)]
    labels = [cov.names[i] for i in keep]
    size = 3.0 + 0.22 * len(keep)
    ax = ax if ax is not None else plt.subplots(figsize=(size + 1.2, size))[1]
    im = ax.imshow(rho, cmap="RdBu_r", vmin=-1, vmax=1)
    ax.set_xticks(range(len(keep)), labels, rotation=90, fontsize=6)
    ax.set_yticks(range(len(keep)), labels, fontsize=6)
    ax.figure.colorbar(im, ax=ax, shrink=0.8, label="correlation ρ")
    return ax


def plot_correlation(cov: Covariance, name: str, folder: Path) -> Path | None:
    """``correlation.png`` (`correlation_axes`); None where it has nothing to show."""
    ax = correlation_axes(cov)
    return None if ax is None else write_figure(ax.figure, f"{name}: parameter correlations",
                                                folder / "correlation.png")


def profile_axes(prof: Profile, ax: plt.Axes | None = None) -> plt.Axes:
    """A parameter's profile likelihood against the covariance's parabola, with both 95 %
    intervals, into `ax` (else a new figure's)."""
    ax = ax if ax is not None else plt.subplots(figsize=(7, 4.2))[1]
    fine = np.linspace(prof.values.min(), prof.values.max(), 200)
    ax.plot(fine, ((fine - prof.estimate) / prof.std) ** 2, "--", color="0.5",
            label="covariance: ((θ - θ̂)/σ)²")
    ax.plot(prof.values, prof.delta_chi_square, "o-", color="C3", ms=4, label="profile Δχ²")
    ax.axhline(THRESHOLD, color="k", lw=0.6)
    for v in prof.interval():
        if v is not None:
            ax.axvline(v, color="C3", lw=0.8, ls=":")
    for v in prof.wald_interval():
        ax.axvline(v, color="0.5", lw=0.8, ls=":")
    ax.set_xlabel(f"{prof.name} [{prof.unit}]")
    ax.set_ylabel("Δχ²  (95 %: 3.84)")
    ax.set_ylim(bottom=-0.2)
    ax.legend(loc="upper center", fontsize=8)
    return ax


def plot_profile(prof: Profile, name: str, folder: Path) -> Path:
    """``profile_<name>.png`` (`profile_axes`)."""
    return write_figure(profile_axes(prof).figure, f"{name}: profile likelihood",
                        folder / f"profile_{file_stem(prof.name)}.png")


def file_stem(text: str) -> str:
    """`text` as a file-name part: letters, digits, '-' and '_' kept, anything else '_'."""
    return "".join(ch if ch.isalnum() or ch in "_-" else "_" for ch in text)


# Shading of the phase windows, by kind: light, distinct colours.
WINDOW_COLOURS = {"deployment": "#cfe2f3", "inflation": "#f9d5cf", "steady": "#d9ead3"}


def plot_sensor_residuals(fit: Fit, windows: Sequence[PhaseWindow], folder: Path,
                          units: DisplayUnits | None = None) -> list[Path]:
    """One figure per sensor (``residuals_<sensor>.png``, `sensor_axes` with the phase
    windows shaded)."""
    return [write_figure(sensor_axes(fit, sensor, windows, units)[0].figure,
                         f"{fit.test.name}: {sensor}, residuals by phase window",
                         folder / f"residuals_{sensor}.png") for sensor in fit.sensors]


def plot_residual_comparison(fit_a: Fit, fit_b: Fit, labels: tuple[str, str],
                             windows: Sequence[PhaseWindow], folder: Path) -> list[Path]:
    """One figure per sensor (``compare_<sensor>.png``, `residual_comparison_axes`)."""
    return [write_figure(
        residual_comparison_axes(fit_a, fit_b, sensor, labels, windows)[0, 0].figure,
        f"{fit_a.test.name}: {sensor}, {labels[0]} against {labels[1]}",
        folder / f"compare_{sensor}.png") for sensor in fit_a.sensors]


def residual_comparison_axes(fit_a: Fit, fit_b: Fit, sensor: str, labels: tuple[str, str],
                             windows: Sequence[PhaseWindow] = (),
                             axes: np.ndarray | None = None) -> np.ndarray:
    """Each channel of `sensor`: its normalised residuals under model A (left) and model B
    (right), same scale, phase windows shaded, the normalised RMS of each in its panel's
    title; into `axes` (a row of two per channel the fits share, else a new figure's);
    the axes."""
    # Channels are paired by name: a model may add pseudo-observations the other lacks.
    in_b = {(r.sensor, r.channel): r for r in fit_b.residuals}
    pairs = [(a, in_b[a.sensor, a.channel]) for a in fit_a.residuals
             if a.sensor == sensor and (a.sensor, a.channel) in in_b]
    shown = windows_for_sensor(fit_a.test, sensor, windows)
    if axes is None:
        axes = plt.subplots(len(pairs), 2, figsize=(12, 2.2 * len(pairs) + 1.2),
                            sharex=True, sharey="row", squeeze=False)[1]
    for i, pair in enumerate(pairs):
        for j, (r, label) in enumerate(zip(pair, labels, strict=True)):
            ax = axes[i, j]
            _shade_windows([ax], shown, legend=i == 0 and j == 0)
            _plot_normalised(ax, r)
            rms = float(np.sqrt(np.mean(r.normalised**2)))
            ax.set_title(f"{label}: {r.channel}, normalised RMS {rms:.3f}", fontsize=9)
            if i == 0 and j == 0 and shown:
                ax.legend(loc="upper right", fontsize=7)
        lim = max(4.0, *(float(np.percentile(np.abs(r.normalised), 99.5)) for r in pair))
        axes[i, 0].set_ylim(-lim, lim)
    for ax in axes[-1]:
        ax.set_xlabel("time [s]")
    return axes


def _shade_windows(axes: list[plt.Axes], windows: Sequence[PhaseWindow], legend: bool) -> None:
    """Shade the phase windows by kind on every axis; label each kind once on the first."""
    labelled: set[str] = set()
    for w in windows:
        label = w.kind if legend and w.kind not in labelled else None
        labelled.add(w.kind)
        for a in axes:
            a.axvspan(w.t0, w.t1, color=WINDOW_COLOURS.get(w.kind, "0.9"), alpha=0.6, lw=0,
                      zorder=0, label=label if a is axes[0] else None)


def _plot_normalised(ax: plt.Axes, r: SensorResidual) -> None:
    """Normalised residuals with the +-1 and +-3 sigma bands."""
    ax.axhspan(-3, 3, color="0.4", alpha=0.12, zorder=0.5, lw=0)
    ax.axhspan(-1, 1, color="0.4", alpha=0.2, zorder=0.6, lw=0)
    ax.plot(r.t, r.normalised, ".", ms=1.5, color="C0", zorder=2)
    ax.axhline(0, color="k", lw=0.5, zorder=1)
    ax.set_ylabel("res/σ (±1, ±3)")
    lim = max(4.0, float(np.percentile(np.abs(r.normalised), 99.5)))
    ax.set_ylim(-lim, lim)


def plot_hull_projections(model: DispersionModel, cases: pd.DataFrame, path: Path,
                          shown: int = 5000) -> Path:
    """The hull's projections (`hull_projection_axes`) written to `path`."""
    return write_figure(hull_projection_axes(model, cases, shown)[0].figure,
                        f"{model.label}: convex hull of the inflation parameters", path)


def hull_projection_axes(model: DispersionModel, cases: pd.DataFrame, shown: int = 5000,
                         axes: Sequence[plt.Axes] | None = None) -> list[plt.Axes]:
    """Each pair of hull parameters (paper Figs. 22, 26): the test points, the outline of
    their hull and of the grown hull (the convex hull of the projected vertices), the caps
    box of the two distributions, and `shown` Monte Carlo cases; into `axes` (one per
    pair, else a new figure's); the axes."""
    names = model.hull_names
    pairs = list(itertools.combinations(range(len(names)), 2))
    if axes is None:
        axes = plt.subplots(1, len(pairs), figsize=(5 * len(pairs), 4.5), squeeze=False)[1][0]
    axes = list(axes)
    grown = model.hull.vertices
    tests = model.test_points[list(names)].to_numpy()
    scale = (1.0 + model.hull.growth)
    own = model.hull.center + (grown - model.hull.center) / scale
    for ax, (i, j) in zip(axes, pairs, strict=True):
        ax.plot(cases[names[i]].to_numpy()[:shown], cases[names[j]].to_numpy()[:shown], ".",
                ms=1, color="0.6", label=f"Monte Carlo cases (first {shown:,})")
        for vertices, style, label in ((own, "C9-", "tests' hull"),
                                       (grown, "k--", f"grown {100 * model.hull.growth:.0f} %")):
            outline = ConvexHull(vertices[:, [i, j]])
            loop = np.append(outline.vertices, outline.vertices[0])
            ax.plot(vertices[loop, i], vertices[loop, j], style, lw=1.2, label=label)
        (x0, x1), (y0, y1) = ((model.dispersions[names[k]].lower_cap,
                               model.dispersions[names[k]].upper_cap) for k in (i, j))
        ax.plot([x0, x1, x1, x0, x0], [y0, y0, y1, y1, y0], "C3-", lw=1.0,
                label="caps (distribution bounds)")
        ax.plot(tests[:, i], tests[:, j], "ko", ms=4, label="tests")
        ax.set_xlabel(names[i])
        ax.set_ylabel(names[j])
    axes[0].legend(fontsize=7)
    return axes


def plot_dispersion_histograms(model: DispersionModel, cases: pd.DataFrame, path: Path) -> Path:
    """The dispersions' histograms (`dispersion_histogram_axes`) written to `path`."""
    return write_figure(dispersion_histogram_axes(model, cases)[0].figure,
                        f"{model.label}: dispersions ({model.tests} tests)", path)


def dispersion_histogram_axes(model: DispersionModel, cases: pd.DataFrame,
                              axes: Sequence[plt.Axes] | None = None) -> list[plt.Axes]:
    """Per dispersed parameter: histogram of the cases (density), the fitted capped density,
    the caps, and the test values as ticks; into `axes` (one per parameter, else a new
    figure's); the axes."""
    names = list(model.dispersions)
    if axes is None:
        axes = plt.subplots(1, len(names), figsize=(3.6 * len(names), 3.4), squeeze=False)[1][0]
    axes = list(axes)
    for ax, name in zip(axes, names, strict=True):
        d = model.dispersions[name]
        # One filled outline, not a patch per bin: the same picture, 60 artists fewer.
        ax.hist(cases[name], bins=60, density=True, color="0.75", label="cases",
                histtype="stepfilled")
        x = np.linspace(d.lower_cap, d.upper_cap, 200)
        density = d.frozen().pdf(x) / d.truncated_mass()
        ax.plot(x, density, "C3-", lw=1.2, label=f"{d.family} (capped)")
        for cap in (d.lower_cap, d.upper_cap):
            ax.axvline(cap, color="C3", ls=":", lw=1)
        ax.plot(model.test_points[name], np.zeros(len(model.test_points)), "k|", ms=14,
                label="tests")
        ax.set_xlabel(name)
    axes[0].legend(fontsize=7)
    return axes


def plot_peak_loads(result: StageLoads, path: Path) -> Path:
    """The peak loads (`peak_load_axes`) written to `path`."""
    return write_figure(peak_load_axes(result)[0].figure,
                        f"{result.cases.label}: Monte Carlo peak loads "
                        f"({result.loads.tension.size:,} cases)", path)


def peak_load_axes(result: StageLoads, axes: Sequence[plt.Axes] | None = None
                   ) -> list[plt.Axes]:
    """A canopy stage's Monte Carlo peak riser tension: histogram (lbf) with the fitted
    values' peak and the 50/99/99.9 % quantiles (left), and the exceedance probability
    P(peak >= x) on a log scale, down to one case in the sample (right); into `axes`
    (two, else a new figure's); the axes."""
    tension = np.sort(result.loads.tension) / LBF
    n = tension.size
    nominal = result.nominal.tension[0] / LBF
    left, right = axes if axes is not None else plt.subplots(1, 2, figsize=(10, 4))[1]
    left.hist(tension, bins=min(80, max(10, n // 20)), color="0.7")
    right.semilogy(tension, 1.0 - np.arange(n) / n, "C0-", lw=1.2, drawstyle="steps-post")
    for ax in (left, right):
        ax.axvline(nominal, color="C3", lw=1.2, label=f"fitted values {nominal:,.0f} lbf")
        for q, style in ((0.5, ":"), (0.99, "--"), (0.999, "-.")):
            x = float(np.quantile(tension, q))
            ax.axvline(x, color="k", ls=style, lw=0.9, label=f"{100 * q:g} %: {x:,.0f} lbf")
        ax.set_xlabel("peak riser tension (lbf)")
    left.set_ylabel("cases")
    right.set_ylabel("P(peak ≥ x)")
    right.set_ylim(0.5 / n, 1.0)
    left.legend(fontsize=7)
    return [left, right]


def plot_drag_area_envelope(env: DragAreaEnvelope, path: Path) -> Path:
    """The drag-area envelope (`drag_area_envelope_axes`) written to `path`."""
    return write_figure(drag_area_envelope_axes(env).figure,
                        f"{env.label}: drag-area growth, Monte Carlo against flight", path)


def drag_area_envelope_axes(env: DragAreaEnvelope, ax: plt.Axes | None = None) -> plt.Axes:
    """Drag area (ft^2) against time from the stage start: the Monte Carlo min-max and 5-95 %
    bands and median (grey), the flight curves (blue), the caps-box corner curves (red: solid
    outside the grown hull, dotted inside or without a hull, each tagged at its peak) and
    the Monte Carlo cases with the extreme peaks and rises (black dashed); all at the
    campaign's median conditions (paper Figs. 18, 27); into `ax` (else a new figure's);
    the axis."""
    c = env.conditions
    area = 1.0 / FT**2
    b = env.bands
    ax = ax if ax is not None else plt.subplots(figsize=(9, 5.5))[1]
    ax.fill_between(env.t, b["min"] * area, b["max"] * area, color="0.88",
                    label=f"Monte Carlo min-max ({env.cases:,} cases)")
    ax.fill_between(env.t, b["p05"] * area, b["p95"] * area, color="0.7", label="5-95 %")
    ax.plot(env.t, b["p50"] * area, color="0.4", lw=1.0, label="median")
    for k, curve in enumerate(env.flight):
        ax.plot(env.t, curve * area, "C0-", lw=0.9, alpha=0.8,
                label=f"flight tests ({len(env.flight)})" if k == 0 else None)
    shown = set()
    for curve, tag, inside in zip(env.corners, env.corner_labels, env.corner_inside,
                                  strict=True):
        kind = {None: "caps corner (no hull)", True: "caps corner inside the grown hull",
                False: "caps corner outside the grown hull"}[inside]
        ax.plot(env.t, curve * area, "C3" + ("-" if inside is False else ":"), lw=1.1,
                label=None if kind in shown else kind)
        shown.add(kind)
        k = int(np.argmax(curve))
        ax.annotate(tag, (env.t[k], curve[k] * area), fontsize=6, color="C3",
                    xytext=(2, 2), textcoords="offset points")
    for k, (name, curve) in enumerate(env.extremes.items()):
        ax.plot(env.t, curve * area, "k--", lw=0.8,
                label="Monte Carlo extremes (peak, rise)" if k == 0 else None)
        j = int(np.argmax(curve))
        ax.annotate(name, (env.t[j], curve[j] * area), fontsize=6, xytext=(2, -8),
                    textcoords="offset points")
    ax.set_xlabel("time from the stage start t_i (s)")
    ax.set_ylabel("drag area CdS (ft²)")
    ax.legend(fontsize=7, loc="lower right")
    ax.set_title(f"{c.inflation.replace('_', ' ')}, D_o {c.diameter / FT:.1f} ft, "
                 f"V_i {c.v_start / FT:.0f} ft/s, previous stage {c.cds_prev * area:.1f} ft² "
                 "(campaign medians)", fontsize=8)
    return ax


def plot_discovery(labels: Sequence[str], chi2_dof: Sequence[float],
                   worst_rms: Sequence[float], path: Path) -> Path:
    """The error's fall (`discovery_axes`) written to `path`."""
    return write_figure(discovery_axes(labels, chi2_dof, worst_rms).figure,
                        "discovery: each step's model", path)


def discovery_axes(labels: Sequence[str], chi2_dof: Sequence[float],
                   worst_rms: Sequence[float], ax: plt.Axes | None = None) -> plt.Axes:
    """The error falling step by step: chi-square per degree of freedom and the worst
    window's normalised RMS of each step's model (`labels`: what each step added), with
    the noise's value 1 marked; into `ax` (else a new figure's); the axis."""
    ax = ax if ax is not None else plt.subplots(figsize=(7.0, 4.0))[1]
    steps = np.arange(len(labels))
    ax.plot(steps, chi2_dof, "o-", label="χ²/dof")
    ax.plot(steps, worst_rms, "s--", label="worst window's normalised RMS")
    ax.axhline(1.0, color="0.5", lw=0.8, label="the noise")
    ax.set_xticks(steps, labels, rotation=20, ha="right")
    ax.set_xlabel("model after each step")
    ax.legend()
    return ax
