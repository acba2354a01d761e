"""A reconstruction in the terminal: its shooting grid, what it may claim, the wind
process's intensity chosen by the evidence, and a what-if study."""

from __future__ import annotations

import numpy as np

from cpas_ocp.inference.process_intensity import IntensityChoice
from cpas_ocp.inference.result_claim import Claim
from cpas_ocp.inference.whatif import WhatIfResult


def grid_text(t: np.ndarray) -> str:
    """One line describing a shooting grid `t` (s)."""
    steps = np.diff(t)
    finest, longest = float(np.min(steps)), float(np.max(steps))
    if longest - finest < 1e-9:
        return f"shooting grid: {len(t)} nodes, uniform {finest * 1e3:g} ms"
    fine = int(np.sum(steps < finest * 1.5))
    return (f"shooting grid: {len(t)} nodes, steps {finest * 1e3:g}-{longest * 1e3:g} ms "
            f"({fine} of {len(steps)} intervals at the finest, from the dynamics)")


def claim_text(claim: Claim) -> str:
    """The claim's verdict, then why it is not a result, the start windows moved and the
    notes, a line each."""
    lines = [f"claim: {claim.verdict()}"]
    lines += [f"  - {p}" for p in claim.problems()]
    lines += [f"  - moved {m}" for m in claim.moves]
    lines += [f"  - {note}" for note in claim.notes]
    return "\n".join(lines)


def intensity_text(choice: IntensityChoice) -> str:
    """Each wind-process intensity tried: its sigmas, chi-square and -2 log evidence (or why
    its fit failed), the one chosen marked."""
    lines = ["wind-process intensity by marginal likelihood (-2 log evidence, lower is "
             "better):"]
    for p in choice.points:
        mark = "  <- chosen" if p is choice.best else ""
        value = (f"chi-square {p.chi_square:11.1f}, -2 log evidence {p.evidence:11.1f}"
                 if p.evidence is not None else p.note)
        horizontal = (f", horizontal {p.sigma_horizontal:6.3f} m/s" if choice.horizontal
                      else "")
        lines.append(f"  vertical {p.sigma_vertical:6.3f} m/s{horizontal}: {value}{mark}")
    return "\n".join(lines)


def whatif_text(result: WhatIfResult, top: int = 8) -> str:
    """The study in the terminal: cost, test, sensitivities, moved parameters, worse data."""
    lines = [f"constraint{'s' if len(result.constraints) > 1 else ''}: "
             + "; ".join(c.text for c in result.constraints)]
    dof = len(result.active)
    cov = result.covariance
    scaled = f"; {result.statistic:.2f} after dividing by chi^2/dof" if cov and cov.scaled else ""
    lines.append(f"chi-square {result.free.chi_square:.1f} -> {result.constrained.chi_square:.1f}"
                 f"  (increase {result.delta_chi_square:.2f}{scaled}; likelihood-ratio p = "
                 f"{result.p_value:.3g} on {dof} active constraint{'s' if dof != 1 else ''})")
    units = {c.name: c.unit for c in result.constraints}
    for name, d in result.constrained.sensitivities.items():
        unit = units[name]
        state = "active" if name in result.active else "inactive"
        lines.append(f"  {name}: d(chi^2)/d(value) = {d:+.4g} per {unit} ({state})")
    lines.append("parameters that moved most (in sigma of the unconstrained fit):")
    moved = sorted(result.shifts().items(), key=lambda kv: -abs(np.nan_to_num(kv[1][2])))
    for name, (a, b, z) in moved[:top]:
        lines.append(f"  {name:30s} {a:12.6g} -> {b:12.6g}  ({z:+.2f} sigma)")
    lines.append("chi-square change per channel: " + ", ".join(
        f"{k} {v:+.1f}" for k, v in list(result.channel_changes().items())[:top]))
    lines.append("windows that got worse: " + "; ".join(
        f"{c} {t0:.1f}-{t1:.1f} s {r:+.1f}" for c, t0, t1, r in result.window_changes()))
    return "\n".join(lines)
