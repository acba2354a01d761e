"""A test folder: manifest.json plus one CSV per sensor, validated and in SI.

The manifest is validated against `data_schemas/manifest.schema.json` (which
references `series.schema.json` for each sensor's columns).  Loading then
checks what a schema cannot: names that refer to each other, the CSV files
against their declared columns, finite values, strictly increasing time, and
events inside the data.  Every violation raises `InputError` naming the file,
the field and the expectation.  Units are converted to SI here and nowhere
else.
"""

from __future__ import annotations

import json
import math
from functools import cache
from importlib import resources
from itertools import pairwise
from pathlib import Path
from typing import Any

import jsonschema
import numpy as np
import pandas as pd
import referencing

from cpas_ocp.errors import InputError
from cpas_ocp.physics.atmosphere import (
    Atmosphere,
    SiteAtmosphere,
    SoundingAtmosphere,
    StandardAtmosphere,
    TableAtmosphere,
)
from cpas_ocp.physics.flight_test import (
    SENSOR_COLUMNS,
    SIGMA_GROUPS,
    Event,
    FlightTest,
    Parachute,
    Sensor,
    Vehicle,
)
from cpas_ocp.physics.units import FACTORS

MANIFEST = "manifest.json"
FORMAT = "cpas-ocp/test-folder/1"

SCHEMAS = ("manifest.schema.json", "series.schema.json", "model.schema.json",
           "flight_card.schema.json", "column_map.schema.json")


@cache
def _schema_registry() -> tuple[dict[str, dict[str, Any]], referencing.Registry]:
    folder = resources.files("cpas_ocp.schemas")
    schemas = {name: json.loads(folder.joinpath(name).read_text()) for name in SCHEMAS}
    registry = referencing.Registry().with_resources(
        (s["$id"], referencing.Resource.from_contents(s)) for s in schemas.values()
    )
    return schemas, registry


def _json_path(parts: Any, prefix: str = "") -> str:
    out = prefix
    for p in parts:
        out += f"[{p}]" if isinstance(p, int) else (f".{p}" if out else str(p))
    return out or "(top level)"


def validate_block(obj: Any, schema: str, file: str, prefix: str = "") -> None:
    """Validate `obj` against one of the shipped JSON Schemas; InputError on the first problem.

    `prefix` is the field path of `obj` inside its file (empty at top level).
    """
    schemas, registry = _schema_registry()
    validator = jsonschema.Draft202012Validator(schemas[schema], registry=registry)
    errors = list(validator.iter_errors(obj))
    # A field a subschema rejects is also "unevaluated" to the block that refuses unknown
    # fields: name the subschema's reason, and an unknown field only where it is the only one.
    error = jsonschema.exceptions.best_match(
        [e for e in errors if e.validator != "unevaluatedProperties"] or errors)
    if error is not None:
        # Descend to the most specific cause so the message names the leaf field.
        while error.context:
            error = jsonschema.exceptions.best_match(error.context)
        path = list(error.absolute_path)
        if error.validator == "required" and isinstance(error.instance, dict):
            # A missing field is named itself, not its parent.
            path.append(next(k for k in error.validator_value if k not in error.instance))
            raise InputError(file, _json_path(path, prefix), "a required field, missing")
        raise InputError(file, _json_path(path, prefix), error.message)


def validate_manifest(manifest: Any, file: str = MANIFEST) -> None:
    """Validate a manifest object against the JSON Schema; raise InputError on the first problem."""
    validate_block(manifest, "manifest.schema.json", file)
    check_magnitudes(manifest, file)


# Largest magnitude a number in a manifest may have.  No quantity of a parachute test comes
# near it in any accepted unit (a 20,000 lb vehicle is 9e3 kg, sea-level pressure 1e5 Pa),
# and squares of larger ones overflow: a vehicle mass of 1e300 passed the schema and ended
# as an internal error in the covariance.
MAX_MAGNITUDE = 1e9


