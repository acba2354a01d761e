"""A flight card: what a rocket's log does not hold (the vehicle's descent mass and forebody
drag area, the parachutes and the flight state that deploys each, the launch site, the
model block, the published nominal drag areas), read from JSON (a built-in card is a
problem with ``"kind": "flight_log"``) with its defaults filled in, quantities in SI.
"""


from __future__ import annotations

import json
from dataclasses import dataclass, field
from importlib import resources
from pathlib import Path
from typing import Any

from cpas_ocp.errors import InputError
from cpas_ocp.io.json_files import check_magnitudes, read_json, validate_block
from cpas_ocp.io.model_spec import spec_from_block
from cpas_ocp.io.problems import problem_names
from cpas_ocp.physics.atmosphere import (
    R_AIR,
    StandardAtmosphere,
)
from cpas_ocp.physics.units import FACTORS

ASSUMED_CD = 0.75  # drag coefficient on pi D_o^2 / 4 of a canopy whose card gives no diameter


DEFAULT_DRY_MASS_FRACTION = 0.005  # of the vehicle's mass: a canopy's where the card gives none


@dataclass(frozen=True)
class FlightCard:
    """What a flight log does not hold; see the module docstring."""

    name: str
    title: str
    label: str
    data_folder: str
    logs: tuple[str, ...]
    vehicle: dict[str, Any]
    parachutes: tuple[dict[str, Any], ...]
    site: dict[str, Any]
    model: dict[str, Any]
    nominal: dict[str, dict[str, Any]]
    source: str
    events: dict[str, dict[str, Any]] = field(default_factory=dict)
    data_format: str | None = None  # the logs' built-in format, for `flight`
    # or their column map: a file relative to the card's folder, or the map inline
    data_columns: str | dict[str, Any] | None = None


def card_from_dict(raw: dict[str, Any], source: str) -> FlightCard:
    """A card from its JSON object; InputError naming the field that breaks
    `data_schemas/flight_card.schema.json` (or whose numbers are beyond any test's).

    The canopies' optional fields are filled in here (`canopy_defaults`), and the vehicle's
    forebody drag area is 0 where the card gives none (the canopies' drag areas then carry
    the body's), so that the manifest the import writes states every value it was built
    with."""
    validate_block(raw, "flight_card.schema.json", source)
    check_magnitudes(raw, source)
    check_card_model(raw.get("model") or {}, source)
    data = raw.get("data", {})
    return FlightCard(raw["name"], raw.get("title", raw["name"]), raw.get("label", ""),
                      data.get("folder", ""), tuple(data.get("logs", ())),
                      {"forebody_cds": {"value": 0.0, "unit": "m^2"}, **raw["vehicle"]},
                      tuple(canopy_defaults(raw["parachutes"], raw["vehicle"], source)),
                      raw["site"], raw.get("model") or {}, raw.get("nominal", {}), source,
                      raw.get("events", {}), data.get("format"), data.get("columns"))


def check_card_model(model: dict[str, Any], source: str) -> None:
    """Refuse a card whose `model` lists an effect the library does not register, or an
    option its effect does not take (InputError naming ``model.effects[i]`` and the known
    effects), when the card is read rather than at the fit of the folder imported with it.

    Where the block names plug-ins (``model.plugins``), their effects are known only once
    their files are loaded, relative to the test folder the block is written to; the
    effects are then checked when that folder's model is built."""
    if "effects" in model and not model.get("plugins"):
        spec_from_block(model, source, Path(source).parent)


def canopy_defaults(parachutes: list[dict[str, Any]], vehicle: dict[str, Any], source: str
                    ) -> list[dict[str, Any]]:
    """The card's canopies with what they leave out filled in: ``type`` drogue for the
    first and main for the others, ``inflation`` finite mass, one stage ``open``, and a
    ``dry_mass`` of `DEFAULT_DRY_MASS_FRACTION` of the vehicle's (a canopy's mass only adds
    to the descent mass it flies with).  A missing ``diameter`` stays missing: the import
    takes it from the descent (`canopy_diameters`)."""
    out = []
    for i, chute in enumerate(parachutes):
        if chute.get("open_at_start"):
            raise InputError(source, f"parachutes[{i}].open_at_start", "a canopy the log sees "
                             "deploy (a flight card's canopies each open at an event of the "
                             "log; open_at_start is for a test folder whose phase begins "
                             "under an open canopy)")
        if len(chute.get("stages", ())) > 1:
            raise InputError(source, f"parachutes[{i}].stages", "one stage: the import finds "
                             "no disreef events in a rocket log")
        filled = {"type": "drogue" if i == 0 else "main", "inflation": "finite_mass",
                  "stages": ["open"], **chute}
        if "dry_mass" not in chute:
            mass = card_quantity(vehicle.get("mass"), "mass", source, "vehicle.mass")
            filled["dry_mass"] = {"value": round(DEFAULT_DRY_MASS_FRACTION * mass, 4),
                                  "unit": "kg"}
        out.append(filled)
    return out


