"""What the library holds, listed for the terminal: the built-in test phases and the
effects a model block may name."""

from __future__ import annotations

from collections.abc import Mapping

from cpas_ocp.io.problems import load_problem, problem_names
from cpas_ocp.physics.effects.registry import BASELINE, BUILTIN, EffectType


def problems_text() -> str:
    """Each built-in test phase: its name, title and label."""
    lines = []
    for name in problem_names():
        prob = load_problem(name)
        lines.append(f"{name:12s} {prob.title}\n{'':12s} {prob.label}")
    return "\n".join(lines)


def effects_text(plugins: Mapping[str, EffectType]) -> str:
    """Every effect of the library and of `plugins`: a mark where it is in the baseline set,
    its name, summary and options, and the file it comes from where not the library."""
    lines = []
    for name, entry in {**BUILTIN, **plugins}.items():
        mark = "*" if name in BASELINE else " "
        options = ", ".join(entry.options()) or "-"
        lines.append(f"{mark} {name:17s} {entry.summary}\n  {'':17s} options: {options}"
                     + (f"; from {entry.source}" if entry.source != "cpas_ocp" else ""))
    lines.append("\n* in the baseline set (used when a manifest has no model block)")
    return "\n".join(lines)
