"""The report folder of a reconstruction: result.json, parameters.csv, figures, and the table."""

from __future__ import annotations

import json
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
import pandas as pd
from scipy.stats import norm

from cpas_ocp.estimation.estimator import EVENTS, PRIORS, Fit
from cpas_ocp.estimation.uncertainty import POORLY_DETERMINED, Covariance
from cpas_ocp.inference.diagnostics import sensor_summary, worst_windows
from cpas_ocp.inference.model_comparison import Criteria
from cpas_ocp.inference.profile_likelihood import Profile
from cpas_ocp.io.output_folder import atomic_folder
from cpas_ocp.physics.units import FT
from cpas_ocp.reports.failure_report import RESULT_MARKERS
from cpas_ocp.reports.flight_report import steady_descent_text
from cpas_ocp.reports.plots import (
    plot_correlation,
    plot_drag_areas,
    plot_events,
    plot_profile,
    plot_sensors,
    plot_wind,
)

if TYPE_CHECKING:
    from cpas_ocp.inference.result_claim import Claim

Z95 = float(norm.ppf(0.975))  # two-sided 95 % quantile of the standard normal
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


SENSOR_UNITS = {"east": "m", "north": "m", "up": "m", "v_east": "m/s", "v_north": "m/s",
                "v_up": "m/s", "load_factor": "g", "tension": "N"}


def channel_unit(fit: Fit, sensor: str, channel: str) -> str:
    """SI unit of a residual channel (event times are in s, a prior in its parameter's unit)."""
    if sensor == PRIORS:
        return fit.model.parameter(channel).unit
    if any(sensor == effect for effect, *_ in fit.model.penalties):
        return "σ"  # a process prior's innovations, in units of their own sigma
    return "s" if sensor == EVENTS else SENSOR_UNITS.get(channel, "SI")


def result_dict(fit: Fit, cov: Covariance | None,
                profiles: Sequence[Profile] = ()) -> dict[str, Any]:
    """Everything a reader of result.json needs; SI units, stated per value."""
    std = cov.std if cov is not None else {}
    params = {}
    for name in fit.free:
        prm = fit.model.parameter(name)
        entry = {"value": fit.parameters[name], "unit": prm.unit,
                 "initial": fit.guess.get(name, prm.default)}
        if cov is not None and name in cov.at_bound:
            entry["at_bound"] = prm.nearer_bound(fit.parameters[name])
            entry["bounds"] = [prm.lower, prm.upper]
        elif cov is not None and name in cov.undetermined:
            entry["undetermined"] = True
        elif name in std:
            entry["std"] = std[name]
            entry["ci95"] = [fit.parameters[name] - Z95 * std[name],
                             fit.parameters[name] + Z95 * std[name]]
        params[name] = entry
    fixed = {n: {"value": v, "unit": fit.model.parameter(n).unit}
             for n, v in fit.parameters.items() if n not in fit.free}
    summary = sensor_summary(fit)
    residuals = {s: {"rms": e["rms"], "unit": {c: channel_unit(fit, s, c) for c in e["rms"]},
                     "normalized_rms": e["normalized_rms"], "samples": e["samples"]}
                 for s, e in summary.items()}
    n = fit.n_samples
    worst = [{"sensor": w.sensor, "channel": w.channel, "window_s": [w.t0, w.t1],
              "normalized_rms": w.normalized_rms} for w in worst_windows(fit)]
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
             "curvature_ratio": w.curvature_ratio, "text": w.text()} for w in cov.weak],
        "profiles": {p.name: p.as_dict() for p in profiles},
        "model": {"effects": [e.name for e in fit.model.effects],
                  "grid": {"nodes": len(fit.t), "finest_step_s": float(np.min(np.diff(fit.t))),
                           "longest_step_s": float(np.max(np.diff(fit.t)))},
                  "fill_length": {c.name: c.fill_length for c in fit.test.parachutes}},
    }


def parameter_table(fit: Fit, cov: Covariance | None) -> str:
    """A readable terminal table of the estimated parameters: value, 1 sigma, 95 % interval,
    correlations and the combinations the data do not determine."""
    std = cov.std if cov is not None else {}
    lines = [f"{'parameter':30s} {'value':>11s} {'± 1σ':>10s} {'95 % interval':>25s}  "
             f"{'unit':5s} {'initial':>10s}"]
    for name in fit.free:
        prm = fit.model.parameter(name)
        v = fit.parameters[name]
        if name in std:
            half = Z95 * std[name]
            s, ci = f"{std[name]:10.4g}", f"[{v - half:.5g}, {v + half:.5g}]"
        else:
            s, ci = f"{'—':>10s}", f"{'—':>25s}"
        extra = f"   ({v / FT**2:7.2f} ft²)" if prm.unit == "m^2" else ""
        flag = ""
        if cov is not None and name in cov.at_bound:
            flag = f"  on its {prm.nearer_bound(v)} bound"
        elif cov is not None and name in cov.undetermined:
            flag = "  undetermined"
        lines.append(f"{name:30s} {v:11.5g} {s} {ci:>25s}  {prm.unit:5s} "
                     f"{fit.guess.get(name, prm.default):10.4g}{extra}{flag}")
    if cov is not None:
        pairs = strong_correlations(cov)
        lines.append(f"correlations |ρ| ≥ {STRONG_CORRELATION}: "
                     + ("none" if not pairs else f"{len(pairs)}, strongest "
                        + "; ".join(f"{a} ~ {b} {r:+.3f}" for a, b, r in pairs[:3])))
        lines.append(identifiability_text(cov))
    return "\n".join(lines)


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
        lines += [f"  {w.text()}" for w in cov.weak]
    if cov.at_bound:
        lines.append(f"  on a bound, so not determined by the data and given no σ "
                     f"({len(cov.at_bound)}): {', '.join(cov.at_bound)}; the optimum lies "
                     "at or beyond the bound: widen it if it is not a physical limit, or "
                     "profile the parameter")
    return "\n".join(lines)


