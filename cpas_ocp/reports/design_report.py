"""What `cpas-ocp design` prints and writes: each candidate instrumentation's predicted
sigma, the single changes ranked, the failure table, the A-/D-optimal summaries, and the
notes where the linearisation is known to be optimistic.

Written to the output folder all at once: design.json, sigma.csv (parameter x
candidate, SI; empty where a parameter is not determined), changes.csv,
failures.csv, population_sigma.csv where the plan names a population's cases, and
design.html, one self-contained page in the report style.
"""

from __future__ import annotations

import math
from pathlib import Path

import pandas as pd
import plotly.graph_objects as go

from cpas_ocp.inference.flight_test_design import Prediction, RankedChange, TestDesign
from cpas_ocp.io.output_folder import atomic_folder
from cpas_ocp.io.strict_json import json_text
from cpas_ocp.reports.html_page import Page

MARKER = "design.json"
WEAK_SHOWN = 8  # weak combinations printed per candidate on screen (all in the files)
METHOD = ("sigma predicted from the Fisher information of the planned test at its nominal "
          "parameters: the Gauss-Newton KKT covariance the reconstruction reports, built on "
          "noise-free simulated data; A = trace and D = log det of the covariance in units "
          "of the parameters' typical magnitudes (lower is better)")
EVENTS_NOTE = ("Deployment and disreef event times (mortar fire, line stretch, bag strip, "
               "disreef) only centre the windows of the start times; their sigma does not "
               "enter the estimate.  A timed full open (each canopy's peak) does.")


def sigma_cell(p: Prediction, name: str) -> str:
    """A parameter's predicted sigma as text: the number, or why there is none."""
    s = p.sigma(name)
    status = p.status(name)
    if s is None:
        return status
    return f"{s:.4g}" + (" (weak)" if status == "poorly determined" else "")


def _summary(p: Prediction, names: list[str] | None = None) -> tuple[str, str]:
    a, d = p.optimality(names)
    return ("undetermined" if a is None else f"{a:.4g}",
            "undetermined" if d is None else f"{d:.2f}")


def _removed_text(r: RankedChange) -> str:
    return "loses a parameter" if not math.isfinite(r.score) else f"{100 * r.score:+.1f} %"


def candidates_text(found: TestDesign) -> str:
    """The candidates' summaries and every parameter's predicted sigma."""
    preds = found.predictions
    lines = [f"{'candidate':34s} {'residuals':>9s} {'A':>12s} {'D':>12s}  undetermined"]
    for p in preds:
        a, d = _summary(p)
        lines.append(f"{p.instrumentation.name[:34]:34s} {p.residuals:9d} {a:>12s} {d:>12s}  "
                     f"{len(p.covariance.undetermined)}")
    head = f"\n{'parameter (SI)':28s} {'nominal':>10s} " + " ".join(
        f"{p.instrumentation.name[:16]:>16s}" for p in preds)
    lines.append(head)
    notes = sorted(set(found.notes.values()))
    for name in found.baseline.covariance.names:
        mark = f" [{notes.index(found.notes[name]) + 1}]" if name in found.notes else ""
        lines.append(f"{name:28s} {found.baseline.values[name]:10.4g} " + " ".join(
            f"{sigma_cell(p, name):>16s}" for p in preds) + mark)
    lines += [f"[{k + 1}] {n}" for k, n in enumerate(notes)]
    for p in preds:
        weak = p.covariance.weak
        if weak:
            lines.append(f"\n{p.instrumentation.name}: {len(weak)} combination(s) the plan "
                         f"determines poorly or not at all:")
            lines += [f"  {w}" for w in weak[:WEAK_SHOWN]]
            if len(weak) > WEAK_SHOWN:
                lines.append(f"  ... and {len(weak) - WEAK_SHOWN} more (design.json)")
    return "\n".join(lines)


def spread_frame(found: TestDesign) -> pd.DataFrame:
    """Per candidate and parameter: the predicted sigma at the nominal values and its rms,
    lowest and highest over the population's parameter sets (SI), and the sets that leave
    it undetermined; empty where the plan names no population."""
    if found.spread is None:
        return pd.DataFrame(columns=["candidate", "parameter", "nominal_sigma", "rms",
                                     "lowest", "highest", "undetermined"])
    frame = found.spread.summary()
    at = {p.instrumentation.name: p for p in found.predictions}
    frame.insert(2, "nominal_sigma", [at[c].sigma(n) for c, n in
                                      zip(frame["candidate"], frame["parameter"], strict=True)])
    return frame


