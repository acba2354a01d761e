"""Design of the next test: the predicted covariance is the Fisher information's inverse, a
sensor that records nothing is one that is not there, undetermined parameters are named,
and the ranking scores what it says."""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path

import numpy as np
import pytest

from cpas_ocp.estimation.uncertainty import Covariance
from cpas_ocp.inference.flight_test_design import (
    ABSENT_FACTOR,
    Planner,
    Prediction,
    RankedChange,
    recorded_only,
    sigma_removed,
)
from cpas_ocp.io.flight_test_plan import (
    Change,
    Instrumentation,
    PlannedSensor,
    default_changes,
    load_plan,
)

PLANS = Path(__file__).parents[2] / "docs" / "plans"
# Agreement of two linearisations that must be equal but for rounding in the KKT solve.
ROUNDING = 1e-6


@pytest.fixture(scope="module")
def fbcp() -> tuple[Planner, Instrumentation]:
    plan = load_plan(PLANS / "fbcp.json")
    return Planner(plan.problem), plan.candidates[0]


def _scaled(base: Instrumentation, factor: float) -> Instrumentation:
    """Every sensor's noise sigma (absolute and relative) times `factor`."""
    sensors = []
    for s in base.sensors:
        entry = json.loads(json.dumps(s.entry))
        for q in entry["sigma"].values():
            q["value"] *= factor
        if "sigma_relative" in entry:
            entry["sigma_relative"] *= factor
        sensors.append(PlannedSensor(entry, s.rate_hz, s.phases))
    return Instrumentation("scaled", tuple(sensors), base.event_sigma)


def test_halving_every_sigma_halves_every_predicted_sigma(fbcp) -> None:
    """The information is J'J of sigma-weighted residuals: every weight doubled, the Fisher
    information is four times larger and each predicted sigma half (the fbcp observes no
    event whose time enters the estimate, so every residual is a sensor's)."""
    planner, base = fbcp
    a, b = planner.predict(base), planner.predict(_scaled(base, 0.5))
    assert a.covariance.names == b.covariance.names and a.covariance.std
    for name, s in a.covariance.std.items():
        assert b.sigma(name) == pytest.approx(0.5 * s, rel=ROUNDING), name


def test_a_sensor_that_records_no_phase_is_a_sensor_not_flown(fbcp) -> None:
    planner, base = fbcp
    without = Change("no imu", removed="imu").applied(base)
    imu = base.sensor("imu")
    silent = Change("silent imu", PlannedSensor(imu.entry, imu.rate_hz, ())).applied(base)
    a, b = planner.predict(without), planner.predict(silent)
    assert a.covariance.names == b.covariance.names
    for name, s in a.covariance.std.items():
        assert b.sigma(name) == pytest.approx(s, rel=ROUNDING), name


def test_a_phase_not_recorded_takes_a_sigma_that_leaves_no_information(fbcp) -> None:
    planner, base = fbcp
    gps = base.sensor("gps")
    entry = recorded_only(gps.entry, ("deployment",), planner.problem)
    after = entry["sigma_after"]
    assert [c["time"]["value"] for c in after] == sorted(c["time"]["value"] for c in after)
    absent = after[0]["sigma"]["position"]
    assert absent["value"] * {"m": 1.0, "km": 1e3, "ft": 0.3048, "in": 0.0254,
                              "kft": 304.8}[absent["unit"]] == pytest.approx(
        ABSENT_FACTOR * 0.5, rel=1e-9)  # 0.5 m, the problem's position sigma
    assert after[1]["sigma"] == gps.entry["sigma"]


def test_gps_alone_leaves_the_split_between_canopies_undetermined_and_says_so(fbcp) -> None:
    planner, base = fbcp
    gps_only = Instrumentation("gps only", (base.sensor("gps"),))
    p = planner.predict(gps_only)
    cov = p.covariance
    assert "CdS[fbcp1,stage1]" in cov.undetermined and "CdS[fbcp2,stage1]" in cov.undetermined
    assert p.sigma("CdS[fbcp1,stage1]") is None
    assert p.status("CdS[fbcp1,stage1]") == "undetermined"
    assert p.optimality() == (None, None)
    named = [w for w in cov.weak if w.std is None]
    assert any({"CdS[fbcp1,stage1]", "CdS[fbcp2,stage1]"} <= set(w.weights) for w in named)


def test_losing_a_load_cell_loses_its_scale_and_widens_its_canopy(fbcp) -> None:
    planner, base = fbcp
    full = planner.predict(base)
    lost = planner.predict(Change("lost", removed="riser_fbcp1").applied(base))
    assert lost.status("loadcell_scale[fbcp1]") == "not estimated"
    assert lost.sigma("Ck[fbcp1,stage1]") > 2.0 * full.sigma("Ck[fbcp1,stage1]")
    a_full, d_full = full.optimality()
    a_lost, d_lost = lost.optimality()
    assert a_lost > a_full and d_lost > d_full  # less information: larger trace and volume


def _prediction(sigmas: dict[str, float | None]) -> Prediction:
    names = list(sigmas)
    undetermined = [n for n, s in sigmas.items() if s is None]
    matrix = np.diag([0.0 if s is None else s**2 for s in sigmas.values()])
    cov = Covariance(names, matrix, [], 1.0, undetermined=undetermined)
    return Prediction(Instrumentation("x", ()), cov, dict.fromkeys(names, 1.0),
                      dict.fromkeys(names, 1.0), dict.fromkeys(names, "1"), 0)


def test_sigma_removed_counts_gains_losses_and_parameters_made_determinable() -> None:
    base = _prediction({"a": 0.2, "b": 0.1, "c": None, "d": None})
    new = _prediction({"a": 0.1, "b": None, "c": 0.5, "d": None})
    removed = sigma_removed(base, new, ["a", "b", "c", "d"])
    assert removed == {"a": pytest.approx(0.5), "b": -np.inf, "c": 1.0, "d": 0.0}
    assert RankedChange(Change("x"), new, sigma_removed(base, new, ["a", "c"])).score == \
        pytest.approx(0.75)


def test_a_parameter_that_leaves_with_its_instrument_is_not_lost() -> None:
    """Removing a load cell removes its own scale from the model: the change ranks by what
    it does to the parameters that remain, as the failures table reports it."""
    base = _prediction({"a": 0.2, "loadcell_scale[x]": 0.01})
    new = _prediction({"a": 0.3})
    removed = sigma_removed(base, new, ["a", "loadcell_scale[x]"])
    assert removed == {"a": pytest.approx(-0.5)}
    assert np.isfinite(RankedChange(Change("without x"), new, removed).score)


def test_a_change_replaces_its_sensor_in_place_and_defaults_cover_every_sensor(fbcp) -> None:
    _, base = fbcp
    changes = default_changes(base)
    assert len(changes) == 2 * len(base.sensors)
    faster = changes[0].applied(base)
    assert [s.name for s in faster.sensors] == [s.name for s in base.sensors]
    assert faster.sensors[0].rate_hz == 2 * base.sensors[0].rate_hz
    halved = changes[1].applied(base).sensors[0].entry["sigma"]
    assert all(q["value"] == 0.5 * base.sensors[0].entry["sigma"][g]["value"]
               for g, q in halved.items())
    assert dataclasses.replace(base, name="same").sensors == base.sensors
