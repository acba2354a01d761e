"""An effect that is not in the library: canopy breathing, found, named, added as a plug-in.

The FBCP phase is simulated with the drag areas oscillating at 3 Hz (4-5 % of
CdS, `tests/plugins/breathing.py`).  `cpas-ocp diagnose` on the baseline model
must find no library effect that explains the residual, and must describe it:
the load cells, the steady window, a line at 3 Hz.  The plug-in file, with the
frequency read off that diagnosis, is then given to `cpas-ocp compare`: the
likelihood ratio must be significant, the load cells' normalised residual RMS
must fall to the noise, and the oscillation's amplitudes and frequency must be
recovered within the noise.
"""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path

import pandas as pd
import pytest

from cpas_ocp.cli import main
from cpas_ocp.estimation.simulate import simulate_problem
from cpas_ocp.io.problems import load_problem
from cpas_ocp.physics.effects import baseline_effects
from cpas_ocp.physics.effects.registry import BASELINE, load_plugin

pytestmark = pytest.mark.slow

PLUGIN = Path(__file__).parents[2] / "tests" / "plugins" / "breathing.py"
FREQUENCY_HZ = 3.0
AMPLITUDES = {"breathing_cos[fbcp1]": 0.04, "breathing_sin[fbcp1]": 0.02,
              "breathing_cos[fbcp2]": 0.03, "breathing_sin[fbcp2]": -0.03}


@pytest.fixture(scope="module")
def breathing_runs(tmp_path_factory):
    """The test folder, the diagnosis (json) and the comparison (json) made by the CLI."""
    root = tmp_path_factory.mktemp("breathing")
    breathing = load_plugin(PLUGIN)["breathing"].cls(frequency=FREQUENCY_HZ)
    base = baseline_effects()
    problem = load_problem("fbcp")
    truth = {**problem.truth, **AMPLITUDES}
    simulate_problem(dataclasses.replace(problem, truth=truth), root / "test", 1,
                     effects=[base[0], breathing, *base[1:]])
    truth = json.loads((root / "test" / "truth.json").read_text())["parameters"]
    (root / "test" / "truth.json").unlink()
    assert main(["diagnose", str(root / "test"), "--out", str(root / "diagnosis")]) == 0
    diagnosis = json.loads((root / "diagnosis" / "diagnosis.json").read_text())
    top = diagnosis["residual_findings"][0]
    # The plug-in, at the frequency the diagnosis found, in a model file for `compare`.
    model = {"effects": [BASELINE[0], {"effect": "breathing",
                                       "frequency": round(top["frequency_hz"], 2)},
                         *BASELINE[1:]]}
    (root / "breathing.json").write_text(json.dumps(model))
    (root / "baseline.json").write_text(json.dumps({"effects": list(BASELINE)}))
    code = main(["compare", str(root / "test"), "--model", str(root / "baseline.json"),
                 "--model", str(root / "breathing.json"), "--plugin", str(PLUGIN),
                 "--out", str(root / "comparison")])
    assert code == 0
    comparison = json.loads((root / "comparison" / "comparison.json").read_text())
    return root, truth, diagnosis, comparison


def test_diagnosis_names_sensor_window_and_frequency(breathing_runs) -> None:
    root, _, diagnosis, _ = breathing_runs
    assert diagnosis["explanation"] is None, diagnosis["verdict"]
    assert diagnosis["verdict"].startswith("no effect in the library explains the residual")
    top = diagnosis["residual_findings"][0]
    assert top["significant"]
    assert top["sensor"].startswith("riser_fbcp") and top["window"].startswith("steady")
    # Within one frequency bin of the window's periodogram.
    assert abs(top["frequency_hz"] - FREQUENCY_HZ) < 1.0 / (top["t1"] - top["t0"])
    assert top["sensor"] in diagnosis["verdict"] and "Hz" in diagnosis["verdict"]
    assert (root / "diagnosis" / "residuals_riser_fbcp1.png").is_file()


