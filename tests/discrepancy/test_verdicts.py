"""Verdicts: "consistent with the noise" is a chi-square test passed, not the absence of a
significant candidate.

A diagnosis with nothing significant and no structure is not called consistent with the
noise unless the chi-square test passes; it gives the test's p-value and says where the
excess lies.  The end-to-end case (`drogue` flown, its sigmas then stated 7 % small) is the
study `benchmarks/studies/test_stated_sigmas.py`.
"""

from __future__ import annotations

import dataclasses
import json
import math

import pytest
from scipy.stats import chi2

from cpas_ocp.discrepancy.diagnosis import ALPHA, Diagnosis
from cpas_ocp.inference.diagnostics import WindowStatistic, departs, window_p_value
from cpas_ocp.inference.noise_test import NoiseTest
from cpas_ocp.io.strict_json import json_text


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
