"""Deployment forensics: did each canopy open, when, how fully.

Synthetic recoveries (`recovery_flights`: a vertical flight with the air's vertical
motion, a noisy altimeter and accelerometer, seeded) where the recovery goes right or
wrong in each way a hobby rocket's does; each verdict must be the truth's, the sentences
must name the canopy, and normal recoveries over 20 seeds must never read "not_opened".
The public logs in ../shared/data/rocketpy-logs are read where present.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from cpas_ocp.io.deployment_forensics import (
    Canopy,
    DragArea,
    Forensics,
    coast_drag_area,
    deployment_forensics,
)
from cpas_ocp.io.rocket_model import late_openings, rocket_model
from tests.io.recovery_flights import (
    BARO_SIGMA_M,
    BODY_CDS,
    DROGUE,
    LINE_STRETCH_S,
    MAIN,
    MASS,
    Chute,
    Recovery,
    density,
    fly_recovery,
)

DATA = Path(__file__).resolve().parents[3] / "shared" / "data" / "rocketpy-logs"


def _forensics(flight: Recovery, chutes: dict[str, Chute], coast: bool = True,
               airframe: DragArea | None = None) -> Forensics:
    """The forensics as the import would run them: the charges' times, the canopies'
    diameters, touchdown less half a second, the coast's airframe drag area."""
    canopies = [Canopy(name, flight.events.get(name), 0.05, c.diameter)
                for name, c in chutes.items()]
    frame = coast_drag_area(flight.t, flight.height, density, MASS,
                            accel=(flight.t, flight.accel)) if coast else None
    t_end = flight.events["landed"] - 0.5 if "landed" in flight.events else None
    return deployment_forensics(flight.t, flight.height, density, MASS, canopies, t_end,
                                BARO_SIGMA_M, airframe=airframe, coast=frame)


NORMAL = {"drogue": DROGUE, "main": MAIN}
BALLISTIC = {"drogue": Chute(0.0, 0.6, 0.61, delay_s=1.0),
             "main": Chute(0.0, 1.2, 1.83, height_m=450.0)}
STREAMER = {"drogue": Chute(0.05, 0.6, 0.61, delay_s=1.0), "main": MAIN}
MAIN_FAILS = {"drogue": DROGUE, "main": Chute(0.0, 1.2, 1.83, height_m=450.0)}


@pytest.mark.parametrize("seed", range(4))
def test_coast_gives_the_airframe_drag_area(seed: int) -> None:
    """From the altimeter alone and with the accelerometer (its 0.2 m/s^2 offset fitted),
    within three stated sigmas of the truth; the accelerometer narrows it."""
    flight = fly_recovery(seed, NORMAL)
    alone = coast_drag_area(flight.t, flight.height, density, MASS)
    both = coast_drag_area(flight.t, flight.height, density, MASS,
                           accel=(flight.t, flight.accel))
    assert alone is not None and both is not None
    assert both.source == "coast (altimeter and accelerometer)"
    for area in (alone, both):
        assert abs(area.value - BODY_CDS) < 3.0 * area.sigma
    assert both.sigma < alone.sigma


def test_normal_recoveries_read_opened_over_20_seeds() -> None:
    """Both canopies opened on every seed, the drag areas needed within three sigmas of the
    truth (the airframe's and the open canopies'), the main's opening timed between its
    charge and its full open, and no canopy ever read "not_opened"."""
    truth = {"drogue": BODY_CDS + DROGUE.cds, "main": BODY_CDS + DROGUE.cds + MAIN.cds}
    for seed in range(20):
        flight = fly_recovery(seed + 100, NORMAL)
        result = _forensics(flight, NORMAL)
        assert [c.verdict for c in result.canopies] == ["opened", "opened"], (
            seed, result.sentences())
        for c in result.canopies:
            assert c.descent is not None and c.descent.trend == "settled"
            assert abs(c.descent.drag_area - truth[c.name]) < 3.0 * c.descent.drag_area_sigma
            assert c.sentence.startswith(f"the {c.name} opened")
        main = result["main"]
        assert main.t_open is not None
        charge = flight.events["main"]
        assert charge <= main.t_open <= charge + LINE_STRETCH_S + MAIN.fill_s + 0.2


