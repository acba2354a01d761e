"""Real flight logs into test folders: a flight card plus a flight-computer log.

A *flight card* (JSON; the built-in ones are problems with ``"kind":
"flight_log"``) holds what the log does not: the vehicle's descent mass and
forebody drag area, the parachutes and the flight state that deploys each,
the launch site (elevation, surface air density, lapse rate or ``"gps"``),
the model block to reconstruct with, and the published nominal drag areas
to compare against.

`import_flight` turns a cleaned log (`flight_record.FlightRecord`, from any
reader: `altus_metrum`, `cats_vega`, `column_map`) and a card into a test
folder:

* the card's deployments name flight states (``drogue``, ``main``): the
  log's own where it logged states, else the events `flight_events`
  detects in the accelerometer and the altimeter (the charge near apogee,
  or apogee itself, is ``drogue``, the next ``main``);
* phase: from the first deployment to touchdown (`flight_events.touchdown`:
  the altitude has stopped falling and the accelerometer is at rest), less
  `TOUCHDOWN_MARGIN_S`; a log that ends before touchdown ends the phase at
  its end, and the import says so;
* events: each deployment as a ``mortar_fire`` of its canopy, with the state
  machine's timing sigma `EVENT_SIGMA_S` or the detector's sigma;
* every series runs `SERIES_MARGIN_S` beyond the phase, so that each
  covers it;
* ``baro.csv``: pressure altitude (m); samples from `EVENT_SIGMA_S` before to
  `EJECTION_EXCLUDE_S` after a deployment are left out (the ejection charge's pressure pulse reads
  as a 150 m jump in one sample);
* ``gps_altitude.csv``: GPS altitude (m MSL) at each new fix with at least
  four satellites;
* ``accelerometer.csv`` (where the log has an accelerometer): axial
  acceleration (m/s^2, 1 g subtracted), fitted by the `axial_accelerometer`
  effect, less the charge samples and, in each
  later canopy's opening, the samples above the drag ceiling
  (`drag_ceiling`: the shock cord's snatch, which no drag model makes; the
  largest is the full-open event below);
* a ``full_open`` event for each later canopy whose opening the
  accelerometer shows (`opening_peak`): the time of the largest axial
  specific force in the `OPENING_WINDOW_S` after the charge, with one
  accelerometer sample interval as its sigma.  On a hobby rocket that peak
  is the snatch of the elastic shock cord, which comes when the canopy, full,
  has stopped ahead of the vehicle: the peak marks full open to within a
  sample (it lies anywhere between two) and needs no attitude (the axis
  swinging against the riser scales the reading, not its timing).  The first
  canopy's is not taken: it opens near apogee, where the load barely rises;
* the site atmosphere (`atmosphere.SiteAtmosphere`): the pad pressure (median
  before launch), the temperature from the card's surface density
  (T = p / (R rho)), and the lapse rate from the card or, with ``"gps"``,
  fitted to the GPS fixes of the descent (`fit_lapse_rate`; in boost the
  receiver lags the vehicle by tens of metres);
* noise sigmas from the data: the altimeter's per canopy phase, from its
  scatter about the local trend (`log_noise.scatter_sigma`; under a 30 m/s drogue the
  static pressure swings by metres over seconds), the GPS altitude's from the
  lapse-rate fit's residuals.  A later canopy's altimeter sigma applies from
  the time its descent has settled (`log_noise.settled_time`), not from its deployment:
  until then the vehicle still falls fast and is jerked about by the opening,
  and the static port errs as it did under the canopy before.  The
  accelerometer's sigma is the RMS of its scatter about the local trend
  (`log_noise.scatter_rms`: the swing's jolts are part of the swing), under each
  canopy's steady descent and apart over each later canopy's opening (from
  the charge until the descent has settled, at least `OPENING_WINDOW_S`),
  where the shock cord bounces the body by g's within a sample.

The folder is written to a temporary sibling and moved into place only once
it loads, so a failed import leaves nothing behind.
"""

from __future__ import annotations

import json
import shutil
import tempfile
from itertools import pairwise
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd
from scipy.optimize import minimize_scalar

from cpas_ocp.errors import InputError
from cpas_ocp.io.altus_metrum import AltusLog
from cpas_ocp.io.flight_card import ASSUMED_CD, FlightCard, card_quantity, pad_temperature
from cpas_ocp.io.flight_events import (
    CLUSTER_GAP_S,
    DROGUE_WINDOW_S,
    FlightEvent,
    detect_events,
    sample_interval,
    second_difference_sigma,
)
from cpas_ocp.io.flight_record import FlightRecord, enu_about, pressure_of_altitude
from cpas_ocp.io.flight_test import FORMAT, MANIFEST, load_test, validate_manifest
from cpas_ocp.io.import_reports import ImportSummary, Snatch
from cpas_ocp.io.log_noise import (
    MIN_DESCENT_SAMPLES,
    RATE_WINDOW_S,
    STEADY_RATE_S,
    accelerometer_blocks,
    block_sigma,
    dead_note,
    dead_samples,
    independent_blocks,
    local_slope,
    scatter_rms,
    settled_time,
)
from cpas_ocp.io.plausibility import (
    MAX_DESCENT_M_S,
    MAX_SPEED_M_S,
    check_boost,
    check_pad_air,
    check_speed,
    check_steady_accelerometer,
)
from cpas_ocp.io.strict_json import json_text
from cpas_ocp.physics.atmosphere import (
    ISA_LAPSE_K_M,
    SiteAtmosphere,
    pressure_altitude,
)
from cpas_ocp.physics.effects.canopy_inflation import MAX_CD
from cpas_ocp.physics.effects.registry import SENSOR_EFFECTS
from cpas_ocp.physics.effects.wind_process import VERTICAL_MEAN_SIGMA_M_S
from cpas_ocp.physics.units import G0

TOUCHDOWN_MARGIN_S = 0.5  # phase ends this long before the detected touchdown (s)


EVENT_SIGMA_S = 0.1  # timing sigma of a flight-state change (one descent sample, s)


MIN_EVENT_SIGMA_S = 1e-6  # least event sigma a manifest states (its times' resolution, s)


