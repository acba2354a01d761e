"""The worked example of docs/test-folder.md is real: its manifest, taken from the page as
printed, with an altimeter series simulated from that manifest, is a test folder that
loads and reconstructs.

The altimeter-only rocket (a drogue fired at apogee, the main at 19.5 s, a `site`
atmosphere) is simulated by the product's simulator with drag areas 0.47 and 5.8 m^2
(seed 1); the page's manifest is written beside the simulated `altimeter.csv`, whose
first rows must be the ones the page prints.  The reconstruction must converge to a
result within the noise and recover both drag areas and the main's start time within
4 sigma; the estimator starts from the offline reduction and never sees the truth.
"""

from __future__ import annotations

import json
import re
import shutil
from io import StringIO
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

import cpas_ocp as co
from cpas_ocp.estimation.simulate import simulate_problem
from cpas_ocp.io.flight_test import load_test
from cpas_ocp.io.problems import Problem
from cpas_ocp.physics.atmosphere import SiteAtmosphere
from cpas_ocp.physics.flight_test import FlightTest

PAGE = Path(__file__).resolve().parents[2] / "docs" / "test-folder.md"

# The synthetic truth (SI) and flight the series are simulated from: each canopy starts
# to inflate 0.5 s after its mortar fire, as the page's events say.
TRUTH = {"CdS[drogue,open]": 0.47, "n[drogue,open]": 10.0, "expopen[drogue,open]": 1.0,
         "t_start[drogue,open]": 1.0, "CdS[main,open]": 5.8, "n[main,open]": 8.0,
         "expopen[main,open]": 1.0, "t_start[main,open]": 20.0}
SIMULATION = {"t_begin": 0.0, "t_end": 40.0, "step": 0.002,
              # Apogee 2,400 m above mean sea level, drifting east at 5 m/s.
              "initial_state": {"position": [0.0, 0.0, 2400.0], "velocity": [5.0, 0.0, 0.0]},
              "rates_hz": {"altimeter": 10}}
SEED = 1


def page_example(file: str) -> str:
    """The fenced block the page marks as the example's `file`, as printed."""
    found = re.search(rf"<!-- test-folder-example: {re.escape(file)} -->\s*```\w*\n(.*?)```",
                      PAGE.read_text(), re.DOTALL)
    assert found is not None, f"docs/test-folder.md marks its example's {file}"
    return found.group(1)


@pytest.fixture(scope="module")
def folder(tmp_path_factory) -> Path:
    """The page's manifest, verbatim, with the altimeter series simulated from it."""
    root = tmp_path_factory.mktemp("altimeter_only")
    manifest = json.loads(page_example("manifest.json"))
    events = [{"name": e["name"], "parachute": e["parachute"], "time": e["time"]["value"],
               "sigma": e["sigma"]["value"]} for e in manifest["events"]]
    problem = Problem("altimeter_only", "altimeter-only rocket", "synthetic", manifest,
                      {**SIMULATION, "events": events}, TRUTH)
    simulate_problem(problem, root / "simulated", SEED)
    test = root / "test"
    test.mkdir()
    (test / "manifest.json").write_text(page_example("manifest.json"))
    for sensor in manifest["sensors"]:
        shutil.copy(root / "simulated" / sensor["file"], test / sensor["file"])
    return test


def test_the_printed_rows_are_the_simulated_series(folder: Path) -> None:
    printed = pd.read_csv(StringIO(page_example("altimeter.csv")))
    simulated = pd.read_csv(folder / "altimeter.csv")
    assert list(printed.columns) == list(simulated.columns) == ["time", "altitude"]
    head = simulated.head(len(printed))
    np.testing.assert_array_equal(printed["time"], head["time"])
    np.testing.assert_allclose(printed["altitude"], head["altitude"], atol=1e-3)  # ft


def test_the_example_loads_as_an_altimeter_only_test(folder: Path) -> None:
    test = load_test(folder)
    assert [s.kind for s in test.sensors] == ["baro"]
    assert isinstance(test.atmosphere, SiteAtmosphere)
    assert test.atmosphere.lapse_rate_k_m == pytest.approx(0.008)
    assert [(e.name, e.parachute) for e in test.events] == [("mortar_fire", "drogue"),
                                                            ("mortar_fire", "main")]
    assert (test.t_start, test.t_end) == (0.0, 40.0)


@pytest.mark.slow
def test_the_example_reconstructs(folder: Path) -> None:
    test: FlightTest = load_test(folder)
    rec = co.reconstruct(test)
    assert rec.is_result, rec.problems
    n = rec.fit.dof
    assert abs(rec.chi_square_per_dof - 1.0) < 4.0 * (2.0 / n) ** 0.5
    table = rec.parameters
    for name in ("CdS[drogue,open]", "CdS[main,open]", "t_start[main,open]"):
        value, sigma = table.loc[name, "value"], table.loc[name, "sigma"]
        assert abs(value - TRUTH[name]) < 4.0 * sigma, (name, value, sigma)
        print(f"{name}: {value:.4f} +- {sigma:.4f} (truth {TRUTH[name]})")
    print(f"chi2/dof {rec.chi_square_per_dof:.3f} on {n} dof")
