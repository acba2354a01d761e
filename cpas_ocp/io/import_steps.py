"""The steps that turn a flight log and its card into a test folder's contents.

`flight_log.import_flight` runs `STEPS` in order on one `LogImport`, the import in
progress: each step reads what the earlier ones found and adds its own (a series, an
event, a decision, a note), or refuses the log with an `InputError` naming the file,
the field and what was expected.  A new recorder's quirk or a new pathology is one
step added to the sequence, tested on its own, not a branch inside the whole:

1. `clean_log_end`: a damaged end of the log (a reset, garbage) left out;
2. `read_altimeter`: the barometer's samples, checked for a flight's speeds and boost,
   and the GNSS's fixes with an altitude;
3. `find_events`: flight states or detected events, the pad's air;
4. `descent_channel`: the channel that reads the descent: the barometer's, or the GNSS
   altitude's where the barometer's file stops in the air and the GNSS's reads on
   (`gnss_descent`);
5. `given_events`: the card's events, a height's crossing read in that channel;
6. `choose_deployments`: the event that deploys each canopy, and a descent long enough;
7. `bound_phase`: touchdown, the phase, the altimeter's samples in it less the charges'
   windows and swings and a dead altimeter's, the descent channel's samples in it;
8. `site_air`: the site atmosphere, its lapse rate given or fitted to the GNSS;
9. `descent_drag`: each canopy's drag area from its settled descent, and the diameters
   the card leaves out;
10. `altimeter_series`: the altimeter averaged over its noise's correlation, with a
   sigma per canopy phase, over the part of the phase it reads;
11. `canopy_forensics`: whether each canopy opened, and how fully, from the log alone;
12. `accelerometer_series`: the axial accelerometer less charges, snatches and dead
   samples, with its sigmas, and each later canopy's full open;
13. `gnss_series`: the GNSS altitude, where the lapse rate was fitted to it or it reads
   the descent;
14. `merged_series`: each series' independent samples merged where the signal is straight,
   so that a long log's steady descent is a few means a second, not every sample;
15. `model_block`: the manifest, with the model to fit (`rocket_model`).

Each file of a log is read over its own span: the altimeter's end is not the GNSS's,
nor the accelerometer's.  A channel that stops inside the phase is left out of the part
it does not read (or of the folder), with a note; it never ends the phase.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from dataclasses import dataclass, field
from itertools import pairwise
from typing import Any

import numpy as np
import pandas as pd

from cpas_ocp.errors import InputError
from cpas_ocp.io.deployment_forensics import (
    Canopy,
    DragArea,
    Forensics,
    coast_drag_area,
    deployment_forensics,
)
from cpas_ocp.io.descent_drag import canopy_diameters, descent_drag_areas, descent_mass
from cpas_ocp.io.flight_card import FlightCard, card_quantity, pad_temperature
from cpas_ocp.io.flight_events import (
    GROUND_BAND_M,
    FlightEvent,
    gnss_reads_on,
    sample_interval,
    second_difference_sigma,
)
from cpas_ocp.io.flight_record import FlightRecord, enu_about
from cpas_ocp.io.flight_test import FORMAT
from cpas_ocp.io.gnss_descent import DATUM_SPEED_M_S, descent_sigma, gnss_channel, gnss_offset
from cpas_ocp.io.import_events import (
    EJECTION_EXCLUDE_S,
    EVENT_SIGMA_S,
    card_events,
    check_charges_deploy,
    flight_events,
)
from cpas_ocp.io.import_reports import Snatch
from cpas_ocp.io.log_hygiene import charge_swing, damaged_end, flagged_stretches, turned_over
from cpas_ocp.io.log_noise import (
    MERGE_SPAN_S,
    MIN_DESCENT_SAMPLES,
    accelerometer_blocks,
    block_sigma,
    correlation_length,
    dead_note,
    dead_samples,
    independent_blocks,
    longest_stretch,
    merged_blocks,
    scatter_rms,
    settled_time,
)
from cpas_ocp.io.opening_loads import MIN_ACCEL_SIGMA, OPENING_WINDOW_S, drag_ceiling, opening_peak
from cpas_ocp.io.plausibility import (
    MAX_DESCENT_M_S,
    MAX_SPEED_M_S,
    check_boost,
    check_pad_air,
    check_speed,
    check_steady_accelerometer,
)
from cpas_ocp.io.rocket_model import (
    effect_names,
    held_closed,
    held_openings,
    late_openings,
    rocket_model,
)
from cpas_ocp.io.site_air import LAPSE_BOUNDS_K_M, fit_lapse_rate, pad_pressure
from cpas_ocp.physics.atmosphere import ISA_LAPSE_K_M, SiteAtmosphere, pressure_altitude
from cpas_ocp.physics.effects.canopy_inflation import MORTAR_TO_INFLATION_S
from cpas_ocp.physics.units import G0

TOUCHDOWN_MARGIN_S = 0.5  # phase ends this long before the detected touchdown (s) ...


TOUCHDOWN_SIGMAS = 3.0  # ... or this many of touchdown's sigmas, where that is longer


MIN_EVENT_SIGMA_S = 1e-6  # least event sigma a manifest states (its times' resolution, s)


OPENING_READ_SAMPLES = 10  # accelerometer rows that read an opening (its OPENING_WINDOW_S)


MIN_BARO_SIGMA_M = 0.3  # floor of the altimeter noise sigma (the pressure resolution, m)


SERIES_MARGIN_S = 1.5  # series extend this far beyond the phase: a 1 Hz GPS covers it (s)


# A log must go on this long after the first deployment to be fitted (s), with at least
# log_noise.MIN_DESCENT_SAMPLES altimeter samples.
MIN_DESCENT_S = 5.0


@dataclass
class LogImport:
    """An import in progress: the log and card it reads, and what the steps have found.

    Times are on the log's own clock (s), heights pressure altitudes (m), pressures Pa,
    temperatures K.  A field is None (or empty) until the step that sets it has run."""

    record: FlightRecord
    card: FlightCard
    still_air: bool = False
    notes: list[str] = field(default_factory=list)
    dropped: dict[str, int] = field(default_factory=dict)
    # read_altimeter
    baro: pd.DataFrame = field(default_factory=pd.DataFrame)
    gnss: pd.DataFrame = field(default_factory=pd.DataFrame)  # time, gps_altitude (m MSL)
    # find_events
    events: dict[str, FlightEvent] = field(default_factory=dict)
    p0: float = float("nan")
    t0: float = float("nan")
    t0_note: str = ""
    pad_altitude: float = float("nan")
    elevation: float = float("nan")
    # descent_channel: the channel that reads the descent ("baro" or "gps_altitude"), its
    # samples as an altimeter's (time, altitude, pressure), and the GNSS's datum offset (m)
    carrier: str = "baro"
    altitude: pd.DataFrame = field(default_factory=pd.DataFrame)
    gnss_offset: float = 0.0
    # given_events
    unreached: dict[str, str] = field(default_factory=dict)  # card events past the log's end
    # choose_deployments
    flown: list[dict[str, Any]] = field(default_factory=list)  # the card's canopies in the log
    deploy: dict[str, float] = field(default_factory=dict)
    deploy_sigma: dict[str, float] = field(default_factory=dict)
    # bound_phase
    t_begin: float = float("nan")
    t_down: float = float("nan")
    t_end: float = float("nan")
    baro_phase: pd.DataFrame = field(default_factory=pd.DataFrame)
    altitude_phase: pd.DataFrame = field(default_factory=pd.DataFrame)  # the carrier's
    gnss_sigma: float = float("nan")  # m, where the GNSS carries the descent
    charge_spans: dict[str, tuple[float, float]] = field(default_factory=dict)
    # site_air
    site: SiteAtmosphere | None = None
    lapse_fit: tuple[float, float, float] | None = None
    # descent_drag
    parachutes: list[dict[str, Any]] = field(default_factory=list)
    descent_areas: dict[str, float] = field(default_factory=dict)
    # altimeter_series
    settled: list[float] = field(default_factory=list)
    baro_sigmas: list[float] = field(default_factory=list)
    # canopy_forensics
    forensics: Forensics | None = None
    # accelerometer_series
    accel_sigmas: list[float] = field(default_factory=list)
    snatches: dict[str, Snatch] = field(default_factory=dict)
    full_open: dict[str, tuple[float, float]] = field(default_factory=dict)
    # Where the axial accelerometer reads the body turned over (`log_hygiene.turned_over`):
    # (first, last) sample times (s) of each stretch, kept with the samples.
    turned_over: list[tuple[float, float]] = field(default_factory=list)
    # every series step: the folder's files and its sensors
    files: dict[str, pd.DataFrame] = field(default_factory=dict)
    sensors: list[dict[str, Any]] = field(default_factory=list)
    # model_block
    manifest: dict[str, Any] = field(default_factory=dict)

    @property
    def source(self) -> str:
        """The log's path, as errors name it."""
        return str(self.record.path)

    def openings_read(self) -> tuple[str, ...]:
        """The canopies whose opening the written accelerometer reads: at least
        `OPENING_READ_SAMPLES` of its rows within `OPENING_WINDOW_S` after the deployment."""
        accel = self.files.get("accelerometer.csv")
        if accel is None:
            return ()
        t = accel["time"].to_numpy()
        return tuple(name for name, t0 in self.deploy.items()
                     if np.count_nonzero((t >= t0) & (t <= t0 + OPENING_WINDOW_S))
                     >= OPENING_READ_SAMPLES)

    @property
    def starts(self) -> list[float]:
        """The deployments' times in order (s)."""
        return sorted(self.deploy.values())

    @property
    def span(self) -> tuple[float, float]:
        """The series' span (s): the phase and `SERIES_MARGIN_S` beyond each end, so that
        every sensor covers it (the estimator uses the samples inside the phase only)."""
        return self.t_begin - SERIES_MARGIN_S, self.t_end + SERIES_MARGIN_S

    def charge_windows(self, t: pd.Series) -> np.ndarray:
        """Which of the times `t` (s) lie in a deployment's charge window: from
        `EVENT_SIGMA_S` before it to `EJECTION_EXCLUDE_S` after, or over the pressure swing
        a recorder's filter spread it into (`charge_spans`), where that is longer (the
        charge's pressure pulse and jolt are no force of the flight)."""
        near = np.zeros(len(t), dtype=bool)
        for name, t_dep in self.deploy.items():
            a, b = self.charge_spans.get(name, (t_dep, t_dep))
            near |= ((t >= min(a, t_dep - EVENT_SIGMA_S))
                     & (t <= max(b, t_dep + EJECTION_EXCLUDE_S))).to_numpy()
        return near


