"""The output folders of `cpas-ocp diagnose`, `cpas-ocp compare` and `cpas-ocp discover`.

diagnose:  diagnosis.md (the text, the window table, the figures),
           diagnosis.json (everything, SI), windows.csv (residual statistics
           per sensor channel and phase window, SI), residuals_<sensor>.png,
           diagnosis.html (verdict, tables and zoomable plots in one page).
compare:   comparison.md, comparison.json, windows.csv (both models, per
           channel and window), residuals_<label>_<sensor>.png per model and
           compare_<sensor>.png (normalised residuals side by side),
           comparison.html (the test, tables and zoomable plots in one page).
Figures and tables are in the display units (`display_units`); JSON and CSV in SI.
discover:  discovery.md (the chain of models with each step's time, how it
           ended, the last model's parameters with sigma, per-channel normalised
           RMS after each step, the last diagnosis), discovery.html, discovery.json
           (strict JSON: null where a number is not defined), discovery.png,
           step_<k>.json (each step's model as a model file), and the last
           model's residuals_<sensor>.png (what remains, windows shaded).
"""

from __future__ import annotations

import dataclasses
import json
from collections.abc import Callable
from pathlib import Path
from typing import Any

import pandas as pd
import plotly.graph_objects as go

from cpas_ocp.discrepancy.diagnosis import Diagnosis
from cpas_ocp.discrepancy.discovery import Discovery
from cpas_ocp.estimation.kkt_system import NonFiniteCurvature
from cpas_ocp.estimation.uncertainty import Covariance
from cpas_ocp.inference.diagnostics import WindowStatistic, window_statistics
from cpas_ocp.inference.model_comparison import Comparison
from cpas_ocp.inference.phase_windows import PhaseWindow, phase_windows
from cpas_ocp.io.model_spec import model_block
from cpas_ocp.io.output_folder import atomic_folder
from cpas_ocp.io.strict_json import json_text
from cpas_ocp.physics.effects.registry import EffectType
from cpas_ocp.precision import Z95
from cpas_ocp.reports.discrepancy_text import comparison_text, diagnosis_text, discovery_text
from cpas_ocp.reports.display_units import DisplayUnits, display_units, pretty
from cpas_ocp.reports.html_page import Page, residual_comparison_figure, window_legend
from cpas_ocp.reports.html_page import parameter_table as parameter_html
from cpas_ocp.reports.plots import (
    file_stem,
    plot_discovery,
    plot_residual_comparison,
    plot_sensor_residuals,
)
from cpas_ocp.reports.report import (
    begin_page,
    parameter_section,
    parameter_table,
    sensor_figures,
    units_note,
)
from cpas_ocp.reports.report_data import channel_series, parameter_rows, sensor_spans


def write_diagnosis(diag: Diagnosis, cov: Covariance | None, out: str | Path,
                    units: DisplayUnits | None = None) -> Path:
    """Write the diagnosis folder atomically: all of it or nothing.  Figures and tables in
    `units` (default the test's own)."""
    out = Path(out)
    fit = diag.fit
    units = units or display_units(fit.test)
    with atomic_folder(out, "diagnosis.json") as tmp:
        table = _window_frame(diag.statistics)
        table.to_csv(tmp / "windows.csv", index=False)
        result: dict[str, Any] = {
            "test": fit.test.name,
            "model": [e.name for e in fit.model.effects],
            "chi_square": fit.chi_square, "samples": fit.n_samples,
            "parameters": {n: fit.parameters[n] for n in fit.free},
            "std": cov.std if cov is not None else {},
            "worst": diag.worst,
            "windows": [dataclasses.asdict(w) for w in diag.windows],
            "effects": [t.as_dict() for t in diag.effects],
            "explanation": diag.explanation.effect if diag.explanation else None,
            "residual_findings": [dataclasses.asdict(f) for f in diag.findings],
            "air_motion": None if diag.air is None else {
                "still_minus_2_log_evidence": diag.air.still,
                "common_residual_p": diag.air.common_p,
                "knot_s": diag.air.process.knot_s, "tau_s": diag.air.process.tau_s,
                "intensities": [dataclasses.asdict(p) for p in diag.air.points],
                "two_ln_bayes_factor": diag.air.two_ln_b, "named": diag.air.decisive},
            "verdict": diag.verdict(),
            "state": diag.state,
            "noise_test": diag.noise.as_dict(),
        }
        (tmp / "diagnosis.json").write_text(json_text(result))
        figures = plot_sensor_residuals(fit, diag.windows, tmp, units)
        shown = _display_frame(table, units)
        (tmp / "diagnosis.md").write_text(
            f"# Diagnosis of {fit.test.name}\n\n{fit.test.label}\n\n"
            f"```\n{parameter_table(fit, cov, units)}\n\n{diagnosis_text(diag)}\n```\n\n"
            "## Residuals per sensor channel and phase window\n\n"
            + _markdown(shown) + "\n\n"
            + "".join(f"![{p.stem}]({p.name})\n\n" for p in figures)
            + f"{units_note(units, display_units(fit.test))}  Interactive plots: "
            "diagnosis.html\n")
        page = begin_page(fit, f"Diagnosis of {fit.test.name}", units)
        page.heading("Verdict")
        page.preformatted(diag.verdict())
        parameter_section(page, fit, cov, units)
        page.heading("Diagnosis")
        page.preformatted(diagnosis_text(diag))
        page.heading("Residuals per sensor channel and phase window")
        _table(page, shown)
        page.heading("Sensors: model against measurement, by phase window")
        sensor_figures(page, fit, units, diag.windows)
        page.write(tmp / "diagnosis.html")
    return out


