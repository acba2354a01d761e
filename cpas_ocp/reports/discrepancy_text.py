"""Where the model fails, in the terminal: a diagnosis, the air-motion evidence, a
discovery chain, and two models compared."""

from __future__ import annotations

import math

from cpas_ocp.discrepancy.diagnosis import Diagnosis
from cpas_ocp.discrepancy.discovery import Discovery
from cpas_ocp.discrepancy.wind_evidence import WindEvidence
from cpas_ocp.inference.model_comparison import Comparison, channel_rms


def diagnosis_text(diag: Diagnosis) -> str:
    """The diagnosis as the command line prints it: the worst fit, each score test, the
    refits, the air motion's evidence, the residual's structure and the verdict."""
    lines = [f"worst fit: {diag.worst}", "",
             f"score tests of the effects the model does not use (significant: p < "
             f"{diag.alpha:g}/{diag.family}):"]
    lines += [f"  {t}" for t in diag.effects]
    refits = [t.refit_text() for t in diag.effects if t.refit_text()]
    if refits:
        lines += ["", "refits with the leading effects:"] + ["  " + r for r in refits]
    if diag.air is not None:
        lines += ["", wind_evidence_text(diag.air)]
    lines += ["", "residual structure:"]
    lines += [f"  {f}" for f in diag.structure[:8]] or ["  none significant"]
    lines += ["", diag.verdict()]
    return "\n".join(lines + diag.notes)


def wind_evidence_text(evidence: WindEvidence) -> str:
    """The air motion's evidence as a diagnosis prints it: the altitude sensors' shared
    residual, and each vertical wind-process intensity's evidence against still air."""
    lines = [f"air motion (the altitude sensors share their residual, Fisher's p = "
             f"{evidence.common_p:.2g}): a vertical wind process, knots every "
             f"{evidence.process.knot_s:g} s, tau {evidence.process.tau_s:g} s, against still "
             f"air (-2 log evidence {evidence.still:.1f}):"]
    for p in evidence.points:
        value = (f"chi-square {p.chi_square:.1f}, -2 log evidence {p.evidence:.1f}, "
                 f"2 ln B = {evidence.still - p.evidence:.1f}" if p.evidence is not None
                 else p.note)
        lines.append(f"  sigma {p.sigma_vertical:.3g} m/s: {value}")
    return "\n".join(lines)


def discovery_text(chain: Discovery) -> str:
    """The chain as a table, then why it stopped and the last verdict."""
    lines = [f"{'step':>4}  {'added':22s} {'chi-square':>11s} {'chi2/dof':>8s} "
             f"{'AIC':>10s} {'BIC':>10s} {'time':>6s}  worst window (normalised RMS); "
             "admitted by"]
    for k, s in enumerate(chain.steps):
        c = s.criteria
        worst = s.worst_window
        where = f"{worst[0]} ({worst[1]:.2f})" if worst else "not diagnosed"
        lines.append(f"{k:4d}  {s.label:22s} {c.chi_square:11.1f} "
                     f"{c.chi_square / s.fit.dof:8.3f} {c.aic:10.1f} {c.bic:10.1f} "
                     f"{s.found_s + s.diagnosed_s:5.0f}s  "
                     f"{where}" + (f"; {s.admitted_by}" if s.admitted_by else "")
                     + (f"; fit from {s.start}" if s.start else ""))
    lines += [""] + [line for s in chain.steps[1:] for line in s.explained_lines()]
    if chain.proposals:
        lines += ["", "plug-ins proposed from the residual's signature, tested as written:"]
        lines += [f"  {t}" for t in chain.proposals]
    if chain.refinements:
        lines += ["", "refinements of the effects added (a structural constant freed), tested "
                      "against the effect as it was:"]
        lines += [f"  {t}" for t in chain.refinements]
    if chain.regressions:
        lines += ["", "drag laws by sparse regression (every term against none, then the weakest "
                      "dropped until each passes):"]
        lines += [f"  {t}" for t in chain.regressions]
    lines += ["", f"ending: {chain.ending()}"] + [f"note: {n}" for n in chain.notes]
    last = chain.steps[-1].diagnosis if chain.steps else None
    if last is not None:
        lines += ["", "last diagnosis: " + last.verdict()]
    return "\n".join(lines)


def comparison_text(comparison: Comparison) -> str:
    """The comparison table, the test, and the per-channel residual RMS before and after."""
    a, b = comparison.criteria
    labels = comparison.labels
    width = max(len(lbl) for lbl in labels) + 2
    lines = [f"{'model':{width}s} {'chi^2':>12s} {'k':>4s} {'n':>7s} {'AIC':>12s} "
             f"{'BIC':>12s}"]
    for label, c in zip(labels, (a, b), strict=True):
        lines.append(f"{label:{width}s} {c.chi_square:12.2f} {c.k:4d} {c.n:7d} "
                     f"{c.aic:12.2f} {c.bic:12.2f}")
    lines.append(f"AIC prefers {labels[int(b.aic < a.aic)]} by "
                 f"{abs(a.aic - b.aic):.1f}; BIC prefers {labels[int(b.bic < a.bic)]} "
                 f"by {abs(a.bic - b.bic):.1f}")
    lines.append(comparison.note + (f": {comparison.lr}" if comparison.lr is not None else ""))
    before, after = channel_rms(comparison.fits[0]), channel_rms(comparison.fits[1])
    lines += ["", f"{'normalised RMS':28s} {labels[0]:>12s} {labels[1]:>12s}"]
    lines += [f"{ch:28s} {before[ch]:12.3f} {after.get(ch, math.nan):12.3f}"
              for ch in before]
    return "\n".join(lines)
