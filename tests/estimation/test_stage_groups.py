"""Canopies whose first stages share a name form a cluster only where they start together.

A rocket-log card that gives no stages names the drogue's and the main's one stage
"open"; the reduction must still reduce them as two canopies opened one after the
other (each its own steady window, each its own drag area), while a CPAS cluster
(two Drogues mortared 0.1 s apart, stages named alike) keeps sharing one group per
stage.
"""

from __future__ import annotations

import json

import pytest

from cpas_ocp.cli import main
from cpas_ocp.estimation.reduction import reduce_and_guess
from cpas_ocp.estimation.stage_groups import SETTLE_S, starts_coincide
from cpas_ocp.io.example_flight import CDS, FILL_S, LINE_STRETCH_S, Flight, fly
from cpas_ocp.io.flight_test import load_test
from cpas_ocp.io.model_spec import spec_of_test
from cpas_ocp.physics.flight_test import FlightTest
from tests.io.test_rocket_log_import import CARD, COLUMN_MAP, write_mapped

# Relative error of a canopy's initial drag area.  The reduction reads it from the descent
# (CdS = W G / q, q from the speed of a 5 s Savitzky-Golay track of the altimeter): the
# 2 Pa altimeter noise moves the window's median by under 0.3 %, but the smoothed track
# blurs each opening into the first SMOOTH_S / 2 = 2.5 s of its steady window, a fifth of
# the drogue's 11 s window, while the vehicle still speeds up to its drogue descent rate:
# that reads the drogue's drag area 1-2 % high (seeds 1, 2, 4), the main's (a 36 s
# window) 0.1 % low.  Reduced as one cluster, both read the mean of the two, 6.7 and 0.54
# times their own.
TOLERANCE = 0.05


@pytest.fixture(scope="module")
def unstaged(tmp_path_factory: pytest.TempPathFactory) -> tuple[FlightTest, Flight]:
    """The known rocket flight (drogue 1 s after apogee, main at 300 m) in a column-mapped
    log, imported with a card that names no stages: both canopies' stage is "open"."""
    folder = tmp_path_factory.mktemp("unstaged")
    flight = fly()
    write_mapped(flight, folder / "log.csv", seed=4)
    (folder / "map.json").write_text(json.dumps(COLUMN_MAP))
    card = {**CARD, "parachutes": [{k: v for k, v in c.items() if k != "stages"}
                                   for c in CARD["parachutes"]]}
    (folder / "card.json").write_text(json.dumps(card))
    assert main(["import", str(folder / "log.csv"), "--columns", str(folder / "map.json"),
                 "--card", str(folder / "card.json"), "--out", str(folder / "test")]) == 0
    return load_test(folder / "test"), flight


def test_a_drogue_and_a_main_both_named_open_are_reduced_apart(unstaged) -> None:
    """Each canopy has its own steady window, from its own start plus SETTLE_S to the next
    canopy's start (so the drogue's lies between the drogue's full opening and the main's),
    and each initial drag area lies near the truth."""
    test, flight = unstaged
    assert [c.stages for c in test.parachutes] == [("open",), ("open",)]
    spec = spec_of_test(test)
    model = spec.model(test)
    guess, red = reduce_and_guess(test, model, spec.fixed_values(model))
    assert [g.canopies for g in red.groups] == [("drogue",), ("main",)]
    start = {n: model.parameter(f"t_start[{n},open]").default for n in ("drogue", "main")}
    drogue, main_ = (red.group_of(name, "open").window for name in ("drogue", "main"))
    assert drogue == pytest.approx((start["drogue"] + SETTLE_S, start["main"]))
    assert main_ == pytest.approx((start["main"] + SETTLE_S, test.t_end))
    full = {n: flight.events[n] + LINE_STRETCH_S + FILL_S[n] for n in ("drogue", "main")}
    assert full["drogue"] < drogue[0] < drogue[1] < full["main"] < main_[1]
    for name in ("drogue", "main"):
        cds = guess[f"CdS[{name},open]"]
        assert abs(cds / CDS[name] - 1.0) < TOLERANCE, (name, cds)


def test_a_cluster_named_alike_keeps_one_group_per_stage(drogue_folder) -> None:
    """Two Drogues mortared 0.1 s apart, stages named alike: one group per stage holding
    both, its steady window from the later canopy's start plus SETTLE_S."""
    test = load_test(drogue_folder(1))
    spec = spec_of_test(test)
    model = spec.model(test)
    _, red = reduce_and_guess(test, model, spec.fixed_values(model))
    assert [(g.stage, g.canopies) for g in red.groups] == [
        (s, ("drogue1", "drogue2")) for s in ("stage1", "stage2", "stage3")]
    starts = {p.name: p.default for p in model.parameters if p.name.startswith("t_start")}
    for group, later in zip(red.groups, ("stage2", "stage3", None), strict=True):
        last = max(starts[f"t_start[{c},{group.stage}]"] for c in group.canopies)
        end = (min(starts[f"t_start[{c},{later}]"] for c in group.canopies) if later
               else test.t_end)
        assert group.window == pytest.approx((last + SETTLE_S, end))


@pytest.mark.parametrize(("dt", "sigmas", "together"), [
    (0.3, (0.05, 0.05), True),  # a cluster's members, a few tenths apart
    (SETTLE_S, (0.0, 0.0), True),  # no steady window of its own before the other opens
    (1.5, (0.05, 0.05), False),  # resolved apart by the settle time and the events
    (1.5, (0.4, 0.4), True),  # 1.5 s < 3 hypot(0.4, 0.4) = 1.7 s: the events cannot tell
    (48.0, (0.325, 0.05), False),  # a rocket's drogue and main
])
def test_starts_coincide_within_the_settle_time_or_their_sigmas(
        dt: float, sigmas: tuple[float, float], together: bool) -> None:
    assert starts_coincide(dt, *sigmas) is together
    assert starts_coincide(-dt, *sigmas) is together