def check_magnitudes(node: Any, file: str, path: str = "") -> None:
    """InputError naming the first number in `node` (a manifest or part of one) that is not
    finite or exceeds MAX_MAGNITUDE."""
    if isinstance(node, bool):
        return
    if isinstance(node, int | float):
        if not (math.isfinite(node) and abs(node) <= MAX_MAGNITUDE):
            raise InputError(file, path or "(value)", f"a finite number of magnitude at most "
                             f"{MAX_MAGNITUDE:g}; got {node!r}")
        return
    items = node.items() if isinstance(node, dict) else \
        enumerate(node) if isinstance(node, list) else ()
    for key, child in items:
        where = f"{path}[{key}]" if isinstance(key, int) else f"{path}.{key}" if path else key
        check_magnitudes(child, file, where)


# Data a sensor may have beyond the window all sensors share, at the phase's start or end,
# before the phase must be trimmed explicitly (s; at least 3 of the coarsest sampling
# intervals).
COVERAGE_SLACK_S = 1.0


def _check_coverage(mfile: str, entries: list[dict[str, Any]], sensors: list[Sensor],
                    check_start: bool, check_end: bool) -> None:
    """InputError where, with the phase's start or end left to the data, one sensor's series
    starts later or ends earlier than the others' by more than the slack: the phase would
    silently shrink to it (a truncated file), where the manifest's `phase` should say so."""
    coarsest = max((float(np.median(np.diff(s.time))) for s in sensors if len(s.time) > 1),
                   default=0.0)
    slack = max(COVERAGE_SLACK_S, 3.0 * coarsest)
    checks = [("start", check_start, [s.time[0] for s in sensors], max, min),
              ("end", check_end, [s.time[-1] for s in sensors], min, max)]
    for edge, wanted, times, shared, widest in checks:
        if not wanted:
            continue
        k = times.index(shared(times))
        if abs(widest(times) - times[k]) > slack:
            word = "starts" if edge == "start" else "ends"
            raise InputError(mfile, f"sensors[{k}]", f"{entries[k]['file']} {word} at "
                             f"{times[k]:.3f} s, {abs(widest(times) - times[k]):.2f} s from the "
                             f"other sensors ({widest(times):.3f} s): a truncated file? Give "
                             f"phase.{edge} to trim the phase explicitly")


# A canopy's deployment events in the order they happen; the Main-bag events of a Pilot.
DEPLOYMENT_ORDER = ("mortar_fire", "line_stretch", "bag_strip")
MAIN_BAG_ORDER = ("main_bag_lift", "main_bag_strip")
# Events out of order by more than this many of their combined sigmas are refused.
EVENT_ORDER_SIGMAS = 3.0


def _check_events(mfile: str, events: list[Event], by_name: dict[str, Parachute]) -> None:
    """InputError for an event given twice, or out of the order the physics fixes (beyond
    EVENT_ORDER_SIGMAS of the two events' combined sigma).

    Per canopy: mortar fire, line stretch, bag strip; every disreef after them,
    in the order of the stages it opens into; a stage's full open after its
    start (the deployment, or the disreef into it); a Pilot's Main-bag lift
    before the Main-bag strip.  A disreef before its own mortar fire made the
    fit run 500 iterations for 9 minutes and fail; a duplicate was silently
    dropped.
    """
    seen: dict[tuple[str, str, str | None], int] = {}
    for i, e in enumerate(events):
        key = (e.name, e.parachute, e.stage)
        if key in seen:
            raise InputError(mfile, f"events[{i}]", f"one {e.name} event per canopy and stage; "
                             f"events[{seen[key]}] is the same event")
        seen[key] = i

    def rank(e: Event) -> tuple[int, int] | None:
        """Position in the canopy's sequence: (stage step, order within it)."""
        if e.name in DEPLOYMENT_ORDER:
            return 0, DEPLOYMENT_ORDER.index(e.name)
        stages = by_name[e.parachute].stages
        step = stages.index(e.stage) if e.stage in stages else 0
        if e.name == "disreef":
            return step, len(DEPLOYMENT_ORDER)
        if e.name == "full_open":
            return step, len(DEPLOYMENT_ORDER) + 1
        return None  # the Main-bag events are a sequence of their own

    for i, a in enumerate(events):
        for j, b in enumerate(events):
            if a.parachute != b.parachute or i == j:
                continue
            ra, rb = rank(a), rank(b)
            if ra is not None and rb is not None:
                before = ra < rb
            else:
                before = a.name in MAIN_BAG_ORDER and b.name in MAIN_BAG_ORDER \
                    and MAIN_BAG_ORDER.index(a.name) < MAIN_BAG_ORDER.index(b.name)
            slack = EVENT_ORDER_SIGMAS * float(np.hypot(a.sigma, b.sigma))
            if before and b.time < a.time - slack:
                what = f"{b.name}{f' ({b.stage})' if b.stage else ''} of {b.parachute}"
                raise InputError(mfile, f"events[{j}].time", f"{what} at {b.time:.3f} s after "
                                 f"events[{i}] ({a.name} at {a.time:.3f} s): the events are "
                                 "out of order")


