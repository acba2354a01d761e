"""`cpas-ocp hierarchical`: bad input is one line and exit 2 with nothing written.  The
command's end-to-end run (two fbcp tests and their drag areas' population in one NLP) is
in the study `benchmarks/studies/test_hierarchical_fit.py`."""

from __future__ import annotations

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
