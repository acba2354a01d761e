"""What a population fit prints and writes: tables, a forest plot per parameter, a page.

`population_text` is what `cpas-ocp population` prints; `write_population`
writes population.md, population.json, population.csv (per population and
parameter: median, tau, I^2, the point-estimate spread), openings.csv (per
opening: estimate, its sigma, shrunken estimate, pull), explained.csv (per
covariate and parameter: the share of the between-test variance it explains),
groupings.csv (the grouping tests, a header alone where none was tested) and
report.html, whose forest plots show each opening's estimate with its own 95 %
interval, its shrunken estimate and the population band mu +- 1.96 tau.

Figures in log space are shown as the median exp(mu) and as tau, the
between-test coefficient of variation to first order.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd
import plotly.graph_objects as go
from plotly.subplots import make_subplots

from cpas_ocp.campaign.population_model import GroupingTest, Interval
from cpas_ocp.campaign.population_study import PopulationGroup
from cpas_ocp.io.output_folder import atomic_folder
from cpas_ocp.io.strict_json import json_text
from cpas_ocp.precision import with_interval
from cpas_ocp.reports.html_page import MEASURED, MODEL, RESIDUAL, Page

MARKER = "population.json"
# A pull beyond this many sigma (two-sided p 0.0027) is named.
PULL_FLAG = 3.0


def _back(value: float, log: bool) -> float:
    return float(np.exp(value)) if log else value


def parameter_frame(group: PopulationGroup) -> pd.DataFrame:
    """Per parameter: the population median (SI) with its interval, tau with its
    interval (log space: a coefficient of variation), I^2 and the point-estimate spread."""
    fit, data = group.fit, group.data
    i2 = fit.i_squared()
    rows = []
    for j, name in enumerate(data.names):
        mu, tau = fit.coefficients[(name, "intercept")], fit.tau[name]
        log = data.log[j]
        rows.append({"population": group.label, "parameter": name,
                     "space": "log" if log else "linear",
                     "median": _back(mu.value, log), "median_lower": _back(mu.lower, log),
                     "median_upper": _back(mu.upper, log), "tau": tau.value,
                     "tau_lower": tau.lower, "tau_upper": tau.upper,
                     "i_squared": float(i2[j]), "point_sd": float(group.point_spread[j])}
                    | _levels(group, name))
    return pd.DataFrame(rows)


def _levels(group: PopulationGroup, name: str) -> dict[str, float]:
    """The test-level and canopy-level standard deviations of `name` with their intervals
    (`nested_population`), NaN where they were not separated."""
    nested = group.nested
    out = {}
    for level in ("test", "canopy"):
        iv = None if nested is None else getattr(nested, f"tau_{level}").get(name)
        out |= {f"tau_{level}": np.nan if iv is None else iv.value,
                f"tau_{level}_lower": np.nan if iv is None else iv.lower,
                f"tau_{level}_upper": np.nan if iv is None else iv.upper}
    return out


def nested_lines(group: PopulationGroup) -> list[str]:
    """The spread split into the test's and the canopy's, a line per parameter."""
    nested = group.nested
    if nested is None:
        return []
    # The test's share of a spread neither level shows is noise: shown where one does.
    share = np.where([nested.tau_test[n].lower > 0.0 or nested.tau_canopy[n].lower > 0.0
                      for n in nested.data.names], nested.test_share(), np.nan)
    lines = [f"test-level and canopy-level spread ({len(nested.data.tests)} tests, each "
             "test's canopies one observation with their cross-covariances; diagonal "
             "Omegas, restricted likelihood):",
             f"  {'parameter':10s} {'tau test':>9s} {'95 % interval':>18s} "
             f"{'tau canopy':>10s} {'95 % interval':>18s} {'test share':>10s}"]
    for j, name in enumerate(nested.data.names):
        a, b = nested.tau_test[name], nested.tau_canopy[name]
        lines.append(f"  {name:10s} {a.value:9.3g} {f'[{a.lower:.3g}, {a.upper:.3g}]':>18s} "
                     f"{b.value:10.3g} {f'[{b.lower:.3g}, {b.upper:.3g}]':>18s} "
                     f"{'-' if np.isnan(share[j]) else f'{share[j]:.0%}':>10s}")
    lines.append("  (test share: tau test^2 / (tau test^2 + tau canopy^2), '-' where neither "
                 "interval is clear of 0)")
    return lines


def opening_frame(group: PopulationGroup) -> pd.DataFrame:
    """Per opening and parameter, in SI: the estimate and its sigma, the shrunken estimate
    and its sigma, the standardised pull; and each opening's pull p-value."""
    data, fit = group.data, group.fit
    theta, cov = fit.shrunken()
    z, p = fit.pulls()
    rows = []
    for i, opening in enumerate(data.openings):
        for j, name in enumerate(data.names):
            log = data.log[j]
            scale = np.exp(data.y[i, j]) if log else 1.0
            shrunk = _back(theta[i, j], log)
            rows.append({"population": group.label, "opening": opening, "parameter": name,
                         "estimate": _back(data.y[i, j], log),
                         "sigma": float(np.sqrt(data.V[i, j, j]) * scale),
                         "shrunken": shrunk,
                         "shrunken_sigma": float(np.sqrt(max(cov[i, j, j], 0.0))
                                                 * (shrunk if log else 1.0)),
                         "pull": float(z[i, j]), "opening_p": float(p[i])})
    return pd.DataFrame(rows)


