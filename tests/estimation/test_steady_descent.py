"""A phase that starts under open canopies: no deployment event, a steady drag area per
canopy (and per altitude band), recovered from an altimeter alone, and the descent rates
they imply against the measured ones.

Truth checks: every drag area within 4 of its reported sigma of the truth (the sigmas
from the fit's covariance, the noise the simulator drew), on three seeds; the guesses
come from the offline reduction of the test folder alone (truth.json is not copied).
"""

from __future__ import annotations

import copy
import dataclasses
import json
import shutil
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from cpas_ocp.errors import InputError
from cpas_ocp.estimation.estimator import Estimator, Fit
from cpas_ocp.estimation.reduction import initial_guess
from cpas_ocp.estimation.simulate import simulate_problem
from cpas_ocp.estimation.uncertainty import Covariance
from cpas_ocp.io import flight_test
from cpas_ocp.io.flight_test import load_test
from cpas_ocp.io.model_spec import spec_of_test
from cpas_ocp.io.problems import load_problem
from cpas_ocp.physics.atmosphere import density_at
from cpas_ocp.physics.effects.canopy_inflation import BAND_BLEND_M, banded_cds
from cpas_ocp.physics.flight_test import FlightTest
from cpas_ocp.physics.units import G0
from cpas_ocp.reports.flight_report import (
    descent_rates,
    nominal_comparisons,
    rate_sigmas,
    steady_descent_text,
    uncompared,
)

SEEDS = (1, 2, 3)
BANDS_TRUTH = {"CdS[drogue,stage1,band1]": 0.47, "CdS[drogue,stage1,band2]": 0.52}
BAND_EDGE_M = 2200.0


def _banded_problem():
    """rocket_steady with the drogue's drag area in two altitude bands (edge 2200 m)."""
    problem = load_problem("rocket_steady")
    manifest = copy.deepcopy(problem.manifest)
    manifest["parachutes"][0]["altitude_bands"] = [{"value": BAND_EDGE_M, "unit": "m"}]
    truth = {k: v for k, v in problem.truth.items() if k != "CdS[drogue,stage1]"}
    return dataclasses.replace(problem, manifest=manifest, truth={**truth, **BANDS_TRUTH})


@pytest.fixture(scope="module")
def steady_fit(tmp_path_factory: pytest.TempPathFactory):
    """A factory: (fit, covariance, truth) of rocket_steady (or its banded variant) for a
    seed, fitted from a copy of the test folder without truth.json."""
    cache: dict[tuple[bool, int], tuple[Fit, Covariance, dict[str, float]]] = {}

    def make(seed: int, banded: bool = False) -> tuple[Fit, Covariance, dict[str, float]]:
        if (banded, seed) not in cache:
            root = tmp_path_factory.mktemp(f"steady{seed}{banded}")
            problem = _banded_problem() if banded else load_problem("rocket_steady")
            simulate_problem(problem, root / "sim", seed)
            truth = json.loads((root / "sim" / "truth.json").read_text())["parameters"]
            shutil.copytree(root / "sim", root / "test",
                            ignore=shutil.ignore_patterns("truth.json"))
            est = Estimator(load_test(root / "test"))
            fit = est.solve()
            cache[banded, seed] = (fit, est.covariance(fit), truth)
        return cache[banded, seed]

    return make


def _manifest(**drogue: object) -> dict:
    manifest = copy.deepcopy(load_problem("rocket_steady").manifest)
    manifest["parachutes"][0].update(drogue)
    manifest["events"] = [{"name": "mortar_fire", "parachute": "main",
                           "time": {"value": 29.5, "unit": "s"},
                           "sigma": {"value": 0.1, "unit": "s"}}]
    return manifest


def _load(manifest: dict, tmp_path: Path):
    series = {"baro": pd.DataFrame({"time": np.arange(0.0, 60.0, 0.1)})}
    return flight_test.flight_test_from_manifest(manifest, tmp_path, series=series)


def _parameter_names(test: FlightTest) -> list[str]:
    return spec_of_test(test).model(test).parameter_names


