"""Self-contained HTML reports: tables and interactive, zoomable plots of plain data.

The plots are drawn with plotly (plotly.js embedded once in the page, so the file opens
offline, with no network): box zoom by dragging, wheel zoom, double click to reset.
The panels of a figure share their time axis, and every time axis of the page follows
a zoom made in any one of them, so an opening of 0.7 s in a descent of 245 s can be
looked at in every sensor at once.  Nothing is decimated: a trace of more than
`LARGE_TRACE` points is drawn with WebGL (plotly's ``scattergl``) and the page says so.
"""

from __future__ import annotations

import html
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import plotly.graph_objects as go
from plotly.offline import get_plotlyjs
from plotly.subplots import make_subplots

from cpas_ocp.precision import Measured
from cpas_ocp.reports.display_units import pretty
from cpas_ocp.reports.plots import WINDOW_COLOURS, DragAreaCurves, WindCurve
from cpas_ocp.reports.report_data import ChannelSeries, ParameterRow, Span

# Points from which a trace is drawn with WebGL rather than SVG (SVG slows beyond this).
LARGE_TRACE = 20_000

CONFIG = {"scrollZoom": True, "displaylogo": False, "responsive": True}

MEASURED = "rgb(140,140,140)"
MODEL = "rgb(214,39,40)"
RESIDUAL = "rgb(31,119,180)"
OTHER = "rgb(255,127,14)"

STYLE = """
body { font-family: system-ui, sans-serif; margin: 1.5em auto; max-width: 1200px;
       padding: 0 1em; color: #222; }
table { border-collapse: collapse; font-size: 0.9em; margin: 0.5em 0 1em; }
th, td { border: 1px solid #ccc; padding: 0.25em 0.6em; text-align: left; }
th { background: #f2f2f2; } td.n { text-align: right; }
tr.flagged td { background: #fde8e4; }
pre { background: #f7f7f7; padding: 0.7em; overflow-x: auto; font-size: 0.85em; }
.warning { background: #fde8e4; border-left: 4px solid #c0392b; padding: 0.6em 1em; }
.note { color: #555; font-size: 0.9em; }
.plot { width: 100%; }
"""

# Every time axis of the page follows a zoom of any one (box, wheel, reset).
SYNC_SCRIPT = """
(function () {
  const plots = Array.from(document.querySelectorAll('div.cpas-time'));
  let busy = false;
  plots.forEach(function (p) {
    p.on('plotly_relayout', function (ev) {
      if (busy) return;
      let range = null, auto = false;
      for (const k in ev) {
        if (/^xaxis\\d*\\.range\\[0\\]$/.test(k)) range = [ev[k], ev[k.replace('[0]', '[1]')]];
        else if (/^xaxis\\d*\\.range$/.test(k)) range = ev[k];
        else if (/^xaxis\\d*\\.autorange$/.test(k)) auto = true;
      }
      if (range === null && !auto) return;
      busy = true;
      const others = plots.filter(function (q) { return q !== p; });
      Promise.all(others.map(function (q) {
        const upd = {};
        if (range !== null) upd[q.dataset.xaxis + '.range'] = range;
        else upd[q.dataset.xaxis + '.autorange'] = true;
        return Plotly.relayout(q, upd);
      })).finally(function () { busy = false; });
    });
  });
})();
"""


