"""Every estimate a person reads is printed to the precision its sigma allows: two significant
digits of the sigma and the value to the same place, in the terminal table, report.md and
report.html alike; parameters.csv and result.json keep every digit."""

from __future__ import annotations

import json
import re

import pandas as pd

from cpas_ocp.precision import interval_text, rounded, sigma_text
from cpas_ocp.reports.display_units import display_units
from cpas_ocp.reports.report import write_report
from cpas_ocp.reports.report_data import parameter_rows


def test_the_reports_print_each_estimate_to_its_sigma(drogue_fit, tmp_path) -> None:
    fit, cov, _ = drogue_fit(1)
    out = write_report(fit, cov, tmp_path / "report")
    md = (out / "report.md").read_text()
    page = (out / "report.html").read_text()
    rows = [r for r in parameter_rows(fit, cov, display_units(fit.test)) if r.std is not None]
    assert rows
    for r in rows:  # in the test's own display units (CdS in ft^2: 80.26 ± 0.65)
        name, value, sigma = r.name, r.value, r.std
        shown, s = rounded(value, sigma), sigma_text(sigma)
        row = next(line for line in md.splitlines() if line.startswith(name + " "))
        assert row.split()[1:3] == [shown, s], row
        assert interval_text(value - 1.959963984540054 * sigma,
                             value + 1.959963984540054 * sigma, sigma) in row
        assert f"<td>{name}</td><td class=n>{shown}</td><td class=n>{s}</td>" in page
        # never more digits than two of the sigma
        decimals = len(s.split(".")[1]) if "." in s else 0
        assert (len(shown.split(".")[1]) if "." in shown else 0) == decimals
    # the files for machines keep full precision
    table = pd.read_csv(out / "parameters.csv").set_index("parameter")
    for name in fit.free:
        assert table.loc[name, "value"] == fit.parameters[name]
    assert json.loads((out / "result.json").read_text())["parameters"]
    assert not re.search(r"\d\.\d{6,} ±", md)


def test_the_hierarchical_table_prints_each_median_and_shared_value_to_its_precision() -> None:
    """A population's median to the precision its interval allows; a parameter shared
    across the tests to its sigma's (1.01771 ± 0.00859 prints 1.0177, sigma 0.0086, not
    four significant digits whatever the sigma)."""
    from types import SimpleNamespace

    from cpas_ocp.reports.hierarchical_report import hierarchical_text

    population = SimpleNamespace(name="CdS[fbcp,stage1]", median=2.012345, lower=1.951234,
                                 upper=2.075432, tau=0.0512, tau_estimated=True,
                                 copies={"0:a": 2.0, "1:b": 2.02})
    shared = SimpleNamespace(name="prf[capsule]", value=1.01771, std=0.00859, members=[0, 1])
    fit = SimpleNamespace(stats=SimpleNamespace(status="Solve_Succeeded"), evaluations=3,
                          chi2=10.0, dof=9, fits=[1, 2], populations=[population],
                          shared=[shared], is_result=True, problems=[])
    text = hierarchical_text(fit)
    assert "| CdS[fbcp,stage1] | 2.012 | [1.951, 2.075] | 0.0512 | 2 |" in text, text
    assert "| prf[capsule] (shared) | 1.0177 | sigma 0.0086 | | 2 |" in text, text
