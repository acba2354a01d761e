"""The events an imported log's canopies deploy at: the log's flight states or the events
detected in its data (`flight_events`), the card's own events, and the check that every
ejection charge the log shows deploys a canopy of the card.
"""

from __future__ import annotations

import numpy as np
import pandas as pd

from cpas_ocp.errors import InputError
from cpas_ocp.io.flight_card import FlightCard, card_quantity
from cpas_ocp.io.flight_events import CLUSTER_GAP_S, FlightEvent, detect_events
from cpas_ocp.io.flight_record import FlightRecord

EVENT_SIGMA_S = 0.1  # timing sigma of a flight-state change (one descent sample, s)


EJECTION_EXCLUDE_S = 0.3  # altimeter samples left out after an ejection charge (s)


def card_events(card: FlightCard, baro: pd.DataFrame, pad_altitude: float,
                events: dict[str, FlightEvent]
                ) -> tuple[dict[str, FlightEvent], dict[str, str]]:
    """The events the card gives (``events``): at a time, or where the descent first
    crosses below a height above the pad after apogee (a main fired by an altimeter at
    its set height), the crossing interpolated between the barometer's samples; each with
    the card's sigma; and, per event at a height the log ends above (a recorder that
    stopped in the air), why it is not in the log.  InputError naming the card's field
    where the time lies outside the log, or the height above apogee."""
    out: dict[str, FlightEvent] = {}
    unreached: dict[str, str] = {}
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
            if after.size and float(after.max()) > height:
                unreached[name] = (f"the log ends at {float(t[-1]):.2f} s, "
                                   f"{float(h[-1]):.0f} m above the pad, before the descent "
                                   f"comes down to {height:.0f} m")
                continue
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
    return out, unreached


def flight_events(record: FlightRecord) -> tuple[dict[str, FlightEvent], list[str]]:
    """The record's flight events with their sigmas: its logged states (sigma
    `EVENT_SIGMA_S`) where it has them, with apogee from the altimeter where they hold
    none, else those `detect_events` finds; touchdown (``landed``) always detected from the
    data, never taken from a state or the log's end (the GNSS altitude's where the
    barometer's file stops in the air and the GNSS's reads on).  Notes say what could not
    be found."""
    detected, notes = detect_events(record.samples,
                                    record.gps_fixes() if record.has_gps_altitude else None)
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
