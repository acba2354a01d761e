"""Drag-area ratios between configurations, from campaign tables with a known wake deficit
and known line-length and cluster-size effects."""

from __future__ import annotations

import numpy as np
import pandas as pd

from cpas_ocp.campaign.campaign import COLUMNS
from cpas_ocp.campaign.configuration_ratios import (
    campaign_ratios,
    drag_area_ratios,
    varies_within_a_stage,
)


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


def test_line_length_grouping_gives_tables_2_and_3() -> None:
    """Drogues with L_s/D_o 1.5 and 2.0, one or two per cluster: the longer lines give 9 %
    more drag and the pair 3 % less than one canopy (paper Tables 2-3 magnitudes), each
    recovered within 4 of its propagated standard errors; a table whose line lengths are
    all empty gets no line-length study."""
    rng = np.random.default_rng(3)
    d_o = 23 * 0.3048
    rows = []
    for k in range(120):
        ratio, size = (1.5, 2.0)[k % 2], (1, 2)[(k // 2) % 2]
        value = 21.0 * (1.09 if ratio == 2.0 else 1.0) * (0.97 if size == 2 else 1.0)
        rows.append({"test": f"t{k}", "parameter": "CdS", "name": "CdS[drogue1,stage3]",
                     "parachute": "drogue1", "type": "drogue", "stage": "stage3",
                     "forebody": "PTV", "cluster_size": size, "line_length": ratio * d_o,
                     "value": value * (1 + 0.02 * rng.standard_normal()), "std": 0.2,
                     "unit": "m^2"})
    table = pd.DataFrame(rows, columns=COLUMNS)
    studies = campaign_ratios(table)
    assert set(studies) == {"forebody", "cluster_size", "line_length",
                            "cluster_size_by_line_length"}
    by_length = drag_area_ratios(table, "line_length", reference=1.5 * d_o,
                                 within=("cluster_size",))
    for row in by_length[by_length.line_length == 2.0 * d_o].itertuples():
        assert row.tests == 30 and abs(row.ratio - 1.09) < 4 * row.ratio_se, row
    table3 = studies["cluster_size_by_line_length"]
    assert sorted(table3.line_length.unique()) == [1.5 * d_o, 2.0 * d_o]
    for row in table3[table3.cluster_size == 2].itertuples():
        # 30 tests of each size: the tie goes to the first size, the single canopy.
        assert row.reference == 1 and abs(row.ratio - 0.97) < 4 * row.ratio_se, row
    assert not varies_within_a_stage(table.assign(line_length=np.nan), "line_length")
    assert "line_length" not in campaign_ratios(table.assign(line_length=np.nan))
