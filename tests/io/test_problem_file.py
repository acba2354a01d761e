"""The problem file (`data_schemas/problem.schema.json`): every built-in problem that is not
an extension of another is one, and a test plan's `problem_file` is checked against it,
a mistake named by its file and field."""

from __future__ import annotations

import json
from importlib import resources
from pathlib import Path

import pytest

from cpas_ocp.errors import InputError
from cpas_ocp.io.flight_test_plan import load_plan
from cpas_ocp.io.json_files import validate_block


def _built_in() -> list[str]:
    folder = resources.files("cpas_ocp.problem_data")
    return sorted(f.name for f in folder.iterdir() if f.name.endswith(".json")
                  and not {"kind", "extends"} & set(json.loads(f.read_text())))


@pytest.mark.parametrize("name", _built_in())
def test_every_built_in_problem_is_a_problem_file(name: str) -> None:
    body = json.loads(resources.files("cpas_ocp.problem_data").joinpath(name).read_text())
    validate_block(body, "problem.schema.json", name)


def _plan_with(tmp_path: Path, change) -> Path:
    body = json.loads(resources.files("cpas_ocp.problem_data").joinpath("fbcp.json")
                      .read_text())
    change(body)
    (tmp_path / "planned.json").write_text(json.dumps(body))
    plan = tmp_path / "plan.json"
    plan.write_text(json.dumps({"format": "cpas-ocp/test-plan/1",
                                "problem_file": "planned.json"}))
    return plan


def test_a_plan_reads_its_problem_file(tmp_path) -> None:
    plan = load_plan(_plan_with(tmp_path, lambda body: body.update(name="planned")))
    assert plan.problem.name == "planned"
    assert [s.name for s in plan.candidates[0].sensors] == [
        s["name"] for s in plan.problem.manifest["sensors"]]


@pytest.mark.parametrize("change, field", [
    (lambda b: b["simulation"]["rates_hz"].update(gps=-10), "simulation.rates_hz.gps"),
    (lambda b: b["simulation"]["initial_state"].update(velocity=[1.0, 2.0]),
     "simulation.initial_state.velocity"),
    (lambda b: b["truth"].pop("parameters"), "truth.parameters"),
    (lambda b: b.update(extends="drogue"), "(top level)"),  # an unknown field: named in
])                                                          # the message
def test_a_mistake_in_a_problem_file_is_named(tmp_path, change, field) -> None:
    with pytest.raises(InputError) as raised:
        load_plan(_plan_with(tmp_path, change))
    assert raised.value.file.endswith("planned.json")
    assert raised.value.field.startswith(field), raised.value
    assert field != "(top level)" or "'extends'" in raised.value.expectation
