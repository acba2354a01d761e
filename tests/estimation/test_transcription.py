"""The multiple-shooting transcription reproduces the simulator on noise-free data.

The simulator integrates at 0.5 ms and stops exactly at every capture time;
the estimator takes one RK4 step per shooting interval and predicts a sample
that falls between nodes by a partial RK4 step from the node before it.  On
noise-free data both must agree to far below the noise, whether or not the
samples sit on nodes.
"""

from __future__ import annotations

import json

import pytest

from cpas_ocp.estimation.estimator import Estimator, Settings
from cpas_ocp.estimation.simulate import simulate_problem
from cpas_ocp.io.flight_test import load_test
from cpas_ocp.io.problems import load_problem


@pytest.mark.parametrize("grid_step", [0.005, 0.004])
def test_noise_free_fbcp_fits_to_zero(tmp_path, grid_step: float) -> None:
    """5 ms puts every 200 Hz sample on a node; 4 ms puts four in five between nodes."""
    folder = tmp_path / "clean"
    simulate_problem(load_problem("fbcp"), folder, seed=1, noise=False)
    truth = json.loads((folder / "truth.json").read_text())["parameters"]
    fit = Estimator(load_test(folder), settings=Settings(grid_step=grid_step)).solve(
        progress=False)
    assert fit.solver.success, fit.solver.status
    # One noisy sample alone contributes about 1 to chi-square; CSV rounding to 9
    # digits and the coarser integration leave far less than that in total.
    assert fit.chi_square < 0.01
    for name in fit.free:
        assert fit.parameters[name] == pytest.approx(truth[name], rel=1e-3, abs=2e-5), name
