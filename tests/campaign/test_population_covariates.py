"""Covariates of a population from the manifests: a canopy's position in the cluster (a
covariate by default where a type flies in two or more), the test's and the canopy's own
named covariates, and the share of the between-test variance each explains.

The estimates are drawn from the two-stage model with fixed differences between positions
and no between-test spread, the case where a population without the position reads the
difference as spread (`benchmarks/studies/test_position_coverage.py` scores the
intervals over many campaigns).
"""

from __future__ import annotations

import json

import numpy as np
import pandas as pd
import pytest

from cpas_ocp.campaign import campaign
from cpas_ocp.campaign.campaign import COLUMNS, COVARIANCE_COLUMNS
from cpas_ocp.campaign.population_study import population_groups
from cpas_ocp.cli import main
from cpas_ocp.errors import InputError
from cpas_ocp.io.flight_test import canopy_covariates

NAMES, UNITS = ("CdS", "Ck", "t_k"), ("m^2", "1", "s")
MEDIAN = np.log(np.array([2.0, 1.3, 0.9]))
# log offsets of the second position against the first: t_k 15 % and Ck 4 % apart, CdS
# alike (the two Drogues of a test, one in the other's wake)
OFFSET = np.array([0.0, 0.04, 0.15])
NOISE = np.array([0.01, 0.008, 0.02])  # each estimate's sigma, in log


def campaign_rows(seed: int, tests: int = 8, tau: float = 0.0, configuration: bool = False,
                  cross: float | None = None) -> tuple[pd.DataFrame, pd.DataFrame]:
    """A campaign's parameter and covariance tables: `tests` tests of two Drogues in
    positions `left` and `right`, the right one's parameters offset by OFFSET in log, a
    between-test spread `tau` (log) shared by nothing, each estimate's noise NOISE.  With
    `configuration`, a test covariate alternating A and B of no effect.  With `cross`, the
    covariances between the two canopies' estimates are written too: their CdS
    correlated `cross` (their noise drawn so), every other pair 0."""
    rng = np.random.default_rng(seed)
    rows, cov = [], []
    for t in range(tests):
        test = f"test{t:02d}"
        shared = rng.standard_normal()
        fulls, sds, values = [], [], []
        for chute, position, offset in (("d1", "left", 0.0), ("d2", "right", 1.0)):
            sd = NOISE * rng.uniform(0.7, 1.4, 3)
            noise = rng.standard_normal(3)
            if cross is not None:  # CdS's noise: a part shared by the two canopies
                sign = 1.0 if offset == 0.0 or cross > 0 else -1.0
                noise[0] = (sign * np.sqrt(abs(cross)) * shared
                            + np.sqrt(1.0 - abs(cross)) * noise[0])
            value = np.exp(MEDIAN + offset * OFFSET + tau * rng.standard_normal(3)
                           + sd * noise)
            full = [f"{n}[{chute},stage1]" for n in NAMES]
            fulls.append(full)
            sds.append(sd * value)
            values.append(value)
            for n, f, v, s, u in zip(NAMES, full, value, sd * value, UNITS, strict=True):
                rows.append({"test": test, "parameter": n, "name": f, "parachute": chute,
                             "type": "drogue", "stage": "stage1", "forebody": "capsule",
                             "cluster_size": 2, "line_length": 4.2672, "position": position,
                             "value": v, "std": s, "unit": u}
                            | ({"configuration": "AB"[t % 2]} if configuration else {}))
            for a in range(3):
                for b in range(a + 1):
                    cov.append({"test": test, "name_a": full[a], "name_b": full[b],
                                "covariance": (sd[a] * value[a]) ** 2 if a == b else 0.0})
        if cross is not None:
            for a in range(3):
                for b in range(3):
                    cov.append({"test": test, "name_a": fulls[1][a], "name_b": fulls[0][b],
                                "covariance": cross * sds[0][0] * sds[1][0]
                                if a == b == 0 else 0.0})
    columns = COLUMNS + (["configuration"] if configuration else [])
    return pd.DataFrame(rows, columns=columns), pd.DataFrame(cov, columns=COVARIANCE_COLUMNS)


def test_the_position_takes_the_difference_and_leaves_no_spread() -> None:
    """Fixed differences between positions and no between-test spread: with the position
    as a covariate (the default), each offset lies in its interval, every tau's interval
    reaches 0 and the position explains the spread a fit without it finds; without it,
    t_k's tau is about half the offset, its interval clear of 0."""
    table, cov = campaign_rows(seed=11)
    (group,), _ = population_groups(table, cov, "campaign", parameters=NAMES)
    column = "position=right"
    assert group.data.columns == ("intercept", column)
    assert any("position taken as a covariate" in n for n in group.notes)
    for name in group.data.names:
        truth = OFFSET[NAMES.index(name)]
        assert group.fit.coefficients[(name, column)].covers(truth), name
        assert group.fit.tau[name].lower == 0.0, name
    (plain,), _ = population_groups(table, cov, "campaign", parameters=NAMES,
                                    by_position=False)
    t_k = plain.fit.tau["t_k"]
    assert t_k.lower > 0.0 and t_k.lower < OFFSET[2] / 2 < t_k.upper
    share = dict(zip(group.data.names, group.explained["position"], strict=True))
    assert share["t_k"] > 0.95 and share["Ck"] > 0.95
    assert np.isnan(share["CdS"])  # alike in both positions: no spread to explain