def spread_text(found: TestDesign) -> str:
    """The candidates' sigma over the population's parameter sets, beside the nominal."""
    if found.spread is None:
        return ""
    frame = spread_frame(found)
    lines = [f"predicted sigma over {found.spread.draws} parameter sets of the population "
             f"({found.spread.source}): rms, and the range",
             f"{'candidate':20s} {'parameter (SI)':28s} {'nominal':>10s} {'rms':>10s} "
             f"{'lowest':>10s} {'highest':>10s}  undetermined"]
    for r in frame.itertuples(index=False):
        lines.append(f"{r.candidate[:20]:20s} {r.parameter:28s} {_g(r.nominal_sigma):>10s} "
                     f"{_g(r.rms):>10s} {_g(r.lowest):>10s} {_g(r.highest):>10s}  "
                     f"{r.undetermined}")
    lines += [f"  {n}" for n in found.spread.notes]
    return "\n".join(lines)


def _g(value: float | None) -> str:
    return "-" if value is None or not math.isfinite(value) else f"{value:.4g}"


def ranking_text(found: TestDesign) -> str:
    """The single changes, best first, with the sigma they remove from each parameter of
    interest."""
    lines = [f"single changes to {found.baseline.instrumentation.name!r}, ranked by the mean "
             f"sigma they remove from: {', '.join(found.interest)}",
             f"{'#':>2s} {'change':46s} {'removed':>10s} {'A':>10s} {'D':>10s}"]
    for k, r in enumerate(found.ranking, 1):
        a, d = _summary(r.prediction)
        lines.append(f"{k:2d} {r.change.label[:46]:46s} {_removed_text(r):>10s} {a:>10s} "
                     f"{d:>10s}")
    return "\n".join(lines)


def failures_text(found: TestDesign) -> str:
    """What can still be determined after each failure of the first candidate's sensors."""
    if not found.failures:
        return ""
    lines = [f"failures of {found.baseline.instrumentation.name!r}: sigma against the plan's"]
    for label, p in found.failures:
        lines.append(f"  {label}: {failure_summary(found, p)}")
    return "\n".join(lines)


def failure_summary(found: TestDesign, p: Prediction) -> str:
    """One line: the parameters lost, else the largest sigma growth and the interest's."""
    lost = p.covariance.undetermined
    if lost:
        return (f"{len(lost)} parameter(s) no longer determined: {', '.join(lost[:6])}"
                + (" ..." if len(lost) > 6 else ""))
    base = found.baseline
    ratios = {n: p.sigma(n) / base.sigma(n) for n in base.covariance.std
              if p.sigma(n) is not None}
    if not ratios:
        return "no parameter determined"
    worst = max(ratios, key=lambda n: ratios[n])
    shown = ", ".join(f"{n} x{ratios[n]:.2f}" for n in found.interest if n in ratios)
    return f"all still determined; worst {worst} sigma x{ratios[worst]:.2f}; {shown}"


def design_text(found: TestDesign) -> str:
    """What `cpas-ocp design` prints."""
    prob = found.plan.problem
    parts = [f"design of {prob.name}: {prob.title}\n{METHOD}", candidates_text(found),
             spread_text(found), ranking_text(found), failures_text(found), EVENTS_NOTE]
    return "\n\n".join(p for p in parts if p)


def sigma_frame(found: TestDesign) -> pd.DataFrame:
    """Parameter x candidate predicted sigma (SI), NaN where not determined, with the
    nominal value, the unit and the note."""
    frame = found.sigma_table()
    frame.insert(0, "unit", [found.baseline.units[n] for n in frame.index])
    frame.insert(0, "nominal", [found.baseline.values[n] for n in frame.index])
    frame["note"] = [found.notes.get(n, "") for n in frame.index]
    frame.index.name = "parameter"
    return frame


def changes_frame(found: TestDesign) -> pd.DataFrame:
    """One row per ranked change: the mean sigma removed, A, D, and per interest parameter
    the predicted sigma."""
    rows = []
    for k, r in enumerate(found.ranking, 1):
        a, d = r.prediction.optimality()
        row = {"rank": k, "change": r.change.label,
               "sigma_removed": r.score if math.isfinite(r.score) else None,
               "A": a, "D": d}
        row.update({f"sigma {n}": r.prediction.sigma(n) for n in found.interest})
        rows.append(row)
    return pd.DataFrame(rows)


def failures_frame(found: TestDesign) -> pd.DataFrame:
    rows = [{"failure": label, "undetermined": " ".join(p.covariance.undetermined),
             "summary": failure_summary(found, p),
             **{f"sigma {n}": p.sigma(n) for n in found.interest}}
            for label, p in found.failures]
    return pd.DataFrame(rows)


