"""The report folder of a reconstruction: result.json contents, figures, and the fit report."""

from __future__ import annotations

import dataclasses
import json
import math

import numpy as np
import pytest

from cpas_ocp.reports.report import STRONG_CORRELATION, parameter_table, write_report


def test_report_folder_carries_values_uncertainties_and_fit_statistics(drogue_fit,
                                                                      tmp_path) -> None:
    fit, cov, _ = drogue_fit(1)
    out = write_report(fit, cov, tmp_path / "report")
    result = json.loads((out / "result.json").read_text())
    assert {p.name for p in out.glob("*.png")} >= {"drag_areas.png"}
    assert len(list(out.glob("*.png"))) >= 2  # sensors and drag areas

    std = cov.std
    for name in fit.free:
        entry = result["parameters"][name]
        assert entry["value"] == pytest.approx(fit.parameters[name])
        assert entry["std"] == pytest.approx(std[name])
        lo, hi = entry["ci95"]
        assert (hi - lo) == pytest.approx(2 * 1.959964 * std[name], rel=1e-6)
        assert lo < entry["value"] < hi
    solver = result["solver"]
    assert solver["success"] and solver["iterations"] > 0 and solver["wall_s"] > 0
    assert {"rms", "normalised_rms"} <= set(next(iter(result["residuals"].values())))

    k, n = len(fit.free), fit.n_samples
    assert result["fit"]["aic"] == pytest.approx(fit.chi_square + 2 * k)
    assert result["fit"]["bic"] == pytest.approx(fit.chi_square + k * math.log(n))

    rho = cov.correlation()
    index = {name: i for i, name in enumerate(cov.names)}
    # The drogue fit has such pairs (the two load-cell scales are tied by their
    # normalisation), so the checks below are not vacuous.
    assert result["strong_correlations"]
    listed = {(c["a"], c["b"]) for c in result["strong_correlations"]}
    upper = np.triu(np.abs(rho) >= STRONG_CORRELATION, k=1)
    assert len(listed) == int(upper.sum())
    for c in result["strong_correlations"]:
        assert c["rho"] == pytest.approx(rho[index[c["a"]], index[c["b"]]])
    sizes = [abs(c["rho"]) for c in result["strong_correlations"]]
    assert sizes == sorted(sizes, reverse=True)
    table = parameter_table(fit, cov)
    assert "correlations |ρ|" in table
    # The full matrix, the covariance's provenance and the identifiability verdict.
    np.testing.assert_allclose(np.array(result["correlation"]["matrix"]), rho, atol=1e-6)
    assert result["correlation"]["names"] == cov.names
    assert result["fit"]["covariance"] == cov.describe()
    assert result["identifiability"] == [] and "every combination" in table
    assert (out / "correlation.png").exists()
    assert "Correlations with |ρ| ≥" in (out / "report.md").read_text()


def test_a_parameter_on_a_bound_is_flagged_and_given_no_sigma(drogue_fit, tmp_path) -> None:
    fit, cov, _ = drogue_fit(1)
    name = next(n for n in fit.free if n.startswith("t_start"))
    held = dataclasses.replace(cov, at_bound=[name])
    assert name not in held.std and name in cov.std
    table = parameter_table(fit, held)
    row = next(line for line in table.splitlines() if line.startswith(name))
    side = fit.model.parameter(name).nearer_bound(fit.parameters[name])
    assert f"on its {side} bound" in row and "—" in row
    assert "on a bound, so not determined by the data" in table and name in table.split(
        "identifiability:")[1]
    out = write_report(fit, held, tmp_path / "report")
    entry = json.loads((out / "result.json").read_text())["parameters"][name]
    assert entry["at_bound"] == side and "std" not in entry and "ci95" not in entry
    prm = fit.model.parameter(name)
    assert entry["bounds"] == [prm.lower, prm.upper]
