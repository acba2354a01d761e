"""A user's mistake gets one line naming file and field, exit code 2, and nothing written."""

from __future__ import annotations

import json
import shutil
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from cpas_ocp.cli import main


def _csv(folder: Path, name: str, change: Callable[[pd.DataFrame], pd.DataFrame]) -> None:
    path = folder / name
    change(pd.read_csv(path)).to_csv(path, index=False)


def _manifest(folder: Path, change: Callable[[dict], None]) -> None:
    path = folder / "manifest.json"
    m = json.loads(path.read_text())
    change(m)
    path.write_text(json.dumps(m))


def _nan_run(d: pd.DataFrame) -> pd.DataFrame:
    d.loc[100:119, "load_factor"] = np.nan
    return d


def _swap_times(d: pd.DataFrame) -> pd.DataFrame:
    d.loc[[10, 11], "time"] = d.loc[[11, 10], "time"].to_numpy()
    return d


def _set(path: list, value) -> Callable[[dict], None]:
    def change(m: dict) -> None:
        node = m
        for key in path[:-1]:
            node = node[key]
        node[path[-1]] = value
    return change


CASES = {
    "missing column": (lambda f: _csv(f, "riser_drogue1.csv", lambda d: d.drop(columns="tension")),
                       "riser_drogue1.csv", "tension"),
    "NaN run": (lambda f: _csv(f, "imu.csv", _nan_run), "imu.csv", "load_factor"),
    "non-monotonic time": (lambda f: _csv(f, "gps.csv", _swap_times), "gps.csv", "time"),
    "unknown unit": (lambda f: _manifest(f, _set(["sensors", 0, "columns", "up"], "furlong")),
                     "manifest.json", "sensors[0].columns.up"),
    "negative mass": (lambda f: _manifest(f, _set(["vehicle", "mass", "value"], -5.0)),
                      "manifest.json", "vehicle.mass"),
    "event outside the data": (lambda f: _manifest(f, _set(["events", 0, "time", "value"], 99.0)),
                               "manifest.json", "events[0].time"),
}


@pytest.mark.parametrize("case", list(CASES))
def test_bad_input_is_one_line_exit_2_nothing_written(case, drogue_folder, tmp_path, capsys):
    mutate, file, field = CASES[case]
    folder = tmp_path / "test"
    shutil.copytree(drogue_folder(1), folder)
    mutate(folder)
    out = tmp_path / "report"
    code = main(["reconstruct", str(folder), "--out", str(out)])
    err = capsys.readouterr().err.strip()
    assert code == 2
    assert len(err.splitlines()) == 1, err
    assert file in err and field in err, err
    assert "Traceback" not in err
    assert not out.exists()


def test_nan_run_names_the_rows(drogue_folder, tmp_path, capsys):
    folder = tmp_path / "test"
    shutil.copytree(drogue_folder(1), folder)
    _csv(folder, "imu.csv", _nan_run)
    assert main(["reconstruct", str(folder), "--out", str(tmp_path / "r")]) == 2
    assert "rows 101-120" in capsys.readouterr().err


def test_missing_folder(tmp_path, capsys):
    assert main(["reconstruct", str(tmp_path / "nowhere"), "--out", str(tmp_path / "r")]) == 2
    assert "manifest.json" in capsys.readouterr().err