def clean_log_end(d: LogImport) -> None:
    """The log without its damaged end (`log_hygiene.damaged_end`): samples no descent
    produces are left out of the altimeter and, where the damage runs to the log's end,
    every channel of the recorder is taken to end where it starts.  The altimeter's end
    is not the flight's: a pulse the altitude comes back from, at the end of an altimeter
    file beside a GNSS that reads the vehicle still coming down after it by more than
    `flight_events.GROUND_BAND_M`, is no impact but an ejection charge's, and is kept
    for the charge's detection."""
    samples = d.record.samples
    baro = samples[["time", "altitude"]].dropna()
    damage = damaged_end(baro["time"].to_numpy(), baro["altitude"].to_numpy())
    if damage is None:
        return
    fixes = d.record.gps_fixes()
    if not damage.to_end and gnss_reads_on(baro["time"].to_numpy(), fixes):
        tg, hg = fixes["time"].to_numpy(float), fixes["gps_altitude"].to_numpy(float)
        fall = float(np.interp(damage.t_from, tg, hg)) - float(hg[tg > damage.t_from].min())
        if fall > GROUND_BAND_M:
            d.notes.append(f"{damage.rows.size} altimeter sample(s) from {damage.t_from:.2f} s, "
                           "near the altimeter's end, kept: they jump off the descent and "
                           f"come back, and the GNSS reads the vehicle {fall:.0f} m further "
                           "down after them: an ejection charge's pressure pulse, not an "
                           "impact")
            return
    rows = baro.index[damage.rows]
    samples = samples.copy()
    samples.loc[rows, ["altitude", "pressure"]] = np.nan
    if damage.to_end:
        samples = samples[samples["time"] < damage.t_from]
    d.notes.append(damage.note(float(baro["time"].iloc[-1])))
    d.dropped["damaged_end_samples"] = int(damage.rows.size)
    d.record = dataclasses.replace(d.record, samples=samples)


