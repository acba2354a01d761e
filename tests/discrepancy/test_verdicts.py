"""Verdicts: "consistent with the noise" is a chi-square test passed, not the absence of a
significant candidate.

`drogue` is flown (seed 3) and its sensors' sigma are then stated 7 % smaller
than the noise they were flown with: the model is right, no effect is missing,
and no window's residual has structure, but the chi-square is 1.145 times its
degrees of freedom (9 sigma above the noise on 7,168 degrees of freedom).  The
diagnosis must not call that consistent with the noise: it must give the test's
p-value and say the excess is spread evenly over the windows (a sigma question).
"""

from __future__ import annotations

import dataclasses
import json
import math
import re

import pytest
from scipy.stats import chi2

from cpas_ocp.discrepancy.diagnosis import ALPHA, Diagnosis, diagnose
from cpas_ocp.estimation.estimator import Estimator
from cpas_ocp.estimation.simulate import simulate_problem
from cpas_ocp.inference.diagnostics import WindowStatistic, departs, window_p_value
from cpas_ocp.inference.noise_test import NoiseTest
from cpas_ocp.io.flight_test import MANIFEST, load_test
from cpas_ocp.io.model_spec import baseline_spec
from cpas_ocp.io.problems import load_problem
from cpas_ocp.io.strict_json import json_text
from cpas_ocp.reports.discrepancy_text import diagnosis_text

UNDERSTATED = 1.07  # the stated sigma are the flown ones divided by this


def _understate(folder, factor: float) -> None:
    """Divide every sensor sigma of the test folder's manifest by `factor`."""
    path = folder / MANIFEST
    manifest = json.loads(path.read_text())
    for sensor in manifest["sensors"]:
        for entry in sensor.get("sigma", {}).values():
            entry["value"] /= factor
        if "sigma_relative" in sensor:
            sensor["sigma_relative"] /= factor
    path.write_text(json.dumps(manifest))


@pytest.mark.slow
def test_a_fit_above_its_chi_square_is_not_consistent_with_the_noise(tmp_path) -> None:
    problem = load_problem("drogue")
    folder = tmp_path / "test"
    simulate_problem(problem, folder, 3)
    (folder / "truth.json").unlink()
    _understate(folder, UNDERSTATED)
    fit = Estimator(load_test(folder), baseline_spec()).solve()
    # The expected excess: (1.07^2 - 1) dof; several sigma on drogue's dof.
    assert fit.chi_square / fit.dof == pytest.approx(UNDERSTATED**2, abs=0.04)
    diag = diagnose(fit, baseline_spec(), confirm_top=1)
    assert diag.explanation is None and not diag.structure, diagnosis_text(diag)
    assert diag.noise.p_value < ALPHA
    assert not diag.consistent_with_noise and diag.state == "misfit"
    verdict = diag.verdict()
    assert "consistent with the sensor noise" not in verdict
    assert f"p = {diag.noise.p_value:.2g}" in verdict
    # Scaled by chi2/dof, every window passes: the advice is the sigma's, with its size.
    # The scale's spread from the noise: sqrt(2 / dof) / 2 in sqrt(chi2/dof), 0.8 % here.
    found = re.search(r"spread evenly.*about (\d+) % too small", verdict)
    assert found is not None, verdict
    spread = 100 * math.sqrt(2.0 / fit.dof) / 2.0
    assert abs(int(found.group(1)) - 100 * (UNDERSTATED - 1)) <= 3 * spread + 0.5


def _window(chi_square: float, samples: int) -> WindowStatistic:
    return WindowStatistic("imu", "load_factor", "deployment drogue1", 0.0, 0.1, samples,
                           1.0, math.sqrt(chi_square / samples), chi_square, 0.01)


def test_a_window_of_a_handful_of_samples_neither_departs_nor_fails_a_verdict() -> None:
    """One 5-sigma sample is an outlier among thousands, not a misfit of its window; ten
    samples at 3 sigma are."""
    one = _window(25.0, 1)
    assert window_p_value(one) == pytest.approx(chi2.sf(25.0, 1))
    assert not departs(one, 3.0)
    ten = _window(90.0, 10)
    assert departs(ten, 3.0)


def test_the_verdict_needs_the_chi_square_test_passed() -> None:
    """The same diagnosis (nothing significant, no structure) is "consistent" with a
    passing noise test and a misfit with a failing one."""
    passing = NoiseTest(5700.0, 5723, float(chi2.sf(5700.0, 5723)), ALPHA, 40)
    failing = NoiseTest(6626.7, 5723, float(chi2.sf(6626.7, 5723)), ALPHA, 40)
    assert passing.passes and not failing.passes and failing.sigmas > 8
    good = Diagnosis(None, [], [], [], [], _noise=passing)  # type: ignore[arg-type]
    bad = Diagnosis(None, [], [], [], [], _noise=failing)  # type: ignore[arg-type]
    assert good.state == "consistent" and "consistent with the sensor noise" in good.verdict()
    assert bad.state == "misfit"
    assert bad.verdict().startswith("no effect in the library explains the residual, a "
                                    "misfit: chi-square 6626.7 on 5723")
    assert "consistent" not in bad.verdict()


def test_result_json_is_strict() -> None:
    """NaN and infinity are written as null, which every JSON parser reads."""
    import numpy as np

    def refuse(name: str) -> None:
        raise ValueError(name)

    text = json_text({"a": math.nan, "b": [np.float64(np.inf), np.int64(3)], "c": (1.5,),
                      "d": dataclasses.asdict(_window(1.0, 1))})
    value = json.loads(text, parse_constant=refuse)
    assert value["a"] is None and value["b"] == [None, 3] and value["c"] == [1.5]


def test_an_estimate_outside_its_plausible_range_is_named(drogue_fit) -> None:
    """A GPS "lag" of -0.06 s (the receiver reporting before the event) is printed with
    the range it leaves, beside its value."""
    from types import SimpleNamespace

    from cpas_ocp.physics.effects import SensorLag
    from cpas_ocp.reports.report_data import implausible_flag

    fit, _, _ = drogue_fit(1)
    lagged = SimpleNamespace(model=SimpleNamespace(effects=[SensorLag.gps()]), test=fit.test,
                             parameters={"lag[gps]": -0.06})
    assert implausible_flag(lagged, "lag[gps]") == "implausible (outside 0 to 0.5)"
    lagged.parameters["lag[gps]"] = 0.1
    assert implausible_flag(lagged, "lag[gps]") == ""