EJECTION_EXCLUDE_S = 0.3  # altimeter samples left out after an ejection charge (s)


MIN_ACCEL_SIGMA = 0.1  # floor of the accelerometer noise sigma (m/s^2)


MIN_BARO_SIGMA_M = 0.3  # floor of the altimeter noise sigma (the pressure resolution, m)


LAPSE_BOUNDS_K_M = (0.002, 0.0098)  # search range of a fitted lapse rate (to the dry adiabat)


SERIES_MARGIN_S = 1.5  # series extend this far beyond the phase: a 1 Hz GPS covers it (s)


OPENING_WINDOW_S = 3.0  # an opening-load peak is looked for this long after the charge (s)


OPENING_BASELINE_S = 5.0  # the steady reading before a charge is taken over this long (s)


OPENING_PEAK_SIGMAS = 5.0  # a peak counts when this many scatter sigmas off the steady reading


# A log must go on this long after the first deployment to be fitted (s), with at least
# log_noise.MIN_DESCENT_SAMPLES altimeter samples.
MIN_DESCENT_S = 5.0




LAUNCH_RISE_M = 10.0  # launch: the altitude has risen this far above its lowest so far (m) ...


LAUNCH_LEAD_S = 1.0  # ... and the pad's samples end this long before that (s)


MIN_PAD_SAMPLES = 10  # the pad's level is their median where the log has this many


def fit_lapse_rate(fixes: pd.DataFrame, pressure: pd.Series, times: pd.Series,
                   elevation: float, p0: float, t0: float) -> tuple[float, float, float]:
    """The lapse rate (K/m) that makes the site atmosphere's altitude of the measured
    pressure match the GPS altitudes, with a constant GPS offset.

    Returns (lapse rate, GPS offset (m), residual standard deviation (m)).
    Least squares over every fix; the offset is profiled out (its estimate is
    the mean difference).
    """
    p_at = np.interp(fixes["time"], times, pressure)
    h_gps = fixes["gps_altitude"].to_numpy()

    def residual(lapse: float) -> np.ndarray:
        site = SiteAtmosphere(elevation, p0, t0, lapse)
        d = h_gps - site.altitude_at_pressure(p_at)
        return d - d.mean()

    best = minimize_scalar(lambda lapse: float(np.sum(residual(lapse) ** 2)),
                           bounds=LAPSE_BOUNDS_K_M, method="bounded",
                           options={"xatol": 1e-6})
    lapse = float(best.x)
    site = SiteAtmosphere(elevation, p0, t0, lapse)
    offset = float(np.mean(h_gps - site.altitude_at_pressure(p_at)))
    return lapse, offset, float(np.std(residual(lapse), ddof=2))


def drag_ceiling(t: np.ndarray, height: np.ndarray, density: np.ndarray, t_charge: float,
                 t_settled: float, t_next: float) -> float | None:
    """The largest axial reading (m/s^2, one g subtracted) the canopies' drag can give in
    the opening that follows a charge at `t_charge`, from the altimeter alone.

    Once settled (from `t_settled`, over STEADY_RATE_S or to `t_next`) the open
    canopies carry the weight at the descent rate v_s, so their full drag area is
    2 m g / (rho_s v_s^2).  No opening pulls more than that area at the speed v_c
    the vehicle had at the charge (the rate over RATE_WINDOW_S before it): a
    specific force of g (rho_c v_c^2) / (rho_s v_s^2), and an axial reading of
    at most that less one g (the axis's cosine to the force is at most 1).  A
    reading above it is the shock cord's snatch, the elastic cord giving back the
    energy it stored as the canopy stopped ahead of the vehicle, which no drag
    model makes.  `height` (m) and `density` (kg/m^3) are the altimeter's
    samples at times `t`.  None where the rates cannot be told."""
    early = t_charge - EVENT_SIGMA_S
    v_c = -local_slope(t, height, early - RATE_WINDOW_S, early)
    end = min(t_settled + STEADY_RATE_S, t_next)
    v_s = -local_slope(t, height, t_settled, end)
    if not (v_c > 0.0 and v_s > 0.0):
        return None
    at_charge = (t >= early - RATE_WINDOW_S) & (t <= early)
    settled = (t >= t_settled) & (t <= end)
    ratio = float(np.mean(density[at_charge]) / np.mean(density[settled]))
    return G0 * ratio * (v_c / v_s) ** 2 - G0


def descent_drag_areas(deploy: dict[str, float], parachutes: list[dict[str, Any]],
                       card: FlightCard, site: SiteAtmosphere, t: np.ndarray, h: np.ndarray,
                       t_end: float) -> dict[str, float]:
    """Each canopy's own drag area (m^2) as its steady descent shows it; NaN where none can
    be told.  Under the canopies open in a canopy's steady descent (the second half of the
    span from its settled time to the next deployment or `t_end`) the drag carries the
    weight: the drag area open is 2 m g / (rho v^2) at that descent rate v and air density
    rho (`site` at the mean pressure altitude `h`, m, of those samples at times `t`, s), m
    the flown mass; the canopy's own is that less what the earlier canopies showed (all of
    it where that is not less: a canopy cut away).  The forebody's drag area is in the
    first canopy's."""
    mass = card_quantity(card.vehicle.get("mass"), "mass", card.source, "vehicle.mass") + sum(
        card_quantity(c["dry_mass"], "mass", card.source, "parachutes.dry_mass")
        for c in parachutes)
    order = sorted(deploy, key=deploy.__getitem__)
    areas = []
    for k, name in enumerate(order):
        t_to = deploy[order[k + 1]] if k + 1 < len(order) else t_end
        mid = 0.5 * (settled_time(t, h, deploy[name], t_to) + t_to)
        rate = -local_slope(t, h, mid, t_to)
        sel = (t >= mid) & (t <= t_to)
        if not rate > 0.0:
            areas.append(float("nan"))
            continue
        altitude = site.altitude_at_pressure(pressure_of_altitude(h[sel]))
        rho = float(np.mean(np.asarray(site.density(altitude), float)))
        areas.append(2.0 * mass * G0 / (rho * rate**2))
    own = {}
    for k, name in enumerate(order):
        before = areas[k - 1] if k > 0 else 0.0
        own[name] = areas[k] - before if np.isfinite(before) and areas[k] > before \
            else areas[k]
    return own