GROUPING_COLUMNS = ["population", "covariate", "levels", "statistic", "dof", "bartlett",
                    "bootstrap", "p_value", "verdict", "parameter", "shift", "shift_lower",
                    "shift_upper"]


def explained_frame(group: PopulationGroup) -> pd.DataFrame:
    """One row per covariate of the mean and parameter: the share of the between-test
    variance it explains (`population_study.explained_spread`; blank where there is no
    spread without it either)."""
    return pd.DataFrame([{"population": group.label, "covariate": covariate,
                          "parameter": name, "explained": float(share[j])}
                         for covariate, share in group.explained.items()
                         for j, name in enumerate(group.data.names)],
                        columns=["population", "covariate", "parameter", "explained"])


def _explained_line(group: PopulationGroup, covariate: str) -> str:
    shares = group.explained[covariate]
    return (f"{covariate} explains of the between-test variance: "
            + ", ".join(f"{n} {'-' if np.isnan(s) else f'{s:.0%}'}"
                        for n, s in zip(group.data.names, shares, strict=True))
            + (" (-: no spread without it either)" if np.isnan(shares).any() else ""))


def grouping_frame(groups: Sequence[PopulationGroup]) -> pd.DataFrame:
    """One row per grouping test and parameter: the levels, the likelihood ratio, its
    p-value and verdict, and the second level's shift of the parameter's mean (the
    columns of GROUPING_COLUMNS, a header alone where nothing was tested)."""
    rows = []
    for group in groups:
        for test in group.groupings:
            for name, shift in test.shift.items():
                rows.append({"population": group.label, "covariate": test.covariate,
                             "levels": " / ".join(test.levels), "statistic": test.statistic,
                             "dof": test.dof, "bartlett": test.bartlett,
                             "bootstrap": test.bootstrap, "p_value": test.p_value,
                             "verdict": "separate" if test.separate else "pooled",
                             "parameter": name, "shift": shift.value,
                             "shift_lower": shift.lower, "shift_upper": shift.upper})
    return pd.DataFrame(rows, columns=GROUPING_COLUMNS)


def no_grouping_line(group: PopulationGroup) -> str | None:
    """Where no grouping was tested, a sentence saying so; None otherwise."""
    if group.groupings:
        return None
    return ("no grouping tested: no column of the campaign's table takes two or more "
            "values over these openings with enough openings at each")


def _interval(iv: Interval, log: bool) -> str:
    return f"[{_back(iv.lower, log):.4g}, {_back(iv.upper, log):.4g}]"


def grouping_line(test: GroupingTest) -> str:
    """One sentence: which levels, the likelihood ratio and what it says."""
    verdict = (f"separate populations (p < {test.alpha:g})" if test.separate
               else f"one population is kept (p >= {test.alpha:g})")
    shifts = ", ".join(f"{n} {s.value:+.3g} [{s.lower:+.3g}, {s.upper:+.3g}]"
                       for n, s in test.shift.items())
    adjusted = (f" (Bartlett factor {test.bartlett:.2f} from {test.bootstrap} campaigns "
                "drawn pooled)" if test.bootstrap else "")
    return (f"{test.covariate} ({' vs '.join(test.levels)}): 2 ln LR = {test.statistic:.2f} "
            f"on {test.dof} dof{adjusted}, p = {test.p_value:.3g}: {verdict}; shift of the mean "
            f"({test.levels[1]} against {test.levels[0]}): {shifts}")