def load_card(name_or_path: str) -> FlightCard:
    """A built-in flight card by problem name, or a card file."""
    path = Path(name_or_path)
    if path.suffix == ".json":
        return card_from_dict(read_json(path, "an existing flight-card JSON file"), str(path))
    names = problem_names("flight_log")
    if name_or_path not in names:
        raise InputError("flight card", "name", f"a card file (.json) or one of "
                         f"{', '.join(names)}; got {name_or_path!r}")
    raw = json.loads(resources.files("cpas_ocp.problem_data")
                     .joinpath(f"{name_or_path}.json").read_text())
    return card_from_dict(raw, f"problems/{name_or_path}.json")


def card_quantity(q: dict[str, Any], dim: str, source: str, field: str) -> float:
    """The quantity `q` ({value, unit}) of dimension `dim` in SI; InputError naming `field`
    of `source` where it is no such quantity."""
    unit = q.get("unit") if isinstance(q, dict) else None
    value = q.get("value") if isinstance(q, dict) else None
    if not isinstance(unit, str) or unit not in FACTORS[dim] \
            or not isinstance(value, int | float) or isinstance(value, bool):
        raise InputError(source, field, f"{{value, unit}} with a {dim} unit "
                         f"({', '.join(sorted(FACTORS[dim]))})")
    return float(q["value"]) * FACTORS[dim][unit]


TEMPERATURE_UNITS = {"K": (1.0, 0.0), "degC": (1.0, 273.15), "degF": (5.0 / 9.0, 255.372222)}


def pad_temperature(site: dict[str, Any], p0: float, elevation: float, source: str
                    ) -> tuple[float, str]:
    """The air temperature on the pad (K) and where it came from: the card's
    ``temperature``, or its ``surface_density`` with the pad pressure `p0` (Pa) through the
    gas law T = p / (R rho), or the standard atmosphere's at the site's `elevation` (m)."""
    if "temperature" in site:
        scale, offset = TEMPERATURE_UNITS[site["temperature"]["unit"]]
        t0 = scale * float(site["temperature"]["value"]) + offset
        if not t0 > 0.0:
            raise InputError(source, "site.temperature", f"a temperature above absolute zero; "
                             f"got {t0:.2f} K")
        return t0, f"pad temperature {t0:.1f} K from the card's site.temperature"
    if "surface_density" in site:
        rho0 = card_quantity(site["surface_density"], "density", source, "site.surface_density")
        t0 = p0 / (R_AIR * rho0)
        return t0, (f"pad temperature {t0:.1f} K from the card's surface density "
                    f"{rho0:.3f} kg/m^3 and the pad pressure (T = p / (R rho))")
    standard = StandardAtmosphere()
    t0 = float(standard.pressure(elevation)) / (R_AIR * float(standard.density(elevation)))
    return t0, (f"pad temperature {t0:.1f} K: the standard atmosphere's at {elevation:.0f} m "
                "(the card gives neither site.temperature nor site.surface_density)")


def is_card_file(card: FlightCard) -> bool:
    """Whether `card` was read from a card file (not a built-in card)."""
    return Path(card.source).suffix == ".json" and Path(card.source).is_file()


def card_folder(card: FlightCard) -> Path:
    """The folder a card's relative paths start from: a card file's own folder (the
    working folder for a built-in card)."""
    return Path(card.source).parent if is_card_file(card) else Path()


def card_reading(card: FlightCard) -> tuple[str | None, Path | dict[str, Any] | None]:
    """How the card says its logs are read: ``data.format`` (a built-in format) and
    ``data.columns`` (a column map, or its file's path from the card's folder)."""
    columns = card.data_columns
    return card.data_format, card_folder(card) / columns if isinstance(columns, str) \
        else columns