def read_altimeter(d: LogImport) -> None:
    """The barometer's samples (time s, pressure altitude m, pressure Pa): at least 20, at
    speeds a rocket flies, with the accelerometer's boost the right way up."""
    samples = d.record.samples
    d.baro = samples[["time", "altitude", "pressure"]].dropna()
    d.gnss = d.record.gps_fixes()[["time", "gps_altitude"]]
    if len(d.baro) < 20:
        raise InputError(d.source, "pressure", "a barometer (pressure or altitude) read in at "
                         f"least 20 samples; the log has {len(d.baro)}")
    check_speed(d.record, d.baro["time"].to_numpy(), d.baro["altitude"].to_numpy(),
                MAX_SPEED_M_S, "no rocket is faster in the lower atmosphere")
    check_boost(d.record, samples)


def find_events(d: LogImport) -> None:
    """The log's flight events (`import_events.flight_events`), the pad's pressure and
    temperature, checked for a pad's air."""
    events, notes = flight_events(d.record)
    d.events, d.notes = events, [*d.notes, *notes]
    card = d.card
    d.p0, pad_note = pad_pressure(d.baro, d.events, card)
    d.pad_altitude = float(pressure_altitude(d.p0))
    d.notes.append(pad_note)
    site_spec = card.site
    d.elevation = card_quantity(site_spec.get("elevation"), "length", card.source,
                                "site.elevation")
    d.t0, d.t0_note = pad_temperature(site_spec, d.p0, d.elevation, card.source)
    check_pad_air(d.record, d.p0, d.t0, "card" if "temperature" in site_spec else
                  "density" if "surface_density" in site_spec else "standard", d.elevation,
                  card.source, "pressure" in site_spec)


def descent_channel(d: LogImport) -> None:
    """The channel that reads the descent: the barometer's where it finds touchdown or no
    GNSS altitude reads on past its end; else the GNSS altitude's (`gnss_descent`), read
    as an altimeter would have read it through the site atmosphere of the card's lapse
    rate, about its datum offset (`gnss_offset`); a note says which and why."""
    d.altitude = d.baro
    landed = d.events.get("landed")
    tb = d.baro["time"].to_numpy()
    if (landed is not None and landed.source != "GNSS altitude") \
            or not gnss_reads_on(tb, d.gnss):
        return
    card = d.card
    if card.site.get("lapse_rate") == "gps":
        raise InputError(card.source, "site.lapse_rate", f"a value: 'gps' fits the lapse rate "
                         f"to the GNSS altitudes of the descent against the barometer's, and "
                         f"{d.source}'s barometer ends at {tb[-1]:.2f} s, before the descent "
                         "the GNSS reads")
    d.site = SiteAtmosphere(d.elevation, d.p0, d.t0, card_lapse_rate(card))
    d.gnss_offset, used = gnss_offset(d.gnss, d.baro, d.site)
    d.altitude = gnss_channel(d.gnss, d.site, d.gnss_offset)
    d.carrier = "gps_altitude"
    tg = d.gnss["time"].to_numpy()
    height = float(d.baro["altitude"].iloc[-1]) - d.pad_altitude
    ending = (f"touchdown at {landed.time:.2f} s" if landed is not None
              else f"their end at {tg[-1]:.2f} s")
    datum = (f"its datum {d.gnss_offset:+.1f} m from the site atmosphere's altitude (the "
             f"median over the {used} fixes where both read the vehicle slower than "
             f"{DATUM_SPEED_M_S:g} m/s)" if used else "no fix where both read a slow "
             "vehicle: its altitude taken as the site atmosphere's")
    d.notes.append(f"the GNSS altitude carries the descent: the barometer's samples end at "
                   f"{tb[-1]:.2f} s, {height:.0f} m above the pad, and the GNSS's "
                   f"{int((tg > tb[-1]).sum())} fixes after that go on to {ending}; the "
                   f"events, the descent's drag areas, the forensics and the fit read the "
                   f"descent in it ({datum})")


def given_events(d: LogImport) -> None:
    """The card's own events over the log's (`import_events.card_events`): at a time, or at
    a height's crossing in the descent's channel."""
    given, d.unreached = card_events(d.card, d.altitude, d.pad_altitude, d.events)
    d.events.update(given)