@pytest.mark.parametrize("seed", range(3))
def test_a_ballistic_descent_reads_not_opened(seed: int) -> None:
    """No canopy opens: the drogue's descent needs the airframe's own drag area; the main's
    charge 450 m up leaves 4 s of log before the impact: too short to tell."""
    result = _forensics(fly_recovery(seed, BALLISTIC), BALLISTIC)
    drogue, main = result.canopies
    assert drogue.verdict == "not_opened", drogue.sentence
    assert drogue.sentence.startswith("the drogue did not open: the descent at ")
    assert "the airframe's own drag area" in drogue.sentence
    assert drogue.descent is not None and drogue.descent.rate > 100.0
    assert main.verdict == "undetermined" and main.sentence.startswith("the main: cannot tell")
    assert "the log ends" in main.sentence


@pytest.mark.parametrize("seed", range(3))
def test_a_streamer_reads_partial(seed: int) -> None:
    """A drogue that gives 0.05 m^2 on a 0.61 m canopy: more than the airframe, far less than
    Cd 0.3 on its area; the main opens."""
    result = _forensics(fly_recovery(seed, STREAMER), STREAMER)
    drogue, main = result.canopies
    assert drogue.verdict == "partial", drogue.sentence
    assert drogue.sentence.startswith("the drogue opened only in part")
    assert drogue.own is not None and abs(drogue.own.value - 0.05) < 3.0 * drogue.own.sigma
    assert main.verdict == "opened", main.sentence


@pytest.mark.parametrize("seed", range(3))
def test_a_main_that_does_not_inflate_reads_not_opened(seed: int) -> None:
    """The main's charge changes nothing: its own drag area is nil within its sigma, far
    below an open canopy's; the drogue opened."""
    flight = fly_recovery(seed, MAIN_FAILS)
    result = _forensics(flight, MAIN_FAILS)
    drogue, main = result.canopies
    assert drogue.verdict == "opened"
    assert main.verdict == "not_opened", main.sentence
    assert main.sentence.startswith("the main did not inflate: the descent rate stayed")
    assert f"at {flight.events['main']:.1f} s" in main.sentence
    assert main.p_opened is not None and main.p_opened > result.alpha


def test_a_log_that_ends_before_the_main_leaves_it_undetermined() -> None:
    flight = fly_recovery(7, NORMAL, end_s=80.0)
    result = _forensics(flight, NORMAL)
    assert result["drogue"].verdict == "opened"
    main = result["main"]
    assert main.verdict == "undetermined" and main.deploy_time is None
    assert "no charge" in main.sentence


def test_without_the_airframe_a_streamer_is_short_of_any_canopy() -> None:
    """No coast and no card value: the streamer's descent is still far faster than any open
    canopy of its diameter allows (not_opened, saying a streamer cannot be told apart);
    the normal drogue reads opened."""
    streamer = _forensics(fly_recovery(3, STREAMER), STREAMER, coast=False)["drogue"]
    assert streamer.verdict == "not_opened" and streamer.before is None
    assert "a streamer cannot be told from no canopy" in streamer.sentence
    normal = _forensics(fly_recovery(3, NORMAL), NORMAL, coast=False)["drogue"]
    assert normal.verdict == "opened"


def test_the_card_airframe_stands_in_for_the_coast() -> None:
    flight = fly_recovery(4, BALLISTIC)
    card = DragArea(BODY_CDS, 0.1 * BODY_CDS, "card")
    drogue = _forensics(flight, BALLISTIC, coast=False, airframe=card)["drogue"]
    assert drogue.verdict == "not_opened" and "from the card" in drogue.sentence


