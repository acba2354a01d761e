"""Drag-area ratios between configurations, from a campaign table with a known wake deficit."""

from __future__ import annotations

import numpy as np
import pandas as pd

from cpas_ocp.campaign import COLUMNS
from cpas_ocp.configuration_ratios import drag_area_ratios


def test_ratio_recovers_a_known_deficit_within_its_standard_error() -> None:
    """40 drogue tests behind forebody A and 20 behind B, where B's wake leaves 0.9 of the
    drag area: the ratio B/A must be 0.9 within 4 of its propagated standard errors, and that
    standard error must match the spread of the ratio over repeated campaigns."""
    ratios, errors = [], []
    for seed in range(200):
        rng = np.random.default_rng(seed)
        rows = []
        for k, forebody in enumerate(["A"] * 40 + ["B"] * 20):
            value = 21.0 * (0.9 if forebody == "B" else 1.0) * (1 + 0.03 * rng.standard_normal())
            rows.append({"test": f"t{k}", "parameter": "CdS", "name": "CdS[drogue1,stage3]",
                         "parachute": "drogue1", "type": "drogue", "stage": "stage3",
                         "forebody": forebody, "cluster_size": 2, "value": value, "std": 0.2,
                         "unit": "m^2"})
        result = drag_area_ratios(pd.DataFrame(rows, columns=COLUMNS), "forebody")
        row = result[result.forebody == "B"].iloc[0]
        assert row.reference == "A" and row.tests == 20
        ratios.append(row.ratio)
        errors.append(row.ratio_se)
        if seed == 0:
            assert abs(row.ratio - 0.9) < 4 * row.ratio_se
    ratios = np.array(ratios)
    # The propagated standard error against the observed spread: a sample sd over 200
    # campaigns is itself uncertain by about 1/sqrt(2 * 199) = 5 %; allow 4 of those.
    assert abs(ratios.std(ddof=1) / np.mean(errors) - 1.0) < 4 * 0.05
    assert abs(ratios.mean() - 0.9) < 4 * ratios.std(ddof=1) / np.sqrt(len(ratios))