def test_an_open_canopy_has_only_its_steady_drag_area(tmp_path: Path) -> None:
    """No start time, shape or captured speed for the open drogue; the main deploys as
    before; with bands, one drag area per band and none for the whole canopy."""
    names = _parameter_names(_load(_manifest(), tmp_path))
    drogue = [n for n in names if "drogue" in n]
    assert drogue == ["CdS[drogue,stage1]"]
    assert "t_start[main,stage2]" in names and "n[main,stage2]" in names
    banded = _manifest(open_at_start=True, altitude_bands=[1800, {"value": 7000, "unit": "ft"}])
    names = _parameter_names(_load(banded, tmp_path))
    assert [n for n in names if "drogue" in n] == [
        "CdS[drogue,stage1,band1]", "CdS[drogue,stage1,band2]", "CdS[drogue,stage1,band3]"]


def test_banded_drag_area_steps_smoothly_between_bands() -> None:
    """Each band's value away from the edges; halfway at an edge; within the blend."""
    edges, values = (1000.0, 2000.0), [1.0, 2.0, 4.0]
    at = [float(banded_cds(h, edges, values)) for h in (0.0, 1000.0, 1500.0, 2000.0, 3000.0,
                                                         2000.0 + BAND_BLEND_M)]
    assert at == pytest.approx([1.0, 1.5, 2.0, 3.0, 4.0, 4.0])


@pytest.mark.parametrize(("drogue", "events", "field"), [
    ({"open_at_start": False, "altitude_bands": [2000]}, None, "parachutes[0].altitude_bands"),
    ({"open_at_start": True, "altitude_bands": [2000, 1500]}, None,
     "parachutes[0].altitude_bands"),
    ({"open_at_start": True, "stages": ["reefed", "full"]}, None, "parachutes[0].stages"),
    ({"open_at_start": True}, [{"name": "mortar_fire", "parachute": "drogue",
                                "time": {"value": 1.0, "unit": "s"},
                                "sigma": {"value": 0.1, "unit": "s"}}], "events[1].parachute"),
])
def test_inconsistent_open_canopy_is_refused(tmp_path: Path, drogue: dict, events, field: str
                                             ) -> None:
    """Bands without an open canopy, bands out of order, an open canopy with reefing
    stages or a deployment event: one-line errors naming the field."""
    manifest = _manifest(**drogue)
    if events is not None:
        manifest["events"] += events
    with pytest.raises(InputError) as err:
        _load(manifest, tmp_path)
    assert err.value.field == field


def test_the_guess_comes_from_the_reduction(steady_fit, tmp_path_factory) -> None:
    """The open drogue's first guess is its steady window's drag area, not the default."""
    folder = tmp_path_factory.mktemp("guess") / "test"
    simulate_problem(load_problem("rocket_steady"), folder, 7)
    test = load_test(folder)
    est = Estimator(test)
    guess = initial_guess(test, est.model)
    default = est.model.parameter("CdS[drogue,stage1]").default
    truth = load_problem("rocket_steady").truth["CdS[drogue,stage1]"]
    assert abs(guess["CdS[drogue,stage1]"] - truth) < 0.1 * abs(default - truth)


@pytest.mark.parametrize("seed", SEEDS)
def test_drag_areas_recovered_within_4_sigma(steady_fit, seed: int) -> None:
    fit, cov, truth = steady_fit(seed)
    assert fit.solver.success, fit.solver.status
    for name in ("CdS[drogue,stage1]", "CdS[main,stage2]"):
        z = (fit.parameters[name] - truth[name]) / cov.std[name]
        assert abs(z) < 4.0, f"{name}: {z:+.2f} sigma"


