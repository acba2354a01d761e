"""The import says whether each canopy opened (`import_steps.canopy_forensics`), and a fit
of a canopy the log shows did not open is no result for that canopy
(`result_claim.deployment_findings`): the import holds it closed, fitting the airframe's
drag area where nothing opened."""

from __future__ import annotations

import json
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pandas as pd
import pytest

from cpas_ocp.cli import main
from cpas_ocp.inference.result_claim import Claim, deployment_findings
from cpas_ocp.io.example_flight import fly
from tests.io.test_rocket_log_import import CARD, COLUMN_MAP, write_mapped


def _import(tmp_path: Path, chutes: tuple[str, ...], cds: dict[str, float], seed: int,
            capsys: pytest.CaptureFixture[str]) -> tuple[dict, str]:
    """Fly a rocket whose canopies reach `cds` (0: it never opens), log it, import it under a
    card naming `chutes`; the import report and what the terminal showed."""
    flight = fly(cds=cds, chutes=chutes, thrust_n=2600.0)
    write_mapped(flight, tmp_path / "log.csv", seed=seed)
    accel = {**COLUMN_MAP["acceleration"], "axis": "-y"}
    (tmp_path / "map.json").write_text(json.dumps({**COLUMN_MAP, "acceleration": accel}))
    card = {**CARD, "parachutes": [c for c in CARD["parachutes"] if c["name"] in chutes]}
    (tmp_path / "card.json").write_text(json.dumps(card))
    assert main(["import", str(tmp_path / "log.csv"), "--columns", str(tmp_path / "map.json"),
                 "--card", str(tmp_path / "card.json"), "--out", str(tmp_path / "test")]) == 0
    return (json.loads((tmp_path / "test" / "import.json").read_text()),
            capsys.readouterr().out)


@pytest.mark.parametrize("seed", [3, 4])
def test_a_ballistic_descent_is_imported_as_a_drogue_that_did_not_open(
        tmp_path: Path, seed: int, capsys: pytest.CaptureFixture[str]) -> None:
    """The drogue's charge fires and nothing opens: the rocket falls at 150 m/s under its
    airframe's drag, which its coast measured; the import says so in a plain sentence."""
    report, out = _import(tmp_path, ("drogue",), {"drogue": 0.0}, seed, capsys)
    drogue = report["deployments"]["drogue"]
    assert drogue["verdict"] == "not_opened"
    assert drogue["sentence"].startswith("the drogue did not open")
    assert "deployment: the drogue did not open" in out
    # What the descent needs is the airframe's drag area (0.012 m^2 in the simulation).
    assert drogue["drag_area_m2"] < 0.05
    # The fit holds the drogue closed and estimates the airframe's drag area instead.
    model = json.loads((tmp_path / "test" / "manifest.json").read_text())["model"]
    assert "CdS_V" in model["free"]
    assert {"CdS[drogue,stage1]", "t_start[drogue,stage1]"} <= set(model["fix"])


def test_a_model_without_the_airframes_drag_does_not_say_it_fits_it(
        tmp_path: Path, capsys: pytest.CaptureFixture[str],
        monkeypatch: pytest.MonkeyPatch) -> None:
    """A card whose own model leaves out forebody_drag: the drogue that did not open is held
    closed, and neither the manifest nor the note claims an airframe's drag area fitted."""
    model = {"effects": [e for e in CARD["model"]["effects"] if e != "forebody_drag"]}
    monkeypatch.setitem(CARD, "model", model)
    report, _ = _import(tmp_path, ("drogue",), {"drogue": 0.0}, 3, capsys)
    assert report["deployments"]["drogue"]["verdict"] == "not_opened"
    manifest = json.loads((tmp_path / "test" / "manifest.json").read_text())
    assert "CdS_V" not in manifest["model"].get("free", [])
    [note] = [n for n in report["notes"] if "did not open" in n and "held closed" in n]
    assert "CdS_V" not in note


def test_a_normal_recovery_is_imported_as_opened(tmp_path: Path,
                                                 capsys: pytest.CaptureFixture[str]) -> None:
    report, _ = _import(tmp_path, ("drogue", "main"), {"drogue": 0.467, "main": 5.78}, 5,
                        capsys)
    assert [e["verdict"] for e in report["deployments"].values()] == ["opened", "opened"]


def _fit_of(folder: Path, deployments: dict, free: tuple[str, ...] = ("CdS_V",)
            ) -> SimpleNamespace:
    """A stand-in fit of a test folder whose import found `deployments`: what
    `deployment_findings` reads of a fit (its canopies' names, the folder and the free
    parameters)."""
    (folder / "import.json").write_text(json.dumps({"deployments": deployments}))
    return SimpleNamespace(test=SimpleNamespace(
        parachutes=[SimpleNamespace(name=name) for name in deployments], path=folder),
        free=list(free))


