"""The drag areas against their nominal values: the drag area the measured descent rate
needs is computed from that rate, not repeated from the fit, and a drag area the fit left
on its bound says so instead of "± 0".

`rocket_steady` (seed 1: an open drogue, then a main, an altimeter alone) is fitted from
its folder; the needed drag areas are set against the truth within the measured rate's
sigma and the quasi-steady bias (falling into denser air the vehicle slows, so the
measured rate exceeds the steady one by about v^3 |d ln rho/dh| / (4 g)).
"""

from __future__ import annotations

import dataclasses
import json
import re
import shutil

import numpy as np
import pytest

from cpas_ocp.estimation.estimator import Estimator
from cpas_ocp.estimation.simulate import simulate_problem
from cpas_ocp.io.flight_test import load_test
from cpas_ocp.io.problems import load_problem
from cpas_ocp.physics.atmosphere import density_at
from cpas_ocp.physics.units import G0
from cpas_ocp.precision import with_sigma
from cpas_ocp.reports.flight_report import descent_rates, nominal_comparisons, nominal_text

NOMINAL = {"CdS[drogue,stage1]": {"value": 0.6, "unit": "m^2", "source": "a design value"},
           "CdS[main,stage2]": {"value": 6.0, "unit": "m^2", "source": "a design value"}}


@pytest.fixture(scope="module")
def steady(tmp_path_factory):
    root = tmp_path_factory.mktemp("steady")
    simulate_problem(load_problem("rocket_steady"), root / "sim", 1)
    truth = json.loads((root / "sim" / "truth.json").read_text())["parameters"]
    shutil.copytree(root / "sim", root / "test", ignore=shutil.ignore_patterns("truth.json"))
    est = Estimator(load_test(root / "test"))
    fit = est.solve()
    return fit, est.covariance(fit), truth


def _needs(text: str, name: str) -> float:
    found = re.search(rf"- {re.escape(name)}: .*? the measured rate needs ([0-9.]+) m²", text)
    assert found is not None, text
    return float(found.group(1))


def test_the_needed_drag_area_comes_from_the_measured_rate(steady) -> None:
    """Each needed drag area is 2 W / (rho v^2) at the window's measured rate less the other
    drag areas open, and lies within the rate's sigma (and the quasi-steady bias) of the
    truth."""
    fit, cov, truth = steady
    rates = descent_rates(fit, cov)
    text = nominal_text(fit, cov, NOMINAL, rates)
    for c in nominal_comparisons(fit, cov, NOMINAL, rates):
        r = c.rate_measured
        rho = float(density_at(fit.test.atmosphere, r.altitude_m)[0])
        total = 2.0 * fit.test.weight / (rho * r.measured**2)
        others = sum(fit.parameters[n] for n in NOMINAL if n != c.name
                     and n.split("[")[1].split(",")[0] in r.canopies)
        assert _needs(text, c.name) == pytest.approx(total - others, abs=6e-4)
        h = np.array([r.altitude_m - 50.0, r.altitude_m + 50.0])
        dlnrho = abs(float(np.diff(np.log(density_at(fit.test.atmosphere, h)))[0])) / 100.0
        bias = 2.0 * total * r.measured**2 * dlnrho / (4.0 * G0)  # 2 dv / v of the area
        assert abs(c.needed - truth[c.name]) < 4.0 * c.sigma_rate + bias, c


def test_a_drag_area_on_its_bound_says_so_and_the_rate_still_speaks(steady) -> None:
    """The main's drag area moved to 0.8 of its fit and left on its bound (no sigma): the
    table says "on its bound", not "± 0", and the measured rate needs what it needed
    before, not the value on the bound."""
    fit, cov, _ = steady
    name = "CdS[main,stage2]"
    before = _needs(nominal_text(fit, cov, NOMINAL), name)
    bounded = dataclasses.replace(fit, parameters={**fit.parameters,
                                                   name: 0.8 * fit.parameters[name]})
    on_bound = dataclasses.replace(cov, at_bound=[*cov.at_bound, name])
    text = nominal_text(bounded, on_bound, NOMINAL)
    row = next(line for line in text.splitlines() if line.startswith(f"| {name} |"))
    assert f"| {name} | {0.8 * fit.parameters[name]:.4f} on its bound |" in row, row
    assert "± 0 " not in row and "± 0 |" not in row
    assert _needs(text, name) == before
    assert abs(_needs(text, name) - 0.8 * fit.parameters[name]) > 0.1 * fit.parameters[name]
    assert f"the fit left it on its bound, at {0.8 * fit.parameters[name]:.3f} m²" in text


def test_the_page_tables_the_drag_areas_against_their_nominal_values(steady) -> None:
    """report.html holds the comparison as an HTML table like its others (its header cells,
    one row per drag area, the fitted value with its sigma in a cell), and its sentences
    as paragraphs: no markdown inside <pre>."""
    from cpas_ocp.reports.display_units import display_units
    from cpas_ocp.reports.report import reconstruction_page

    fit, cov, _ = steady
    page = reconstruction_page(fit, cov, None, display_units(fit.test), nominal=NOMINAL).html()
    section = page.split("<h2>Drag areas against the card&#x27;s nominal values</h2>")[1].lstrip()
    assert section.startswith("<table><thead><tr><th>parameter</th><th>fitted (m²)</th>"
                              "<th>σ from the measured rate (m²)</th>"), section[:400]
    for name in NOMINAL:
        # the value to the decimal place of two digits of its sigma, aligned as a number
        value = with_sigma(fit.parameters[name], cov.std[name])
        assert f"<td>{name}</td><td class=n>{value}</td>" in section
        assert f"<p>{name}: with the nominal" in section
    assert "|---" not in page and "| parameter |" not in page
    assert not any("nominal" in pre for pre in re.findall(r"<pre>(.*?)</pre>", page, re.S))
