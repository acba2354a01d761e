"""What a joint fit prints and writes: the shared parameters against each test's own fit.

`joint_frame` has a row per shared parameter and copy: the joint estimate and
its standard deviation beside the copy's own estimate from its test fitted
alone (a drag area behind a wake is PRF*CdS there).  `joint_text` is what
`cpas-ocp joint` prints; `write_joint` writes joint.md, joint.csv (that table),
parameters.csv (every test's free parameters at the joint solution with their
standard deviations) and joint.json, whole or not at all.
"""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
import pandas as pd

from cpas_ocp.io.output_folder import atomic_folder
from cpas_ocp.io.strict_json import json_text

if TYPE_CHECKING:
    from cpas_ocp.inference.joint_fit import JointFit

MARKER = "joint.json"


def joint_frame(jf: JointFit) -> pd.DataFrame:
    """Per shared parameter and copy: the joint estimate and sigma, the copy's own (SI)."""
    rows = []
    for s in jf.shared:
        for t, name in s.members:
            own = jf.individual_covariances[t]
            rows.append({"shared": s.name, "value": s.value, "std": s.std,
                         "test": jf.labels[t], "parameter": name,
                         "alone": jf.individual[t].parameters[name],
                         "alone_std": own.std.get(name, np.nan)})
    return pd.DataFrame(rows)


def parameter_table(jf: JointFit) -> pd.DataFrame:
    """Every test's free parameters at the joint solution (SI) with their sigmas."""
    shared = {(t, n): s.name for s in jf.shared for t, n in s.members}
    rows = []
    for t, (label, fit) in enumerate(zip(jf.labels, jf.fits, strict=True)):
        for name in fit.free:
            key = f"{t}:{name}"
            rows.append({"test": label, "parameter": name, "value": fit.parameters[name],
                         "std": jf.covariance.std.get(key, np.nan),
                         "shared_as": shared.get((t, name), "")})
    return pd.DataFrame(rows)


def joint_text(jf: JointFit) -> str:
    """The joint fit in a few lines and a table of the shared parameters."""
    s = jf.stats
    lines = [f"Joint fit of {len(jf.fits)} tests: {s.status} after {s.iterations} iterations "
             f"({s.wall_s:.1f} s); chi-square {jf.chi2:.1f} on {jf.dof} degrees of freedom "
             f"(chi2/dof {jf.chi2 / max(jf.dof, 1):.3f}).", "",
             "| shared parameter | joint estimate | sigma | copies | alone (range) |",
             "|---|---|---|---|---|"]
    frame = joint_frame(jf)
    for s_est in jf.shared:
        alone = frame.loc[frame["shared"] == s_est.name, "alone"]
        sigma = f"{s_est.std:.3g}" if s_est.determined else "not determined"
        lines.append(f"| {s_est.name} | {s_est.value:.5g} | {sigma} | "
                     f"{len(s_est.members)} | {alone.min():.4g} to {alone.max():.4g} |")
    alone_chi2 = sum(2 * f.solver.objective for f in jf.individual)
    lines += ["", f"Each test alone: chi-square {alone_chi2:.1f} with "
              f"{sum(len(f.free) for f in jf.individual)} free parameters; jointly "
              f"{jf.chi2:.1f} with {jf.n_free}."]
    if not jf.is_result:
        lines += ["", "**Not a result.** " + " ".join(f"{p[0].upper()}{p[1:]}." for p in
                                                    jf.problems)]
    if not all(s_est.determined for s_est in jf.shared):
        lines += ["", "The tests together do not determine every shared parameter; the "
                  "combinations left open (test index:parameter):"]
        lines += [f"- {w}" for w in jf.covariance.weak if w.std is None]
    return "\n".join(lines)


def write_joint(jf: JointFit, out: Path) -> None:
    """joint.md, joint.csv, parameters.csv and joint.json in `out`, written whole."""
    with atomic_folder(out, MARKER) as tmp:
        (tmp / "joint.md").write_text(joint_text(jf) + "\n")
        joint_frame(jf).to_csv(tmp / "joint.csv", index=False)
        parameter_table(jf).to_csv(tmp / "parameters.csv", index=False)
        (tmp / MARKER).write_text(json_text({
            "tests": jf.labels, "status": jf.stats.status, "iterations": jf.stats.iterations,
            "chi2": jf.chi2, "dof": jf.dof, "fit_p_value": jf.fit_p_value,
            "result": jf.is_result, "problems": jf.problems,
            "shared": [{"name": s.name, "value": s.value, "std": s.std,
                        "copies": [{"test": jf.labels[t], "parameter": n} for t, n in s.members]}
                       for s in jf.shared]}))