def test_a_manifest_covariate_is_a_column_to_regress_on() -> None:
    """A test covariate the manifests name (`configuration`, of no effect here) enters the
    mean on request; its effects' intervals cover 0 and it explains none of a spread that
    is not there."""
    table, cov = campaign_rows(seed=12, configuration=True)
    (group,), _ = population_groups(table, cov, "campaign", parameters=NAMES,
                                    covariates=["configuration"])
    assert group.data.columns == ("intercept", "configuration=B", "position=right")
    for name in group.data.names:
        assert group.fit.coefficients[(name, "configuration=B")].covers(0.0), name
    assert set(group.explained) == {"configuration", "position"}


def test_an_unknown_covariate_names_the_columns_there_are() -> None:
    table, cov = campaign_rows(seed=13)
    with pytest.raises(InputError, match=r"covariate colour.*position"):
        population_groups(table, cov, "campaign", parameters=NAMES, covariates=["colour"])


def test_a_position_held_by_one_opening_is_not_a_covariate() -> None:
    table, cov = campaign_rows(seed=14)
    table.loc[(table.test == "test03") & (table.parachute == "d2"), "position"] = "centre"
    (group,), _ = population_groups(table, cov, "campaign", parameters=NAMES)
    assert group.data.columns == ("intercept",)
    assert any("position not taken as a covariate: centre has 1 opening" in n
               for n in group.notes)


def test_the_command_reports_what_each_covariate_explains(tmp_path, capsys) -> None:
    """`cpas-ocp population`: the position line in the text, explained.csv, and a
    groupings.csv with its header where nothing was tested as a grouping (one type,
    nothing else varying)."""
    folder = tmp_path / "campaign"
    folder.mkdir()
    table, cov = campaign_rows(seed=15)
    table.to_csv(folder / "parameters.csv", index=False)
    cov.to_csv(folder / "covariances.csv", index=False)
    out = tmp_path / "population"
    assert main(["population", str(folder), "--out", str(out), "--no-position"]) == 0
    printed = capsys.readouterr().out
    assert "no grouping tested" not in printed  # position is a grouping without the covariate
    assert main(["population", str(folder), "--out", str(out)]) == 0
    printed = capsys.readouterr().out
    assert "effect of position=right" in printed
    assert "position explains of the between-test variance: CdS -" in printed
    explained = pd.read_csv(out / "explained.csv")
    assert set(explained.covariate) == {"position"} and len(explained) == 3
    summary = json.loads((out / "population.json").read_text())
    assert summary["populations"][0]["columns"] == ["intercept", "position=right"]
    lone = table[table.parachute == "d1"]
    lone.to_csv(folder / "parameters.csv", index=False)
    assert main(["population", str(folder), "--out", str(out)]) == 0
    assert "no grouping tested" in capsys.readouterr().out
    groupings = (out / "groupings.csv").read_text()
    assert groupings.startswith("population,covariate,levels,statistic")
    assert pd.read_csv(out / "groupings.csv").empty


def test_manifest_covariates_reach_the_campaign_table() -> None:
    """The canopy's position (its name where none is given), the test's covariates and the
    canopy's own, each a column of the parameter table."""
    manifest = {"covariates": {"configuration": "two-drogue", "date": 20260312},
                "parachutes": [{"name": "d1", "position": "left", "covariates": {"lot": "L7"}},
                               {"name": "d2"}]}
    found = canopy_covariates(manifest, "m.json")
    assert found == {"d1": {"position": "left", "configuration": "two-drogue",
                            "date": 20260312, "lot": "L7"},
                     "d2": {"position": "d2", "configuration": "two-drogue",
                            "date": 20260312}}
    row = {c: 1 for c in COLUMNS}
    outcomes = [campaign.TestOutcome("a", "a", "ok", rows=[row | {"lot": "L7"}]),
                campaign.TestOutcome("b", "b", "ok", rows=[row | {"date": 3}])]
    assert list(campaign.parameter_table(outcomes).columns) == [*COLUMNS, "lot", "date"]


