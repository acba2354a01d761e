"""Sigmas stated wrong on a right model: the verdict is the chi-square test's, and it says
by how much the sigmas are off.

`drogue` is flown (seed 3) and its sensors' sigma are then stated 7 % smaller, or 25 %
larger, than the noise they were flown with.  The model is right, no effect is missing and
no window's residual has structure, but the chi-square is 1.07^2 (or 1/1.25^2) times its
degrees of freedom: several sigma from the noise on 7,168 degrees of freedom.  The
diagnosis must not call that consistent with the noise: it gives the test's p-value and
the factor the sigmas are off by, within the scale's spread from the noise,
sqrt(2 / dof) / 2 in sqrt(chi^2/dof).  The suite's smaller cases:
`tests/discrepancy/test_verdicts.py` and `test_noise_tails.py` (the verdicts from chi-square
values, no fit).
"""

from __future__ import annotations

import json
import math
import re
from pathlib import Path

import pytest

from cpas_ocp.discrepancy.diagnosis import ALPHA, Diagnosis, diagnose
from cpas_ocp.estimation.estimator import Estimator
from cpas_ocp.estimation.fit import Fit
from cpas_ocp.estimation.simulate import simulate_problem
from cpas_ocp.io.flight_test import MANIFEST, load_test
from cpas_ocp.io.model_spec import baseline_spec
from cpas_ocp.io.problems import load_problem
from cpas_ocp.reports.discrepancy_text import diagnosis_text

UNDERSTATED = 1.07  # the stated sigma are the flown ones divided by this
OVERSTATED = 1.25  # ... or multiplied by this


def _fit_restated(folder: Path, factor: float) -> tuple[Fit, Diagnosis]:
    """`drogue` seed 3 flown into `folder`, every sensor sigma of its manifest multiplied by
    `factor`, fitted with the baseline model and diagnosed."""
    simulate_problem(load_problem("drogue"), folder, 3)
    (folder / "truth.json").unlink()
    manifest = json.loads((folder / MANIFEST).read_text())
    for sensor in manifest["sensors"]:
        for entry in sensor.get("sigma", {}).values():
            entry["value"] *= factor
        if "sigma_relative" in sensor:
            sensor["sigma_relative"] *= factor
    (folder / MANIFEST).write_text(json.dumps(manifest))
    fit = Estimator(load_test(folder), baseline_spec()).solve()
    return fit, diagnose(fit, baseline_spec(), confirm_top=1)


def _spread_percent(dof: int) -> float:
    """The spread of sqrt(chi^2/dof) from the noise alone, in percent."""
    return 100 * math.sqrt(2.0 / dof) / 2.0


def test_a_fit_above_its_chi_square_is_not_consistent_with_the_noise(tmp_path) -> None:
    fit, diag = _fit_restated(tmp_path / "test", 1.0 / UNDERSTATED)
    # The expected excess: (1.07^2 - 1) dof; several sigma on drogue's dof.
    assert fit.chi_square / fit.dof == pytest.approx(UNDERSTATED**2, abs=0.04)
    assert diag.explanation is None and not diag.structure, diagnosis_text(diag)
    assert diag.noise.p_value < ALPHA
    assert not diag.consistent_with_noise and diag.state == "misfit"
    verdict = diag.verdict()
    assert "consistent with the sensor noise" not in verdict
    assert f"p = {diag.noise.p_value:.2g}" in verdict
    # Scaled by chi2/dof, every window passes: the advice is the sigma's, with its size.
    found = re.search(r"spread evenly.*about (\d+) % too small", verdict)
    assert found is not None, verdict
    assert abs(int(found.group(1)) - 100 * (UNDERSTATED - 1)) <= \
        3 * _spread_percent(fit.dof) + 0.5


def test_a_fit_with_its_sigma_overstated_is_below_the_noise(tmp_path) -> None:
    """The chi-square is 1 / 1.25^2 = 0.64 times its degrees of freedom: the diagnosis says
    the residuals lie below the noise and by how much the sigma are too large."""
    fit, diag = _fit_restated(tmp_path / "test", OVERSTATED)
    assert diag.explanation is None
    assert diag.state == "below the noise", diag.verdict()
    found = re.search(r"about (\d+) % too large", diag.verdict())
    assert found is not None, diag.verdict()
    assert abs(int(found.group(1)) - 100 * (OVERSTATED - 1)) <= \
        3 * _spread_percent(fit.dof) + 1.0
