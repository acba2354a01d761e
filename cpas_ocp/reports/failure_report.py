"""The report of a solve that did not converge: why it stopped, never a result.

When Ipopt ends without a converged, feasible solution, the command exits 3
and writes no result.json.  What it writes instead, in the same folder, is
`failure.md` and `failure.json`, headed NOT CONVERGED: the solver's status,
its iteration count and worst constraint, and the residual figures of the
last iterate (normalised RMS per sensor, the worst 0.5 s windows, the free
parameters there and which of them sit on a bound).  They are there so the
user can see why the solve failed (a start guess far off, a parameter
pushed against a bound, a sensor the model cannot follow), not to be read
as estimates.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

from cpas_ocp.errors import SolverFailure
from cpas_ocp.estimation.estimator import Fit
from cpas_ocp.inference.diagnostics import sensor_summary, worst_windows
from cpas_ocp.io.output_folder import atomic_folder
from cpas_ocp.io.strict_json import json_text

# Files that mark a reconstruction's output folder, converged or not: either may be
# replaced by the next run's.
FAILURE_MARKER = "failure.json"
RESULT_MARKERS = ("result.json", FAILURE_MARKER)
BANNER = "NOT CONVERGED"


def failure_dict(exc: SolverFailure) -> dict[str, Any]:
    """failure.json: the solver's outcome, and the last iterate's figures (SI) if known."""
    out: dict[str, Any] = {"converged": False, "status": exc.status,
                           "iterations": exc.iterations,
                           "worst_constraint": exc.worst_constraint,
                           "chi_square_last_iterate": exc.chi_square,
                           "note": f"{BANNER}: the figures below describe the last iterate, "
                                   "not an estimate"}
    fit = exc.last_iterate
    if fit is None:
        return out
    out["test"] = fit.test.name
    out["residuals_last_iterate"] = {
        s: {"normalised_rms": e["normalised_rms"], "samples": e["samples"]}
        for s, e in sensor_summary(fit).items()}
    out["worst_windows_last_iterate"] = [
        {"sensor": w.sensor, "channel": w.channel, "t0": w.t0, "t1": w.t1,
         "normalised_rms": w.normalised_rms} for w in worst_windows(fit)]
    out["parameters_last_iterate"] = {
        n: {"value": fit.parameters[n], "unit": fit.model.parameter(n).unit,
            "initial": fit.guess.get(n, fit.model.parameter(n).default),
            "on_bound": _bound_side(fit, n)} for n in fit.free}
    return out


def failure_markdown(exc: SolverFailure) -> str:
    """failure.md: the same, for a reader."""
    d = failure_dict(exc)
    name = d.get("test", "the test")
    lines = [f"# {BANNER}: {name}", "",
             f"The solver stopped without a converged solution: status {exc.status} after "
             f"{exc.iterations} iterations"
             + (f"; worst constraint {exc.worst_constraint}" if exc.worst_constraint else "")
             + ".", "",
             "**Nothing here is a result.** The figures describe the last iterate, to show "
             "where the fit was when it stopped.", ""]
    if "residuals_last_iterate" not in d:
        return "\n".join(lines)
    fit = exc.last_iterate
    lines += ["## Residuals at the last iterate", "",
              f"chi-square {fit.chi_square:.6g} on {fit.n_samples} residuals "
              f"(chi²/dof {fit.chi_square / fit.dof:.3g}).", "",
              "| sensor | samples | normalised RMS |",
              "|---|---|---|"]
    lines += [f"| {s} | {e['samples']} | {e['normalised_rms']:.3g} |"
              for s, e in d["residuals_last_iterate"].items()]
    lines += ["", "## Worst windows at the last iterate", "",
              "| sensor.channel | window (s) | normalised RMS |", "|---|---|---|"]
    lines += [f"| {w['sensor']}.{w['channel']} | {w['t0']:.2f}-{w['t1']:.2f} | "
              f"{w['normalised_rms']:.3g} |" for w in d["worst_windows_last_iterate"]]
    lines += ["", "## Free parameters at the last iterate", "",
              "| parameter | value | unit | initial | on a bound |", "|---|---|---|---|---|"]
    lines += [f"| {n} | {p['value']:.6g} | {p['unit']} | {p['initial']:.6g} | "
              f"{p['on_bound'] or ''} |" for n, p in d["parameters_last_iterate"].items()]
    return "\n".join(lines) + "\n"


def write_failure_report(exc: SolverFailure, out: str | Path) -> Path:
    """Write failure.md and failure.json into `out` (atomically, replacing an earlier
    reconstruction's output) and return the folder."""
    out = Path(out)
    with atomic_folder(out, RESULT_MARKERS) as tmp:
        (tmp / FAILURE_MARKER).write_text(json_text(failure_dict(exc)))
        (tmp / "failure.md").write_text(failure_markdown(exc))
    return out


def _bound_side(fit: Fit, name: str) -> str | None:
    """"lower" or "upper" for a parameter within 1e-6 of its bounds' span (of its own size
    where a bound is infinite) of that bound, else None."""
    prm = fit.model.parameter(name)
    value = fit.parameters[name]
    span = prm.upper - prm.lower
    tol = 1e-6 * (span if span < float("inf") else max(abs(value), 1.0))
    if value - prm.lower <= tol or prm.upper - value <= tol:
        return prm.nearer_bound(value)
    return None