def test_banded_drag_areas_recovered_within_4_sigma(steady_fit) -> None:
    fit, cov, truth = steady_fit(1, banded=True)
    assert fit.solver.success, fit.solver.status
    for name in (*BANDS_TRUTH, "CdS[main,stage2]"):
        z = (fit.parameters[name] - truth[name]) / cov.std[name]
        assert abs(z) < 4.0, f"{name}: {z:+.2f} sigma"
    rates = descent_rates(fit, cov)
    assert [(r.canopies, r.band) for r in rates] == [
        (("drogue",), "band2"), (("drogue",), "band1"), (("drogue", "main"), "band1")]
    # Each band's drag area has its own sigma from its own rate, not one band's overwritten.
    sigmas = rate_sigmas(fit, rates)
    assert set(sigmas) == {*BANDS_TRUTH, "CdS[main,stage2]"}
    assert all(np.isfinite(v) and v > 0 for v in sigmas.values())
    assert "CdS[drogue,stage1,band2]" in steady_descent_text(fit, cov)


def test_implied_descent_rates_match_the_measured(steady_fit) -> None:
    """Under the open drogue from the phase's start, then drogue and main: the rate the
    fitted drag areas imply agrees with the altimeter's within 4 combined sigma plus the
    quasi-steady bias.  The implied rate takes drag equal to weight, but a canopy falling
    into denser air decelerates by a = v^2 |dln(rho)/dh| / 2, so drag exceeds weight by
    m a and the true rate is higher by v a / (2 g)."""
    fit, cov, _ = steady_fit(1)
    rates = descent_rates(fit, cov)
    assert [r.canopies for r in rates] == [("drogue",), ("drogue", "main")]
    assert rates[0].t0 == pytest.approx(fit.test.t_start)
    for r in rates:
        h = np.array([r.altitude_m - 50.0, r.altitude_m + 50.0])
        dlnrho = abs(float(np.diff(np.log(density_at(fit.test.atmosphere, h)))[0])) / 100.0
        bias = r.measured * r.measured**2 * dlnrho / 2.0 / (2.0 * G0)
        assert abs(r.implied - r.measured) < 4.0 * np.hypot(r.implied_sigma,
                                                            r.measured_sigma) + bias, r
    text = steady_descent_text(fit, cov)
    assert "| drogue | CdS[drogue,stage1] | all |" in text


def test_a_nominal_without_a_steady_window_is_named_not_compared(steady_fit) -> None:
    """A nominal drag area whose canopy has no steady window (here: no rates at all) is
    left out of the comparison and named, not a crash."""
    fit, cov, _ = steady_fit(1)
    nominal = {"CdS[main,stage2]": {"value": 5.8, "unit": "m^2", "source": "test"}}
    rates = descent_rates(fit, cov)
    assert [c.name for c in nominal_comparisons(fit, cov, nominal, rates)] == \
        ["CdS[main,stage2]"]
    assert nominal_comparisons(fit, cov, nominal, []) == []
    assert uncompared(fit, nominal, []) == ["CdS[main,stage2]"]


def test_two_banded_canopies_are_refused(tmp_path: Path) -> None:
    """One set of bands splits the descent: bands on a second canopy are one-line errors."""
    manifest = _manifest(altitude_bands=[2000])
    manifest["parachutes"][1].update(open_at_start=True, altitude_bands=[1500])
    manifest["events"] = []
    with pytest.raises(InputError) as err:
        _load(manifest, tmp_path)
    assert err.value.field == "parachutes[1].altitude_bands"


def test_a_band_the_descent_never_enters_is_refused(tmp_path: Path) -> None:
    """A band edge above the whole phase leaves the upper band's drag area without data: the
    reduction refuses it naming the bands, rather than a fit reporting the guess."""
    manifest = _manifest(altitude_bands=[100_000])
    series = {"baro": pd.DataFrame({"time": np.arange(0.0, 60.0, 0.1),
                                    "altitude": np.linspace(2600.0, 1500.0, 600)})}
    test = flight_test.flight_test_from_manifest(manifest, tmp_path, series=series)
    with pytest.raises(InputError) as err:
        initial_guess(test, spec_of_test(test).model(test), {})
    assert err.value.field == "parachutes[0].altitude_bands"
    assert "band2" in str(err.value)
