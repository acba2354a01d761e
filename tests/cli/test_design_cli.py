"""`cpas-ocp design PLAN --out DIR`: a bad plan gets one line naming the plan file, the
field and the expectation, exit code 2, and nothing written; a good one writes its folder."""

from __future__ import annotations

import json
from collections.abc import Callable
from pathlib import Path

import pandas as pd
import pytest

from cpas_ocp.cli import main

GOOD = {
    "format": "cpas-ocp/test-plan/1",
    "problem": "fbcp",
    "interest": ["Ck[fbcp1,stage1]"],
    "changes": [{"label": "GPS at 20 Hz", "sensor": {"name": "gps", "rate_hz": 20}}],
    "failures": False,
}


def _candidate(sensor: dict) -> Callable[[dict], None]:
    def change(plan: dict) -> None:
        plan["candidates"] = [{"name": "c", "sensors": [{"name": "gps"}, sensor]}]
    return change


def _set(key: str, value: object) -> Callable[[dict], None]:
    def change(plan: dict) -> None:
        plan[key] = value
    return change


BAD = {
    "unknown kind": (_candidate({"name": "lidar", "kind": "lidar", "rate_hz": 10,
                                 "sigma": {"range": {"value": 1, "unit": "m"}}}),
                     "candidates[0].sensors[1].kind"),
    "rate zero": (_candidate({"name": "imu", "rate_hz": 0}), "candidates[0].sensors[1].rate_hz"),
    "rate negative": (_candidate({"name": "imu", "rate_hz": -5}),
                      "candidates[0].sensors[1].rate_hz"),
    "new sensor without rate": (_candidate({"name": "imu2", "kind": "imu_load_factor",
                                            "sigma": {"load_factor": {"value": 0.01,
                                                                      "unit": "g"}}}),
                                "candidates[0].sensors[1].rate_hz"),
    "load cell of no canopy": (_candidate({"name": "riser_fbcp1", "parachute": "main9"}),
                               "candidates[0].sensors[1].parachute"),
    "noise group of another kind": (_candidate({"name": "imu", "sigma": {
        "tension": {"value": 1, "unit": "lbf"}}}), "candidates[0].sensors[1].sigma.tension"),
    "phase that does not exist": (_candidate({"name": "imu", "phases": ["stage7"]}),
                                  "candidates[0].sensors[1].phases"),
    "event never observed": (_set("changes", [{"label": "x", "event_sigma": {
        "landing": {"value": 1, "unit": "s"}}}]), "changes[0].event_sigma.landing"),
    "problem unknown": (_set("problem", "nosuch"), "problem"),
    "interest unknown": (_set("interest", ["Ck[fbcp9,stage1]"]), "interest"),
}


@pytest.mark.parametrize("case", sorted(BAD))
def test_a_bad_plan_gets_one_line_and_exit_2(case: str, tmp_path: Path, capsys) -> None:
    change, field = BAD[case]
    plan = json.loads(json.dumps(GOOD))
    change(plan)
    path = tmp_path / "plan.json"
    path.write_text(json.dumps(plan))
    out = tmp_path / "out"
    assert main(["design", str(path), "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1, err
    assert str(path) in err and field in err, err
    assert not out.exists()


def test_a_plan_that_is_not_there_or_not_json_exits_2(tmp_path: Path, capsys) -> None:
    assert main(["design", str(tmp_path / "none.json"), "--out", str(tmp_path / "o")]) == 2
    bad = tmp_path / "bad.json"
    bad.write_text("{")
    assert main(["design", str(bad), "--out", str(tmp_path / "o")]) == 2
    lines = capsys.readouterr().err.strip().splitlines()
    assert len(lines) == 2 and "none.json" in lines[0] and "bad.json" in lines[1]
    assert not (tmp_path / "o").exists()


def test_a_good_plan_writes_its_folder_and_names_its_ranking(tmp_path: Path, capsys) -> None:
    path = tmp_path / "plan.json"
    path.write_text(json.dumps(GOOD))
    out = tmp_path / "out"
    assert main(["design", str(path), "--out", str(out)]) == 0
    text = capsys.readouterr().out
    assert "GPS at 20 Hz" in text and "without riser_fbcp1" in text
    assert {p.name for p in out.iterdir()} == {"design.json", "design.html", "sigma.csv",
                                               "changes.csv", "failures.csv"}
    changes = pd.read_csv(out / "changes.csv")
    assert list(changes["rank"]) == list(range(1, len(changes) + 1))
    scores = changes["sigma_removed"].fillna(-float("inf")).to_numpy()
    assert all(scores[:-1] >= scores[1:])
    record = json.loads((out / "design.json").read_text())
    assert record["interest"] == ["Ck[fbcp1,stage1]"]