def _si(quantity: dict[str, Any], dimension: str) -> float:
    return float(quantity["value"]) * FACTORS[dimension][quantity["unit"]]


def read_text(path: Path, missing: str) -> str:
    """The text of `path` as UTF-8 (a leading byte-order mark dropped); InputError with
    `missing` if absent, and naming the byte where it is not UTF-8 text."""
    if not path.is_file():
        raise InputError(str(path), "(file)", missing)
    try:
        return path.read_text(encoding="utf-8-sig")
    except UnicodeDecodeError as exc:
        raise InputError(str(path), f"byte {exc.start}",
                         "UTF-8 text (this file is binary or in another encoding)") from None


def _no_constant(name: str) -> float:
    raise ValueError(f"{name} is not a JSON number; write a finite number")


def read_json(path: Path, missing: str) -> Any:
    """The JSON content of `path`; InputError with `missing` if absent, the line if invalid.

    JSON has no NaN or Infinity: Python's reader accepts those literals, and a
    NaN that reached the model would surface as a solver failure minutes
    later, so they are refused here."""
    text = read_text(path, missing)
    try:
        return json.loads(text, parse_constant=_no_constant)
    except json.JSONDecodeError as exc:
        raise InputError(str(path), f"line {exc.lineno}", f"valid JSON ({exc.msg})") from None
    except ValueError as exc:  # a NaN or Infinity literal
        raise InputError(str(path), "(value)", str(exc)) from None


def load_test(folder: str | Path) -> FlightTest:
    """Load and validate a test folder; everything returned is in SI."""
    folder = Path(folder)
    manifest = read_json(folder / MANIFEST, "a test folder must contain manifest.json")
    return test_from_manifest(manifest, folder)


