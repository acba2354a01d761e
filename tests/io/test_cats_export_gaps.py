"""A CATS export with a part missing: the import says what it did without it, and refuses
what it cannot read in one line with nothing else printed."""

from __future__ import annotations

import json
import shutil
import warnings
from pathlib import Path

import pytest

from cpas_ocp.cli import main
from cpas_ocp.io.example_flight import fly
from tests.io.test_rocket_log_import import CARD, write_cats


@pytest.fixture(scope="module")
def export(tmp_path_factory: pytest.TempPathFactory) -> Path:
    root = tmp_path_factory.mktemp("cats")
    write_cats(fly(), root / "export", seed=8)
    (root / "card.json").write_text(json.dumps(CARD))
    return root


def _import(export: Path, folder: Path, out: Path) -> int:
    return main(["import", str(folder), "--format", "cats", "--card",
                 str(export / "card.json"), "--out", str(out)])


@pytest.mark.parametrize(("states", "said"), [
    (None, "the export has no flightStates.csv, so the flight events are detected from the "
           "data"),
    ("No data recorded", "the export records no flight states in flightStates.csv, so the "
                         "flight events are detected from the data"),
    ("ts,state\n1.0,9\n2.0,0\n", "the export records no flight states in flightStates.csv, so "
                                 "the flight events are detected from the data")])
def test_an_export_without_flight_states_says_its_events_are_detected(
        export: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str], states: str | None,
        said: str) -> None:
    folder = tmp_path / "export"
    shutil.copytree(export / "export", folder)
    if states is None:
        (folder / "flightStates.csv").unlink()
    else:
        (folder / "flightStates.csv").write_text(states)
    assert _import(export, folder, tmp_path / "test") == 0
    report = json.loads((tmp_path / "test" / "import.json").read_text())
    assert said in report["notes"]
    assert f"note: {said}" in capsys.readouterr().out
    assert {"drogue", "main"} <= set(report["flight_events"])
    assert all(e["source"] != "flight state" for e in report["flight_events"].values())


def test_an_export_whose_accelerometer_cells_are_all_blank_is_one_line_and_no_warning(
        export: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """Every Ax, Ay, Az blank: one line naming imu.csv and its columns, exit 2, and no
    numpy "Mean of empty slice" warning printed before it."""
    folder = tmp_path / "export"
    shutil.copytree(export / "export", folder)
    lines = (folder / "imu.csv").read_text().splitlines()
    blank = [",".join([*row.split(",")[:2], "", "", "", *row.split(",")[5:]])
             for row in lines[1:]]
    (folder / "imu.csv").write_text("\n".join([lines[0], *blank]) + "\n")
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        code = _import(export, folder, tmp_path / "test")
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and len(err) == 1 and "imu.csv: Ax/Ay/Az:" in err[0], err
    assert not [w for w in caught if issubclass(w.category, RuntimeWarning)], \
        [str(w.message) for w in caught]
    assert not (tmp_path / "test").exists()