def test_the_claim_says_what_did_not_open(tmp_path: Path) -> None:
    """Nothing opened: no result, the fit being the airframe's.  The main did not inflate
    beside a drogue that opened: the fit is the drogue's, said beside it.  A streamer is
    said.  A folder that was not imported says nothing."""
    closed = {"verdict": "not_opened", "sentence": "the drogue did not open: X"}
    opened = {"verdict": "opened", "sentence": "the drogue opened: Y", "above_diameter": False}
    failed, notes = deployment_findings(_fit_of(tmp_path, {"drogue": closed}))  # type: ignore[arg-type]
    assert failed == ["the drogue did not open: X; the fit holds it closed and fits the "
                      "airframe's drag area (CdS_V) instead"] and notes == []
    claim = Claim(100.0, 100, 0.5, [], failed_deployments=failed)
    assert not claim.is_result and claim.problems()[0] == failed[0]
    # A model without the airframe's drag (the card's own, without forebody_drag) fits no
    # CdS_V, and the sentence does not say it does.
    failed, _ = deployment_findings(_fit_of(tmp_path, {"drogue": closed}, free=()))  # type: ignore[arg-type]
    assert failed == ["the drogue did not open: X; the fit holds it closed"]
    main_closed = {"verdict": "not_opened", "sentence": "the main did not inflate: Z"}
    failed, notes = deployment_findings(_fit_of(  # type: ignore[arg-type]
        tmp_path, {"drogue": opened, "main": main_closed}))
    assert failed == [] and notes == ["the main did not inflate: Z; the fit holds it closed"]
    claim = Claim(100.0, 100, 0.5, [], deployment_notes=notes)
    assert claim.is_result and claim.headline().startswith("The main did not inflate: Z")
    streamer = {"verdict": "partial", "sentence": "the drogue opened only in part: W"}
    assert deployment_findings(_fit_of(tmp_path, {"drogue": streamer})) == (  # type: ignore[arg-type]
        [], ["the drogue opened only in part: W"])
    too_big = {**opened, "above_diameter": True}
    failed, _ = deployment_findings(_fit_of(tmp_path, {"drogue": too_big}))  # type: ignore[arg-type]
    assert len(failed) == 1 and "more than that canopy's" in failed[0]
    fit = _fit_of(tmp_path, {"drogue": closed})
    fit.test.path = tmp_path / "elsewhere"
    assert deployment_findings(fit) == ([], [])  # type: ignore[arg-type]


def test_a_ground_impact_at_the_log_s_end_is_no_charge(tmp_path: Path,
                                                       capsys: pytest.CaptureFixture[str]
                                                       ) -> None:
    """A ballistic descent whose log ends at the impact, with its 30 g jolt: the jolt is the
    ground, not a charge deploying a canopy the card lacks, and the import goes on."""
    flight = fly(cds={"drogue": 0.0}, chutes=("drogue",), thrust_n=2600.0,
                 seconds_after_touchdown=0.3)
    write_mapped(flight, tmp_path / "log.csv", seed=6)
    log = pd.read_csv(tmp_path / "log.csv")
    hit = int(np.argmin(np.abs(1e-3 * log["t_ms"].to_numpy() - flight.events["landed"])))
    log.loc[hit:hit + 2, "ay_g"] = -30.0  # the axial axis is -y: +30 g along it
    log.to_csv(tmp_path / "log.csv", index=False, float_format="%.7g")
    accel = {**COLUMN_MAP["acceleration"], "axis": "-y"}
    (tmp_path / "map.json").write_text(json.dumps({**COLUMN_MAP, "acceleration": accel}))
    card = {**CARD, "parachutes": [CARD["parachutes"][0]]}
    (tmp_path / "card.json").write_text(json.dumps(card))
    assert main(["import", str(tmp_path / "log.csv"), "--columns", str(tmp_path / "map.json"),
                 "--card", str(tmp_path / "card.json"), "--out", str(tmp_path / "test")]) == 0
    report = json.loads((tmp_path / "test" / "import.json").read_text())
    assert "main" not in report["flight_events"]
    assert any("the impact on the ground, not an ejection charge" in n
               for n in report["notes"])
    assert report["deployments"]["drogue"]["verdict"] == "not_opened"


def test_a_drag_area_its_descent_contradicts_is_no_result(tmp_path: Path) -> None:
    """A fitted drag area beside what its settled descent needs (the import's forensics):
    within the family-wise 1 % level it stands; beyond it (a main pinned at 13.8 m^2 by its
    opening's shape where its descent needs 31.9 +- 1.0) the claim refuses, naming both."""
    from scipy.stats import norm

    from cpas_ocp.inference.result_claim import DESCENT_LEVEL, descent_disagreements
    opened = {"verdict": "opened", "sentence": "s", "above_diameter": False}
    deployments = {"drogue": {**opened, "own": {"value_m2": 0.593, "sigma_m2": 0.038}},
                   "main": {**opened, "own": {"value_m2": 31.9, "sigma_m2": 1.0}}}
    fit = _fit_of(tmp_path, deployments, free=("CdS[drogue,open]", "CdS[main,open]"))
    for chute in fit.test.parachutes:
        chute.stages = ["open"]
    std = {"CdS[drogue,open]": 0.015, "CdS[main,open]": 2.7}
    limit = norm.isf(DESCENT_LEVEL / 4)  # two canopies compared, two-sided
    # The main 0.9 of the limit below what its descent needs: it stands.
    main_ok = 31.9 - 0.9 * limit * np.hypot(2.7, 1.0)
    fit.parameters = {"CdS[drogue,open]": 0.598, "CdS[main,open]": main_ok}
    assert descent_disagreements(fit, lambda: std) == []  # type: ignore[arg-type]
    # 1.1 of the limit: refused, with both numbers.
    fit.parameters["CdS[main,open]"] = 31.9 - 1.1 * limit * np.hypot(2.7, 1.0)
    [sentence] = descent_disagreements(fit, lambda: std)  # type: ignore[arg-type]
    assert sentence.startswith("the main's fitted drag area CdS[main,open]")
    assert "31.9 ± 1.0 m^2 its settled descent needs" in sentence
    # A canopy that did not open, or one needing more than its diameter gives, is judged
    # by its own sentence, not this one.
    deployments["main"] = {**deployments["main"], "above_diameter": True}
    fit = _fit_of(tmp_path, deployments, free=("CdS[drogue,open]", "CdS[main,open]"))
    for chute in fit.test.parachutes:
        chute.stages = ["open"]
    fit.parameters = {"CdS[drogue,open]": 0.598, "CdS[main,open]": 13.8}
    assert descent_disagreements(fit, lambda: std) == []  # type: ignore[arg-type]
