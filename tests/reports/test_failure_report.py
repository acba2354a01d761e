"""A solve that does not converge exits 3, writes no result, and says why in a report
marked NOT CONVERGED."""

from __future__ import annotations

import json

import pytest

from cpas_ocp.cli import main


@pytest.mark.slow
def test_an_unconverged_solve_writes_a_failure_report_and_no_result(drogue_folder, tmp_path,
                                                                    capsys) -> None:
    # The drogue fit takes 4 iterations from the reduction: capped at 1 it cannot converge.
    folder = drogue_folder(1)
    out = tmp_path / "report"
    assert main(["reconstruct", str(folder), "--out", str(out), "--max-iter", "1"]) == 3
    err = capsys.readouterr().err
    assert "solver failed: status Maximum_Iterations_Exceeded after 1 iterations" in err
    assert "NOT CONVERGED" in err
    assert not (out / "result.json").exists() and not (out / "parameters.csv").exists()
    failure = json.loads((out / "failure.json").read_text())
    assert failure["converged"] is False and failure["iterations"] == 1
    assert failure["status"] == "Maximum_Iterations_Exceeded"
    # The last iterate's figures are there to show why, each sensor and free parameter.
    manifest = json.loads((folder / "manifest.json").read_text())
    assert set(failure["residuals_last_iterate"]) >= {s["name"] for s in manifest["sensors"]}
    assert all(e["normalised_rms"] > 0 for e in failure["residuals_last_iterate"].values())
    assert failure["parameters_last_iterate"] and failure["worst_windows_last_iterate"]
    text = (out / "failure.md").read_text()
    assert text.startswith("# NOT CONVERGED") and "Nothing here is a result" in text

    # A converged run replaces the failure report with the result, and nothing of it stays.
    assert main(["reconstruct", str(folder), "--out", str(out)]) == 0
    assert (out / "result.json").exists() and not (out / "failure.json").exists()


def test_max_iter_below_one_is_bad_input(drogue_folder, tmp_path, capsys) -> None:
    out = tmp_path / "report"
    assert main(["reconstruct", str(drogue_folder(1)), "--out", str(out),
                 "--max-iter", "0"]) == 2
    assert "--max-iter: an integer >= 1; got '0'" in capsys.readouterr().err
    assert not out.exists()