def canopy_diameters(parachutes: list[dict[str, Any]], areas: dict[str, float],
                     card: FlightCard) -> list[str]:
    """Fill in the diameter D_o of each canopy whose card gives none from its descent drag
    area (`descent_drag_areas`): the diameter whose area pi D_o^2 / 4 gives it at Cd
    `ASSUMED_CD`.  D_o sets the fill time's length scale and the drag area's upper bound
    (`canopy_inflation.MAX_CD` pi D_o^2 / 4), which the report names where a fit presses it.
    Returns a note per canopy filled in, and per canopy whose card's diameter bounds its
    drag area below what its descent shows (the fit would press that bound).  InputError
    naming the card's field where a diameter is missing and no steady descent under the
    canopy can be told."""
    notes = []
    for i, chute in enumerate(parachutes):
        name, own = chute["name"], areas[chute["name"]]
        if "diameter" in chute:
            d = card_quantity(chute["diameter"], "length", card.source, f"parachutes[{i}].diameter")
            bound = MAX_CD * np.pi * d**2 / 4.0
            if np.isfinite(own) and own > bound:
                notes.append(f"{name}: the card's diameter {d:.2f} m bounds its drag area at "
                             f"{bound:.3f} m^2 ({MAX_CD:g} pi D_o^2 / 4), below the {own:.3f} "
                             "m^2 its steady descent shows: check the diameter (or leave it "
                             "out to take it from the descent)")
            continue
        if not (np.isfinite(own) and own > 0.0):
            raise InputError(card.source, f"parachutes[{i}].diameter", f"a value: {name}'s "
                             "diameter cannot be taken from the log, which shows no steady "
                             "descent under it")
        diameter = float(np.sqrt(4.0 * own / (np.pi * ASSUMED_CD)))
        chute["diameter"] = {"value": round(diameter, 4), "unit": "m"}
        notes.append(f"{name}: no diameter in the card; D_o {diameter:.2f} m from the steady "
                     f"descent under it (drag area {own:.3f} m^2 at Cd {ASSUMED_CD:g}); its "
                     f"drag area is bounded at {MAX_CD:g} pi D_o^2 / 4 = "
                     f"{MAX_CD * np.pi * diameter**2 / 4.0:.3f} m^2")
    return notes


# The rocket-log model where the card lists no effects: the air's vertical motion (an
# Ornstein-Uhlenbeck process with a 1 m/s prior, knots every 4 s: a rocket's descent rate
# of metres per second is moved by the air as much as by its canopy), the canopies' drag on
# a rigid riser, the altimeter, and the other sensors' effects where the folder has them.
# The altimeter's bias and lag only with a second sensor: against the altimeter alone a
# bias is the initial altitude and a lag a shift of every event, which no fit can tell.
ROCKET_EFFECTS: tuple[str | dict[str, Any], ...] = (
    {"effect": "wind_process", "components": ["up"], "knot_s": 4.0, "tau_s": 20.0,
     "sigma_vertical": 1.0, "sigma_mean_vertical": VERTICAL_MEAN_SIGMA_M_S},
    "canopy_inflation", "forebody_drag", "rigid_riser", "baro")


ALTIMETER_ERRORS = ("baro_bias", "baro_lag")


# Held opening shape of a canopy deployed near apogee (the effect's default fill constant,
# linear growth): its fill time n D_o / V_i divides by the small speed at deployment, and
# no sensor of a rocket log resolves that opening.  A later canopy whose opening no
# accelerometer reads has its shape exponent held (linear growth): the altimeter sees the
# opening's duration, not the curve's shape.
HELD_FILL_CONSTANT = 8.0


HELD_EXPOPEN = 1.0


MIN_START_WINDOW_S = 2.0  # least half-width of an inflation start's window about its event


def held_openings(deploy: dict[str, float], events: dict[str, FlightEvent]) -> list[str]:
    """Canopies deployed within `flight_events.DROGUE_WINDOW_S` of apogee (after it, or
    before it by less than apogee's sigma plus a second), whose opening shape the default
    model holds."""
    if "apogee" not in events:
        return []
    top = events["apogee"]
    return [name for name, t in deploy.items()
            if top.time - top.sigma - 1.0 <= t <= top.time + DROGUE_WINDOW_S]


def rocket_model(block: dict[str, Any], sensor_kinds: list[str],
                 canopies: list[tuple[str, str]], held: list[str],
                 deploy_sigma: dict[str, float], still_air: bool = False) -> dict[str, Any]:
    """The manifest's model block: the card's where it lists effects; else `ROCKET_EFFECTS`
    with the sensors' (`sensor_kinds`) and, with a second sensor, the altimeter's errors;
    each start window at least three of its deployment's sigmas (and `MIN_START_WINDOW_S`);
    the opening shape (n, expopen) of the canopies named in `held` held at
    `HELD_FILL_CONSTANT`, `HELD_EXPOPEN`, and without an accelerometer every canopy's
    expopen (`canopies`: each canopy's name and first stage); the card's own fixes, frees
    and priors win.  `still_air` leaves the air's motion out."""
    if "effects" in block:
        return block
    window = max(MIN_START_WINDOW_S, *(3.0 * s for s in deploy_sigma.values()))
    effects = [{"effect": "canopy_inflation", "start_window": round(window, 3)}
               if e == "canopy_inflation" else e for e in ROCKET_EFFECTS
               if not (still_air and isinstance(e, dict) and e["effect"] == "wind_process")]
    others = [SENSOR_EFFECTS[k] for k in dict.fromkeys(sensor_kinds) if k != "baro"]
    effects += [*(ALTIMETER_ERRORS if others else ()), *others]
    fix: dict[str, Any] = {}
    accelerometer = "axial_accelerometer" in sensor_kinds
    for name, stage in canopies:
        if name in held:
            fix[f"n[{name},{stage}]"] = HELD_FILL_CONSTANT
        if name in held or not accelerometer:
            fix[f"expopen[{name},{stage}]"] = HELD_EXPOPEN
    return {**block, "effects": effects, "fix": {**fix, **block.get("fix", {})}}