def choose_deployments(d: LogImport) -> None:
    """Each canopy's deployment: the event its card names, one event per canopy; every
    charge the log shows deploys one; the log goes on long enough after the first."""
    card = d.card
    kind = "a flight state of the log" if d.record.states else \
        "an event detected in the log (it has no flight states)"
    deploying = {name: e for name, e in d.events.items() if name != "landed"}
    for i, chute in enumerate(card.parachutes):
        state = chute["deployment"]
        if state in d.unreached and (d.flown or i + 1 < len(card.parachutes)):
            d.notes.append(f"{chute['name']}: {d.unreached[state]} at which the card deploys "
                           "it: its deployment is not in the log, and the fit leaves it out")
            continue
        if state in d.unreached:
            raise InputError(card.source, f"parachutes[{i}].deployment", f"a deployment the "
                             f"log shows; {d.unreached[state]} ({state!r})")
        if state not in deploying:
            listed = ", ".join(f"{n} {e.time:.2f} ± {e.sigma:.2f} s ({e.source})"
                               for n, e in deploying.items())
            raise InputError(card.source, f"parachutes[{i}].deployment",
                             f"{kind} {d.source} that deploys {chute['name']}, or one the "
                             f"card's 'events' gives (found: {listed or 'none'}); got {state!r}")
        # Each canopy's opening is told apart by its own event (its charge, its snatch).
        if any(card.parachutes[j]["deployment"] == state for j in range(i)):
            raise InputError(card.source, f"parachutes[{i}].deployment",
                             f"an event no other canopy of the card deploys at; "
                             f"{state!r} deploys an earlier one too")
        d.deploy[chute["name"]] = d.events[state].time
        d.deploy_sigma[chute["name"]] = d.events[state].sigma
        d.flown.append(chute)
    check_charges_deploy(d.events, d.deploy, card, d.source, bool(d.record.states))
    d.t_begin = min(d.deploy.values())
    descent = d.altitude[d.altitude["time"] > d.t_begin]
    if len(descent) < MIN_DESCENT_SAMPLES or \
            float(descent["time"].max()) - d.t_begin < MIN_DESCENT_S:
        span = float(descent["time"].max()) - d.t_begin if len(descent) else 0.0
        first = min(d.deploy, key=d.deploy.__getitem__)
        what = "GNSS fixes" if d.carrier == "gps_altitude" else "altimeter samples"
        raise InputError(d.source, "(time)", f"a descent of at least {MIN_DESCENT_S:g} s and "
                         f"{MIN_DESCENT_SAMPLES} {what} after the first deployment "
                         f"({first} at {d.t_begin:.2f} s) to fit (or a GNSS altitude that "
                         f"reads on to the ground); the log ends {span:.2f} s after it, with "
                         f"{len(descent)} samples")


def bound_phase(d: LogImport) -> None:
    """The phase, from the first deployment to `TOUCHDOWN_MARGIN_S` (or `TOUCHDOWN_SIGMAS`
    of touchdown's sigma) before touchdown (or the descent channel's end), and the
    altimeter's samples over it and `SERIES_MARGIN_S` beyond, less the charges' windows
    and a dead altimeter's samples, at speeds a canopy descends; the descent channel's
    samples over it (the GNSS's, with their noise sigma, where it carries the descent)."""
    baro, alt = d.baro, d.altitude
    read_as = "pressure altitude" if d.carrier == "baro" else \
        "the GNSS altitude as pressure altitude"
    landed = d.events.get("landed")
    if landed is not None:
        d.t_down = landed.time
        after = alt[alt["time"] >= d.t_down]
        ground = after[after["time"] <= d.t_down + max(3.0, 5.0 * sample_interval(
            alt["time"].to_numpy()))]["altitude"]
        level = float(ground.median()) if len(ground) else float(alt["altitude"].iloc[-1])
        d.notes.append(f"touchdown at {d.t_down:.2f} s, {level - d.pad_altitude:+.1f} m "
                       f"({read_as}) from the pad")
        d.t_end = d.t_down - max(TOUCHDOWN_MARGIN_S, TOUCHDOWN_SIGMAS * landed.sigma)
    else:
        d.t_down = float(alt["time"].iloc[-1])
        ends = "the log ends" if d.carrier == "baro" else "the GNSS's fixes end"
        d.notes.append(f"{ends} at {d.t_down:.2f} s, "
                       f"{float(alt['altitude'].iloc[-1]) - d.pad_altitude:.1f} m ({read_as}) "
                       "above the pad: the phase ends at the log's end")
        d.t_end = d.t_down - TOUCHDOWN_MARGIN_S
    if not d.record.gnss.empty:
        last = enu_about(d.record.gnss).iloc[-1]
        d.notes.append(f"GNSS: {len(d.record.gnss)} fixes, the last {last['east']:+.0f} m "
                       f"east, {last['north']:+.0f} m north of the first (the descent is "
                       "fitted vertically: horizontal positions are not written to the "
                       "folder)")
    lo, hi = d.span
    t, h = baro["time"].to_numpy(), baro["altitude"].to_numpy()
    for name, t_dep in d.deploy.items():
        swing = charge_swing(t, h, t_dep)
        if swing is not None and (swing[0] < t_dep - EVENT_SIGMA_S
                                  or swing[1] > t_dep + EJECTION_EXCLUDE_S):
            d.charge_spans[name] = (swing[0] - EVENT_SIGMA_S, swing[1] + EJECTION_EXCLUDE_S)
            d.notes.append(f"{name}'s charge: the altitude swings off its trend from "
                           f"{swing[0]:.2f} to {swing[1]:.2f} s (a pressure pulse a recorder's "
                           "filter spread out): left out like the charge's own window")
    in_phase = ((baro["time"] >= lo) & (baro["time"] <= hi)).to_numpy()
    near_charge = d.charge_windows(baro["time"])
    d.dropped["ejection_charge_samples"] = int((in_phase & near_charge).sum())
    phase = baro[in_phase & ~near_charge]
    dead = dead_samples(phase["time"].to_numpy(), phase["altitude"].to_numpy())
    if dead.any():
        d.notes.append(dead_note("altimeter", phase["time"].to_numpy()[dead],
                                 phase["altitude"].to_numpy()[dead], "m"))
        phase = phase[~dead]
    check_speed(d.record, phase["time"].to_numpy(), phase["altitude"].to_numpy(),
                MAX_DESCENT_M_S, "no canopy descends faster")
    d.baro_phase = d.altitude_phase = phase
    if d.carrier == "gps_altitude":
        d.altitude_phase = alt[(alt["time"] >= lo) & (alt["time"] <= hi)]
        d.gnss_sigma = descent_sigma(d.gnss["time"].to_numpy(),
                                     d.gnss["gps_altitude"].to_numpy(), d.starts, d.t_end)