def group_text(group: PopulationGroup) -> str:
    """The population's table, covariate effects, correlations, pulls, groupings and notes."""
    fit, data = group.fit, group.data
    tests = group.covariates.test.nunique()
    lines = [f"{group.label}: {data.n} openings of {tests} tests, Omega "
             f"{'full' if fit.full_omega else 'diagonal'}, "
             f"{'restricted' if fit.reml else 'full'} likelihood; t intervals on {fit.dof} dof",
             f"  {'parameter':10s} {'median':>10s} {'95 % interval':>22s} {'tau':>7s} "
             f"{'95 % interval':>18s} {'I^2':>5s} {'point SD':>8s}"]
    for row in parameter_frame(group).itertuples():
        median, interval = with_interval(row.median, row.median_lower, row.median_upper)
        lines.append(f"  {row.parameter:10s} {median:>10s} {interval:>22s} "
                     f"{row.tau:7.3g} {f'[{row.tau_lower:.3g}, {row.tau_upper:.3g}]':>18s} "
                     f"{row.i_squared:5.2f} {row.point_sd:8.3g}")
    lines.append("  (median exp(mu) in SI; tau and the point SD in log space, a coefficient "
                 "of variation, where the space is log)")
    for column in data.columns[1:]:
        effects = ", ".join(f"{n} {fit.coefficients[(n, column)].value:+.3g} "
                            f"[{fit.coefficients[(n, column)].lower:+.3g}, "
                            f"{fit.coefficients[(n, column)].upper:+.3g}]" for n in data.names)
        lines.append(f"  effect of {column}: {effects}")
    lines += [f"  {_explained_line(group, c)}" for c in group.explained]
    lines += [f"  {line}" for line in nested_lines(group)]
    corr = fit.correlation()
    strong = [(data.names[a], data.names[b], corr[a, b]) for a in range(data.k)
              for b in range(a) if np.isfinite(corr[a, b]) and abs(corr[a, b]) >= 0.5]
    if fit.full_omega and strong:
        lines.append("  between-test correlations |rho| >= 0.5: "
                     + ", ".join(f"{a} ~ {b} {r:+.2f}" for a, b, r in strong))
    z, _ = fit.pulls()
    flagged = [(data.openings[i], data.names[int(np.argmax(abs(z[i])))], z[i].max())
               for i in range(data.n) if np.abs(z[i]).max() > PULL_FLAG]
    lines.append(f"  openings pulled beyond {PULL_FLAG:g} sigma: "
                 + (", ".join(f"{o} ({n})" for o, n, _ in flagged) if flagged else "none"))
    lines += ["  grouping " + grouping_line(t) for t in group.groupings]
    lines += [f"  {line}" for line in [no_grouping_line(group)] if line]
    lines += [f"  note: {n}" for n in group.notes]
    return "\n".join(lines)


def population_text(groups: Sequence[PopulationGroup], skipped: Sequence[str]) -> str:
    return "\n\n".join([group_text(g) for g in groups]
                       + (["not fitted:\n" + "\n".join(f"  {s}" for s in skipped)]
                          if skipped else []))


def _unit(group: PopulationGroup, name: str) -> str:
    """The parameter's SI unit as the campaign's table gives it."""
    return group.units.get(name, "SI")


def forest_figure(group: PopulationGroup) -> go.Figure:
    """One panel per parameter: each opening's estimate with its own 95 % interval, its
    shrunken estimate, and the population median with the band mu +- 1.96 tau (at the
    covariates' reference)."""
    frame = opening_frame(group)
    data, fit = group.data, group.fit
    fig = make_subplots(rows=1, cols=data.k, shared_yaxes=True, horizontal_spacing=0.02)
    for j, name in enumerate(data.names):
        f = frame[frame.parameter == name]
        log = data.log[j]
        mu, tau = fit.coefficients[(name, "intercept")].value, fit.tau[name].value
        lo, hi = _back(mu - 1.96 * tau, log), _back(mu + 1.96 * tau, log)
        half = 1.96 * f.sigma.to_numpy()
        fig.add_trace(go.Scatter(x=f.estimate, y=f.opening, mode="markers",
                                 marker={"color": MEASURED}, name="estimate ± 1.96σ",
                                 error_x={"type": "data", "array": half, "visible": True},
                                 showlegend=j == 0), row=1, col=j + 1)
        fig.add_trace(go.Scatter(x=f.shrunken, y=f.opening, mode="markers",
                                 marker={"color": RESIDUAL, "symbol": "diamond"},
                                 name="shrunken", showlegend=j == 0), row=1, col=j + 1)
        fig.update_xaxes(title_text=f"{name} ({_unit(group, name)})", row=1, col=j + 1)
        # After the traces: plotly leaves shapes out of subplots that are still empty.
        fig.add_vrect(x0=lo, x1=hi, fillcolor=MODEL, opacity=0.12, line_width=0,
                      row=1, col=j + 1)
        fig.add_vline(x=_back(mu, log), line_color=MODEL, row=1, col=j + 1)
    fig.update_layout(height=160 + 18 * data.n,
                      title=f"{group.label}: estimates, shrunken estimates and the population "
                            "(median, ±1.96 τ)")
    return fig