def pad_pressure(baro: pd.DataFrame, events: dict[str, FlightEvent], card: FlightCard
                 ) -> tuple[float, str]:
    """The air pressure on the pad (Pa) and a sentence saying where it came from.

    The card's ``site.pressure`` where it gives one; else the median of the barometer's
    samples before launch, launch being the boost the accelerometer saw or, without one,
    `LAUNCH_LEAD_S` before the altitude first stands `LAUNCH_RISE_M` above its lowest
    reading so far (a log that starts on the pad); where fewer than `MIN_PAD_SAMPLES`
    precede it (the log starts at launch), the lowest reading before the rise: the
    recorder's first samples, taken as the rocket left the pad."""
    if "pressure" in card.site:
        p0 = card_quantity(card.site["pressure"], "pressure", card.source, "site.pressure")
        return p0, f"pad pressure {p0:.0f} Pa from the card's site.pressure"
    t, h = baro["time"].to_numpy(), baro["altitude"].to_numpy()
    rise = np.flatnonzero(h - np.minimum.accumulate(h) > LAUNCH_RISE_M)
    k_rise = int(rise[0]) if rise.size else len(h) - 1
    t_launch = events["boost"].time if "boost" in events else float(t[k_rise]) - LAUNCH_LEAD_S
    pad = baro[baro["time"] < t_launch]
    if len(pad) >= MIN_PAD_SAMPLES:
        p0 = float(pad["pressure"].median())
        return p0, (f"pad pressure {p0:.0f} Pa: the median of the {len(pad)} barometer "
                    f"samples before launch ({t_launch:.2f} s)")
    k = int(np.argmin(h[:k_rise + 1]))
    p0 = float(baro["pressure"].iloc[k])
    return p0, (f"pad pressure {p0:.0f} Pa: the log starts at launch (only {len(pad)} "
                f"samples before it), so the pad is its lowest reading before the climb, "
                f"at {t[k]:.2f} s; give site.pressure in the card where that is not the pad")


def card_events(card: FlightCard, baro: pd.DataFrame, pad_altitude: float,
                events: dict[str, FlightEvent]) -> dict[str, FlightEvent]:
    """The events the card gives (``events``): at a time, or where the descent first
    crosses below a height above the pad after apogee (a main fired by an altimeter at
    its set height), the crossing interpolated between the barometer's samples; each with
    the card's sigma.  InputError naming the card's field where the descent never comes
    down to that height, or the time lies outside the log."""
    out: dict[str, FlightEvent] = {}
    for name, spec in card.events.items():
        field_name = f"events.{name}"
        sigma = card_quantity(spec["sigma"], "time", card.source, f"{field_name}.sigma")
        if "time" in spec:
            t_event = card_quantity(spec["time"], "time", card.source, f"{field_name}.time")
            first, last = float(baro["time"].iloc[0]), float(baro["time"].iloc[-1])
            if not first <= t_event <= last:
                raise InputError(card.source, f"{field_name}.time", f"a time the log covers "
                                 f"(its altimeter reads from {first:.2f} to {last:.2f} s, on "
                                 f"the log's own clock); got {t_event:.2f} s")
            out[name] = FlightEvent(t_event, sigma, "the card")
            continue
        height = card_quantity(spec["altitude"], "length", card.source, f"{field_name}.altitude")
        t, h = baro["time"].to_numpy(), baro["altitude"].to_numpy() - pad_altitude
        top = events["apogee"].time if "apogee" in events else float(t[np.argmax(h)])
        below = np.flatnonzero((t > top) & (h <= height))
        if below.size == 0 or below[0] == 0:
            after = h[t > top]
            raise InputError(card.source, f"{field_name}.altitude", f"a height above the pad "
                             f"the descent passes below; after apogee at {top:.2f} s the log "
                             f"reads {float(after.min()) if after.size else float('nan'):.1f}"
                             " m at the lowest")
        k = int(below[0])
        if not h[k - 1] > height:
            raise InputError(card.source, f"{field_name}.altitude", f"a height below apogee, "
                             f"which the log reads {float(np.max(h)):.1f} m above the pad; got "
                             f"{height:.1f} m")
        frac = (h[k - 1] - height) / (h[k - 1] - h[k])
        out[name] = FlightEvent(float(t[k - 1] + frac * (t[k] - t[k - 1])), sigma,
                                f"the card: the {height:.0f} m crossing")
    return out


def flight_events(record: FlightRecord) -> tuple[dict[str, FlightEvent], list[str]]:
    """The record's flight events with their sigmas: its logged states (sigma
    `EVENT_SIGMA_S`) where it has them, with apogee from the altimeter where they hold
    none, else those `detect_events` finds; touchdown (``landed``) always detected from the
    data, never taken from a state or the log's end.  Notes say what could not be found."""
    detected, notes = detect_events(record.samples)
    if record.states:
        events = {name: FlightEvent(t, EVENT_SIGMA_S, "flight state")
                  for name, t in record.states.items() if name != "landed"}
        for name in ("apogee", "landed"):  # the altimeter's, where the log logged no such state
            if name in detected and name not in events:
                events[name] = detected[name]
        notes = [n for n in notes if "touchdown" in n]
    else:
        events = detected
    if "landed" not in events:
        notes.append("no touchdown found: the log ends while the vehicle still descends")
    return events, notes