def card_lapse_rate(card: FlightCard) -> float:
    """The card's lapse rate (K/m; the standard atmosphere's where it gives none), above 0
    and at most the dry adiabat's; InputError naming ``site.lapse_rate`` otherwise (or for
    ``"gps"``, which is fitted, not given)."""
    lapse_spec = card.site.get("lapse_rate", {"value": 1e3 * ISA_LAPSE_K_M, "unit": "K/km"})
    lapse = card_quantity(lapse_spec, "lapse_rate", card.source, "site.lapse_rate")
    if not 0.0 < lapse <= LAPSE_BOUNDS_K_M[1]:
        raise InputError(card.source, "site.lapse_rate", f"a lapse rate above 0 and at "
                         f"most the dry adiabat's {1e3 * LAPSE_BOUNDS_K_M[1]:g} K/km (or "
                         f"'gps'); got {1e3 * lapse:g} K/km")
    return lapse


def site_air(d: LogImport) -> None:
    """The site atmosphere: the pad's pressure and temperature, and the card's lapse rate
    or, with ``"gps"``, the one fitted to the descent's GNSS altitudes (already set where
    the GNSS carries the descent: `descent_channel`)."""
    card = d.card
    d.notes.append(d.t0_note)
    if d.site is not None:
        return
    if card.site.get("lapse_rate") == "gps":
        fixes = d.record.gps_fixes()
        descent = fixes[(fixes["time"] >= d.t_begin) & (fixes["time"] <= d.t_down)]
        if len(descent) < 10:
            raise InputError(card.source, "site.lapse_rate", f"a value: 'gps' needs GPS "
                             f"fixes in the descent, and {d.source} has {len(descent)}")
        d.lapse_fit = fit_lapse_rate(descent, d.baro["pressure"], d.baro["time"],
                                     d.elevation, d.p0, d.t0)
        lapse = d.lapse_fit[0]
    else:
        lapse = card_lapse_rate(card)
        if d.record.has_gps_altitude:
            d.notes.append("the GNSS altitudes are not fitted: the card's lapse rate is given "
                           "('gps' fits it to them and fits them)")
    d.site = SiteAtmosphere(d.elevation, d.p0, d.t0, lapse)


def descent_drag(d: LogImport) -> None:
    """Each canopy's own drag area from its settled descent (`descent_drag_areas`), the
    diameters the card leaves out taken from it, and each later canopy's settled time,
    from which its altimeter sigma applies."""
    assert d.site is not None
    t, h = d.altitude_phase["time"].to_numpy(), d.altitude_phase["altitude"].to_numpy()
    starts = d.starts
    d.settled = [settled_time(t, h, a, b) for a, b in pairwise([*starts[1:], d.t_end])]
    d.parachutes = [dict(c) for c in d.flown]
    d.descent_areas = descent_drag_areas(d.deploy, d.parachutes, d.card, d.site, t, h, d.t_end)
    d.notes += canopy_diameters(d.parachutes, d.descent_areas, d.card)


def altimeter_series(d: LogImport) -> None:
    """``baro.csv``: the altimeter over the phase, each canopy phase's samples averaged in
    blocks as long as its noise's correlation (`independent_blocks`: a recorder's filter,
    the static port's swings as the vehicle swings), so that the fit weighs what the
    altimeter measured independently; each sigma the scatter of the block means, a later
    canopy's from its settled time.  Where the GNSS carries the descent, the altimeter's
    file stopped inside the phase: it is written over the canopy phases it reads into, or
    left out of the folder where it reads fewer than `MIN_DESCENT_SAMPLES` samples of
    the phase, with a note."""
    lo, hi = d.span
    starts = d.starts
    in_phase = d.baro_phase[(d.baro_phase["time"] >= d.t_begin)
                            & (d.baro_phase["time"] <= d.t_end)]
    last = float(d.baro["time"].iloc[-1])
    if d.carrier == "gps_altitude":
        if len(in_phase) < MIN_DESCENT_SAMPLES:
            d.notes.append(f"altimeter: its samples end at {last:.2f} s, with "
                           f"{len(in_phase)} in the phase ({d.t_begin:.2f}-{d.t_end:.2f} s): "
                           "left out of the folder, whose descent the GNSS altitude carries")
            return
        d.notes.append(f"altimeter: its samples end at {last:.2f} s, inside the phase: "
                       f"baro.csv reads the phase to there, the GNSS altitude all of it")
    edges = [lo, *d.settled, hi + 1.0]
    parts = []
    sigma_after = []
    order = sorted(d.deploy, key=d.deploy.__getitem__)
    for (a, b), name, steady_end in zip(pairwise(edges), order, [*starts[1:], d.t_end],
                                        strict=True):
        if a > last:  # the altimeter's file ended before this canopy phase
            break
        part = d.baro_phase[(d.baro_phase["time"] >= a) & (d.baro_phase["time"] < b)]
        blocks, size = independent_blocks(part[["time", "altitude"]], steady_end)
        parts.append(blocks)
        if size > 1:
            seconds = size * sample_interval(part["time"].to_numpy())
            d.notes.append(f"altimeter under the {name} (from {a:.2f} s): noise correlated "
                           f"over {size} samples ({seconds:.2f} s), averaged in blocks of that "
                           f"length: {len(part)} samples -> {len(blocks)}")
        if len(blocks) < MIN_DESCENT_SAMPLES:  # too short a segment: the whole phase's
            blocks, steady_end = independent_blocks(d.baro_phase[["time", "altitude"]])[0], \
                d.t_end
        d.baro_sigmas.append(max(MIN_BARO_SIGMA_M, block_sigma(blocks, steady_end)))
        if len(d.baro_sigmas) > 1:
            sigma_after.append({"time": {"value": round(a, 3), "unit": "s"},
                                "sigma": {"altitude": {"value": round(d.baro_sigmas[-1], 3),
                                                       "unit": "m"}}})
    d.files["baro.csv"] = pd.concat(parts, ignore_index=True)
    d.sensors.append(
        {"name": "baro", "kind": "baro", "file": "baro.csv",
         "columns": {"time": "s", "altitude": "m"},
         "sigma": {"altitude": {"value": round(d.baro_sigmas[0], 3), "unit": "m"}},
         "sigma_after": sigma_after})


