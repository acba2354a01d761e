"""The report folder of a reconstruction: result.json, parameters.csv, figures, and the table."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
import pandas as pd

from cpas_ocp.estimation.estimator import EVENTS, PRIORS, Fit
from cpas_ocp.estimation.uncertainty import POORLY_DETERMINED, Covariance
from cpas_ocp.inference.diagnostics import sensor_summary, worst_windows
from cpas_ocp.inference.model_comparison import Criteria
from cpas_ocp.inference.phase_windows import PhaseWindow, phase_windows
from cpas_ocp.inference.profile_likelihood import Profile
from cpas_ocp.io.import_reports import import_nominal, nominal_area
from cpas_ocp.io.output_folder import atomic_folder
from cpas_ocp.io.strict_json import json_text
from cpas_ocp.physics.parameters import split_name
from cpas_ocp.physics.units import SI_UNIT
from cpas_ocp.reports.display_units import (
    CHANNEL_DIMENSION,
    DisplayUnits,
    display_units,
    pretty,
)
from cpas_ocp.reports.failure_report import RESULT_MARKERS
from cpas_ocp.reports.fit_text import claim_text
from cpas_ocp.reports.flight_report import (
    DESCENT_RATE_HEADER,
    NOMINAL_HEADER,
    STEADY_HEADER,
    descent_rate_rows,
    descent_rate_text,
    descent_rates,
    nominal_section,
    nominal_text,
    steady_descent_text,
    steady_drag_area_section,
    steady_drag_area_text,
)
from cpas_ocp.reports.html_page import (
    Page,
    drag_area_figure,
    sensor_figure,
    wind_figure,
    window_legend,
)
from cpas_ocp.reports.html_page import parameter_table as parameter_html
from cpas_ocp.reports.plots import (
    DragAreaCurves,
    drag_area_curves,
    plot_correlation,
    plot_drag_areas,
    plot_events,
    plot_profile,
    plot_sensors,
    plot_wind,
    wind_curves,
)
from cpas_ocp.reports.report_data import (
    Z95,
    bound_flag,
    channel_series,
    event_rows,
    parameter_rows,
    sensor_spans,
    undetermined_window,
)

if TYPE_CHECKING:
    from cpas_ocp.inference.result_claim import Claim

STRONG_CORRELATION = 0.9  # |rho| from which a parameter pair is named in the terminal
REPORTED_CORRELATION = 0.5  # |rho| from which report.md lists a pair (the map shows all)


def information_criteria(fit: Fit) -> dict[str, float]:
    """AIC and BIC of a fit with known sensor sigmas (`model_comparison.Criteria`): only
    differences between fits of the same data mean anything."""
    c = Criteria.of(fit)
    return {"aic": c.aic, "bic": c.bic}


def strong_correlations(cov: Covariance,
                        threshold: float = STRONG_CORRELATION) -> list[tuple[str, str, float]]:
    """Parameter pairs whose correlation is at least `threshold` in size, strongest first."""
    rho = cov.correlation()
    i, j = np.triu_indices(len(cov.names), k=1)
    keep = np.abs(rho[i, j]) >= threshold
    pairs = [(cov.names[a], cov.names[b], float(rho[a, b])) for a, b in zip(i[keep], j[keep],
                                                                             strict=True)]
    return sorted(pairs, key=lambda p: -abs(p[2]))


# SI unit of each sensor channel: that of its dimension (one table of channels, in
# display_units).
SENSOR_UNITS = {channel: SI_UNIT[dim] for channel, dim in CHANNEL_DIMENSION.items()}


def channel_unit(fit: Fit, sensor: str, channel: str) -> str:
    """SI unit of a residual channel (event times are in s, a prior in its parameter's unit)."""
    if sensor == PRIORS:
        return fit.model.parameter(channel).unit
    if any(sensor == effect for effect, *_ in fit.model.penalties):
        return "σ"  # a process prior's innovations, in units of their own sigma
    return "s" if sensor == EVENTS else SENSOR_UNITS.get(channel, "SI")


def display_channel(fit: Fit, units: DisplayUnits, sensor: str, channel: str
                    ) -> tuple[str, float]:
    """A residual channel's display unit and its factor from SI."""
    if sensor in fit.pseudo_sensors:
        return channel_unit(fit, sensor, channel), 1.0
    return units.channel(channel)


def result_dict(fit: Fit, cov: Covariance | None,
                profiles: Sequence[Profile] = ()) -> dict[str, Any]:
    """Everything a reader of result.json needs; SI units, stated per value."""
    std = cov.std if cov is not None else {}
    params = {}
    for name in fit.free:
        prm = fit.model.parameter(name)
        entry = {"value": fit.parameters[name], "unit": prm.unit,
                 "initial": fit.guess.get(name, prm.default)}
        flag = bound_flag(fit, cov, name)
        entry["bound"] = flag or None
        if flag:
            entry["bounds"] = [prm.lower, prm.upper]
        if cov is not None and name in cov.at_bound:
            entry["at_bound"] = prm.nearer_bound(fit.parameters[name])
        elif cov is not None and name in cov.undetermined:
            entry["undetermined"] = True
        elif name in std:
            entry["std"] = std[name]
            entry["ci95"] = [fit.parameters[name] - Z95 * std[name],
                             fit.parameters[name] + Z95 * std[name]]
            # Its sigma wider than its bounds: the interval is no interval (`ParameterRow`).
            entry["undetermined_within_bounds"] = undetermined_window(fit, cov, name) \
                is not None
            if entry["undetermined_within_bounds"]:
                entry["bounds"] = [prm.lower, prm.upper]
        params[name] = entry
    fixed = {n: {"value": v, "unit": fit.model.parameter(n).unit}
             for n, v in fit.parameters.items() if n not in fit.free}
    summary = sensor_summary(fit)
    residuals = {s: {"rms": e["rms"], "unit": {c: channel_unit(fit, s, c) for c in e["rms"]},
                     "normalised_rms": e["normalised_rms"], "samples": e["samples"]}
                 for s, e in summary.items()}
    n = fit.n_samples
    worst = [{"sensor": w.sensor, "channel": w.channel, "window_s": [w.t0, w.t1],
              "normalised_rms": w.normalised_rms} for w in worst_windows(fit)]
    return {
        "test": fit.test.name,
        "label": fit.test.label,
        "parameters": params,
        "fixed": fixed,
        "captures": fit.captures,
        "solver": {"status": fit.solver.status, "success": fit.solver.success,
                   "iterations": fit.solver.iterations, "wall_s": fit.solver.wall_s,
                   "chi2_decrement": fit.solver.chi2_decrement, "start": fit.solver.start},
        "residuals": residuals,
        "fit": {"chi_square": fit.chi_square, "samples": n, "free_parameters": len(fit.free),
                "chi_square_per_dof": fit.chi_square / fit.dof, **information_criteria(fit),
                "covariance": cov.describe() if cov else "none"},
        "worst_windows": worst,
        "strong_correlations": [] if cov is None else [
            {"a": a, "b": b, "rho": r} for a, b, r in strong_correlations(cov)],
        "correlation": None if cov is None else {
            "names": cov.names, "matrix": np.round(cov.correlation(), 6).tolist()},
        "identifiability": [] if cov is None else [
            {"weights": w.weights, "other": w.other, "std": w.std,
             "curvature_ratio": w.curvature_ratio, "text": str(w)} for w in cov.weak],
        "profiles": {p.name: p.as_dict() for p in profiles},
        "model": {"effects": [e.name for e in fit.model.effects],
                  "grid": {"nodes": len(fit.t), "finest_step_s": float(np.min(np.diff(fit.t))),
                           "longest_step_s": float(np.max(np.diff(fit.t)))},
                  "fill_length": {c.name: c.fill_length for c in fit.test.parachutes}},
    }


def parameter_table(fit: Fit, cov: Covariance | None, units: DisplayUnits | None = None) -> str:
    """A readable terminal table of the estimated parameters in `units` (default the
    test's own): value, 1 sigma, 95 % interval, correlations and the combinations the data
    do not determine."""
    units = units or display_units(fit.test)
    rows = parameter_rows(fit, cov, units)
    width = max([25, *(len(row.interval) for row in rows)])
    lines = [f"{'parameter':30s} {'value':>11s} {'± 1σ':>10s} {'95 % interval':>{width}s}  "
             f"{'unit':6s} {'initial':>10s}"]
    for row in rows:
        lines.append(f"{row.name:30s} {row.value_text:>11s} {row.std_text:>10s} "
                     f"{row.interval:>{width}s}  "
                     f"{row.unit:6s} {row.initial:10.4g}" + (f"  {row.flag}" if row.flag else ""))
    if cov is not None:
        lines.append(correlation_line(cov))
        lines.append(identifiability_text(cov))
    return "\n".join(lines)


def correlation_line(cov: Covariance) -> str:
    """How many parameter pairs are strongly correlated, and the three strongest."""
    pairs = strong_correlations(cov)
    return (f"correlations |ρ| ≥ {STRONG_CORRELATION}: "
            + ("none" if not pairs else f"{len(pairs)}, strongest "
               + "; ".join(f"{a} ~ {b} {r:+.3f}" for a, b, r in pairs[:3])))


def identifiability_text(cov: Covariance) -> str:
    """One line when the data determine every parameter combination off the bounds; else
    one per weak combination, and one naming the parameters the fit left on a bound."""
    interior = len(cov.names) - len(cov.at_bound)
    if not cov.weak:
        lines = [f"identifiability: every combination of the {interior} parameters off their "
                 f"bounds is determined (none worse than ±{POORLY_DETERMINED:g} parameter "
                 "scales)"]
    else:
        lines = [f"identifiability: {len(cov.weak)} combination"
                 f"{'s' if len(cov.weak) > 1 else ''} the data do not fix:"]
        lines += [f"  {w}" for w in cov.weak]
    if cov.at_bound:
        lines.append(f"  on a bound, so not determined by the data and given no σ "
                     f"({len(cov.at_bound)}): {', '.join(cov.at_bound)}; the optimum lies "
                     "at or beyond the bound: widen it if it is not a physical limit, or "
                     "profile the parameter")
    return "\n".join(lines)


def fit_parts(fit: Fit, units: DisplayUnits) -> tuple[str, list[tuple[str, float, str]], str]:
    """The fit's outcome in three parts: the solver's line (status, iterations, time,
    chi-square/dof, AIC, BIC), per sensor (name, normalised RMS, RMS per channel in
    `units`), and where the model fits worst ('' where nowhere is named)."""
    ic = information_criteria(fit)
    solver = (f"solver: {fit.solver.status}, {fit.solver.iterations} iterations, "
              f"{fit.solver.wall_s:.1f} s, from {fit.solver.start};  "
              f"chi²/dof = {fit.chi_square:.1f}/{fit.dof} = {fit.chi_square / fit.dof:.3f};  "
              f"AIC {ic['aic']:.1f}, BIC {ic['bic']:.1f}")
    sensors = [(s, e["normalised_rms"],
                ", ".join(f"{c} {v * k:.4g} {unit}" for c, v in e["rms"].items()
                          for unit, k in [display_channel(fit, units, s, c)]))
               for s, e in sensor_summary(fit).items()]
    worst = worst_windows(fit, top=1)
    where = "" if not worst else (
        f"worst fit: {worst[0].sensor}.{worst[0].channel} in {worst[0].t0:.2f}-"
        f"{worst[0].t1:.2f} s, normalised RMS {worst[0].normalised_rms:.2f}")
    return solver, sensors, where


def fit_summary(fit: Fit, units: DisplayUnits | None = None) -> str:
    """Solver outcome, residuals per sensor (RMS in `units`, default the test's own) and
    where the model fits worst."""
    solver, sensors, where = fit_parts(fit, units or display_units(fit.test))
    out = [solver] + [f"  {s:16s} normalised RMS {n:.3f}   (RMS {rms})" for s, n, rms in sensors]
    return "\n".join(out + ([where] if where else []))


def fit_section(page: Page, fit: Fit, units: DisplayUnits) -> None:
    """The fit's outcome on a page (`fit_parts`): the solver's line, a table of the sensors'
    residuals, and where the model fits worst."""
    solver, sensors, where = fit_parts(fit, units)
    page.heading("Fit")
    page.paragraph(solver)
    page.table(["sensor", "normalised RMS", "RMS per channel"],
               [[s, round(n, 3), rms] for s, n, rms in sensors])
    if where:
        page.paragraph(where)


def correlation_markdown(cov: Covariance, threshold: float = REPORTED_CORRELATION) -> str:
    """The covariance's provenance and the correlated pairs, as report.md lists them."""
    pairs = strong_correlations(cov, threshold)
    rows = "".join(f"| {a} | {b} | {r:+.3f} |\n" for a, b, r in pairs)
    return (f"Uncertainties: {cov.describe()}.\n\n"
            f"Correlations with |ρ| ≥ {threshold} ({len(pairs)}; correlation.png shows all):\n\n"
            + (f"| parameter | parameter | ρ |\n|---|---|---|\n{rows}\n" if pairs else "none\n\n"))


def units_note(units: DisplayUnits, test_units: DisplayUnits) -> str:
    """Which units a report's figures and tables are in, and why (result.json is SI)."""
    name = {"us": "US customary", "si": "SI"}
    why = ("as the manifest is written" if units == test_units else
           f"as asked (the manifest is written in {name[test_units.system]})")
    return (f"Figures and tables in {name[units.system]} units, {why}; result.json is in "
            "SI.")


def begin_page(fit: Fit, title: str, units: DisplayUnits) -> Page:
    """An HTML page begun with the test's label and the units it is drawn in."""
    page = Page(title)
    page.paragraph(fit.test.label)
    page.paragraph(units_note(units, display_units(fit.test)), "note")
    return page


def parameter_section(page: Page, fit: Fit, cov: Covariance | None,
                      units: DisplayUnits, knots: bool = True) -> None:
    """The parameter table (flagged rows highlighted; a process's knots left out without
    `knots`, drawn as a curve instead), then the strong correlations and the combinations
    the data do not determine."""
    page.heading("Parameters")
    rows = parameter_rows(fit, cov, units)
    if not knots:
        rows = [r for r in rows if not fit.model.parameter(r.name).process_knot]
    parameter_html(page, rows)
    if cov is not None:
        page.preformatted(f"{correlation_line(cov)}\n{identifiability_text(cov)}")


def sensor_figures(page: Page, fit: Fit, units: DisplayUnits,
                   windows: Sequence[PhaseWindow]) -> None:
    """One interactive figure per sensor: model over measurement, normalised residuals
    with their bands, the phase windows shaded."""
    series = channel_series(fit, units)
    spans = sensor_spans(fit, windows)
    if windows:
        window_legend(page)
    for sensor, shown in spans.items():
        sensor_figure(page, sensor, [c for c in series if c.sensor == sensor], shown)


def answer_section(page: Page, fit: Fit, cov: Covariance | None, claim: Claim | None,
                   units: DisplayUnits, nominal: dict[str, dict[str, Any]]) -> None:
    """What a reader came for, first: whether the fit is a result (and why not), and each
    canopy stage's drag area with its sigma and 95 % interval, beside the card's nominal
    value where an import kept one."""
    if claim is not None and claim.headline():
        page.warning(claim.headline())
    page.heading("The answer")
    if claim is not None:
        page.paragraph(f"Claim: {claim.verdict()}.")
    areas = [r for r in parameter_rows(fit, cov, units) if split_name(r.name)[0] == "CdS"]
    if areas:
        k = units.factor("area")
        shown = [_nominal_area(nominal.get(r.name), k) for r in areas]
        page.table(["drag area", "value", "± 1σ", "95 % interval", "unit", "nominal"],
                   [[r.name, r.value_text, r.std_text, r.interval, pretty(r.unit), n]
                    for r, n in zip(areas, shown, strict=True)],
                   flagged=[bool(r.flag) for r in areas])
    if claim is not None:
        for line in [*claim.problems(), *(f"moved {m}" for m in claim.moves), *claim.notes]:
            page.paragraph(line)


def _nominal_area(spec: dict[str, Any] | None, k: float) -> str:
    """A card's nominal drag area (`import_nominal`'s entry) in the display unit ('' where
    none): design figures carry no sigma, so three significant digits."""
    if spec is None:
        return ""
    return f"{nominal_area(spec) * k:.3g}"


def reconstruction_page(fit: Fit, cov: Covariance | None, claim: Claim | None,
                        units: DisplayUnits,
                        curves: Sequence[DragAreaCurves] | None = None,
                        nominal: dict[str, dict[str, Any]] | None = None) -> Page:
    """The reconstruction as one HTML page: the claim, the parameters, the fit, each
    sensor's model against its measurement, and the canopies' drag areas (`curves`,
    `drag_area_curves` of the fit where not given); with a flight card's `nominal` drag
    areas (an imported log), the steady descent rates and the nominal comparison."""
    page = begin_page(fit, f"Reconstruction of {fit.test.name}", units)
    answer_section(page, fit, cov, claim, units, nominal or {})
    parameter_section(page, fit, cov, units, knots=False)
    wind = wind_figure(wind_curves(fit, cov, units), pretty(units.unit("velocity")))
    if wind is not None:
        page.heading("The air's motion")
        page.paragraph("The wind process's estimate at its knots, with its 95 % band; the "
                       "knots' values are in result.json and parameters.csv.", "note")
        page.figure(wind, rows=1)
    fit_section(page, fit, units)
    events = event_rows(fit)
    if events:
        page.heading("Events: observed against the model")
        page.table(["event", "observed [s]", "model [s]", "σ [s]", "(observed - model)/σ"],
                   [[e.event, e.observed, e.model, e.sigma, e.z] for e in events],
                   flagged=[abs(e.z) > 3.0 for e in events])
    page.heading("Sensors: model against measurement")
    sensor_figures(page, fit, units, phase_windows(fit))
    page.heading("Canopy drag areas")
    drag_area_figure(page, drag_area_curves(fit) if curves is None else curves,
                     units.factor("area"), units.unit("area"))
    if cov is not None and nominal:
        rates = descent_rates(fit, cov)
        page.heading("Steady descent rates")
        page.table(DESCENT_RATE_HEADER, descent_rate_rows(rates),
                   flagged=[abs(r.z) > 3.0 for r in rates])
        for title, header, section in (
                ("Drag areas from the steady descent", STEADY_HEADER,
                 steady_drag_area_section(fit, cov, rates)),
                ("Drag areas against the card's nominal values", NOMINAL_HEADER,
                 nominal_section(fit, cov, nominal, rates))):
            page.heading(title)
            page.table(header, section.rows, flagged=section.flagged)
            page.paragraph(section.note, "note")
            for sentence in section.sentences:
                page.paragraph(sentence)
    return page


def flight_markdown(fit: Fit, cov: Covariance, nominal: dict[str, dict[str, Any]]) -> str:
    """report.md's sections for an imported log with nominal drag areas: the steady descent
    rates and the drag areas against the card's nominal values."""
    rates = descent_rates(fit, cov)
    return (f"{descent_rate_text(rates)}\n\n{steady_drag_area_text(fit, cov, rates)}\n\n"
            f"{nominal_text(fit, cov, nominal, rates)}\n\n")


def write_report(fit: Fit, cov: Covariance | None, out: str | Path,
                 profiles: Sequence[Profile] = (), claim: Claim | None = None,
                 units: DisplayUnits | None = None) -> Path:
    """Write the report folder atomically: all of it or nothing.  With `claim`, result.json
    and report.md say what the fit may claim, a fit that is not a result first of all.
    Figures and tables are in `units` (default the test's own; result.json is SI);
    report.html holds them as one interactive page."""
    out = Path(out)
    units = units or display_units(fit.test)
    with atomic_folder(out, RESULT_MARKERS) as tmp:
        nominal = import_nominal(fit.test.path)
        result = result_dict(fit, cov, profiles)
        if claim is not None:
            result["claim"] = claim.as_dict()
        (tmp / "result.json").write_text(json_text(result))
        std = cov.std if cov is not None else {}
        rows = [{"parameter": n, "value": fit.parameters[n], "std": std.get(n, np.nan),
                 "unit": fit.model.parameter(n).unit, "bound": bound_flag(fit, cov, n)}
                for n in fit.free]
        pd.DataFrame(rows).to_csv(tmp / "parameters.csv", index=False)
        plot_sensors(fit, tmp, units)
        # The drag areas against their reduction (which re-reduces the test), drawn in
        # the figure and the page from one computation.
        curves = drag_area_curves(fit)
        plot_drag_areas(fit, tmp, units, curves)
        plot_events(fit, tmp)
        plot_wind(fit, cov, tmp, units)
        if cov is not None:
            plot_correlation(cov, fit.test.name, tmp)
        for prof in profiles:
            plot_profile(prof, fit.test.name, tmp)
        headline = claim.headline() if claim is not None else ""
        warning = f"**{headline.replace('. ', '.** ', 1)}\n\n" if headline else ""
        (tmp / "report.md").write_text(
            f"# Reconstruction of {fit.test.name}\n\n{fit.test.label}\n\n{warning}```\n"
            f"{parameter_table(fit, cov, units)}\n\n{fit_summary(fit, units)}\n"
            + (f"{claim_text(claim)}\n" if claim is not None else "") + "```\n\n"
            + (correlation_markdown(cov) if cov is not None else "")
            + (steady_descent_text(fit, cov, units) + "\n" if cov is not None
               and any(c.open_at_start for c in fit.test.parachutes) else "")
            + (flight_markdown(fit, cov, nominal) if cov is not None and nominal else "")
            + "".join(f"Profile likelihood, {p}\n\n" for p in profiles)
            + "".join(f"![{p.stem}]({p.name})\n\n" for p in sorted(tmp.glob("*.png")))
            + f"{units_note(units, display_units(fit.test))}  Interactive plots: report.html\n")
        reconstruction_page(fit, cov, claim, units, curves, nominal).write(tmp / "report.html")
    return out
