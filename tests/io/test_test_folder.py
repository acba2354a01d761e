"""Test-folder format: schema, units at the boundary, simulator determinism and naming."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pandas as pd

from cpas_ocp.estimation.simulate import simulate_problem
from cpas_ocp.io.flight_test import load_test
from cpas_ocp.io.problems import load_problem, problem_names
from cpas_ocp.physics.effects import baseline_effects
from cpas_ocp.physics.model import Model
from cpas_ocp.physics.units import FACTORS, FT, LBF

SCHEMAS = Path(__file__).resolve().parents[2] / "data_schemas"


def test_schema_units_match_the_converter() -> None:
    series = json.loads((SCHEMAS / "series.schema.json").read_text())
    for dim, table in FACTORS.items():
        assert sorted(series["$defs"][f"unit_{dim}"]["enum"]) == sorted(table)


def test_units_converted_at_the_boundary(drogue_folder) -> None:
    folder = drogue_folder(1)
    test = load_test(folder)
    raw = pd.read_csv(folder / "gps.csv")
    gps = test.sensors_of("gps")[0].data
    np.testing.assert_allclose(gps["up"], raw["up"] * FT)
    raw = pd.read_csv(folder / "riser_drogue1.csv")
    cell = next(s for s in test.sensors if s.name == "riser_drogue1").data
    np.testing.assert_allclose(cell["tension"], raw["tension"] * LBF)
    assert test.vehicle.mass == 20000 * 0.45359237
    assert test.parachutes[0].diameter == 23 * FT


def test_simulation_is_reproducible_by_seed(tmp_path) -> None:
    problem = load_problem("drogue")
    a = simulate_problem(problem, tmp_path / "a", seed=7)
    b = simulate_problem(problem, tmp_path / "b", seed=7)
    c = simulate_problem(problem, tmp_path / "c", seed=8)
    for sa, sb, sc in zip(a.sensors, b.sensors, c.sensors, strict=True):
        pd.testing.assert_frame_equal(sa.data, sb.data)
        assert not sa.data.equals(sc.data)


def test_truth_uses_the_reconstruction_names(drogue_folder) -> None:
    folder = drogue_folder(1)
    truth = json.loads((folder / "truth.json").read_text())["parameters"]
    model = Model(load_test(folder), baseline_effects())
    assert set(truth) == set(model.parameter_names)


def test_drogue_is_listed() -> None:
    assert "drogue" in problem_names()
