"""The example recorder log (`cpas_ocp.io.example_flight.example_log`): an Altus Metrum
export of the known flight and its card, which `cpas-ocp import` reads as written, and
whose deployment forensics say what the flight did: both canopies opened with their own
drag areas, or, where the main never inflated, that it did not."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from cpas_ocp.cli import main
from cpas_ocp.io.example_flight import CDS, example_log


def _imported(folder: Path) -> dict:
    assert main(["import", str(folder / "flight.csv"), "--card", str(folder / "card.json"),
                 "--out", str(folder / "test")]) == 0
    return json.loads((folder / "test" / "import.json").read_text())


def test_the_example_log_imports_and_each_canopy_opened(tmp_path: Path) -> None:
    report = _imported(example_log(tmp_path, seed=3))
    assert report["recorder"].startswith("Altus Metrum")
    for name, verdict in report["deployments"].items():
        assert verdict["verdict"] == "opened", verdict["sentence"]
        own = verdict["own"]
        # The settled descent's drag area covers the truth within its stated sigma.
        assert abs(own["value_m2"] - CDS[name]) <= 3.0 * own["sigma_m2"], (name, own)


def test_a_main_that_never_inflated_is_said_so(tmp_path: Path) -> None:
    report = _imported(example_log(tmp_path, seed=4, main_opens=False))
    main_ = report["deployments"]["main"]
    assert main_["verdict"] == "not_opened"
    assert main_["sentence"].startswith("the main did not inflate")
    assert report["deployments"]["drogue"]["verdict"] == "opened"


@pytest.mark.parametrize("seed", [1, 2])
def test_the_example_is_seeded(tmp_path: Path, seed: int) -> None:
    a = example_log(tmp_path / "a", seed=seed).joinpath("flight.csv").read_text()
    b = example_log(tmp_path / "b", seed=seed).joinpath("flight.csv").read_text()
    c = example_log(tmp_path / "c", seed=seed + 10).joinpath("flight.csv").read_text()
    assert a == b and a != c