def check_charges_deploy(events: dict[str, FlightEvent], deploy: dict[str, float],
                         card: FlightCard, src: str, logged_states: bool) -> None:
    """InputError naming the card's canopies where the log `src` shows an ejection charge
    (`flight_events.detect_events`: the drogue's and the main's, found in the data, not a
    logged state, which a computer logs whether or not a canopy is rigged to it) that
    deploys none of them: no canopy's deployment time (s, `deploy`) lies within
    `CLUSTER_GAP_S` or three of the charge's sigmas of it.  The card has too few canopies
    (or the log is another flight's): the phase would hold an opening no model term makes."""
    if logged_states:
        return
    for name in ("drogue", "main"):
        charge = events.get(name)
        if charge is None or charge.source.startswith("apogee"):
            continue
        if all(abs(t - charge.time) > max(CLUSTER_GAP_S, 3.0 * charge.sigma)
               for t in deploy.values()):
            deployed = ", ".join(f"{n} at {t:.2f} s" for n, t in deploy.items())
            raise InputError(card.source, "parachutes", f"a canopy for each ejection charge "
                             f"the log shows; {src} shows one at {charge.time:.2f} s "
                             f"({charge.source}) that deploys none of the card's "
                             f"{len(deploy)} ({deployed})")


def import_flight(log: FlightRecord | AltusLog, card: FlightCard, out: str | Path,
                  still_air: bool = False) -> ImportSummary:
    """Write the test folder of `log` under `card` to `out` (see the module docstring);
    `still_air`: the default model (`rocket_model`) without the air's motion."""
    out = Path(out)
    record = log if isinstance(log, FlightRecord) else log.record()
    samples = record.samples
    src = str(record.path)
    baro = samples[["time", "altitude", "pressure"]].dropna()
    if len(baro) < 20:
        raise InputError(src, "pressure", "a barometer (pressure or altitude) read in at "
                         f"least 20 samples; the log has {len(baro)}")
    check_speed(record, baro["time"].to_numpy(), baro["altitude"].to_numpy(), MAX_SPEED_M_S,
                "no rocket is faster in the lower atmosphere")
    check_boost(record, samples)
    events, notes = flight_events(record)
    p0, pad_note = pad_pressure(baro, events, card)
    pad_altitude = float(pressure_altitude(p0))
    notes.append(pad_note)
    site_spec = card.site
    elevation = card_quantity(site_spec.get("elevation"), "length", card.source, "site.elevation")
    t0, t0_note = pad_temperature(site_spec, p0, elevation, card.source)
    check_pad_air(record, p0, t0, "card" if "temperature" in site_spec else
                  "density" if "surface_density" in site_spec else "standard", elevation,
                  card.source, "pressure" in site_spec)
    events.update(card_events(card, baro, pad_altitude, events))
    deploy: dict[str, float] = {}
    deploy_sigma: dict[str, float] = {}
    kind = "a flight state of the log" if record.states else \
        "an event detected in the log (it has no flight states)"
    deploying = {name: e for name, e in events.items() if name != "landed"}
    for i, chute in enumerate(card.parachutes):
        state = chute["deployment"]
        if state not in deploying:
            listed = ", ".join(f"{n} {e.time:.2f} ± {e.sigma:.2f} s ({e.source})"
                               for n, e in deploying.items())
            raise InputError(card.source, f"parachutes[{i}].deployment",
                             f"{kind} {src} that deploys {chute['name']}, or one the card's "
                             f"'events' gives (found: {listed or 'none'}); got {state!r}")
        # Each canopy's opening is told apart by its own event (its charge, its snatch).
        if any(card.parachutes[j]["deployment"] == state for j in range(i)):
            raise InputError(card.source, f"parachutes[{i}].deployment",
                             f"an event no other canopy of the card deploys at; "
                             f"{state!r} deploys an earlier one too")
        deploy[chute["name"]] = events[state].time
        deploy_sigma[chute["name"]] = events[state].sigma
    check_charges_deploy(events, deploy, card, src, bool(record.states))
    t_begin = min(deploy.values())
    descent = baro[baro["time"] > t_begin]
    if len(descent) < MIN_DESCENT_SAMPLES or \
            float(descent["time"].max()) - t_begin < MIN_DESCENT_S:
        span = float(descent["time"].max()) - t_begin if len(descent) else 0.0
        raise InputError(src, "(time)", f"a descent of at least {MIN_DESCENT_S:g} s and "
                         f"{MIN_DESCENT_SAMPLES} altimeter samples after the first deployment "
                         f"({min(deploy, key=deploy.__getitem__)} at {t_begin:.2f} s) to fit; "
                         f"the log ends {span:.2f} s after it, with {len(descent)} samples")
    if "landed" in events:
        t_down = events["landed"].time
        ground = baro[(baro["time"] >= t_down) & (baro["time"] <= t_down + 3.0)]["altitude"]
        notes.append(f"touchdown at {t_down:.2f} s, {float(ground.median()) - pad_altitude:+.1f}"
                     " m (pressure altitude) from the pad")
    else:
        t_down = float(baro["time"].iloc[-1])
        notes.append(f"the log ends at {t_down:.2f} s, "
                     f"{float(baro['altitude'].iloc[-1]) - pad_altitude:.1f} m above the pad: "
                     "the phase ends at the log's end")
    t_end = t_down - TOUCHDOWN_MARGIN_S
    if not record.gnss.empty:
        last = enu_about(record.gnss).iloc[-1]
        notes.append(f"GNSS: {len(record.gnss)} fixes, the last {last['east']:+.0f} m east, "
                     f"{last['north']:+.0f} m north of the first (the descent is fitted "
                     "vertically: horizontal positions are not written to the folder)")
    # Series run SERIES_MARGIN_S beyond the phase so that every sensor covers it (the
    # estimator uses the samples inside the phase only).
    lo, hi = t_begin - SERIES_MARGIN_S, t_end + SERIES_MARGIN_S
    in_phase = (baro["time"] >= lo) & (baro["time"] <= hi)
    near_charge = np.zeros(len(baro), dtype=bool)
    for t_dep in deploy.values():
        near_charge |= ((baro["time"] >= t_dep - EVENT_SIGMA_S)
                        & (baro["time"] <= t_dep + EJECTION_EXCLUDE_S)).to_numpy()
    baro_phase = baro[in_phase.to_numpy() & ~near_charge]
    dead_baro = dead_samples(baro_phase["time"].to_numpy(), baro_phase["altitude"].to_numpy())
    if dead_baro.any():
        notes.append(dead_note("altimeter", baro_phase["time"].to_numpy()[dead_baro],
                               baro_phase["altitude"].to_numpy()[dead_baro], "m"))
        baro_phase = baro_phase[~dead_baro]

    check_speed(record, baro_phase["time"].to_numpy(), baro_phase["altitude"].to_numpy(),
                MAX_DESCENT_M_S, "no canopy descends faster")
    notes.append(t0_note)
    lapse_spec = site_spec.get("lapse_rate", {"value": 1e3 * ISA_LAPSE_K_M, "unit": "K/km"})
    fixes = record.gps_fixes()
    lapse_fit = None
    if lapse_spec == "gps":
        descent = fixes[(fixes["time"] >= t_begin) & (fixes["time"] <= t_down)]
        if len(descent) < 10:
            raise InputError(card.source, "site.lapse_rate", f"a value: 'gps' needs GPS "
                             f"fixes in the descent, and {src} has {len(descent)}")
        lapse_fit = fit_lapse_rate(descent, baro["pressure"], baro["time"], elevation, p0, t0)
        lapse = lapse_fit[0]
    else:
        lapse = card_quantity(lapse_spec, "lapse_rate", card.source, "site.lapse_rate")
        if not 0.0 < lapse <= LAPSE_BOUNDS_K_M[1]:
            raise InputError(card.source, "site.lapse_rate", f"a lapse rate above 0 and at "
                             f"most the dry adiabat's {1e3 * LAPSE_BOUNDS_K_M[1]:g} K/km (or "
                             f"'gps'); got {1e3 * lapse:g} K/km")
        if record.has_gps_altitude:
            notes.append("the GNSS altitudes are not fitted: the card's lapse rate is given "
                         "('gps' fits it to them and fits them)")
    site = SiteAtmosphere(elevation, p0, t0, lapse)
    # One altimeter sigma per canopy phase, from the scatter about the local trend; a later
    # phase's from the time its descent has settled.
    t_baro, h_baro = baro_phase["time"].to_numpy(), baro_phase["altitude"].to_numpy()
    starts = sorted(deploy.values())
    bounds = [starts[0], *(settled_time(t_baro, h_baro, a, b)
                           for a, b in pairwise([*starts[1:], t_end])), t_end]
    parachutes = [dict(c) for c in card.parachutes]
    notes += canopy_diameters(parachutes, descent_drag_areas(deploy, parachutes, card, site,
                                                             t_baro, h_baro, t_end), card)
    # The altimeter's noise is correlated over a fraction of a second (a recorder's filter,
    # the static port's pressure swings as the vehicle swings): each canopy phase's samples
    # are averaged in blocks as long as that correlation (`independent_blocks`), so that the
    # fit weighs what the altimeter measured independently, and each sigma is the scatter of
    # the block means.
    edges = [lo, *bounds[1:-1], hi + 1.0]
    parts, baro_sigmas = [], []
    for (a, b), name, steady_end in zip(pairwise(edges), sorted(deploy, key=deploy.__getitem__),
                                        [*starts[1:], t_end], strict=True):
        part = baro_phase[(baro_phase["time"] >= a) & (baro_phase["time"] < b)]
        blocks, size = independent_blocks(part[["time", "altitude"]], steady_end)
        parts.append(blocks)
        if size > 1:
            seconds = size * sample_interval(part["time"].to_numpy())
            notes.append(f"altimeter under the {name} (from {a:.2f} s): noise correlated over "
                         f"{size} samples ({seconds:.2f} s), averaged in blocks of that "
                         f"length: {len(part)} samples -> {len(blocks)}")
        if len(blocks) < MIN_DESCENT_SAMPLES:  # too short a segment: the whole phase's
            blocks, steady_end = independent_blocks(baro_phase[["time", "altitude"]])[0], t_end
        baro_sigmas.append(max(MIN_BARO_SIGMA_M, block_sigma(blocks, steady_end)))
    baro_blocks = pd.concat(parts, ignore_index=True)

    fixes_phase = fixes[(fixes["time"] >= lo) & (fixes["time"] <= hi)]
    accel = samples[["time", "acceleration"]].dropna()
    dead_accel = dead_samples(accel["time"].to_numpy(), accel["acceleration"].to_numpy(),
                              clipped=True)
    accel_in = ((accel["time"] >= lo) & (accel["time"] <= hi)).to_numpy()
    if (dead_accel & accel_in).any():
        notes.append(dead_note("accelerometer", accel["time"].to_numpy()[dead_accel & accel_in],
                               accel["acceleration"].to_numpy()[dead_accel & accel_in],
                               "m/s^2"))
    accel = accel[accel_in & ~dead_accel]
    check_steady_accelerometer(record, accel["acceleration"].to_numpy())
    full_open = {name: peak for name, t in deploy.items() if t > t_begin
                 and (peak := opening_peak(accel, t)) is not None}
    # The accelerometer loses the same charge windows as the altimeter (the charge's jolt
    # is no force of the flight) and, in each later canopy's opening, the samples above the
    # drag ceiling (the shock cord's snatch; its time is the full-open event).
    accel_charge = np.zeros(len(accel), dtype=bool)
    for t_dep in deploy.values():
        accel_charge |= ((accel["time"] >= t_dep - EVENT_SIGMA_S)
                         & (accel["time"] <= t_dep + EJECTION_EXCLUDE_S)).to_numpy()
    accel = accel[~accel_charge]
    density = np.asarray(site.density(site.altitude_at_pressure(
        baro_phase["pressure"].to_numpy())), dtype=float).ravel()
    later = sorted((t, name) for name, t in deploy.items() if t > starts[0])
    snatches: dict[str, Snatch] = {}
    snatch = np.zeros(len(accel), dtype=bool)
    # A later canopy's opening lasts from its charge until its descent has settled, and at
    # least the OPENING_WINDOW_S its load peak is looked for in.
    # The next deployment (or the phase's end) after each later canopy's.
    nexts = [*starts[1:], t_end][1:]
    opening_ends = [min(max(t_settled, t_charge + OPENING_WINDOW_S), t_next) for t_charge,
                    t_settled, t_next in zip(starts[1:], bounds[1:-1], nexts, strict=True)]
    for (t_charge, name), t_settled, t_open, t_next in zip(
            later, bounds[1:-1], opening_ends, nexts, strict=True):
        ceiling = drag_ceiling(t_baro, h_baro, density, t_charge, t_settled, t_next)
        opening = (accel["time"] >= t_charge) & (accel["time"] < t_open)
        if ceiling is None or not opening.any():  # no accelerometer reading of the opening
            continue
        above = ((accel["time"] >= t_charge) & (accel["time"] < t_open)
                 & (accel["acceleration"] > ceiling)).to_numpy()
        left_out = accel[above]
        k = int(np.argmax(left_out["acceleration"])) if above.any() else None
        snatches[name] = Snatch(ceiling, int(above.sum()),
                                None if k is None else float(left_out["acceleration"].iloc[k]),
                                None if k is None else float(left_out["time"].iloc[k]))
        snatch |= above
    accel = accel[~snatch]
    # A sigma per segment from the scatter about a local trend (the body's swing about its
    # mean attitude is noise of this sensor): under each canopy's steady descent, and
    # apart in each later canopy's opening.
    accel_bounds = [*sorted({*starts, *opening_ends} - {t_end}), t_end]
    accel_sigmas = []
    # A test folder's sensors each cover the whole phase: an accelerometer that stops
    # reading inside it (dead, or logged in the boost only) is left out.
    has_accel = len(accel) >= 10 and float(accel["time"].min()) <= t_begin + SERIES_MARGIN_S \
        and float(accel["time"].max()) >= t_end - SERIES_MARGIN_S
    if not has_accel:
        accel_bounds = []
        span = (f" (its samples there span {accel['time'].min():.2f}-"
                f"{accel['time'].max():.2f} s, not the phase {t_begin:.2f}-{t_end:.2f} s)"
                if len(accel) else "")
        notes.append(f"no accelerometer over the log's phase{span}: the folder has the "
                     "altimeter only")
    # Each canopy's steady segment (the series' margins included) is written as block means
    # of its correlation length at their sigma (`accelerometer_blocks`); a later canopy's
    # opening keeps its samples, whose load peak the fit times.
    accel_parts = []
    for (a, b), (seg_lo, seg_hi) in zip(pairwise(accel_bounds), pairwise(
            [lo, *accel_bounds[1:-1], hi + 1.0] if accel_bounds else []), strict=True):
        part = accel[(accel["time"] >= seg_lo) & (accel["time"] < seg_hi)]
        if len(part) > 10 and a not in starts[1:]:
            n, (part, sigma, size) = len(part), accelerometer_blocks(part, b)
            if size > 1:
                notes.append(f"accelerometer from {seg_lo:.2f} s: noise correlated over "
                             f"{size} samples, averaged in blocks of that length: {n} -> "
                             f"{len(part)}")
        else:
            sigma = scatter_rms(part["time"].to_numpy(), part["acceleration"].to_numpy()) \
                if len(part) > 10 else second_difference_sigma(accel["acceleration"].to_numpy())
        accel_parts.append(part)
        accel_sigmas.append(max(MIN_ACCEL_SIGMA, sigma))
    accel = pd.concat(accel_parts, ignore_index=True) if accel_parts else accel
    files = {"baro.csv": baro_blocks}
    sensors: list[dict[str, Any]] = [
        {"name": "baro", "kind": "baro", "file": "baro.csv",
         "columns": {"time": "s", "altitude": "m"},
         "sigma": {"altitude": {"value": round(baro_sigmas[0], 3), "unit": "m"}},
         "sigma_after": [{"time": {"value": round(t, 3), "unit": "s"},
                          "sigma": {"altitude": {"value": round(sig, 3), "unit": "m"}}}
                         for t, sig in zip(bounds[1:-1], baro_sigmas[1:], strict=True)]}]
    if has_accel:
        files["accelerometer.csv"] = accel
        sensors.append({
            "name": "accelerometer", "kind": "axial_accelerometer",
            "file": "accelerometer.csv", "columns": {"time": "s", "acceleration": "m/s^2"},
            "sigma": {"acceleration": {"value": round(accel_sigmas[0], 3), "unit": "m/s^2"}},
            "sigma_after": [{"time": {"value": round(t, 3), "unit": "s"},
                             "sigma": {"acceleration": {"value": round(sig, 3),
                                                        "unit": "m/s^2"}}}
                            for t, sig in zip(accel_bounds[1:-1], accel_sigmas[1:],
                                              strict=True)]})
    if lapse_fit is not None and len(fixes_phase) >= 2:
        files["gps_altitude.csv"] = fixes_phase[["time", "gps_altitude"]].rename(
            columns={"gps_altitude": "up"})
        sensors.append({"name": "gps_altitude", "kind": "gps_altitude",
                        "file": "gps_altitude.csv", "columns": {"time": "s", "up": "m"},
                        "sigma": {"altitude": {"value": round(lapse_fit[2], 3), "unit": "m"}}})
    manifest = {
        "format": FORMAT,
        "name": card.name,
        "description": f"{card.title}: {record.recorder} log {record.path.name}",
        "label": card.label,
        "vehicle": card.vehicle,
        "parachutes": [{k: v for k, v in c.items() if k != "deployment"}
                       for c in parachutes],
        "events": [event_entry("mortar_fire", name, t, deploy_sigma[name])
                   for name, t in deploy.items()]
                  + [event_entry("full_open", name, t, sigma)
                     for name, (t, sigma) in full_open.items()],
        "sensors": sensors,
        "atmosphere": {"model": "site",
                       "elevation": {"value": elevation, "unit": "m"},
                       "pressure": {"value": round(p0, 2), "unit": "Pa"},
                       "temperature": {"value": round(t0, 3), "unit": "K"},
                       "lapse_rate": {"value": round(1e3 * lapse, 4), "unit": "K/km"}},
        "phase": {"start": {"value": instant(t_begin), "unit": "s"},
                  "end": {"value": round(t_end, 3), "unit": "s"}},
        "model": rocket_model(card.model, [s["kind"] for s in sensors],
                              [(c["name"], c["stages"][0]) for c in parachutes
                               if not c.get("open_at_start")],
                              held_openings(deploy, events), deploy_sigma, still_air),
    }
    try:
        validate_manifest(manifest, card.source)
    except InputError as exc:
        raise blamed(exc, card.source, src, MANIFEST) from None
    summary = ImportSummary(
        record.recorder, (t_begin, t_end),
        {**deploy, **{f"{name} full open": t for name, (t, _) in full_open.items()},
         "touchdown": t_down}, site, lapse_fit,
        baro_sigmas, {name: len(frame) for name, frame in files.items()},
        {**record.dropped,
         "ejection_charge_samples": int((in_phase.to_numpy() & near_charge).sum()),
         "ejection_charge_accelerometer_samples": int(accel_charge.sum()),
         "snatch_samples_above_drag_ceiling": int(snatch.sum())},
        accel_sigmas, snatches, events, [*record.notes, *notes], card.nominal)
    _write_folder(out, manifest, files, summary, card.source, src)
    return summary


