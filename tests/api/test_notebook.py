"""The example notebook (docs/notebook.py, jupytext percent format) runs as written, and
the loop it shows works: a result, the missing effect named, the error falling."""

from __future__ import annotations

import runpy
import tempfile
from pathlib import Path

import pytest

pytestmark = pytest.mark.slow

NOTEBOOK = Path(__file__).parents[2] / "docs" / "notebook.py"


def test_the_notebook_runs_and_finds_the_hidden_added_mass(capsys, monkeypatch,
                                                          tmp_path) -> None:
    # The notebook works in a folder of its own (tempfile.mkdtemp) that a reader keeps;
    # the test's goes under its own temporary folder.
    monkeypatch.setattr(tempfile, "tempdir", str(tmp_path))
    ns = runpy.run_path(str(NOTEBOOK), run_name="__main__")
    rec, diag, comparison = ns["rec"], ns["diag"], ns["comparison"]
    assert rec.is_result
    assert list(rec.parameters.columns) == ["value", "sigma", "low_95", "high_95", "unit",
                                            "bound"]
    assert (rec.parameters["sigma"] > 0).all()
    assert diag.explanation is not None and diag.explanation.effect == "added_mass"
    lr = comparison.lr
    assert lr is not None and lr.p_value < 1e-6
    assert comparison.fits[1].chi_square < comparison.fits[0].chi_square
    for name, value in ns["truth"].items():
        fit, cov = comparison.fits[1], comparison.covariances[1]
        assert abs(fit.parameters[name] - value) < 4.0 * cov.std[name], name
    assert (ns["work"] / "riser_fbcp1.png").is_file() and ns["work"].parent == tmp_path
    printed = capsys.readouterr().out
    assert "missing effect: added_mass" in printed
