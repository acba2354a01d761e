"""The model an imported rocket log is fitted with where its card lists no effects: the
air's vertical motion, the canopies' drag, the altimeter and the other sensors' effects,
with the openings no sensor of a rocket log resolves held at a shape.
"""

from __future__ import annotations

from typing import Any

from cpas_ocp.io.flight_events import DROGUE_WINDOW_S, FlightEvent
from cpas_ocp.physics.effects.registry import SENSOR_EFFECTS
from cpas_ocp.physics.effects.wind_process import VERTICAL_MEAN_SIGMA_M_S

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
# an altimeter does not resolve that opening.  Where an accelerometer reads it (the fall
# from weightlessness to the steady pull, over a second or two) the fill constant is
# left to the data, linear growth held: a held n there makes the fill last as long as the
# small V_i says, and the fit bends the air and the drag area to shorten it.  A later
# canopy whose opening no accelerometer reads has its shape exponent held (linear
# growth): the altimeter sees the opening's duration, not the curve's shape.
HELD_FILL_CONSTANT = 8.0


HELD_EXPOPEN = 1.0


# A canopy the log shows did not open is held at this share of its open area, twice the
# least the canopy model allows: drag no sensor tells from none.
UNOPENED_SHARE = 2e-3


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
                 deploy_sigma: dict[str, float], still_air: bool = False,
                 timed: tuple[str, ...] = ()) -> dict[str, Any]:
    """The manifest's model block: the card's where it lists effects; else `ROCKET_EFFECTS`
    with the sensors' (`sensor_kinds`) and, with an altimeter and a second sensor, the
    altimeter's errors;
    each start window at least three of its deployment's sigmas (and `MIN_START_WINDOW_S`);
    the opening shape (n, expopen) of the canopies named in `held` held at
    `HELD_FILL_CONSTANT`, `HELD_EXPOPEN` (those in `timed`, whose opening an accelerometer
    reads, their expopen only), and without an accelerometer every canopy's expopen
    (`canopies`: each canopy's name and first stage); the card's own fixes, frees and
    priors win.  `still_air` leaves the air's motion out."""
    if "effects" in block:
        return block
    window = max(MIN_START_WINDOW_S, *(3.0 * s for s in deploy_sigma.values()))
    effects = [{"effect": "canopy_inflation", "start_window": round(window, 3)}
               if e == "canopy_inflation" else e for e in ROCKET_EFFECTS
               if not (still_air and isinstance(e, dict) and e["effect"] == "wind_process")]
    others = [SENSOR_EFFECTS[k] for k in dict.fromkeys(sensor_kinds) if k != "baro"]
    effects += [*(ALTIMETER_ERRORS if others and "baro" in sensor_kinds else ()), *others]
    fix: dict[str, Any] = {}
    accelerometer = "axial_accelerometer" in sensor_kinds
    for name, stage in canopies:
        if name in held and name not in timed:
            fix[f"n[{name},{stage}]"] = HELD_FILL_CONSTANT
        if name in held or not accelerometer:
            fix[f"expopen[{name},{stage}]"] = HELD_EXPOPEN
    return {**block, "effects": effects, "fix": {**fix, **block.get("fix", {})}}



def held_closed(model: dict[str, Any], vehicle: dict[str, Any], closed: dict[str, float],
                areas: dict[str, float], stages: dict[str, str], first: str,
                airframe_m2: float, infinite_mass: dict[str, bool]
                ) -> tuple[dict[str, Any], dict[str, Any]]:
    """The manifest's model and vehicle with the canopies in `closed` (name: deployment
    time, s) held closed: the deployment forensics found they did not open.  Each one's
    drag area is held at `UNOPENED_SHARE` of its open area (`areas`, m^2, pi D_o^2 / 4),
    its start at its deployment and, for a monotone fill (not `infinite_mass`), its shape
    at the held values; where the first canopy deployed (`first`) did not open, the
    airframe carried the descent, so its drag area CdS_V is estimated (where the model
    has `forebody_drag`), from `airframe_m2` (m^2, what the descent needed) where the card
    gives none.  The card's own fixes win."""
    if not closed:
        return model, vehicle
    fix: dict[str, Any] = {}
    for name, t_deploy in closed.items():
        key = f"{name},{stages[name]}"
        fix |= {f"CdS[{key}]": UNOPENED_SHARE * areas[name], f"t_start[{key}]": t_deploy}
        if not infinite_mass.get(name):  # a monotone fill's shape (an over-inflation's is
            # left to the data, which then say nothing of it)
            fix |= {f"n[{key}]": HELD_FILL_CONSTANT, f"expopen[{key}]": HELD_EXPOPEN}
    model = {**model, "fix": {**fix, **model.get("fix", {})}}
    if first in closed:
        model, vehicle = airframe_estimated(model, vehicle, airframe_m2)
    return model, vehicle


def late_openings(model: dict[str, Any], vehicle: dict[str, Any], late: dict[str, float],
                  stages: dict[str, str], fall_m2: float) -> tuple[dict[str, Any],
                                                                   dict[str, Any]]:
    """The manifest's model and vehicle where the log shows a canopy that took hold late
    (`deployment_forensics.late_opening`): `late` maps each such canopy to the shift (s)
    from the start its charge seeds (`CanopyInflation.observed_start`) to the corner of the
    descent where it opened, written as the canopy_inflation effect's ``start_shifts`` so
    that its start's window lies about the opening; and the drag that held the fall before
    it (`fall_m2`, m^2: the airframe and the canopy streaming, which no opening curve from
    the charge gives) is the airframe's CdS_V, estimated from that guess (where the model
    has `forebody_drag`; the canopy's own drag area is then what it added).  Without this
    the fit opens the canopy at its charge and the air's motion must sink at the fall's
    excess speed.  The card's own start shifts and airframe drag area win."""
    if not late:
        return model, vehicle
    shifts = {f"t_start[{name},{stages[name]}]": round(shift, 3)
              for name, shift in late.items()}
    effects = []
    for e in model.get("effects", ()):
        if e == "canopy_inflation" or (isinstance(e, dict)
                                       and e.get("effect") == "canopy_inflation"):
            entry = {"effect": "canopy_inflation"} if isinstance(e, str) else dict(e)
            entry["start_shifts"] = {**shifts, **entry.get("start_shifts", {})}
            e = entry
        effects.append(e)
    return airframe_estimated({**model, "effects": effects}, vehicle, fall_m2)


def effect_names(model: dict[str, Any]) -> set[str]:
    """The names of the effects a manifest's model block lists (a name, or an entry with
    its ``effect``)."""
    return {e if isinstance(e, str) else e.get("effect") for e in model.get("effects", ())}


def airframe_estimated(model: dict[str, Any], vehicle: dict[str, Any], guess_m2: float
                       ) -> tuple[dict[str, Any], dict[str, Any]]:
    """The model with the airframe's drag area CdS_V freed, where it has
    ``forebody_drag``, and the vehicle's ``forebody_cds`` starting it at `guess_m2` (m^2)
    where the card gives none."""
    if "forebody_drag" not in effect_names(model):
        return model, vehicle
    model = {**model, "free": [*dict.fromkeys([*model.get("free", []), "CdS_V"])]}
    if not vehicle.get("forebody_cds", {}).get("value"):
        vehicle = {**vehicle, "forebody_cds": {"value": round(guess_m2, 6), "unit": "m^2"}}
    return model, vehicle