@dataclass
class Page:
    """An HTML report being built: a title, then sections of HTML in order."""

    title: str
    parts: list[str] = field(default_factory=list)
    large: list[str] = field(default_factory=list)  # traces drawn with WebGL, said so
    _figures: int = 0

    def heading(self, text: str, level: int = 2) -> None:
        self.parts.append(f"<h{level}>{html.escape(text)}</h{level}>")

    def paragraph(self, text: str, css: str = "") -> None:
        cls = f' class="{css}"' if css else ""
        self.parts.append(f"<p{cls}>{html.escape(text)}</p>")

    def preformatted(self, text: str) -> None:
        self.parts.append(f"<pre>{html.escape(text)}</pre>")

    def warning(self, text: str) -> None:
        self.parts.append(f'<div class="warning">{html.escape(text)}</div>')

    def table(self, header: Sequence[str], rows: Sequence[Sequence[object]],
              flagged: Sequence[bool] = ()) -> None:
        """A table; numbers right-aligned, those without a sigma to 5 significant digits
        (a `precision.Measured` text is already rounded to its sigma); `flagged` rows
        highlighted."""
        def cell(v: object) -> str:
            if isinstance(v, Measured):
                return f"<td class=n>{html.escape(v)}"
            if isinstance(v, float | np.floating):
                return "<td class=n>" + ("—" if not np.isfinite(v) else f"{float(v):.5g}")
            if isinstance(v, int | np.integer):
                return f"<td class=n>{v}"
            return f"<td>{html.escape(str(v))}"
        head = "".join(f"<th>{html.escape(h)}</th>" for h in header)
        body = "".join(
            f'<tr{" class=flagged" if k < len(flagged) and flagged[k] else ""}>'
            + "".join(f"{cell(v)}</td>" for v in row) + "</tr>"
            for k, row in enumerate(rows))
        self.parts.append(f"<table><thead><tr>{head}</tr></thead><tbody>{body}</tbody></table>")

    def figure(self, fig: go.Figure, rows: int, time_axis: bool = True) -> None:
        """A plotly figure of `rows` stacked panels; with `time_axis`, its x axis follows
        the page's other time axes."""
        self._figures += 1
        div = f"plot{self._figures}"
        fig.update_layout(template="plotly_white", margin={"l": 70, "r": 20, "t": 50, "b": 40},
                          legend={"orientation": "h", "y": 1.0, "yanchor": "bottom",
                                  "x": 1.0, "xanchor": "right"})
        body = fig.to_html(full_html=False, include_plotlyjs=False, div_id=div, config=CONFIG)
        bottom = "xaxis" if rows == 1 else f"xaxis{rows}"
        cls = "plot cpas-time" if time_axis else "plot"
        self.parts.append(f"<div>{body}</div>"
                          f"<script>(function () {{ const d = document.getElementById('{div}');"
                          f" d.classList.add({', '.join(repr(c) for c in cls.split())});"
                          f" d.dataset.xaxis = '{bottom}'; }})();</script>")

    def scatter(self, n: int, what: str) -> type[go.Scatter] | type[go.Scattergl]:
        """The trace type for `n` points (WebGL from `LARGE_TRACE` on, noted on the page)."""
        if n < LARGE_TRACE:
            return go.Scatter
        self.large.append(f"{what} ({n:,} points)")
        return go.Scattergl

    def html(self) -> str:
        """The whole page: plotly.js embedded, the sections, the axis-linking script."""
        large = ("" if not self.large else
                 "<p class=note>Drawn in full with WebGL (no points left out) because they are "
                 f"large: {html.escape('; '.join(self.large))}.</p>")
        return ("<!DOCTYPE html>\n<html lang=en><head><meta charset=utf-8>"
                f"<title>{html.escape(self.title)}</title><style>{STYLE}</style>"
                f"<script>{get_plotlyjs()}</script></head><body>"
                f"<h1>{html.escape(self.title)}</h1>"
                "<p class=note>Plots: drag to zoom a box, scroll to zoom, double-click to "
                "reset; every time axis follows the zoom.</p>"
                + large + "\n".join(self.parts)
                + f"<script>{SYNC_SCRIPT}</script></body></html>\n")

    def write(self, path: Path) -> Path:
        path.write_text(self.html(), encoding="utf-8")
        return path


def parameter_table(page: Page, rows: Sequence[ParameterRow]) -> None:
    """The free parameters: value, 1 sigma, 95 % interval, unit, initial guess, flag."""
    page.table(["parameter", "value", "± 1σ", "95 % interval", "unit", "initial", "flag"],
               [[r.name, r.value_text, r.std_text, r.interval,
                 pretty(r.unit), r.initial, r.flag] for r in rows],
               flagged=[bool(r.flag) or r.window is not None for r in rows])


def _axis(row: int) -> str:
    """The suffix of a stacked panel's axes: '' for the first, '2', '3', ... after."""
    return "" if row == 1 else str(row)


def _window_shapes(spans: Sequence[Span], rows: int) -> list[dict]:
    """Shapes shading the phase windows on every panel, by kind (layout dicts: plotly's
    add_vrect over many panels is slow)."""
    return [{"type": "rect", "xref": f"x{_axis(k)}", "yref": f"y{_axis(k)} domain",
             "x0": s.t0, "x1": s.t1, "y0": 0.0, "y1": 1.0, "layer": "below",
             "fillcolor": WINDOW_COLOURS.get(s.kind, "#e5e5e5"), "opacity": 0.6,
             "line": {"width": 0}} for s in spans for k in range(1, rows + 1)]


