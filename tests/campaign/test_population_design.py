"""The design over a population (`campaign.population_design`): each planned canopy takes its
own rows of its type's cases, the candidates are predicted at exactly those parameter sets,
and a plan whose cases are missing or too few is refused naming its field."""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from cpas_ocp.campaign.population_design import design_over_population, population_draws
from cpas_ocp.cli import main
from cpas_ocp.inference.flight_test_design import Planner
from cpas_ocp.io.flight_test_plan import load_plan

PLAN = {"format": "cpas-ocp/test-plan/1", "problem": "fbcp", "failures": False,
        "changes": [], "population": {"cases": "cases", "draws": 2}}


def _plan(tmp_path: Path, cases: pd.DataFrame, **population: object) -> Path:
    folder = tmp_path / "cases"
    folder.mkdir(parents=True)
    cases.to_parquet(folder / "cases_fbcp_stage1.parquet")
    plan = json.loads(json.dumps(PLAN))
    plan["population"].update(population)
    path = tmp_path / "plan.json"
    path.write_text(json.dumps(plan))
    return path


# four Monte Carlo cases of the fbcp type (SI): drag areas and fill constants apart
CASES = pd.DataFrame({"CdS": [1.6, 2.6, 2.0, 2.3], "t_k": [0.10, 0.16, 0.13, 0.11]})


def test_each_canopy_of_a_type_takes_its_own_rows(tmp_path: Path) -> None:
    draws, notes = population_draws(load_plan(_plan(tmp_path, CASES)))
    assert notes == []
    assert [d["CdS[fbcp1,stage1]"] for d in draws] == [1.6, 2.6]
    assert [d["CdS[fbcp2,stage1]"] for d in draws] == [2.0, 2.3]
    assert [d["t_k[fbcp2,stage1]"] for d in draws] == [0.13, 0.11]


@pytest.mark.slow
def test_the_candidates_are_predicted_at_the_drawn_parameters(tmp_path: Path) -> None:
    plan = load_plan(_plan(tmp_path, CASES))
    spread = design_over_population(plan)
    frame = spread.sigma["as planned"]
    assert frame.shape[1] == 2
    draws, _ = population_draws(plan)
    for k, draw in enumerate(draws):  # the same prediction made directly at that truth
        problem = dataclasses.replace(plan.problem, truth={**plan.problem.truth, **draw})
        direct = Planner(problem).predict(plan.candidates[0])
        for name in direct.covariance.std:
            assert frame.loc[name, k] == pytest.approx(direct.sigma(name), rel=1e-9)
    # the drag areas drawn 20 % apart from one another are not predicted alike
    cds = frame.loc["CdS[fbcp1,stage1]"].to_numpy()
    assert abs(np.log(cds[1] / cds[0])) > 0.01
    summary = spread.summary().set_index(["candidate", "parameter"])
    row = summary.loc[("as planned", "CdS[fbcp1,stage1]")]
    assert row["rms"] == pytest.approx(np.sqrt(np.mean(cds**2)))
    assert row["lowest"] == cds.min() and row["highest"] == cds.max()


def test_cases_that_are_not_there_or_too_few_exit_2(tmp_path: Path, capsys) -> None:
    few = _plan(tmp_path / "a", CASES, draws=3)  # two canopies need six rows
    plan = json.loads(few.read_text())
    plan["population"]["cases"] = "nowhere"
    missing = tmp_path / "a" / "missing.json"
    missing.write_text(json.dumps(plan))
    for path, field in ((few, "population.draws"), (missing, "population.cases")):
        out = tmp_path / "out"
        assert main(["design", str(path), "--out", str(out)]) == 2
        err = capsys.readouterr().err.strip()
        assert len(err.splitlines()) == 1 and str(path) in err and field in err, err
        assert not out.exists()
