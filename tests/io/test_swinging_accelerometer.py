"""A swinging rocket's accelerometer weighed at its information, and still air found still.

A rocket swinging under its drogue reads its swing on the axial accelerometer as a noise
correlated over a fraction of a second.  Counted sample by sample as white, a 100 Hz
accelerometer outweighs the altimeter many times over, and the fit bends the air's motion
and the drag area to follow its wander.  The import writes each steady segment as block
means of its correlation length (`log_noise.accelerometer_blocks`), and the default
model holds the vertical air's mean over the descent (`wind_process`
`sigma_mean_vertical`): a seeded descent in still air, reconstructed with the default
model, gives its true drag area and a mean vertical wind of zero within two sigma.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from cpas_ocp.cli import main
from cpas_ocp.estimation.estimator import Estimator
from cpas_ocp.io.example_flight import CDS, RATE_HZ, fly
from cpas_ocp.io.flight_test import load_test
from cpas_ocp.physics.effects.wind_process import WindProcess
from cpas_ocp.physics.units import G0
from tests.io.test_rocket_log_import import CARD, COLUMN_MAP, write_mapped

SWING_TAU_S = 0.4  # correlation time of the swing's AR(1) part (s)
SWING_SIGMA = 1.2  # its stationary sigma (m/s^2)
SWING_AMPLITUDE = 0.8  # a pendulum swing's sinusoid on top (m/s^2) ...
SWING_PERIOD_S = 1.7  # ... of this period (s) and a random phase


def swing(t: np.ndarray, seed: int) -> np.ndarray:
    """The axial reading's swing (m/s^2, zero mean): an AR(1) noise of correlation time
    SWING_TAU_S and sigma SWING_SIGMA plus a sinusoid of SWING_PERIOD_S at a random
    phase."""
    rng = np.random.default_rng(seed)
    a = np.exp(-1.0 / (RATE_HZ * SWING_TAU_S))
    e = rng.normal(0.0, SWING_SIGMA * np.sqrt(1.0 - a * a), t.size)
    ar = np.zeros(t.size)
    for k in range(1, t.size):
        ar[k] = a * ar[k - 1] + e[k]
    return ar + SWING_AMPLITUDE * np.sin(2.0 * np.pi * t / SWING_PERIOD_S
                                         + rng.uniform(0.0, 2.0 * np.pi))


@pytest.fixture(scope="module")
def swinging_descent(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A drogue descent of about 30 s in still air logged at 100 Hz, the axial reading
    swinging (`swing`), imported with the card's model left to the rocket default."""
    folder = tmp_path_factory.mktemp("swing")
    flight = fly(thrust_n=1000.0, drogue_delay_s=0.0, chutes=("drogue",))
    write_mapped(flight, folder / "log.csv", seed=3)
    table = pd.read_csv(folder / "log.csv")
    table["ay_g"] = np.round(table["ay_g"] - swing(table["t_ms"].to_numpy() / 1e3, 11) / G0, 4)
    table.to_csv(folder / "log.csv", index=False, float_format="%.7g")
    card = {k: v for k, v in CARD.items() if k != "model"}
    card["parachutes"] = [p for p in CARD["parachutes"] if p["name"] == "drogue"]
    (folder / "card.json").write_text(json.dumps(card))
    (folder / "map.json").write_text(json.dumps(COLUMN_MAP))
    assert main(["import", str(folder / "log.csv"), "--columns", str(folder / "map.json"),
                 "--card", str(folder / "card.json"), "--out", str(folder / "test")]) == 0
    return folder / "test"


def test_a_swinging_descent_in_still_air_gives_its_drag_area_and_no_wind(
        swinging_descent: Path) -> None:
    """The folder holds the accelerometer in block means (fewer rows than the log's
    samples in the phase); the default model's fit gives the drogue's true drag area
    within 2 sigma and the air's mean vertical velocity over the descent within 2 sigma
    of zero."""
    test = load_test(swinging_descent)
    samples = json.loads((swinging_descent / "import.json").read_text())["samples"]
    phase_samples = (test.t_end - test.t_start) * RATE_HZ
    assert samples["accelerometer.csv"] < phase_samples / 5
    est = Estimator(test)
    fit = est.solve()
    cov = est.covariance(fit)
    name = "CdS[drogue,stage1]"
    assert abs(fit.parameters[name] - CDS["drogue"]) < 2.0 * cov.std[name]
    wind = next(e for e in fit.model.effects if isinstance(e, WindProcess))
    assert wind.sigma_mean_vertical is not None
    weights = wind.mean_weights(test, "up", test.t_start, test.t_end)
    g = np.array([weights.get(n, 0.0) for n in cov.names])
    mean, sigma = sum(w * fit.parameters[k] for k, w in weights.items()), float(
        np.sqrt(g @ cov.matrix @ g))
    assert abs(mean) < 2.0 * sigma