def test_from_manifest(manifest: dict[str, Any], folder: Path,
                       series: dict[str, pd.DataFrame] | None = None) -> FlightTest:
    """Build a FlightTest from a manifest object whose CSV files live in `folder`.

    `series` (sensor name -> SI DataFrame) replaces reading the files; the
    simulator uses it to plan sample times before any data exist.
    """
    mfile = str(folder / MANIFEST)
    validate_manifest(manifest, mfile)

    v = manifest["vehicle"]
    vehicle = Vehicle(v["name"], _si(v["mass"], "mass"), _si(v["forebody_cds"], "area"))

    parachutes = []
    for i, p in enumerate(manifest["parachutes"]):
        if len(set(p["stages"])) != len(p["stages"]):
            raise InputError(mfile, f"parachutes[{i}].stages", "stage names must be unique")
        is_open = bool(p.get("open_at_start", False))
        if is_open and len(p["stages"]) != 1:
            raise InputError(mfile, f"parachutes[{i}].stages", "one stage for a canopy open "
                             "at the start (its steady drag area)")
        bands = _altitude_bands(mfile, f"parachutes[{i}].altitude_bands",
                                p.get("altitude_bands", []), is_open)
        parachutes.append(Parachute(p["name"], p["type"], _si(p["diameter"], "length"),
                                    _si(p["dry_mass"], "mass"), p["inflation"],
                                    p.get("fill_length", "diameter"), tuple(p["stages"]),
                                    _si(p["line_length"], "length") if "line_length" in p
                                    else None, is_open, bands))
    _unique(mfile, "parachutes", [p.name for p in parachutes])
    banded = [i for i, p in enumerate(parachutes) if p.altitude_bands]
    if len(banded) > 1:
        raise InputError(mfile, f"parachutes[{banded[1]}].altitude_bands", "altitude bands on "
                         "one canopy at most (a descent rate under canopies open together is "
                         "split by one set of bands)")
    by_name = {p.name: p for p in parachutes}

    sensors = [_load_sensor(mfile, folder, i, s, by_name, series)
               for i, s in enumerate(manifest["sensors"])]
    _unique(mfile, "sensors", [s.name for s in sensors])

    t_lo = max(s.time[0] for s in sensors)
    t_hi = min(s.time[-1] for s in sensors)
    phase = manifest.get("phase", {})
    _check_coverage(mfile, manifest["sensors"], sensors, check_start="start" not in phase,
                    check_end="end" not in phase)
    t_start = _si(phase["start"], "time") if "start" in phase else t_lo
    t_end = _si(phase["end"], "time") if "end" in phase else t_hi
    if not (t_lo <= t_start < t_end <= t_hi):
        raise InputError(mfile, "phase", f"a window inside the data shared by all sensors "
                         f"[{t_lo:.3f}, {t_hi:.3f}] s with start < end")

    events = []
    for i, e in enumerate(manifest["events"]):
        where = f"events[{i}]"
        if e["parachute"] not in by_name:
            raise InputError(mfile, f"{where}.parachute", f"one of {sorted(by_name)}")
        stage = e.get("stage")
        if stage is not None and stage not in by_name[e["parachute"]].stages:
            raise InputError(mfile, f"{where}.stage",
                             f"one of {list(by_name[e['parachute']].stages)}")
        if e["name"] == "disreef" and stage is None:
            raise InputError(mfile, f"{where}.stage",
                             "a disreef event names the stage it opens into")
        if by_name[e["parachute"]].open_at_start:
            raise InputError(mfile, f"{where}.parachute", f"a canopy that deploys in the phase;"
                             f" {e['parachute']} is open at the start (open_at_start), so it "
                             "has no events")
        if e["name"] == "full_open" and stage is None:
            stage = by_name[e["parachute"]].stages[0]
        t = _si(e["time"], "time")
        if not (t_start <= t <= t_end):
            raise InputError(mfile, f"{where}.time", f"{t:.3f} s lies outside the data "
                             f"[{t_start:.3f}, {t_end:.3f}] s")
        events.append(Event(e["name"], e["parachute"], stage, t, _si(e["sigma"], "time")))
    _check_events(mfile, events, by_name)

    return FlightTest(
        name=manifest["name"], path=folder, vehicle=vehicle, parachutes=tuple(parachutes),
        events=tuple(events), sensors=tuple(sensors),
        atmosphere=_load_atmosphere(mfile, folder, manifest["atmosphere"]),
        t_start=t_start, t_end=t_end, description=manifest.get("description", ""),
        label=manifest.get("label", ""), manifest=manifest,
    )


def _altitude_bands(mfile: str, where: str, given: list[Any], is_open: bool
                    ) -> tuple[float, ...]:
    """Band edges (m) of a canopy's drag area: numbers in m or {value, unit}, strictly
    increasing, only for a canopy open at the start."""
    if given and not is_open:
        raise InputError(mfile, where, "altitude bands only for a canopy open at the start "
                         "(open_at_start: true)")
    edges = tuple(float(e) if isinstance(e, int | float) else _si(e, "length") for e in given)
    if any(b <= a for a, b in pairwise(edges)):
        raise InputError(mfile, where, f"strictly increasing altitudes; got "
                         f"{', '.join(f'{e:g}' for e in edges)} m")
    return edges


def _unique(file: str, field_name: str, names: list[str]) -> None:
    dup = sorted({n for n in names if names.count(n) > 1})
    if dup:
        raise InputError(file, field_name, f"names must be unique (repeated: {', '.join(dup)})")