def write_comparison(comparison: Comparison, out: str | Path,
                     units: DisplayUnits | None = None) -> Path:
    """Write the comparison folder atomically.  Figures and tables in `units` (default the
    test's own)."""
    out = Path(out)
    fit_a, fit_b = comparison.fits
    units = units or display_units(fit_a.test)
    windows = phase_windows(fit_a)
    with atomic_folder(out, "comparison.json") as tmp:
        frames = []
        for label, fit in zip(comparison.labels, comparison.fits, strict=True):
            frame = _window_frame(window_statistics(fit, windows))
            frame.insert(0, "model", label)
            frames.append(frame)
        table = pd.concat(frames, ignore_index=True)
        table.to_csv(tmp / "windows.csv", index=False)
        wide = _before_after(table, comparison.labels)
        a, b = comparison.criteria
        result = {
            "test": fit_a.test.name,
            "models": {label: {"effects": [e.name for e in fit.model.effects],
                               "chi_square": c.chi_square, "k": c.k, "n": c.n, "aic": c.aic,
                               "bic": c.bic,
                               "parameters": {n: fit.parameters[n] for n in fit.free},
                               "std": cov.std, "undetermined": cov.undetermined,
                               "solver": dataclasses.asdict(fit.solver)}
                       for label, fit, cov, c in zip(comparison.labels, comparison.fits,
                                                     comparison.covariances, (a, b),
                                                     strict=True)},
            "nesting": comparison.note,
            "likelihood_ratio": None if comparison.lr is None else {
                **dataclasses.asdict(comparison.lr), "p_value": comparison.lr.p_value},
        }
        (tmp / "comparison.json").write_text(json_text(result))
        figures = []
        for label, fit in zip(comparison.labels, comparison.fits, strict=True):
            sub = tmp / file_stem(label)
            sub.mkdir()
            figures += plot_sensor_residuals(fit, windows, sub, units)
        side = plot_residual_comparison(fit_a, fit_b, comparison.labels, windows, tmp)
        title = f"{comparison.labels[0]} against {comparison.labels[1]} on {fit_a.test.name}"
        (tmp / "comparison.md").write_text(
            f"# {title}\n\n"
            f"```\n{comparison_text(comparison)}\n```\n\n"
            "## Normalised residual RMS per sensor channel and phase window\n\n"
            + _markdown(wide) + "\n\n"
            + "".join(f"![{p.stem}]({p.name})\n\n" for p in side)
            + "".join(f"![{p.parent.name} {p.stem}]({p.parent.name}/{p.name})\n\n"
                      for p in figures)
            + "Interactive plots: comparison.html\n")
        comparison_page(comparison, title, wide, windows, units).write(
            tmp / "comparison.html")
    return out