# Manifest fields the import copies from the card; the others it derives from the log.
CARD_FIELDS = ("name", "label", "vehicle", "parachutes", "model")


def blamed(exc: InputError, card_source: str, log_source: str, written: str) -> InputError:
    """What the test folder's loading refused in the file `written` of an import, named
    against where it came from: the card (the manifest's vehicle, canopies and model) or
    the log (the phase, events, sensors, atmosphere)."""
    if written == MANIFEST and exc.field.startswith(CARD_FIELDS):
        return InputError(card_source, exc.field, f"{exc.expectation} (in the manifest the "
                          "card makes)")
    return InputError(log_source, f"(imported as {written}: {exc.field})", exc.expectation)


def instant(t: float) -> float:
    """A time (s) as the manifest states it, to the microsecond: the phase's start and the
    first deployment, rounded alike, stay equal."""
    return round(t, 6)


def event_entry(name: str, parachute: str, t: float, sigma: float) -> dict[str, Any]:
    """A manifest event of `parachute` at `t` (s) with its timing `sigma` (s): the time to
    the microsecond and the sigma to four significant digits, never below `MIN_EVENT_SIGMA_S`
    (a detected event's sigma is a sample interval, a quarter of a millisecond at 4 kHz,
    which rounding to the millisecond made 0)."""
    return {"name": name, "parachute": parachute, "time": {"value": instant(t), "unit": "s"},
            "sigma": {"value": max(MIN_EVENT_SIGMA_S, float(f"{sigma:.4g}")), "unit": "s"}}