def _load_sensor(mfile: str, folder: Path, i: int, s: dict[str, Any],
                 parachutes: dict[str, Parachute],
                 series: dict[str, pd.DataFrame] | None) -> Sensor:
    where = f"sensors[{i}]"
    kind = s["kind"]
    parachute = s.get("parachute")
    if kind == "load_cell" and parachute not in parachutes:
        raise InputError(mfile, f"{where}.parachute",
                         f"a load cell names its canopy, one of {sorted(parachutes)}")
    sigma = _sigmas(mfile, f"{where}.sigma", kind, s["sigma"], required=True)
    changes = tuple((_si(c["time"], "time"),
                     _sigmas(mfile, f"{where}.sigma_after[{j}].sigma", kind, c["sigma"],
                             required=False))
                    for j, c in enumerate(s.get("sigma_after", [])))
    if series is not None:
        data = series[s["name"]]
    else:
        data = read_series(folder / s["file"], s["columns"], SENSOR_COLUMNS[kind])
    return Sensor(s["name"], kind, parachute, s["file"], data, sigma,
                  float(s.get("sigma_relative", 0.0)), changes)


def _sigmas(mfile: str, where: str, kind: str, given: dict[str, Any], required: bool
            ) -> dict[str, float]:
    """Channel -> sigma (SI) from a sensor's sigma groups; every group if `required`."""
    sigma: dict[str, float] = {}
    for key in given:
        if key not in SIGMA_GROUPS[kind]:
            raise InputError(mfile, f"{where}.{key}", f"a noise group of a {kind} sensor "
                             f"({', '.join(SIGMA_GROUPS[kind])})")
    for group, (dim, channels) in SIGMA_GROUPS[kind].items():
        q = given.get(group)
        if q is None:
            if required:
                raise InputError(mfile, f"{where}.{group}", f"noise sigma in {dim} units")
            continue
        if q["unit"] not in FACTORS[dim]:
            raise InputError(mfile, f"{where}.{group}.unit",
                             f"one of {sorted(FACTORS[dim])}, got {q['unit']!r}")
        for c in channels:
            sigma[c] = _si(q, dim)
    return sigma


def _read_columns(path: Path, units: dict[str, str], dimensions: dict[str, str],
                  what: str) -> dict[str, np.ndarray]:
    """Read the named columns of a CSV file as finite numbers in SI."""
    file = str(path)
    if not path.is_file():
        raise InputError(file, "(file)", f"{what} must exist")
    try:
        raw = pd.read_csv(path, encoding="utf-8-sig")
    except (pd.errors.ParserError, pd.errors.EmptyDataError, UnicodeDecodeError) as exc:
        raise InputError(file, "(csv)", f"a CSV table with a header row ({exc})") from None
    out = {}
    for column, dim in dimensions.items():
        if column not in raw.columns:
            raise InputError(file, column, f"a column named {column!r} (header has "
                             f"{', '.join(map(str, raw.columns))})")
        values = pd.to_numeric(raw[column], errors="coerce").to_numpy(dtype=float)
        bad = np.flatnonzero(~np.isfinite(values))
        if bad.size:
            raise InputError(file, column, f"finite numbers; missing or non-numeric values in "
                             f"data rows {_runs(bad)} (clean the series before loading)")
        huge = np.flatnonzero(np.abs(values) > MAX_MAGNITUDE)
        if huge.size:
            raise InputError(file, column, f"numbers of magnitude at most {MAX_MAGNITUDE:g}; "
                             f"data rows {_runs(huge)} exceed it")
        out[column] = values * FACTORS[dim][units[column]]
    return out


def read_series(path: Path, units: dict[str, str], dimensions: dict[str, str]) -> pd.DataFrame:
    """Read one sensor's CSV series, check it, and return its columns in SI."""
    out = _read_columns(path, units, dimensions, "the sensor's series file")
    t = out["time"]
    if len(t) < 2:
        raise InputError(str(path), "time", "at least two samples")
    steps = np.diff(t)
    if (steps <= 0).any():
        k = int(np.flatnonzero(steps <= 0)[0])
        raise InputError(str(path), "time", f"strictly increasing; row {k + 2} ({t[k + 1]:.6g} s)"
                         f" does not follow row {k + 1} ({t[k]:.6g} s)")
    return pd.DataFrame(out)