def test_a_descent_needing_more_than_the_drogue_can_give_is_flagged() -> None:
    """The main comes out at apogee in the drogue's place (a 0.82 m "drogue" on the card):
    the descent needs more drag than MAX_CD on the drogue's area, and the real main's charge
    then changes nothing: undetermined (it may have been out), never "not_opened"."""
    swapped = {"drogue": Chute(MAIN.cds, 1.2, 0.82, delay_s=1.0),
               "main": Chute(0.0, 1.2, 1.83, height_m=450.0)}
    result = _forensics(fly_recovery(5, swapped), swapped)
    drogue, main = result.canopies
    assert drogue.verdict == "opened" and drogue.above_diameter
    assert "more than its 0.82 m diameter can give" in drogue.sentence
    assert main.verdict == "undetermined" and "out already" in main.sentence


# --- the public logs --------------------------------------------------------------------

needs_logs = pytest.mark.skipif(not DATA.is_dir(), reason=f"{DATA} is absent")


def _geometric(pressure: np.ndarray, p0: float, elevation: float, t0: float):
    from cpas_ocp.physics.atmosphere import SiteAtmosphere

    site = SiteAtmosphere(elevation, p0, t0)
    return (site.altitude_at_pressure(pressure) - elevation,
            lambda h: np.asarray(site.density(elevation + np.asarray(h)), dtype=float))


@needs_logs
def test_hedy_drogue_opened_and_its_main_changed_nothing_at_450_m() -> None:
    """Hedy 2025 (CATS, 17.2 kg): the drogue at 36.7 s (the altimeter's pulse) opened, its
    descent near the published 0.53 m^2; at the card's 450 m main height the descent rate
    does not change (the main "did not deploy fully"): not_opened, not opened."""
    from cpas_ocp.io.cats_vega import read_cats_log
    from cpas_ocp.io.flight_events import detect_events
    from cpas_ocp.io.log_noise import scatter_sigma

    record = read_cats_log(DATA / "hedy-2025" / "cats_tust")
    baro = record.samples[["time", "pressure"]].dropna()
    t = baro["time"].to_numpy()
    p0 = float(baro[baro["time"] < 0.0]["pressure"].median())
    h, rho = _geometric(baro["pressure"].to_numpy(), p0, 160.0, 293.15)
    events, _ = detect_events(record.samples)
    accel = record.samples[["time", "acceleration"]].dropna()
    coast = coast_drag_area(t, h, rho, 17.2, t_burnout=events["coast"].time,
                            accel=(accel["time"].to_numpy(), accel["acceleration"].to_numpy()))
    t_main = float(t[np.flatnonzero((t > events["apogee"].time) & (h <= 450.0))[0]])
    result = deployment_forensics(
        t, h, rho, 17.2, [Canopy("drogue", events["drogue"].time, events["drogue"].sigma),
                          Canopy("main", t_main, 1.0)],
        t_end=float(t[-1]) - 1.0, noise_sigma=scatter_sigma(t, h), coast=coast)
    drogue, main = result.canopies
    assert coast is not None and drogue.verdict == "opened", drogue.sentence
    assert drogue.descent is not None and 0.45 < drogue.descent.drag_area < 0.65
    assert main.verdict in ("not_opened", "partial"), main.sentence


@needs_logs
def test_andromeda_descent_needs_far_more_than_its_drogue() -> None:
    """Andromeda 2022 (20.0 kg): from apogee at 3436 m the descent at 6-9 m/s needs several
    square metres, more than the card's 0.82 m drogue can give at any Cd; the log ends far
    above the main's 500 m."""
    from cpas_ocp.io.log_noise import scatter_sigma
    from cpas_ocp.physics.atmosphere import SiteAtmosphere

    table = pd.read_csv(DATA / "andromeda-2022" / "flight_data.csv").iloc[:-2]
    t, h = table["t(s)"].to_numpy(), table["alt(m)"].to_numpy()
    site = SiteAtmosphere(160.0, 99000.0, 293.15)
    rho = lambda x: np.asarray(site.density(160.0 + np.asarray(x)), dtype=float)  # noqa: E731
    top = float(t[np.argmax(h)])
    result = deployment_forensics(
        t, h, rho, 20.0, [Canopy("drogue", top, 0.5, 0.82), Canopy("main", None, 1.0, 2.2)],
        noise_sigma=scatter_sigma(t, h), coast=coast_drag_area(t, h, rho, 20.0))
    drogue, main = result.canopies
    assert drogue.verdict == "opened" and drogue.above_diameter, drogue.sentence
    assert drogue.descent is not None and drogue.descent.drag_area > 3.0 * math.pi * 0.41**2
    assert main.verdict == "undetermined"