def comparison_page(comparison: Comparison, title: str, wide: pd.DataFrame,
                    windows: list[PhaseWindow], units: DisplayUnits) -> Page:
    """The comparison as one HTML page: the likelihood-ratio test and the criteria, each
    model's parameters, the normalised RMS per channel and window, and per sensor both
    models' normalised residuals on one time axis."""
    fit_a, fit_b = comparison.fits
    labels = comparison.labels
    page = begin_page(fit_a, title, units)
    page.heading("Likelihood-ratio test")
    page.paragraph(comparison.note)
    page.paragraph("no likelihood-ratio test: the models are not nested"
                   if comparison.lr is None else str(comparison.lr))
    page.preformatted(comparison_text(comparison))
    for label, fit, cov in zip(labels, comparison.fits, comparison.covariances, strict=True):
        page.heading(f"Parameters: {label}")
        parameter_html(page, parameter_rows(fit, cov, units))
    page.heading("Normalised residual RMS per sensor channel and phase window")
    _table(page, wide)
    page.heading(f"Normalised residuals: {labels[0]} and {labels[1]}")
    in_b = {(c.sensor, c.channel): c for c in channel_series(fit_b, units)}
    series_a = channel_series(fit_a, units)
    if windows:
        window_legend(page)
    for sensor, spans in sensor_spans(fit_a, windows).items():
        # Channels are paired by name: a model may add pseudo-observations the other lacks.
        pairs = [(c, in_b[c.sensor, c.channel]) for c in series_a
                 if c.sensor == sensor and (c.sensor, c.channel) in in_b]
        if pairs:
            residual_comparison_figure(page, sensor, labels, pairs, spans)
    return page


def _window_frame(stats: list[WindowStatistic]) -> pd.DataFrame:
    return pd.DataFrame([{**dataclasses.asdict(s), "excess": s.excess} for s in stats])


def _display_frame(table: pd.DataFrame, units: DisplayUnits) -> pd.DataFrame:
    """The window table as read: each RMS in its channel's display unit, named beside it."""
    if table.empty:
        return table
    shown = table.copy()
    unit_factor = [units.channel(c) for c in shown["channel"]]
    shown["rms"] = shown["rms"] * [k for _, k in unit_factor]
    shown.insert(shown.columns.get_loc("rms") + 1, "unit", [pretty(u) for u, _ in unit_factor])
    return shown


def _table(page: Page, frame: pd.DataFrame) -> None:
    """A data frame as a table of the page."""
    page.table([str(c) for c in frame.columns], [list(row) for row in frame.itertuples(False)])


def _before_after(table: pd.DataFrame, labels: tuple[str, str]) -> pd.DataFrame:
    """Normalised RMS per channel and window, one column per model."""
    wide = table.pivot_table(index=["sensor", "channel", "window"], columns="model",
                             values="normalised_rms", sort=False).reset_index()
    return wide[["sensor", "channel", "window", *labels]]


def _markdown(frame: pd.DataFrame) -> str:
    """A Markdown table of `frame`, numbers to 4 significant digits."""
    def cell(v: Any) -> str:
        return f"{v:.4g}" if isinstance(v, float) else str(v)
    head = "| " + " | ".join(map(str, frame.columns)) + " |"
    rule = "|" + "---|" * len(frame.columns)
    rows = ["| " + " | ".join(cell(v) for v in row) + " |" for row in frame.itertuples(False)]
    return "\n".join([head, rule, *rows])