def canopy_forensics(d: LogImport) -> None:
    """Whether each canopy opened, and how fully, from the log alone
    (`deployment_forensics`): the drag area its settled descent needs against the
    airframe's (from the coast, else the card's ``forebody_cds`` where it gives one) and
    against what its diameter gives; one sentence per canopy for the import's report.  The
    coast is the barometer's, the descents the descent channel's (the GNSS altitude's at its
    own noise sigma, where it carries the descent)."""
    assert d.site is not None
    site, elevation = d.site, d.elevation

    def heights(channel: pd.DataFrame) -> tuple[np.ndarray, np.ndarray]:
        """Times (s) and geometric heights above the site (m), less the charges' windows."""
        kept = channel[~d.charge_windows(channel["time"])]
        return kept["time"].to_numpy(), np.asarray(site.altitude_at_pressure(
            kept["pressure"].to_numpy()), dtype=float).ravel() - elevation

    t, height = heights(d.baro)

    def density(h: np.ndarray | float) -> np.ndarray:
        return np.asarray(site.density(elevation + np.asarray(h, dtype=float)),
                          dtype=float).reshape(np.shape(h))

    mass = descent_mass(d.card, d.parachutes)
    accel = d.record.samples[["time", "acceleration"]].dropna()
    coast = coast_drag_area(
        t, height, density, mass,
        t_burnout=d.events["coast"].time if "coast" in d.events else None,
        t_apogee=d.events["apogee"].time if "apogee" in d.events else None,
        accel=(accel["time"].to_numpy(), accel["acceleration"].to_numpy())
        if len(accel) else None)
    card_cds = card_quantity(d.card.vehicle.get("forebody_cds", {"value": 0, "unit": "m^2"}),
                             "area", d.card.source, "vehicle.forebody_cds")
    # The card's airframe drag area as a measurement of a quarter of itself.
    airframe = DragArea(card_cds, 0.25 * card_cds, "card") if card_cds > 0.0 else None
    # Only a diameter the card gives is a reference: one taken from the descent
    # (`canopy_diameters`) would judge the descent against itself.
    canopies = [Canopy(c["name"], d.deploy[c["name"]], d.deploy_sigma[c["name"]],
                       card_quantity(c["diameter"], "length", d.card.source,
                                     f"parachutes[{i}].diameter") if "diameter" in c else None)
                for i, c in enumerate(d.flown)]
    if d.carrier == "gps_altitude":
        t, height = heights(d.altitude)
    d.forensics = deployment_forensics(
        t, height, density, mass, canopies, t_end=d.t_end,
        noise_sigma=d.gnss_sigma if d.carrier == "gps_altitude" else d.baro_sigmas,
        airframe=airframe, coast=coast)


def accelerometer_series(d: LogImport) -> None:
    """``accelerometer.csv`` where the log's accelerometer reads over the whole phase: less
    dead and clipped samples, the charges' windows and, in each later canopy's opening,
    the samples above the drag ceiling (`drag_ceiling`: the shock cord's snatch, whose
    time is that canopy's full open); a sigma per steady descent and per later opening
    from the scatter about a local trend (the body's swing is noise of this sensor)."""
    assert d.site is not None
    lo, hi = d.span
    starts = d.starts
    accel = d.record.samples[["time", "acceleration"]].dropna()
    dead = dead_samples(accel["time"].to_numpy(), accel["acceleration"].to_numpy(),
                        clipped=True)
    inside = ((accel["time"] >= lo) & (accel["time"] <= hi)).to_numpy()
    if (dead & inside).any():
        d.notes.append(dead_note("accelerometer", accel["time"].to_numpy()[dead & inside],
                                 accel["acceleration"].to_numpy()[dead & inside], "m/s^2"))
    accel = accel[inside & ~dead]
    check_steady_accelerometer(d.record, accel["acceleration"].to_numpy())
    d.full_open = {name: peak for name, t in d.deploy.items() if t > d.t_begin
                   and (peak := opening_peak(accel, t)) is not None}
    charge = d.charge_windows(accel["time"])
    d.dropped["ejection_charge_accelerometer_samples"] = int(charge.sum())
    accel = accel[~charge]
    # The series is the body's acceleration (gravity taken out): its specific force adds g.
    d.turned_over = flagged_stretches(accel["time"].to_numpy(),
                                      turned_over(accel["time"].to_numpy(),
                                                  accel["acceleration"].to_numpy() + G0))
    for first, last in d.turned_over:
        d.notes.append(f"the body turned over from {first:.2f} to {last:.2f} s: the axial "
                       "accelerometer reads the drag reversed there, which no canopy's "
                       "drag makes (a tumble, or the rocket hanging nose down?)")
    t_baro, h_baro = d.altitude_phase["time"].to_numpy(), d.altitude_phase["altitude"].to_numpy()
    density = np.asarray(d.site.density(d.site.altitude_at_pressure(
        d.altitude_phase["pressure"].to_numpy())), dtype=float).ravel()
    later = sorted((t, name) for name, t in d.deploy.items() if t > starts[0])
    snatch = np.zeros(len(accel), dtype=bool)
    # A later canopy's opening lasts from its charge until its descent has settled, and at
    # least the OPENING_WINDOW_S its load peak is looked for in, up to the next deployment
    # (or the phase's end).
    nexts = [*starts[1:], d.t_end][1:]
    opening_ends = [min(max(t_settled, t_charge + OPENING_WINDOW_S), t_next) for t_charge,
                    t_settled, t_next in zip(starts[1:], d.settled, nexts, strict=True)]
    for (t_charge, name), t_settled, t_open, t_next in zip(
            later, d.settled, opening_ends, nexts, strict=True):
        ceiling = drag_ceiling(t_baro, h_baro, density, t_charge, t_settled, t_next)
        opening = (accel["time"] >= t_charge) & (accel["time"] < t_open)
        if ceiling is None or not opening.any():  # no accelerometer reading of the opening
            continue
        above = (opening & (accel["acceleration"] > ceiling)).to_numpy()
        left_out = accel[above]
        k = int(np.argmax(left_out["acceleration"])) if above.any() else None
        d.snatches[name] = Snatch(
            ceiling, int(above.sum()),
            None if k is None else float(left_out["acceleration"].iloc[k]),
            None if k is None else float(left_out["time"].iloc[k]))
        snatch |= above
    d.dropped["snatch_samples_above_drag_ceiling"] = int(snatch.sum())
    accel = accel[~snatch]
    # A test folder's sensors each cover the whole phase: an accelerometer that stops
    # reading inside it (dead, or logged in the boost only) is left out.  Gaps inside it (the
    # charges', a tumble's) are not.
    if not (len(accel) >= 10 and float(accel["time"].min()) <= d.t_begin + SERIES_MARGIN_S
            and float(accel["time"].max()) >= d.t_end - SERIES_MARGIN_S):
        span = (f" (its samples there span {accel['time'].min():.2f}-"
                f"{accel['time'].max():.2f} s, not the phase {d.t_begin:.2f}-{d.t_end:.2f} s)"
                if len(accel) else "")
        d.notes.append(f"no accelerometer over the log's phase{span}: left out of the "
                       "folder")
        return
    bounds = [*sorted({*starts, *opening_ends} - {d.t_end}), d.t_end]
    # Each canopy's steady segment (the series' margins included) is written as block means
    # of its noise's correlation length at their sigma (`accelerometer_blocks`: a swinging
    # rocket's readings are correlated over a fraction of a second, and each sample counted
    # as independent would weigh the accelerometer tens of times over); a later canopy's
    # opening keeps its samples, whose load peak the fit times.
    parts = []
    for (a, b), (seg_lo, seg_hi) in zip(pairwise(bounds),
                                        pairwise([lo, *bounds[1:-1], hi + 1.0]), strict=True):
        part = accel[(accel["time"] >= seg_lo) & (accel["time"] < seg_hi)]
        if len(part) > 10 and a not in starts[1:]:
            n, (part, sigma, size) = len(part), accelerometer_blocks(part, b)
            if size > 1:
                d.notes.append(f"accelerometer from {seg_lo:.2f} s: noise correlated over "
                               f"{size} samples, averaged in blocks of that length: {n} -> "
                               f"{len(part)}")
        else:
            sigma = scatter_rms(part["time"].to_numpy(), part["acceleration"].to_numpy()) \
                if len(part) > 10 else second_difference_sigma(accel["acceleration"].to_numpy())
        parts.append(part)
        d.accel_sigmas.append(max(MIN_ACCEL_SIGMA, sigma))
    accel = pd.concat(parts, ignore_index=True)
    d.files["accelerometer.csv"] = accel
    d.sensors.append({
        "name": "accelerometer", "kind": "axial_accelerometer",
        "file": "accelerometer.csv", "columns": {"time": "s", "acceleration": "m/s^2"},
        "sigma": {"acceleration": {"value": round(d.accel_sigmas[0], 3), "unit": "m/s^2"}},
        "sigma_after": [{"time": {"value": round(t, 3), "unit": "s"},
                         "sigma": {"acceleration": {"value": round(sig, 3), "unit": "m/s^2"}}}
                        for t, sig in zip(bounds[1:-1], d.accel_sigmas[1:], strict=True)]})


