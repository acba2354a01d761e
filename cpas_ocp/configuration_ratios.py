"""Grouping and wake studies: mean drag-area ratios between test configurations.

The paper's Tables 1-3 compare a canopy's steady drag area across
configurations: behind one forebody or another (the wake deficit), alone or
in a cluster of two or three (cluster efficiency).  From a campaign's table
the steady drag area CdS[P,S] of every canopy is averaged per parachute type,
stage and configuration value; the ratio of each configuration's mean to the
reference configuration's mean carries the standard error of both means
(first-order propagation of independent means:
(sigma_r / r)^2 = (se_a / a)^2 + (se_b / b)^2, se the standard error of the
mean over tests, or the mean of the fits' own sigmas where one test only).
"""

from __future__ import annotations

import numpy as np
import pandas as pd

CONFIGURATIONS = ("forebody", "cluster_size")


def drag_area_ratios(table: pd.DataFrame, by: str, reference: object | None = None
                     ) -> pd.DataFrame:
    """Per type and stage, mean CdS per value of the column `by` and its ratio to the
    `reference` value (default: the value with the most tests)."""
    if by not in table.columns:
        raise ValueError(f"no column {by!r} in the campaign table")
    cds = table[table.parameter == "CdS"]
    rows = []
    for (kind, stage), group in cds.groupby(["type", "stage"], sort=True):
        stats = {}
        for value, g in group.groupby(by, sort=True):
            values = g["value"].to_numpy()
            se = (values.std(ddof=1) / np.sqrt(len(values)) if len(values) > 1
                  else float(g["std"].mean()))
            stats[value] = (float(values.mean()), float(se), len(values))
        if reference is not None and reference in stats:
            ref = reference
        else:
            ref = max(stats, key=lambda v: stats[v][2])
        mean_ref, se_ref, _ = stats[ref]
        for value, (mean, se, n) in stats.items():
            ratio = mean / mean_ref
            rel = np.hypot(se / mean, se_ref / mean_ref) if value != ref else 0.0
            rows.append({"type": kind, "stage": stage, by: value, "tests": n,
                         "mean_CdS": mean, "se_CdS": se, "reference": ref, "ratio": ratio,
                         "ratio_se": ratio * rel})
    return pd.DataFrame(rows, columns=["type", "stage", by, "tests", "mean_CdS", "se_CdS",
                                       "reference", "ratio", "ratio_se"])