def write_discovery(discovery: Discovery, out: str | Path,
                    plugins: dict[str, EffectType] | None = None,
                    units: DisplayUnits | None = None, figures: bool = True,
                    extra: Callable[[Path], None] | None = None) -> Path:
    """Write the discovery folder atomically: discovery.md (the chain with each step's
    time, how it ended, the last model's parameters with sigma, each step's
    normalised RMS per channel, the figure, the last diagnosis with the last model's
    residual figures), discovery.html (the same, interactive), discovery.json (strict
    JSON), and each step's model as a model file (`step_K.json`, reusable with
    `reconstruct --model`).  Without `figures` (a chain cut short by a signal, written
    in the second or two a signal allows), no figures, no HTML page and no sigma: the
    chain, its JSON and its model files.  `extra` writes more files into the folder
    before it takes its place (`discovery_checkpoint.write_checkpoint`)."""
    out = Path(out)
    steps = discovery.steps
    final = steps[-1].fit
    cov = final_covariance(discovery) if figures else None
    units = units or display_units(final.test)
    with atomic_folder(out, "discovery.json") as tmp:
        labels = [s.label for s in steps]
        registry = {**(plugins or {}), **discovery.plugins}
        for k, s in enumerate(steps):
            block = model_block(s.spec, registry)
            # A proposed plug-in the step's model uses is named by its file, beside it.
            files = [f"proposed/{t.proposal.file_name}" for t in discovery.proposals
                     if t.proposal.name in s.spec.effect_names]
            if files:
                block["plugins"] = files
            (tmp / f"step_{k}.json").write_text(json.dumps(block, indent=2) + "\n")
        if discovery.proposals:
            (tmp / "proposed").mkdir()
        for trial in discovery.proposals:
            (tmp / "proposed" / trial.proposal.file_name).write_text(trial.proposal.source)
        worst = [s.worst_window for s in steps]
        if figures:
            plot_discovery(labels, [s.fit.chi_square / s.fit.dof for s in steps],
                           [w[1] if w else float("nan") for w in worst],
                           tmp / "discovery.png")
        rms = pd.DataFrame([s.channel_rms for s in steps], index=labels).T
        rms.columns = [f"{k}: {label}" for k, label in enumerate(labels)]
        result = {
            "test": steps[0].fit.test.name,
            "steps": [{"added": s.added, "dropped": s.dropped, "refined": s.refined,
                       "refinement": s.refinement or None, "admitted_by": s.admitted_by,
                       "model_file": f"step_{k}.json", "chi_square": s.fit.chi_square,
                       "dof": s.fit.dof, "aic": s.criteria.aic, "bic": s.criteria.bic,
                       "channel_normalised_rms": s.channel_rms,
                       "excess_chi_square_removed": s.explained,
                       "window_excess_removed": [
                           {"sensor": w.sensor, "channel": w.channel, "window": w.window,
                            "excess_before": w.excess, "share": share}
                           for w, _, share in s.windows_explained],
                       "stand_in": s.stand_in,
                       "start": s.start or None,
                       "seconds_to_find": s.found_s, "seconds_to_diagnose": s.diagnosed_s,
                       "worst_window": None if w is None else {"where": w[0],
                                                               "normalised_rms": w[1]},
                       "verdict": s.verdict}
                      for k, (s, w) in enumerate(zip(steps, worst, strict=True))],
            "proposals": [{"step": t.step, "effect": t.proposal.name,
                           "file": f"proposed/{t.proposal.file_name}",
                           "reason": t.proposal.reason, "confirmed": t.confirmed,
                           "plugins_tried": t.tried,
                           "test": {**t.test.as_dict(),
                                    "source": f"proposed/{t.proposal.file_name}"},
                           "chi_square": None if t.test.refitted is None
                           else t.test.refitted[1].chi_square}
                          for t in discovery.proposals],
            "refinements": [t.as_dict() for t in discovery.refinements],
            "regressions": [t.as_dict() for t in discovery.regressions],
            "stopped": discovery.stopped,
            "ending": {"state": discovery.state, "text": discovery.ending(),
                       "noise_test": discovery.noise.as_dict()},
            "seconds": discovery.seconds,
            "final_parameters": {n: {"value": final.parameters[n],
                                     "std": (cov.std.get(n) if cov is not None else None)}
                                 for n in final.free},
            "notes": discovery.notes,
        }
        (tmp / "discovery.json").write_text(json_text(result))
        last = steps[-1].diagnosis
        drawn = [] if last is None or not figures else \
            plot_sensor_residuals(last.fit, last.windows, tmp)
        final_table = parameter_table(final, cov, units)
        (tmp / "discovery.md").write_text(
            f"# Discovery on {steps[0].fit.test.name}\n\n```\n{discovery_text(discovery)}\n```\n\n"
            + ("![the error falling step by step](discovery.png)\n\n" if figures else "")
            + f"## The last model's parameters\n\n```\n{final_table}\n```\n\n"
            "## Normalised RMS per sensor channel after each step\n\n"
            + _markdown(rms.reset_index(names="channel")) + "\n\n"
            + "Each step's model is `step_K.json` here (a model file: `cpas-ocp reconstruct "
            "TEST --model step_K.json`, with `--plugin FILE` for a plug-in it names).\n"
            + ("Plug-ins written from the residual's signature are in `proposed/`, each "
               "tested as written: read them, edit them, pass them to `--plugin`.\n"
               if discovery.proposals else "")
            + ("" if last is None else
               f"\n## The last diagnosis\n\n```\n{diagnosis_text(last)}\n```\n\n")
            + "".join(f"![{p.stem}]({p.name})\n\n" for p in drawn))
        if extra is not None:
            extra(tmp)
        if not figures:
            return out
        page = begin_page(final, f"Discovery on {final.test.name}", units)
        chain_section(page, discovery)
        parameter_section(page, final, cov, units)
        if last is not None:
            page.heading("Sensors: the last model against measurement, by phase window")
            sensor_figures(page, last.fit, units, last.windows)
        page.write(tmp / "discovery.html")
    return out