def gnss_series(d: LogImport) -> None:
    """``gps_altitude.csv``: the GNSS altitude over the phase, where the lapse rate was
    fitted to it (at the fit's residual sigma), or where it carries the descent (less its
    datum offset, `gnss_descent.gnss_offset`, so that it reads the site atmosphere's
    geometric altitude, at its own sigma from its scatter, `gnss_descent.gnss_sigma`)."""
    if d.lapse_fit is None and d.carrier != "gps_altitude":
        return
    lo, hi = d.span
    fixes = d.gnss[(d.gnss["time"] >= lo) & (d.gnss["time"] <= hi)]
    if len(fixes) < 2:
        return
    sigma, offset = (d.lapse_fit[2], 0.0) if d.lapse_fit is not None else \
        (d.gnss_sigma, d.gnss_offset)
    d.files["gps_altitude.csv"] = pd.DataFrame({
        "time": fixes["time"].to_numpy(), "up": fixes["gps_altitude"].to_numpy() - offset})
    d.sensors.append({"name": "gps_altitude", "kind": "gps_altitude",
                      "file": "gps_altitude.csv", "columns": {"time": "s", "up": "m"},
                      "sigma": {"altitude": {"value": round(sigma, 3), "unit": "m"}}})


def merged_series(d: LogImport) -> None:
    """Each series written, its independent samples merged into means of 2^k wherever the
    signal is straight enough that the mean says what its samples say (`merged_blocks`),
    each noise segment (the sensor's sigma, then each `sigma_after`) on its own; a run of
    means of one size gets the sigma of such a mean.  Rows still correlated (an opening's
    raw accelerometer samples) merge at sigma sqrt(min(m, tau) / m), tau their correlation
    length (samples) over the later half of the segment's longest stretch between
    deployments and the phase's end (`longest_stretch`: an opening's deceleration and the
    touchdown are signal, not correlated noise).

    A 10-minute log at 100 Hz is 60,000 samples a channel; its steady descent changes over
    seconds, so its information is in a few means a second, and a fit to the means costs
    what the information is worth, not what the recorder's rate is."""
    for sensor in d.sensors:
        frame = d.files[sensor["file"]]
        column = next(c for c in frame.columns if c != "time")
        (group, given), = sensor["sigma"].items()
        unit = given["unit"]
        segments = [(-np.inf, given["value"])] + [
            (c["time"]["value"], c["sigma"][group]["value"])
            for c in sensor.get("sigma_after", [])]
        t_all, v_all = frame["time"].to_numpy(float), frame[column].to_numpy(float)
        times, values, changes = [], [], []
        for (t_from, sigma), (t_to, _) in zip(segments, [*segments[1:], (np.inf, 0.0)],
                                              strict=True):
            sel = (t_all >= t_from) & (t_all < t_to)
            t, v = t_all[sel], v_all[sel]
            if t.size == 0:
                changes.append((t_from, sigma))
                continue
            steady = longest_stretch(t, [*d.starts, d.t_end])
            tau = correlation_length(t[steady], v[steady])
            mt, mv, count = merged_blocks(t, v, sigma)
            sig = sigma * np.sqrt(np.minimum(count, tau) / count)
            first = np.r_[0, np.flatnonzero(np.diff(sig)) + 1]
            for k in first:
                at = t_from if k == 0 else 0.5 * (mt[k - 1] + mt[k])
                changes.append((at, float(sig[k])))
            times.append(mt)
            values.append(mv)
        merged = np.concatenate(times)
        if merged.size == len(frame):
            continue
        d.notes.append(f"{sensor['name']}: {len(frame)} samples merged into {merged.size} "
                       "means where the signal is straight within the noise (up to "
                       f"{MERGE_SPAN_S:g} s), an opening's samples kept")
        d.files[sensor["file"]] = pd.DataFrame({"time": merged,
                                                column: np.concatenate(values)})
        (_, s0), *rest = changes
        sensor["sigma"] = {group: {"value": float(f"{s0:.4g}"), "unit": unit}}
        sensor["sigma_after"] = [
            {"time": {"value": instant(at), "unit": "s"},
             "sigma": {group: {"value": float(f"{sig:.4g}"), "unit": unit}}}
            for at, sig in rest]


