"""Two canopies the data cannot tell apart: an identifiability report, not a crash or NaN.

The `drogue` problem is flown with both Drogues mortared together and
inflating alike (drogue2's truth is drogue1's), and without riser load cells:
only GPS and the IMU see the drag, and they see the sum of the two drag
areas.  The reconstruction asserts that the canopies inflate alike (both
held at drogue1's shape and timing from the offline reduction) and estimates
each canopy's drag area per stage.  The data fix CdS[drogue1] + CdS[drogue2]
per stage and nothing about their difference.
"""

from __future__ import annotations

import copy
import json
import math
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from cpas_ocp.cli import main
from cpas_ocp.estimation.estimator import Estimator, Settings
from cpas_ocp.estimation.reduction import initial_guess
from cpas_ocp.estimation.simulate import simulate_problem
from cpas_ocp.io.flight_test import load_test
from cpas_ocp.io.model_spec import spec_of_test
from cpas_ocp.io.problems import load_problem

STAGES = ("stage1", "stage2", "stage3")
SEED = 1


@pytest.fixture(scope="module")
def twin_folder(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The simulated twin-Drogue test folder (no load cells; drogue2 inflates as drogue1)."""
    prob = load_problem("drogue")
    manifest = copy.deepcopy(prob.manifest)
    simulation = copy.deepcopy(prob.simulation)
    manifest["sensors"] = [s for s in manifest["sensors"] if s["kind"] != "load_cell"]
    simulation["rates_hz"] = {k: v for k, v in simulation["rates_hz"].items()
                              if not k.startswith("riser")}
    for event in simulation["events"]:
        if event["name"] == "mortar_fire":
            event["time"] = 1.0
    truth = {k: v for k, v in prob.truth.items()
             if not k.startswith(("loadcell_scale", "drag_scale"))}  # no load cells
    truth.update({k.replace("drogue1", "drogue2"): v for k, v in truth.items()
                  if "[drogue1," in k})
    twin = replace(prob, name="twin", manifest=manifest, simulation=simulation, truth=truth)
    folder = tmp_path_factory.mktemp("twin") / "test"
    simulate_problem(twin, folder, SEED)
    return folder


def _alike(folder: Path) -> tuple[list[str], dict[str, float]]:
    """Free drag areas, and every other parameter held at drogue1's reduction guess."""
    test = load_test(folder)
    spec = spec_of_test(test)
    model = spec.model(test)
    guess = initial_guess(test, model, spec.fixed_values(model))
    names = spec.free_names(model)
    free = [n for n in names if n.startswith("CdS[")]
    fixed = {n: guess[n.replace("drogue2", "drogue1")] for n in names if n not in free}
    return free, fixed


def test_undetermined_differences_are_named_and_the_sums_keep_their_sigma(twin_folder) -> None:
    free, fixed = _alike(twin_folder)
    est = Estimator(load_test(twin_folder), settings=Settings(free=free, fixed=fixed))
    fit = est.solve()
    cov = est.covariance(fit)
    assert fit.solver.success
    assert np.all(np.isfinite(cov.matrix))
    assert sorted(cov.undetermined) == sorted(free) and cov.std == {}
    # One undetermined combination per stage: the two canopies' difference, nothing else.
    assert len(cov.weak) == len(STAGES) and all(w.std is None for w in cov.weak)
    named = set()
    for w in cov.weak:
        (a, wa), (b, wb) = w.weights.items()
        stage = a.split(",")[1].rstrip("]")
        assert {a, b} == {f"CdS[drogue1,{stage}]", f"CdS[drogue2,{stage}]"}
        assert wa == pytest.approx(-wb, abs=1e-6)
        assert abs(wa) == pytest.approx(math.sqrt(0.5), abs=1e-6)
        assert w.other < 1e-3
        named.add(stage)
    assert named == set(STAGES)
    # The sum is determined: a finite sigma under 1 % from the same covariance.  The shapes
    # are held at the reduction's guesses, not fitted, so the sum carries their bias; the
    # 2 % check is on the size of that bias (about 1 % on this seed), not a noise bound.
    truth = json.loads((twin_folder / "truth.json").read_text())["parameters"]
    for stage in STAGES:
        pair = [cov.names.index(f"CdS[{c},{stage}]") for c in ("drogue1", "drogue2")]
        d = np.zeros(len(cov.names))
        d[pair] = 1.0
        total = sum(fit.parameters[cov.names[i]] for i in pair)
        sigma = float(np.sqrt(d @ cov.matrix @ d))
        assert 0.0 < sigma < 0.01 * total, stage
        true_total = truth[f"CdS[drogue1,{stage}]"] + truth[f"CdS[drogue2,{stage}]"]
        assert abs(total - true_total) < 0.02 * true_total, stage


def test_command_line_reports_identifiability_without_nan(twin_folder, tmp_path,
                                                          capsys) -> None:
    """The report names the undetermined combinations, holds no NaN, and the drag areas in
    them make the fit no result."""
    free, fixed = _alike(twin_folder)
    model = tmp_path / "alike.json"
    model.write_text(json.dumps({"fix": fixed}))
    code = main(["reconstruct", str(twin_folder), "--out", str(tmp_path / "report"),
                 "--model", str(model)])
    out, err = capsys.readouterr()
    # Drag areas the data do not determine: not a result (exit 4), the report still written.
    assert code == 4
    assert "the data do not determine the drag area CdS[drogue" in err
    assert "not determined at all" in out
    text = (tmp_path / "report" / "result.json").read_text()

    def refuse(constant: str) -> float:
        raise AssertionError(f"result.json holds {constant}")

    result = json.loads(text, parse_constant=refuse)
    assert len(result["identifiability"]) == len(STAGES)
    for name in free:
        entry = result["parameters"][name]
        assert entry.get("undetermined") is True and "std" not in entry
