"""`cpas-ocp hierarchical`: bad input is one line and exit 2 with nothing written; two fbcp
tests and their drag areas' population in one NLP write the population's median with its
interval and every copy beside its own test's estimate."""

from __future__ import annotations

import json

import pandas as pd
import pytest

from cpas_ocp.cli import main


@pytest.mark.parametrize(("argv", "field"), [
    (["--population", "CdS"], "tests"),  # one test folder: no population to speak of
    (["--population", "CdS", "--share", "CdS"], "population"),  # both drawn and shared
    (["--population", "CdS:fleet"], "--population"),
])
def test_bad_input_is_one_line_and_exit_2(argv, field, problem_folder, tmp_path,
                                          capsys) -> None:
    folders = [str(problem_folder("fbcp", 1))]
    if field != "tests":
        folders.append(str(problem_folder("fbcp", 2)))
    out = tmp_path / "out"
    assert main(["hierarchical", *folders, *argv, "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and field in err, err
    assert not out.exists()


@pytest.mark.slow
def test_two_tests_and_their_population_in_one_nlp(problem_folder, tmp_path, capsys) -> None:
    folders = [str(problem_folder("fbcp", seed)) for seed in (1, 2)]
    out = tmp_path / "out"
    code = main(["hierarchical", *folders, "--population", "CdS", "--out", str(out)])
    assert code in (0, 4)  # 4: written, and said why it is not a result
    printed = capsys.readouterr().out
    assert "| population | median |" in printed
    record = json.loads((out / "hierarchical.json").read_text())
    assert record["result"] == (code == 0)
    pops = pd.read_csv(out / "hierarchical.csv")
    assert set(pops["population"]) == {"CdS[fbcp,stage1]"}
    row = pops.iloc[0]
    assert row["lower"] < row["median"] < row["upper"] and row["copies"] == 4
    copies = pd.read_csv(out / "copies.csv")
    assert len(copies) == 4 and set(copies["test"]) == set(folders)
    # each copy between its own estimate and the median, or within a sigma of its own
    for c in copies.itertuples():
        lo, hi = sorted((c.alone, row["median"]))
        assert lo - c.alone_std <= c.value <= hi + c.alone_std, c