def model_block(d: LogImport) -> None:
    """The manifest: the card's name, label, vehicle and canopies, each deployment as a
    ``mortar_fire`` event, each later canopy's opening peak as a ``full_open`` event where
    the folder has no accelerometer series (where it has one, the fit reads the opening's
    load from its samples, and the peak's time as the end of the fill would be a second,
    stricter reading of the same samples under an assumption: on the 10-minute benchmark
    log, whose snatch comes mid-fill, it pulled the drogue's drag area 3.6 sigma low), the
    sensors, the site atmosphere, the phase and the model (`rocket_model`)."""
    assert d.site is not None
    card = d.card
    d.manifest = {
        "format": FORMAT,
        "name": card.name,
        "description": f"{card.title}: {d.record.recorder} log {d.record.path.name}",
        "label": card.label,
        "vehicle": card.vehicle,
        "parachutes": [{k: v for k, v in c.items() if k != "deployment"}
                       for c in d.parachutes],
        "events": [event_entry("mortar_fire", name, t, d.deploy_sigma[name])
                   for name, t in d.deploy.items()]
                  + [event_entry("full_open", name, t, sigma)
                     for name, (t, sigma) in d.full_open.items()
                     if "accelerometer.csv" not in d.files],
        "sensors": d.sensors,
        "atmosphere": {"model": "site",
                       "elevation": {"value": d.elevation, "unit": "m"},
                       "pressure": {"value": round(d.p0, 2), "unit": "Pa"},
                       "temperature": {"value": round(d.t0, 3), "unit": "K"},
                       "lapse_rate": {"value": round(1e3 * d.site.lapse_rate_k_m, 4),
                                      "unit": "K/km"}},
        "phase": {"start": {"value": instant(d.t_begin), "unit": "s"},
                  "end": {"value": round(d.t_end, 3), "unit": "s"}},
        "model": rocket_model(card.model, [s["kind"] for s in d.sensors],
                              [(c["name"], c["stages"][0]) for c in d.parachutes
                               if not c.get("open_at_start")],
                              held_openings(d.deploy, d.events), d.deploy_sigma, d.still_air,
                              d.openings_read()),
    }
    if d.carrier == "gps_altitude" and "gps_altitude" not in effect_names(d.manifest["model"]):
        effects = d.manifest["model"].get("effects", [])
        d.manifest["model"] = {**d.manifest["model"], "effects": [*effects, "gps_altitude"]}
        d.notes.append("the card's model lists no gps_altitude effect, which the descent the "
                       "GNSS carries needs: added")
    if d.forensics is None:
        return
    closed = {c.name: instant(d.deploy[c.name]) for c in d.forensics.canopies
              if c.verdict == "not_opened"}
    if closed:
        areas = {c["name"]: np.pi * card_quantity(c["diameter"], "length", card.source,
                                                  "parachutes.diameter") ** 2 / 4.0
                 for c in d.parachutes}
        first = min(d.deploy, key=d.deploy.__getitem__)
        needed = d.forensics[first].descent
        d.manifest["model"], d.manifest["vehicle"] = held_closed(
            d.manifest["model"], d.manifest["vehicle"], closed, areas,
            {c["name"]: c["stages"][0] for c in d.parachutes}, first,
            needed.drag_area if needed is not None else 0.0,
            {c["name"]: c.get("inflation") == "infinite_mass" for c in d.parachutes})
        d.notes.append(f"{', '.join(closed)}: did not open (see the deployment forensics): "
                       "held closed in the fit" + (", which estimates the airframe's drag "
                                                   "area CdS_V instead"
                                                   if "CdS_V" in d.manifest["model"].get("free", ())
                                                   else ""))
    late = {c.name: c for c in d.forensics.canopies
            if c.fall_before is not None and c.t_open is not None}
    if late:
        d.manifest["model"], d.manifest["vehicle"] = late_openings(
            d.manifest["model"], d.manifest["vehicle"],
            {name: c.t_open - (d.deploy[name] + MORTAR_TO_INFLATION_S)  # type: ignore[operator]
             for name, c in late.items()},
            {c["name"]: c["stages"][0] for c in d.parachutes},
            max(c.fall_before.value for c in late.values()))  # type: ignore[union-attr]
        d.notes.append(f"{', '.join(late)}: took hold late (see the deployment forensics): "
                       "its start's window is centred on the opening, and the fall before "
                       "it is fitted as the airframe's drag area CdS_V")


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


# The import, step by step (see the module docstring).
STEPS: tuple[Callable[[LogImport], None], ...] = (
    clean_log_end, read_altimeter, find_events, descent_channel, given_events,
    choose_deployments, bound_phase, site_air, descent_drag, altimeter_series,
    canopy_forensics, accelerometer_series, gnss_series, merged_series, model_block)