def design_record(found: TestDesign) -> dict:
    """design.json: every candidate's sigma, status and weak combinations, the ranking and
    the failures, as plain data."""
    def prediction(p: Prediction) -> dict:
        a, d = p.optimality()
        return {"name": p.instrumentation.name,
                "sensors": [{**s.entry, "rate_hz": s.rate_hz,
                             "phases": None if s.phases is None else list(s.phases)}
                            for s in p.instrumentation.sensors],
                "event_sigma_s": p.instrumentation.event_sigma, "residuals": p.residuals,
                "A": a, "D": d,
                "sigma": {n: p.sigma(n) for n in p.covariance.names},
                "status": {n: p.status(n) for n in p.covariance.names},
                "weak": [str(w) for w in p.covariance.weak]}
    return {"plan": found.plan.path, "problem": found.plan.problem.name, "method": METHOD,
            "interest": found.interest, "candidates": [prediction(p) for p in found.predictions],
            "ranking": [{"change": r.change.label, "sigma_removed": r.score
                         if math.isfinite(r.score) else None, "removed": {
                             n: v if math.isfinite(v) else None for n, v in r.removed.items()},
                         "prediction": prediction(r.prediction)} for r in found.ranking],
            "failures": [{"failure": label, "prediction": prediction(p)}
                         for label, p in found.failures],
            "notes": found.notes, "events_note": EVENTS_NOTE,
            "population": None if found.spread is None else {
                "source": found.spread.source, "draws": found.spread.draws,
                "notes": found.spread.notes,
                "sigma": spread_frame(found).to_dict(orient="records")}}


def design_page(found: TestDesign) -> Page:
    """The HTML page: method, candidates, predicted sigma, ranking (with its chart),
    failures, notes."""
    prob = found.plan.problem
    page = Page(f"Test design: {prob.name}")
    page.paragraph(f"{prob.title}. {prob.label}")
    page.paragraph(METHOD + ".", "note")
    page.heading("Candidates")
    page.table(["candidate", "residuals", "A", "D", "undetermined"],
               [[p.instrumentation.name, p.residuals, *_summary(p),
                 len(p.covariance.undetermined)] for p in found.predictions],
               [bool(p.covariance.undetermined) for p in found.predictions])
    for p in found.predictions:
        if p.covariance.undetermined:
            page.warning(f"{p.instrumentation.name}: not determined: "
                         + "; ".join(str(w) for w in p.covariance.weak if w.std is None))
    page.heading("Predicted sigma (SI)")
    frame = sigma_frame(found)
    page.table(["parameter", "unit", "nominal",
                *[p.instrumentation.name for p in found.predictions], "note"],
               [[n, found.baseline.units[n], found.baseline.values[n],
                 *[sigma_cell(p, n) for p in found.predictions], found.notes.get(n, "")]
                for n in frame.index], [n in found.notes for n in frame.index])
    if found.spread is not None:
        page.heading("Predicted sigma over the population (SI)")
        page.paragraph(spread_text(found).splitlines()[0])
        spread = spread_frame(found)
        page.table(list(spread.columns), [[_g(v) if isinstance(v, float) else v for v in row]
                                          for row in spread.itertuples(index=False)],
                   [bool(u) for u in spread["undetermined"]])
        for note in found.spread.notes:
            page.paragraph(note, "note")
    page.heading("Single changes, ranked")
    page.paragraph(ranking_text(found).splitlines()[0])
    changes = changes_frame(found)
    page.table(list(changes.columns), changes.itertuples(index=False))
    page.figure(_ranking_figure(found), rows=1, time_axis=False)
    if found.failures:
        page.heading("Failures")
        page.table(["failure", "what is left"],
                   [[label, failure_summary(found, p)] for label, p in found.failures],
                   [bool(p.covariance.undetermined) for _, p in found.failures])
    page.heading("Limits")
    page.paragraph(EVENTS_NOTE)
    for note in sorted(set(found.notes.values())):
        page.paragraph(note, "note")
    return page


def _ranking_figure(found: TestDesign) -> go.Figure:
    """Bars: the mean sigma removed by each change (a change that loses a parameter at
    -100 %, marked)."""
    labels = [r.change.label for r in found.ranking]
    values = [100 * max(r.score, -1.0) if math.isfinite(r.score) else -100.0
              for r in found.ranking]
    fig = go.Figure(go.Bar(x=values, y=labels, orientation="h",
                           text=[_removed_text(r) for r in found.ranking]))
    fig.update_layout(title="mean sigma removed from the parameters of interest (%)",
                      yaxis={"autorange": "reversed"}, height=120 + 28 * len(labels))
    return fig


def write_design(found: TestDesign, out: str | Path) -> Path:
    """The output folder (`MARKER`, sigma.csv, changes.csv, failures.csv, design.html),
    written all at once."""
    out = Path(out)
    with atomic_folder(out, MARKER) as tmp:
        sigma_frame(found).to_csv(tmp / "sigma.csv")
        changes_frame(found).to_csv(tmp / "changes.csv", index=False)
        failures_frame(found).to_csv(tmp / "failures.csv", index=False)
        if found.spread is not None:
            spread_frame(found).to_csv(tmp / "population_sigma.csv", index=False)
        design_page(found).write(tmp / "design.html")
        (tmp / MARKER).write_text(json_text(design_record(found)))
    return out

