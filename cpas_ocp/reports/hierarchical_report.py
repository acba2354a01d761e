"""What `cpas-ocp hierarchical` prints and writes: each population's median with its interval
and tau, every copy at the joint mode beside its own test's estimate, and whether the fit is
a result.

Written to the output folder all at once: hierarchical.md, hierarchical.csv (one row per
population), copies.csv (one row per copy) and hierarchical.json.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd

from cpas_ocp.inference.hierarchical_fit import LEVEL, HierarchicalFit
from cpas_ocp.io.output_folder import atomic_folder
from cpas_ocp.io.strict_json import json_text
from cpas_ocp.precision import rounded, sigma_text, with_interval

MARKER = "hierarchical.json"


def population_frame(hf: HierarchicalFit) -> pd.DataFrame:
    """One row per population (SI): median, its interval at LEVEL, the sigma of log median,
    tau (log space) and whether it was estimated, and the number of copies."""
    return pd.DataFrame([{"population": p.name, "median": p.median, "lower": p.lower,
                          "upper": p.upper, "mu_std": p.mu_std, "tau": p.tau,
                          "tau_estimated": p.tau_estimated, "copies": len(p.copies)}
                         for p in hf.populations])


def copies_frame(hf: HierarchicalFit) -> pd.DataFrame:
    """One row per copy (SI): its value at the joint mode (drawn towards the median by the
    population), and its own test's estimate and sigma alone."""
    rows = []
    for p in hf.populations:
        for key, value in p.copies.items():
            t, name = key.split(":", 1)
            i = int(t)
            rows.append({"population": p.name, "test": hf.labels[i], "parameter": name,
                         "value": value, "alone": hf.individual[i].parameters[name],
                         "alone_std": hf.individual_covariances[i].std.get(name, np.nan)})
    return pd.DataFrame(rows)


def hierarchical_text(hf: HierarchicalFit) -> str:
    """The fit in a few lines, a table of the populations (each median to the precision its
    interval allows; a shared parameter to its sigma's), and why it is not a result where it
    is not."""
    s = hf.stats
    lines = [f"Hierarchical fit of {len(hf.fits)} tests: {s.status}; {hf.evaluations} solves "
             f"for tau; chi-square {hf.chi2:.1f} on {hf.dof} degrees of freedom (the copies' "
             f"pseudo-observations counted).", "",
             f"| population | median | {LEVEL:.0%} interval | tau (log) | copies |",
             "|---|---|---|---|---|"]
    for p in hf.populations:
        median, interval = with_interval(p.median, p.lower, p.upper)
        tau = f"{p.tau:.3g}" + ("" if p.tau_estimated else " (held)")
        lines.append(f"| {p.name} | {median} | {interval} | {tau} | {len(p.copies)} |")
    for s_est in hf.shared:
        lines.append(f"| {s_est.name} (shared) | {rounded(s_est.value, s_est.std)} | "
                     f"sigma {sigma_text(s_est.std)} | | {len(s_est.members)} |")
    if not hf.is_result:
        lines += ["", "**Not a result.** " + " ".join(f"{p[0].upper()}{p[1:]}."
                                                      for p in hf.problems)]
    return "\n".join(lines)


def write_hierarchical(hf: HierarchicalFit, out: Path) -> Path:
    """hierarchical.md, hierarchical.csv, copies.csv and hierarchical.json in `out`, written
    whole."""
    with atomic_folder(out, MARKER) as tmp:
        (tmp / "hierarchical.md").write_text(hierarchical_text(hf) + "\n")
        population_frame(hf).to_csv(tmp / "hierarchical.csv", index=False)
        copies_frame(hf).to_csv(tmp / "copies.csv", index=False)
        (tmp / MARKER).write_text(json_text({
            "tests": hf.labels, "status": hf.stats.status, "solves": hf.evaluations,
            "chi2": hf.chi2, "dof": hf.dof, "result": hf.is_result, "problems": hf.problems,
            "level": LEVEL,
            "populations": population_frame(hf).to_dict(orient="records"),
            "shared": [{"name": s.name, "value": s.value, "std": s.std} for s in hf.shared]}))
    return out