def _runs(rows: np.ndarray) -> str:
    """Describe sorted row indices (0-based data rows) as 1-based runs, e.g. '12-18, 40'."""
    parts, start = [], rows[0]
    for a, b in zip(rows, [*rows[1:], math.inf], strict=True):
        if b != a + 1:
            parts.append(f"{start + 1}" if start == a else f"{start + 1}-{a + 1}")
            start = b
    return ", ".join(parts[:5]) + (" ..." if len(parts) > 5 else "")


# Dimension of each column an atmosphere table may have beside altitude.
TABLE_COLUMNS = {"density": "density", "pressure": "pressure", "temperature": "temperature",
                 "wind_east": "velocity", "wind_north": "velocity"}


def _load_atmosphere(mfile: str, folder: Path, spec: dict[str, Any]) -> Atmosphere:
    if spec["model"] == "standard":
        return StandardAtmosphere()
    if spec["model"] == "site":
        lapse = _si(spec["lapse_rate"], "lapse_rate") if "lapse_rate" in spec else None
        return SiteAtmosphere(_si(spec["elevation"], "length"), _si(spec["pressure"], "pressure"),
                              _si(spec["temperature"], "temperature"),
                              *([lapse] if lapse is not None else []))
    columns = spec["columns"]
    given = [k for k in ("density", "pressure", "temperature") if k in columns]
    if given in ([], ["pressure"]):
        raise InputError(mfile, "atmosphere.columns", "a density or temperature column (with "
                         "altitude; pressure alone gives no density)")
    if ("wind_east" in columns) != ("wind_north" in columns):
        raise InputError(mfile, "atmosphere.columns", "both wind_east and wind_north for a "
                         "wind (a horizontal wind has two components), or neither")
    dims = {"altitude": "length", **{k: TABLE_COLUMNS[k] for k in columns if k != "altitude"}}
    file = folder / spec["file"]
    data = read_series_table(file, columns, dims)
    for k in given:
        if (data[k] <= 0).any():
            raise InputError(str(file), k, "positive values")
    winds = data.get("wind_east"), data.get("wind_north")
    if given == ["density"]:
        if "surface_pressure" in spec:
            raise InputError(mfile, "atmosphere.surface_pressure", "a temperature column to "
                             "integrate from it (a density table has no pressure)")
        return TableAtmosphere(data["altitude"], data["density"], *winds)
    if "pressure" in data:
        if "surface_pressure" in spec:
            raise InputError(mfile, "atmosphere.surface_pressure", "no surface pressure where "
                             "the table has a pressure column")
        if (np.diff(data["pressure"]) >= 0).any():
            k = int(np.flatnonzero(np.diff(data["pressure"]) >= 0)[0])
            raise InputError(str(file), "pressure", f"pressure falling with altitude; data row "
                             f"{k + 2} ({data['pressure'][k + 1]:.6g} Pa) is not below row "
                             f"{k + 1}")
    base = _si(spec["surface_pressure"], "pressure") if "surface_pressure" in spec else None
    return SoundingAtmosphere.from_profile(
        data["altitude"], temperature_k=data.get("temperature"), pressure_pa=data.get("pressure"),
        density_kg_m3=data.get("density"), base_pressure_pa=base,
        wind_east_m_s=winds[0], wind_north_m_s=winds[1])


def read_series_table(path: Path, units: dict[str, str],
                      dimensions: dict[str, str]) -> dict[str, np.ndarray]:
    """Read a profile table (no time column) with strictly increasing altitude, in SI."""
    out = _read_columns(path, units, dimensions, "the atmosphere table")
    if out["altitude"].size < 2:
        raise InputError(str(path), "altitude", "at least two rows (the profile is "
                         f"interpolated between rows); got {out['altitude'].size}")
    if (np.diff(out["altitude"]) <= 0).any():
        raise InputError(str(path), "altitude", "strictly increasing altitude")
    return out