def _write_folder(out: Path, manifest: dict[str, Any], files: dict[str, pd.DataFrame],
                  summary: ImportSummary, card_source: str, log_source: str) -> None:
    """Write into a temporary sibling, check that it loads, then move it to `out`.  What the
    loading refuses in the manifest is named against where it came from: the card (its
    vehicle, canopies and model) or the log (the phase, events, sensors, atmosphere)."""
    if out.exists() and any(out.iterdir()):
        raise InputError(str(out), "(folder)", "a new or empty folder for the test")
    out.parent.mkdir(parents=True, exist_ok=True)
    tmp = Path(tempfile.mkdtemp(prefix=f".{out.name}-", dir=out.parent))
    try:
        for name, frame in files.items():
            frame.to_csv(tmp / name, index=False)
        (tmp / MANIFEST).write_text(json.dumps(manifest, indent=2) + "\n")
        (tmp / "import.json").write_text(json_text(summary.to_dict()))
        try:
            load_test(tmp)
        except InputError as exc:
            written = Path(exc.file)
            if written.parent != tmp:
                raise
            raise blamed(exc, card_source, log_source, written.name) from None
        if out.exists():
            out.rmdir()
        tmp.rename(out)
    finally:
        if tmp.exists():
            shutil.rmtree(tmp)