@pytest.mark.parametrize("manifest, field", [
    ({"covariates": {"type": "x"}, "parachutes": []}, "covariates.type"),
    ({"covariates": {"lot": 1}, "parachutes": [{"name": "d1", "covariates": {"lot": 2}}]},
     "parachutes[0].covariates.lot"),
])
def test_a_covariate_named_as_a_column_is_refused(manifest, field) -> None:
    with pytest.raises(InputError) as raised:
        canopy_covariates(manifest, "m.json")
    assert raised.value.field == field


def test_the_manifest_schema_takes_positions_and_covariates() -> None:
    """A built-in problem's manifest with a position and covariates validates; a covariate
    holding a list does not, named by its path."""
    import copy

    from cpas_ocp.io.flight_test import validate_manifest
    from cpas_ocp.io.problems import load_problem
    manifest = copy.deepcopy(load_problem("drogue").manifest)
    manifest["covariates"] = {"configuration": "two-drogue", "drop": 3}
    manifest["parachutes"][0] |= {"position": "left", "covariates": {"lot": "L7"}}
    validate_manifest(manifest, "m.json")
    manifest["parachutes"][0]["covariates"]["lot"] = ["L7"]
    with pytest.raises(InputError, match=r"parachutes.*covariates.*lot"):
        validate_manifest(manifest, "m.json")


def test_the_command_line_names_the_built_in_covariates() -> None:
    from cpas_ocp.campaign.population_study import COVARIATE_COLUMNS
    from cpas_ocp.cli.arguments import COVARIATES
    assert COVARIATES == COVARIATE_COLUMNS


def test_a_population_fit_that_did_not_converge_exits_3(tmp_path, capsys, monkeypatch) -> None:
    """L-BFGS-B ending away from a stationary point (its line search abandoned at a point
    whose gradient is large) is a solver failure: exit 3, one line with the optimiser's
    message and iterations, no folder."""
    from scipy.optimize import OptimizeResult

    from cpas_ocp.campaign import population_model

    def stuck(fun, x0, jac, method, bounds):
        return OptimizeResult(success=False, message="ABNORMAL_TERMINATION_IN_LNSRCH", nit=4,
                              x=np.asarray(x0), fun=fun(np.asarray(x0))[0],
                              jac=np.full(len(x0), 5.0))

    monkeypatch.setattr(population_model.optimize, "minimize", stuck)
    folder = tmp_path / "campaign"
    folder.mkdir()
    table, cov = campaign_rows(seed=16)
    table.to_csv(folder / "parameters.csv", index=False)
    cov.to_csv(folder / "covariances.csv", index=False)
    assert main(["population", str(folder), "--out", str(tmp_path / "o")]) == 3
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1
    assert "ABNORMAL_TERMINATION_IN_LNSRCH" in err and "after 4 iterations" in err
    assert not (tmp_path / "o").exists()


def test_dispersions_are_drawn_at_a_named_position(tmp_path, capsys) -> None:
    """`cpas-ocp dispersions --population --at position=right`: with no spread beyond the
    positions' difference, the cases at each position sit at that position's median (the
    covariate's effect between them, to within the cases' own scatter); a configuration
    the population cannot draw at is exit 2, naming it."""
    folder = tmp_path / "campaign"
    folder.mkdir()
    table, cov = campaign_rows(seed=17)
    table.to_csv(folder / "parameters.csv", index=False)
    cov.to_csv(folder / "covariances.csv", index=False)
    medians = {}
    for position in ("left", "right"):
        out = tmp_path / position
        assert main(["dispersions", str(folder), "--out", str(out), "--cases", "2000",
                     "--seed", "3", "--population", "--at", f"position={position}"]) == 0
        cases = pd.read_parquet(out / "cases_drogue_stage1.parquet")
        medians[position] = np.log(cases[["CdS", "Ck", "t_k"]].median())
    printed = capsys.readouterr().out
    assert "drawn at position=right" in printed
    (group,), _ = population_groups(table, cov, "campaign", parameters=NAMES)
    for name in ("CdS", "Ck", "t_k"):
        effect = group.fit.coefficients[(name, "position=right")].value
        j = group.data.names.index(name)
        scatter = np.sqrt(group.fit.omega[j, j])
        assert abs(medians["right"][name] - medians["left"][name] - effect) < 0.1 * scatter \
            + 1e-6, name
    for args, field in ((["--at", "position=right"], "--population"),
                        (["--population", "--at", "colour=red"], "--at colour"),
                        (["--population", "--at", "position=centre"], "--at position"),
                        (["--population", "--at", "position"], "NAME=VALUE")):
        assert main(["dispersions", str(folder), "--out", str(tmp_path / "bad"), "--cases",
                     "100", "--seed", "1", *args]) == 2
        err = capsys.readouterr().err.strip()
        assert len(err.splitlines()) == 1 and field in err, err
        assert not (tmp_path / "bad").exists()