# A single main fired 1 s after apogee that hangs 7 s streaming (0.25 m^2) before it fills:
# the Lince 2023 log's recovery, whose main took hold 8 s after its charge.
HUNG_MAIN = {"main": Chute(2.5, 1.0, 1.5, delay_s=1.0, hang_s=7.0, streaming_cds=0.25)}


@pytest.mark.parametrize("seed", range(3))
def test_a_main_that_hangs_after_its_charge_is_found_where_it_took_hold(seed: int) -> None:
    """The descent's corner lies between the fill's start and its end plus three speed
    relaxation times of the fall (v / 2g: the deceleration's tail); the fall before it
    needs the streaming canopy's and the airframe's drag area, which its line overstates
    a little (the fall still speeds up towards its terminal rate): a first guess within a
    quarter of the truth for the fit to estimate; the sentence says when and how late."""
    flight = fly_recovery(seed, HUNG_MAIN)
    main = _forensics(flight, HUNG_MAIN)["main"]
    assert main.verdict == "opened", main.sentence
    chute, charge = HUNG_MAIN["main"], flight.events["main"]
    fill_start = charge + LINE_STRETCH_S + chute.hang_s
    assert main.t_open is not None and main.fall_before is not None
    terminal = math.sqrt(2.0 * MASS * 9.80665 / (float(density(np.array([2000.0]))[0])
                                                 * (BODY_CDS + chute.streaming_cds)))
    assert fill_start <= main.t_open <= fill_start + chute.fill_s + 3.0 * terminal / (
        2.0 * 9.80665)
    truth = BODY_CDS + chute.streaming_cds
    assert truth <= main.fall_before.value + 3.0 * main.fall_before.sigma
    assert abs(main.fall_before.value - truth) < 0.25 * truth
    assert f"it took hold {main.t_open - charge:.1f} s after its charge" in main.sentence


def test_a_canopy_that_opens_at_its_charge_is_never_read_as_late() -> None:
    """Over 20 normal recoveries (the drogue filling 0.3 s after its charge near apogee) the
    first canopy is never said to have hung."""
    for seed in range(20):
        drogue = _forensics(fly_recovery(seed + 200, NORMAL), NORMAL)["drogue"]
        assert drogue.fall_before is None, (seed, drogue.sentence)


def test_a_late_opening_moves_the_start_s_window_and_frees_the_airframe_s_drag() -> None:
    """The rocket model of a canopy that took hold late: its start's window centred on the
    opening (the shift from the start its charge seeds), the fall's drag area the airframe's
    first guess, CdS_V free; the card's own shift and airframe drag area win."""
    model = rocket_model({}, ["baro"], [("main", "open")], ["main"], {"main": 0.01})
    out, vehicle = late_openings(model, {"name": "r", "mass": {"value": 9.9, "unit": "kg"}},
                                 {"main": 7.74}, {"main": "open"}, 0.30)
    [inflation] = [e for e in out["effects"]
                   if isinstance(e, dict) and e["effect"] == "canopy_inflation"]
    assert inflation["start_shifts"] == {"t_start[main,open]": 7.74}
    assert "CdS_V" in out["free"] and vehicle["forebody_cds"]["value"] == 0.30
    card = {**model, "effects": [*model["effects"][:1],
                                 {"effect": "canopy_inflation",
                                  "start_shifts": {"t_start[main,open]": 5.0}},
                                 *model["effects"][2:]]}
    out, vehicle = late_openings(card, {"forebody_cds": {"value": 0.1, "unit": "m^2"}},
                                 {"main": 7.74}, {"main": "open"}, 0.30)
    [inflation] = [e for e in out["effects"]
                   if isinstance(e, dict) and e["effect"] == "canopy_inflation"]
    assert inflation["start_shifts"] == {"t_start[main,open]": 5.0}
    assert vehicle["forebody_cds"]["value"] == 0.1
