"""Drag areas from a log's settled descents: what each canopy's own drag area is where the
drag carries the weight, and the canopy diameters a card leaves out, taken from them.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from cpas_ocp.errors import InputError
from cpas_ocp.io.flight_card import ASSUMED_CD, FlightCard, card_quantity
from cpas_ocp.io.flight_record import pressure_of_altitude
from cpas_ocp.io.log_noise import local_slope, settled_time
from cpas_ocp.physics.atmosphere import SiteAtmosphere
from cpas_ocp.physics.effects.canopy_inflation import MAX_CD
from cpas_ocp.physics.units import G0


def descent_mass(card: FlightCard, parachutes: list[dict[str, Any]]) -> float:
    """The mass flown under the canopies (kg): the card's vehicle and every canopy's dry
    mass."""
    return card_quantity(card.vehicle.get("mass"), "mass", card.source, "vehicle.mass") + sum(
        card_quantity(c["dry_mass"], "mass", card.source, "parachutes.dry_mass")
        for c in parachutes)


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
    mass = descent_mass(card, parachutes)
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