def _band_shapes(row: int) -> list[dict]:
    """The +-1 and +-3 sigma bands and the zero line of a normalised-residual panel."""
    x, y = f"x{_axis(row)} domain", f"y{_axis(row)}"
    bands = [{"type": "rect", "xref": x, "yref": y, "x0": 0.0, "x1": 1.0, "y0": -half,
              "y1": half, "layer": "below", "fillcolor": "rgb(100,100,100)",
              "opacity": opacity, "line": {"width": 0}}
             for half, opacity in ((3.0, 0.12), (1.0, 0.2))]
    return [*bands, {"type": "line", "xref": x, "yref": y, "x0": 0.0, "x1": 1.0, "y0": 0.0,
                     "y1": 0.0, "line": {"width": 0.6, "color": "black"}}]


def _residual_range(*series: np.ndarray) -> list[float]:
    """Symmetric axis range (sigmas) of normalised residuals: at least +-4, wide enough
    for 99.5 % of the largest series (a few outliers do not squash the rest)."""
    lim = max([4.0, *(float(np.percentile(np.abs(s), 99.5)) for s in series if s.size)])
    return [-lim, lim]


def sensor_figure(page: Page, sensor: str, channels: Sequence[ChannelSeries],
                  spans: Sequence[Span] = ()) -> None:
    """A sensor's channels: model over measurement, and beneath each the normalised
    residual with its +-1 and +-3 sigma bands; phase windows shaded; one time axis."""
    n = 2 * len(channels)
    fig = make_subplots(rows=n, cols=1, shared_xaxes=True, vertical_spacing=0.02,
                        row_heights=[3, 1.4] * len(channels))
    shapes: list[dict] = []
    for i, c in enumerate(channels):
        top, low = 2 * i + 1, 2 * i + 2
        trace = page.scatter(c.t.size, f"{sensor}.{c.channel}")
        fig.add_trace(trace(x=c.t, y=c.measured, mode="markers", name="measured",
                            marker={"size": 3, "color": MEASURED}, legendgroup="measured",
                            showlegend=i == 0), row=top, col=1)
        fig.add_trace(trace(x=c.t, y=c.model, mode="lines", name="model",
                            line={"width": 1.3, "color": MODEL}, legendgroup="model",
                            showlegend=i == 0), row=top, col=1)
        fig.add_trace(trace(x=c.t, y=c.normalised, mode="markers", name="residual / σ",
                            marker={"size": 3, "color": RESIDUAL}, legendgroup="res",
                            showlegend=i == 0), row=low, col=1)
        shapes += _band_shapes(low)
        fig.update_yaxes(title_text=f"{c.channel} [{pretty(c.unit)}]", row=top, col=1)
        fig.update_yaxes(title_text="res/σ", range=_residual_range(c.normalised), row=low,
                         col=1)
    fig.update_layout(shapes=_window_shapes(spans, n) + shapes)  # bands over the windows
    fig.update_xaxes(title_text="time [s]", row=n, col=1)
    fig.update_layout(title=f"{sensor}: model against measurement",
                      height=170 * len(channels) * 2 + 120)
    page.figure(fig, n)


def drag_area_figure(page: Page, curves: Sequence[DragAreaCurves], factor: float,
                     unit: str) -> None:
    """Each canopy's reconstructed drag area against its offline reduction (load cell),
    in `unit` (`factor` from m^2); its stages' start times dashed."""
    fig = make_subplots(rows=len(curves), cols=1, shared_xaxes=True, vertical_spacing=0.04)
    shapes: list[dict] = []
    notes: list[dict] = []
    for i, c in enumerate(curves, start=1):
        if c.data_t is not None and c.data_cds is not None:
            trace = page.scatter(c.data_t.size, f"{c.canopy} riser reduction")
            fig.add_trace(trace(x=c.data_t, y=c.data_cds * factor, mode="markers",
                                name="riser data, Eq. 3, with fitted scales",
                                marker={"size": 2.5, "color": MEASURED},
                                legendgroup="data", showlegend=i == 1), row=i, col=1)
        trace = page.scatter(c.t.size, f"{c.canopy} CdS(t)")
        fig.add_trace(trace(x=c.t, y=c.cds * factor, mode="lines", name="reconstructed CdS(t)",
                            line={"width": 1.5, "color": MODEL}, legendgroup="model",
                            showlegend=i == 1), row=i, col=1)
        for stage, t0 in c.starts.items():
            x, y = f"x{_axis(i)}", f"y{_axis(i)} domain"
            shapes.append({"type": "line", "xref": x, "yref": y, "x0": t0, "x1": t0, "y0": 0.0,
                           "y1": 1.0, "line": {"width": 0.8, "dash": "dash", "color": "green"}})
            notes.append({"xref": x, "yref": y, "x": t0, "y": 1.0, "text": stage,
                          "showarrow": False, "xanchor": "left", "yanchor": "top",
                          "font": {"size": 9}})
        fig.update_yaxes(title_text=f"{c.canopy} CdS [{pretty(unit)}]", row=i, col=1)
    fig.update_xaxes(title_text="time [s]  (dashed: reconstructed stage start times)",
                     row=len(curves), col=1)
    fig.update_layout(title="canopy drag areas", height=260 * len(curves) + 120,
                      shapes=shapes, annotations=[*fig.layout.annotations, *notes])
    page.figure(fig, len(curves))