def fit_summary(fit: Fit) -> str:
    """Solver outcome, residuals per sensor and where the model fits worst."""
    ic = information_criteria(fit)
    out = [f"solver: {fit.solver.status}, {fit.solver.iterations} iterations, "
           f"{fit.solver.wall_s:.1f} s, from {fit.solver.start};  "
           f"chi²/dof = {fit.chi_square:.1f}/{fit.dof} = {fit.chi_square / fit.dof:.3f};  "
           f"AIC {ic['aic']:.1f}, BIC {ic['bic']:.1f}"]
    for s, e in sensor_summary(fit).items():
        rms = ", ".join(f"{c} {v:.4g} {channel_unit(fit, s, c)}" for c, v in e["rms"].items())
        out.append(f"  {s:16s} normalised RMS {e['normalized_rms']:.3f}   (RMS {rms})")
    worst = worst_windows(fit, top=1)
    if worst:
        w = worst[0]
        out.append(f"worst fit: {w.sensor}.{w.channel} in {w.t0:.2f}-{w.t1:.2f} s, "
                   f"normalised RMS {w.normalized_rms:.2f}")
    return "\n".join(out)


def correlation_markdown(cov: Covariance, threshold: float = REPORTED_CORRELATION) -> str:
    """The covariance's provenance and the correlated pairs, as report.md lists them."""
    pairs = strong_correlations(cov, threshold)
    rows = "".join(f"| {a} | {b} | {r:+.3f} |\n" for a, b, r in pairs)
    return (f"Uncertainties: {cov.describe()}.\n\n"
            f"Correlations with |ρ| ≥ {threshold} ({len(pairs)}; correlation.png shows all):\n\n"
            + (f"| parameter | parameter | ρ |\n|---|---|---|\n{rows}\n" if pairs else "none\n\n"))


def write_report(fit: Fit, cov: Covariance | None, out: str | Path,
                 profiles: Sequence[Profile] = (), claim: Claim | None = None) -> Path:
    """Write the report folder atomically: all of it or nothing.  With `claim`, result.json
    and report.md say what the fit may claim, a fit that is not a result first of all."""
    out = Path(out)
    with atomic_folder(out, RESULT_MARKERS) as tmp:
        result = result_dict(fit, cov, profiles)
        if claim is not None:
            result["claim"] = claim.as_dict()
        (tmp / "result.json").write_text(json.dumps(result, indent=2))
        std = cov.std if cov is not None else {}
        rows = [{"parameter": n, "value": fit.parameters[n], "std": std.get(n, np.nan),
                 "unit": fit.model.parameter(n).unit} for n in fit.free]
        pd.DataFrame(rows).to_csv(tmp / "parameters.csv", index=False)
        plot_sensors(fit, tmp)
        plot_drag_areas(fit, tmp)
        plot_events(fit, tmp)
        plot_wind(fit, cov, tmp)
        if cov is not None:
            plot_correlation(cov, fit.test.name, tmp)
        for prof in profiles:
            plot_profile(prof, fit.test.name, tmp)
        warning = ("**Not a result.** " + " ".join(f"{p}." for p in claim.problems()) + "\n\n"
                   if claim is not None and not claim.is_result else "")
        (tmp / "report.md").write_text(
            f"# Reconstruction of {fit.test.name}\n\n{fit.test.label}\n\n{warning}```\n"
            f"{parameter_table(fit, cov)}\n\n{fit_summary(fit)}\n"
            + (f"{claim.text()}\n" if claim is not None else "") + "```\n\n"
            + (correlation_markdown(cov) if cov is not None else "")
            + (steady_descent_text(fit, cov) + "\n" if cov is not None
               and any(c.open_at_start for c in fit.test.parachutes) else "")
            + "".join(f"Profile likelihood, {p.text()}\n\n" for p in profiles)
            + "".join(f"![{p.stem}]({p.name})\n\n" for p in sorted(tmp.glob("*.png"))))
    return out
