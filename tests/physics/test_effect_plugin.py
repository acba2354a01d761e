"""A new physical effect is one file: no edit of the model, the estimator or the CLI.

The effect here, an accelerometer bias, is the Python source below, written
to a plug-in file inside the test folder and named in the manifest's model
block.  Data are simulated with it; `cpas-ocp reconstruct` with the plug-in
recovers the bias and fits to the noise, while the baseline model cannot
explain the data.
"""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path

import numpy as np
import pytest

from cpas_ocp.cli import main
from cpas_ocp.estimation.estimator import Estimator, Settings
from cpas_ocp.estimation.simulate import simulate_problem
from cpas_ocp.io.flight_test import load_test
from cpas_ocp.io.model_spec import baseline_spec
from cpas_ocp.io.problems import load_problem
from cpas_ocp.physics.effects import baseline_effects
from cpas_ocp.physics.effects.registry import BASELINE, load_plugin
from cpas_ocp.physics.parameters import param_name

pytestmark = pytest.mark.slow

TRUE_BIAS = 0.03  # g; three times the IMU's per-sample noise

PLUGIN = '''"""Constant additive bias b (g) on every IMU load-factor reading: y = |f|/g0 + b."""

from dataclasses import dataclass

from cpas_ocp.physics.effects import Effect
from cpas_ocp.physics.parameters import Parameter, param_name



@dataclass(frozen=True)
class AccelerometerBias(Effect):
    """Constant additive bias b (g) on every IMU load-factor reading."""

    name: str = "accelerometer_bias"

    def parameters(self, test):
        return [Parameter(param_name("imu_bias", s.name), "g", 0.0, -0.5, 0.5,
                          description="load-factor bias", scale=0.01)
                for s in test.sensors_of("imu_load_factor")]

    def observations(self, ctx):
        for s in ctx.test.sensors_of("imu_load_factor"):
            ctx.y[s.name]["load_factor"] = (ctx.y[s.name]["load_factor"]
                                            + ctx.p[param_name("imu_bias", s.name)])
'''


@pytest.fixture(scope="module")
def biased_folder(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """Drogue data simulated with the plug-in; the manifest names it in its model block."""
    plugin = tmp_path_factory.mktemp("plugin") / "accelerometer_bias.py"
    plugin.write_text(PLUGIN)
    bias = load_plugin(plugin)["accelerometer_bias"].build({}, str(plugin), "test")
    problem = load_problem("drogue")
    imu = next(s["name"] for s in problem.manifest["sensors"] if s["kind"] == "imu_load_factor")
    truth = {**problem.truth, param_name("imu_bias", imu): TRUE_BIAS}
    folder = tmp_path_factory.mktemp("biased") / "test"
    simulate_problem(dataclasses.replace(problem, truth=truth), folder, seed=3,
                     effects=[*baseline_effects(), bias])
    (folder / plugin.name).write_text(PLUGIN)
    manifest = json.loads((folder / "manifest.json").read_text())
    manifest["model"] = {"effects": [*BASELINE, "accelerometer_bias"],
                         "plugins": [plugin.name]}
    (folder / "manifest.json").write_text(json.dumps(manifest))
    return folder


def test_plugin_effect_is_estimated_and_explains_the_data(biased_folder: Path,
                                                          tmp_path: Path) -> None:
    out = tmp_path / "report"
    assert main(["reconstruct", str(biased_folder), "--out", str(out)]) == 0
    result = json.loads((out / "result.json").read_text())
    assert "accelerometer_bias" in result["model"]["effects"]
    name = next(n for n in result["parameters"] if n.startswith("imu_bias["))
    entry = result["parameters"][name]
    assert entry["initial"] == 0.0  # the estimator starts from the default, not the truth
    assert abs(entry["value"] - TRUE_BIAS) < 4 * entry["std"]
    assert entry["std"] < TRUE_BIAS / 10
    fit = result["fit"]
    dof = fit["samples"] - fit["free_parameters"]
    assert abs(fit["chi_square_per_dof"] - 1.0) < 5 * np.sqrt(2.0 / dof)

    # The nested model without the bias, refitted from the full fit's estimate (the
    # usual start for a likelihood-ratio comparison).  From the reduction's guess the
    # misspecified baseline fit wanders: Gauss-Newton with 3-sigma systematic IMU
    # residuals ran 500 iterations without converging.
    start = {n: e["value"] for n, e in result["parameters"].items() if n != name}
    test = load_test(biased_folder)
    baseline = Estimator(test, baseline_spec(), Settings(guess=start)).solve()
    # Without the bias the model cannot fit the IMU: chi-square rises by far more than
    # the 1-parameter likelihood-ratio threshold (3.84 at 5 %).
    assert baseline.chi_square - fit["chi_square"] > 100.0
