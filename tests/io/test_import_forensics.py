"""The import says whether each canopy opened (`import_steps.canopy_forensics`), and a fit
of a canopy the log shows did not open is no result for that canopy
(`result_claim.failed_deployments`)."""

from __future__ import annotations

import json
from pathlib import Path
from types import SimpleNamespace

import pytest

from cpas_ocp.cli import main
from cpas_ocp.inference.result_claim import Claim, failed_deployments
from tests.io.test_rocket_log_import import CARD, COLUMN_MAP, fly, write_mapped


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


def test_a_normal_recovery_is_imported_as_opened(tmp_path: Path,
                                                 capsys: pytest.CaptureFixture[str]) -> None:
    report, _ = _import(tmp_path, ("drogue", "main"), {"drogue": 0.467, "main": 5.78}, 5,
                        capsys)
    assert [e["verdict"] for e in report["deployments"].values()] == ["opened", "opened"]


def test_the_claim_names_a_canopy_that_did_not_open(tmp_path: Path) -> None:
    """A folder whose import found the drogue did not open and the main opened: the claim
    lists the drogue's sentence and is no result; a folder without forensics lists none."""
    (tmp_path / "import.json").write_text(json.dumps({"deployments": {
        "drogue": {"verdict": "not_opened", "sentence": "the drogue did not open: X"},
        "main": {"verdict": "opened", "sentence": "the main opened: Y",
                 "above_diameter": False}}}))
    fit = SimpleNamespace(test=SimpleNamespace(
        parachutes=[SimpleNamespace(name="drogue"), SimpleNamespace(name="main")],
        path=tmp_path))
    found = failed_deployments(fit)  # type: ignore[arg-type]
    assert found == ["the drogue did not open: X; the fit's drag area for the drogue is not "
                     "that canopy's"]
    claim = Claim(100.0, 100, 0.5, [], failed_deployments=found)
    assert not claim.is_result and claim.problems()[0] == found[0]
    assert claim.verdict() == "NOT A RESULT"
    fit.test.path = tmp_path / "elsewhere"
    assert failed_deployments(fit) == []  # type: ignore[arg-type]