CHAIN_HEADER = ("step", "change", "chi-square", "dof", "chi²/dof", "share of the excess removed",
                "time (s)", "worst window (normalised RMS)", "admitted by")


def chain_rows(discovery: Discovery) -> list[list[object]]:
    """One row per step (`CHAIN_HEADER`): what it changed, chi-square and its dof, and the
    share of the first fit's excess over the noise (chi-square - dof) the step removed
    (a share, not a test: the step's own test is in "admitted by"); None where the first
    fit had no excess."""
    first = discovery.steps[0]
    excess = first.criteria.chi_square - first.fit.dof
    rows, before = [], None
    for k, s in enumerate(discovery.steps):
        chi2 = s.criteria.chi_square
        share = (None if before is None or excess <= 0.0
                 else f"{100.0 * (before - chi2) / excess:+.1f} %")
        worst = s.worst_window
        rows.append([k, s.label, round(chi2, 1), s.fit.dof, round(chi2 / s.fit.dof, 3),
                     share or "", round(s.found_s + s.diagnosed_s),
                     f"{worst[0]} ({worst[1]:.2f})" if worst else "not diagnosed",
                     s.admitted_by])
        before = chi2
    return rows


def chain_figure(discovery: Discovery) -> go.Figure:
    """chi-square/dof after each step against the band the noise allows about 1 (1 +- 1.96
    sqrt(2/dof), the chi-square's 95 % range over dof): the loop's aim drawn."""
    steps = discovery.steps
    x = [f"{k}: {s.label}" for k, s in enumerate(steps)]
    ratio = [s.criteria.chi_square / s.fit.dof for s in steps]
    half = [Z95 * (2.0 / s.fit.dof) ** 0.5 for s in steps]
    fig = go.Figure([
        go.Scatter(x=x, y=[1.0 + h for h in half], mode="lines", line={"width": 0},
                   showlegend=False, hoverinfo="skip"),
        go.Scatter(x=x, y=[1.0 - h for h in half], mode="lines", line={"width": 0},
                   fill="tonexty", fillcolor="rgba(120, 170, 120, 0.35)",
                   name="the noise's 95 % range"),
        go.Scatter(x=x, y=ratio, mode="lines+markers", name="χ²/dof after the step",
                   marker={"size": 9}),
    ])
    fig.update_layout(title="χ²/dof step by step, against the noise",
                      yaxis={"title": "χ²/dof", "type": "log" if max(ratio) > 20 else "linear"},
                      height=380)
    return fig


def chain_section(page: Page, discovery: Discovery) -> None:
    """The page's opening: how the chain ended, the error falling step by step towards the
    noise (`chain_figure`), the steps as a table, then what each step explained and what
    else was tried."""
    page.heading("The error, step by step")
    page.paragraph(discovery.ending())
    page.figure(chain_figure(discovery), rows=1, time_axis=False)
    page.table(list(CHAIN_HEADER), chain_rows(discovery))
    for line in [line for s in discovery.steps[1:] for line in s.explained_lines()]:
        page.paragraph(line)
    for title, items in (("Plug-ins proposed from the residual's signature, tested as "
                          "written", discovery.proposals),
                         ("Refinements of the effects added, tested against the effect as "
                          "it was", discovery.refinements),
                         ("Drag laws by sparse regression", discovery.regressions)):
        if items:
            page.heading(title)
            for item in items:
                page.paragraph(str(item))
    for note in discovery.notes:
        page.paragraph(note, "note")
    last = discovery.steps[-1].diagnosis
    if last is not None:
        page.paragraph("Last diagnosis: " + last.verdict())


def final_covariance(discovery: Discovery) -> Covariance | None:
    """The covariance of the chain's last fit, where its estimator was kept and its
    curvature is finite (None otherwise: the parameters are then shown without sigma)."""
    last = discovery.steps[-1]
    if last.estimator is None:
        return None
    try:
        return last.estimator.covariance(last.fit)
    except NonFiniteCurvature:
        return None
