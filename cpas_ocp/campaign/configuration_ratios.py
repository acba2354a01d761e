"""Grouping and wake studies: mean drag-area ratios between test configurations.

The paper's Tables 1-3 compare a canopy's steady drag area across
configurations: behind one forebody or another (the wake deficit), alone or
in a cluster of two or three (cluster efficiency), with suspension lines of
one length or another (Table 2: L_s/D_o 2.0 against 1.5; Table 3: cluster
size within each line length).  From a campaign's table
the steady drag area CdS[P,S] of every canopy is averaged per parachute type,
stage and configuration value; the ratio of each configuration's mean to the
reference configuration's mean carries the standard error of both means
(first-order propagation of independent means:
(sigma_r / r)^2 = (se_a / a)^2 + (se_b / b)^2, se the standard error of the
mean over tests, or the mean of the fits' own sigmas where one test only).
Canopies whose manifest gives no value of a configuration (an empty line
length) take no part in its comparison.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import pandas as pd

CONFIGURATIONS = ("forebody", "cluster_size")
# Tabulated only where the manifests give it and it varies within a type and stage.
LINE_LENGTH = "line_length"


def drag_area_ratios(table: pd.DataFrame, by: str, reference: object | None = None,
                     within: Sequence[str] = ()) -> pd.DataFrame:
    """Per type and stage (and per value of each column in `within`), mean CdS per value of
    the column `by` and its ratio to the `reference` value (default: the value with the
    most tests)."""
    for column in (by, *within):
        if column not in table.columns:
            raise ValueError(f"no column {column!r} in the campaign table")
    cds = table[table.parameter == "CdS"]
    rows = []
    for key, group in cds.groupby(["type", "stage", *within], sort=True):
        kind, stage, *inside = key
        stats = {}
        for value, g in group.groupby(by, sort=True):
            values = g["value"].to_numpy()
            se = (values.std(ddof=1) / np.sqrt(len(values)) if len(values) > 1
                  else float(g["std"].mean()))
            stats[value] = (float(values.mean()), float(se), len(values))
        if not stats:  # no canopy of this type and stage has a value of `by`
            continue
        if reference is not None and reference in stats:
            ref = reference
        else:
            ref = max(stats, key=lambda v: stats[v][2])
        mean_ref, se_ref, _ = stats[ref]
        for value, (mean, se, n) in stats.items():
            ratio = mean / mean_ref
            rel = np.hypot(se / mean, se_ref / mean_ref) if value != ref else 0.0
            rows.append({"type": kind, "stage": stage, **dict(zip(within, inside, strict=True)),
                         by: value, "tests": n, "mean_CdS": mean, "se_CdS": se,
                         "reference": ref, "ratio": ratio, "ratio_se": ratio * rel})
    return pd.DataFrame(rows, columns=["type", "stage", *within, by, "tests", "mean_CdS",
                                       "se_CdS", "reference", "ratio", "ratio_se"])


def varies_within_a_stage(table: pd.DataFrame, column: str) -> bool:
    """Whether some parachute type and stage has steady drag areas at two or more values of
    `column` (empty values not counted)."""
    if column not in table.columns:
        return False
    cds = table[table.parameter == "CdS"]
    return bool((cds.groupby(["type", "stage"])[column].nunique() > 1).any())


def campaign_ratios(table: pd.DataFrame) -> dict[str, pd.DataFrame]:
    """The ratio tables a campaign writes, by name: per forebody and per cluster size; where
    the line length varies, per line length (Table 2) and per cluster size within each line
    length (Table 3)."""
    out = {by: drag_area_ratios(table, by) for by in CONFIGURATIONS}
    if varies_within_a_stage(table, LINE_LENGTH):
        out[LINE_LENGTH] = drag_area_ratios(table, LINE_LENGTH)
        out[f"cluster_size_by_{LINE_LENGTH}"] = drag_area_ratios(table, "cluster_size",
                                                                 within=(LINE_LENGTH,))
    return out
