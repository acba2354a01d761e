"""A process's departure beside a stretch where the body turned over is put to it."""

from __future__ import annotations

from cpas_ocp.inference.result_claim import TURNED_REACH_S, Claim, ProcessDeparture


def _claim(turned_over: list[tuple[float, float]]) -> Claim:
    knot = ProcessDeparture("wind_process", "knot", "wind_up[2]", 44.73, 6.04, 6.04, "m/s")
    return Claim(900.0, 200, 0.0, [], departures=[knot], turned_over=turned_over)


def _departure_line(claim: Claim) -> str:
    [line] = [p for p in claim.problems() if p.startswith("a process departs")]
    return line


def test_a_departure_beside_a_tumble_names_the_nearest_stretch() -> None:
    line = _departure_line(_claim([(36.01, 39.87), (44.86, 51.29)]))
    assert "the body turned over from 44.86 to 51.29 s" in line
    assert "a late opening" not in line


def test_a_departure_far_from_any_tumble_keeps_the_general_hint() -> None:
    far = 44.73 + TURNED_REACH_S + 1.0
    for spans in ([], [(far, far + 3.0)]):
        line = _departure_line(_claim(spans))
        assert "(a late opening, a wrong sigma)" in line
        assert "turned over" not in line