def test_plugin_lowers_the_error_and_recovers_the_oscillation(breathing_runs) -> None:
    root, truth, _, comparison = breathing_runs
    lr = comparison["likelihood_ratio"]
    assert comparison["nesting"] == "baseline is nested in breathing"
    assert lr["p_value"] < 1e-10 and lr["dof"] == 5
    before = comparison["models"]["baseline"]
    after = comparison["models"]["breathing"]
    assert after["aic"] < before["aic"] and after["bic"] < before["bic"]
    # In the steady windows the load cells' residuals fall to the noise: chi^2/n within
    # 4 standard deviations, sqrt(2/n), of 1.
    table = pd.read_csv(root / "comparison" / "windows.csv")
    steady = table[table.sensor.str.startswith("riser_") & table.window.str.startswith("steady")]
    assert len(steady) == 4
    for _, rows in steady.groupby(["sensor", "window"]):
        by_model = rows.set_index("model")
        n = int(by_model.loc["breathing", "samples"])
        assert by_model.loc["breathing", "normalised_rms"] < by_model.loc["baseline",
                                                                          "normalised_rms"]
        assert abs(by_model.loc["breathing", "normalised_rms"] ** 2 - 1.0) < 4.0 * (2.0 / n) ** 0.5
    for name in ["breathing_frequency", *AMPLITUDES]:
        estimate, std = after["parameters"][name], after["std"][name]
        assert abs(estimate - truth[name]) < 4.0 * std, name
    assert after["chi_square"] / after["n"] < 1.0 + 4.0 * (2.0 / after["n"]) ** 0.5
    assert sorted(p.name for p in (root / "comparison").glob("compare_*.png")) == [
        "compare_gps.png", "compare_imu.png", "compare_riser_fbcp1.png",
        "compare_riser_fbcp2.png"]


def test_discover_writes_the_modulation_from_the_signature_and_it_works_as_written(
        breathing_runs) -> None:
    """`discover` on the same data, without the plug-in: the periodic signature makes it
    write a drag-area modulation plug-in, which, tested as written, is confirmed, brings
    chi-square within 5 % of the model that made the data (fitted above by `compare`)
    and leaves residuals consistent with the noise; its step's model file names the
    file, so `reconstruct --model step_1.json` runs it with nothing added."""
    root, _, _, comparison = breathing_runs
    assert main(["discover", str(root / "test"), "--out", str(root / "discovery")]) == 0
    found = json.loads((root / "discovery" / "discovery.json").read_text())
    proposal = found["proposals"][0]
    assert proposal["effect"] == "drag_area_modulation" and proposal["confirmed"]
    assert proposal["file"] == "proposed/drag_area_modulation.py"
    # The truth pulses from the phase's start, the window the line was seen in starts
    # later: its start may be refined, a step of its own, where its likelihood ratio says.
    assert [s["added"] for s in found["steps"][:2]] == [None, "drag_area_modulation"]
    assert [s["refined"] for s in found["steps"][2:]] in ([], ["drag_area_modulation"])
    assert found["stopped"] == "the residuals are consistent with the noise"
    truth_chi2 = comparison["models"]["breathing"]["chi_square"]
    assert abs(found["steps"][1]["chi_square"] - truth_chi2) < 0.05 * truth_chi2
    frequency = proposal["test"]["refit_estimate"]["modulation_frequency"]
    assert abs(frequency - FREQUENCY_HZ) < 1.0 / 3.0  # a periodogram bin of the 3 s window
    step = root / "discovery" / "step_1.json"
    assert json.loads(step.read_text())["plugins"] == ["proposed/drag_area_modulation.py"]
    assert main(["reconstruct", str(root / "test"), "--model", str(step),
                 "--out", str(root / "as_written")]) == 0
    written = json.loads((root / "as_written" / "result.json").read_text())
    assert abs(written["fit"]["chi_square"] - found["steps"][1]["chi_square"]) < 1.0