def residual_comparison_figure(page: Page, sensor: str, labels: tuple[str, str],
                               pairs: Sequence[tuple[ChannelSeries, ChannelSeries]],
                               spans: Sequence[Span] = ()) -> None:
    """A sensor's normalised residuals under two models, one panel per channel, with
    the +-1 and +-3 sigma bands and the phase windows; one time axis."""
    fig = make_subplots(rows=len(pairs), cols=1, shared_xaxes=True, vertical_spacing=0.03)
    shapes: list[dict] = []
    for i, pair in enumerate(pairs, start=1):
        for c, label, colour in zip(pair, labels, (RESIDUAL, OTHER), strict=True):
            rms = float(np.sqrt(np.mean(c.normalised**2)))
            trace = page.scatter(c.t.size, f"{sensor}.{c.channel} ({label})")
            fig.add_trace(trace(x=c.t, y=c.normalised, mode="markers",
                                name=f"{label}: {c.channel}, normalised RMS {rms:.3f}",
                                marker={"size": 3, "color": colour, "opacity": 0.7}),
                          row=i, col=1)
        shapes += _band_shapes(i)
        fig.update_yaxes(title_text=f"{pair[0].channel} res/σ",
                         range=_residual_range(*(c.normalised for c in pair)), row=i, col=1)
    fig.update_layout(shapes=_window_shapes(spans, len(pairs)) + shapes)
    fig.update_xaxes(title_text="time [s]", row=len(pairs), col=1)
    fig.update_layout(title=f"{sensor}: normalised residuals, {labels[0]} and {labels[1]}",
                      height=220 * len(pairs) + 140)
    page.figure(fig, len(pairs))


def wind_figure(curves: Sequence[WindCurve], speed: str) -> go.Figure | None:
    """The air's motion against time: each component's estimate at the knots and its 95 %
    band (`plots.wind_curves`); None where there is none."""
    if not curves:
        return None
    fig = make_subplots(rows=len(curves), cols=1, shared_xaxes=True, vertical_spacing=0.06)
    for row, c in enumerate(curves, 1):
        fig.add_trace(go.Scatter(x=c.t, y=c.velocity + c.band, mode="lines", line={"width": 0},
                                 showlegend=False, hoverinfo="skip"), row=row, col=1)
        fig.add_trace(go.Scatter(x=c.t, y=c.velocity - c.band, mode="lines", line={"width": 0},
                                 fill="tonexty", fillcolor="rgba(31, 119, 180, 0.25)",
                                 name="95 % band", showlegend=row == 1), row=row, col=1)
        fig.add_trace(go.Scatter(x=c.t, y=c.velocity, mode="lines+markers",
                                 marker={"size": 4}, line={"color": "rgb(31, 119, 180)"},
                                 name="estimate at the knots", showlegend=row == 1),
                      row=row, col=1)
        fig.update_yaxes(title_text=f"{c.component} [{speed}]", row=row, col=1)
    fig.update_xaxes(title_text="time [s]", row=len(curves), col=1)
    fig.update_layout(title="The air's motion (wind process)", height=160 + 220 * len(curves))
    return fig


def window_legend(page: Page) -> None:
    """Which colour shades which kind of phase window."""
    page.parts.append("<p class=note>Shaded: " + ", ".join(
        f'<span style="background:{c};padding:0 0.4em">{html.escape(k)}</span>'
        for k, c in WINDOW_COLOURS.items()) + " windows.</p>")