def population_page(groups: Sequence[PopulationGroup], skipped: Sequence[str],
                    title: str) -> Page:
    page = Page(title)
    for group in groups:
        page.heading(group.label)
        frame = parameter_frame(group)
        page.table(["parameter", "space", "median", "95 % interval", "tau", "95 % interval",
                    "I²", "point SD"],
                   [[r.parameter, r.space,
                     *with_interval(r.median, r.median_lower, r.median_upper),
                     r.tau, f"[{r.tau_lower:.3g}, {r.tau_upper:.3g}]",
                     r.i_squared, r.point_sd] for r in frame.itertuples()])
        page.figure(forest_figure(group), rows=1, time_axis=False)
        if group.nested is not None:
            page.paragraph(nested_lines(group)[0])
            page.table(["parameter", "tau test", "95 % interval", "tau canopy",
                        "95 % interval"],
                       [[r.parameter, r.tau_test, f"[{r.tau_test_lower:.3g}, "
                         f"{r.tau_test_upper:.3g}]", r.tau_canopy,
                         f"[{r.tau_canopy_lower:.3g}, {r.tau_canopy_upper:.3g}]"]
                        for r in frame.itertuples()])
        for covariate in group.explained:
            page.paragraph(_explained_line(group, covariate))
        for test in group.groupings:
            page.paragraph(grouping_line(test))
        if no_grouping_line(group):
            page.paragraph(no_grouping_line(group), "note")
        for note in group.notes:
            page.paragraph(note, "note")
    if skipped:
        page.heading("Not fitted")
        for s in skipped:
            page.paragraph(s, "note")
    return page


def population_summary(groups: Sequence[PopulationGroup]) -> list[dict[str, Any]]:
    """The JSON form: per population its members, parameters, coefficients, Omega and
    groupings."""
    out = []
    for g in groups:
        fit = g.fit
        out.append({"population": g.label, "members": [list(m) for m in g.members],
                    "openings": list(g.data.openings), "parameters": list(g.data.names),
                    "log_space": list(g.data.log), "columns": list(g.data.columns),
                    "beta": fit.beta.tolist(), "omega": fit.omega.tolist(),
                    "full_omega": fit.full_omega, "log_likelihood": fit.log_likelihood,
                    "table": parameter_frame(g).to_dict("records"),
                    "explained": explained_frame(g).to_dict("records"),
                    "nested": None if g.nested is None else {
                        "tests": list(g.nested.data.tests),
                        "beta": g.nested.beta.tolist(),
                        "omega_test": g.nested.omega_test.tolist(),
                        "omega_canopy": g.nested.omega_canopy.tolist(),
                        "log_likelihood": g.nested.log_likelihood},
                    "groupings": grouping_frame([g]).to_dict("records"), "notes": g.notes})
    return out


def write_population(groups: Sequence[PopulationGroup], skipped: Sequence[str],
                     out: str | Path, title: str) -> Path:
    """Write the population folder atomically (see the module's docstring)."""
    with atomic_folder(out, MARKER) as tmp:
        pd.concat([parameter_frame(g) for g in groups]).to_csv(tmp / "population.csv",
                                                               index=False)
        pd.concat([opening_frame(g) for g in groups]).to_csv(tmp / "openings.csv",
                                                             index=False)
        grouping_frame(groups).to_csv(tmp / "groupings.csv", index=False)
        pd.concat([explained_frame(g) for g in groups]).to_csv(tmp / "explained.csv",
                                                               index=False)
        (tmp / MARKER).write_text(json_text({"populations": population_summary(groups),
                                             "skipped": list(skipped)}))
        (tmp / "population.md").write_text(
            f"# {title}\n\n```\n{population_text(groups, skipped)}\n```\n\n"
            "Forest plots: report.html\n")
        population_page(groups, skipped, title).write(tmp / "report.html")
    return Path(out)