def descent_load_factor_peak(accel: pd.DataFrame, t_from: float, t_to: float
                             ) -> tuple[float, float]:
    """Largest axial specific force (g) between `t_from` and `t_to` (s) and its time (s).

    The logger's axial acceleration has 1 g subtracted, so the specific force
    along the axis is (a + g0) / g0; its magnitude is a lower bound on the
    load factor (the axis need not point along the riser)."""
    sel = accel[(accel["time"] >= t_from) & (accel["time"] <= t_to)]
    if sel.empty:
        raise ValueError(f"no accelerometer samples in [{t_from}, {t_to}] s")
    f = np.abs(sel["acceleration"].to_numpy() + G0) / G0
    k = int(np.argmax(f))
    return float(f[k]), float(sel["time"].iloc[k])


def opening_peak(accel: pd.DataFrame, t_charge: float) -> tuple[float, float] | None:
    """(time, sigma) in s of the opening-load peak after the charge at `t_charge` (s): the
    largest axial specific force from `EJECTION_EXCLUDE_S` to `OPENING_WINDOW_S` after it
    (`descent_load_factor_peak`; the charge's own jolt comes first), sigma the median
    sample interval.  None where the peak stands fewer than `OPENING_PEAK_SIGMAS` scatter
    sigmas (1.4826 MAD) off the median reading of the `OPENING_BASELINE_S` before the
    charge, or where the accelerometer has too few samples there to tell."""
    lo, hi = t_charge + EJECTION_EXCLUDE_S, t_charge + OPENING_WINDOW_S
    before = accel[(accel["time"] >= t_charge - OPENING_BASELINE_S)
                   & (accel["time"] < t_charge - EVENT_SIGMA_S)]["acceleration"].to_numpy()
    after = accel["time"][(accel["time"] >= lo) & (accel["time"] <= hi)].to_numpy()
    if before.size < 10 or after.size < 3:
        return None
    peak, t_peak = descent_load_factor_peak(accel, lo, hi)
    steady = float(np.median(before))
    scatter = max(MIN_ACCEL_SIGMA, 1.4826 * float(np.median(np.abs(before - steady))))
    if abs(peak * G0 - abs(steady + G0)) < OPENING_PEAK_SIGMAS * scatter:
        return None
    return t_peak, float(np.median(np.diff(after)))
