"""A test folder: manifest.json plus one CSV per sensor, validated and in SI.

The manifest is validated against `data_schemas/manifest.schema.json` (which
references `series.schema.json` for each sensor's columns).  Loading then
checks what a schema cannot: names that refer to each other, the CSV files
against their declared columns, finite values, strictly increasing time, and
events inside the data.  Every violation raises `InputError` naming the file,
the field and the expectation.  The JSON is read and validated by `json_files`,
the series and quantities converted to SI by `series_files`, nowhere else; the
result is the domain types of `physics.flight_test`.
"""

from __future__ import annotations

from itertools import pairwise
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from cpas_ocp.errors import InputError
from cpas_ocp.io.json_files import check_magnitudes, read_json, validate_block
from cpas_ocp.io.series_files import load_atmosphere, read_series, si_value
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


def validate_manifest(manifest: Any, file: str = MANIFEST) -> None:
    """Validate a manifest object against the JSON Schema; raise InputError on the first problem."""
    validate_block(manifest, "manifest.schema.json", file)
    check_magnitudes(manifest, file)


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


def load_test(folder: str | Path) -> FlightTest:
    """Load and validate a test folder; everything returned is in SI."""
    folder = Path(folder)
    manifest = read_json(folder / MANIFEST, "a test folder must contain manifest.json")
    return flight_test_from_manifest(manifest, folder)


def flight_test_from_manifest(manifest: dict[str, Any], folder: Path,
                       series: dict[str, pd.DataFrame] | None = None) -> FlightTest:
    """Build a FlightTest from a manifest object whose CSV files live in `folder`.

    `series` (sensor name -> SI DataFrame) replaces reading the files; the
    simulator uses it to plan sample times before any data exist.
    """
    mfile = str(folder / MANIFEST)
    validate_manifest(manifest, mfile)

    v = manifest["vehicle"]
    vehicle = Vehicle(v["name"], si_value(v["mass"], "mass"), si_value(v["forebody_cds"], "area"))

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
        parachutes.append(Parachute(p["name"], p["type"], si_value(p["diameter"], "length"),
                                    si_value(p["dry_mass"], "mass"), p["inflation"],
                                    p.get("fill_length", "diameter"), tuple(p["stages"]),
                                    si_value(p["line_length"], "length") if "line_length" in p
                                    else None, is_open, bands))
    _unique(mfile, "parachutes", [p.name for p in parachutes])
    canopy_covariates(manifest, mfile)
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
    t_start = si_value(phase["start"], "time") if "start" in phase else t_lo
    t_end = si_value(phase["end"], "time") if "end" in phase else t_hi
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
        t = si_value(e["time"], "time")
        if not (t_start <= t <= t_end):
            raise InputError(mfile, f"{where}.time", f"{t:.3f} s lies outside the data "
                             f"[{t_start:.3f}, {t_end:.3f}] s")
        events.append(Event(e["name"], e["parachute"], stage, t, si_value(e["sigma"], "time")))
    _check_events(mfile, events, by_name)

    return FlightTest(
        name=manifest["name"], path=folder, vehicle=vehicle, parachutes=tuple(parachutes),
        events=tuple(events), sensors=tuple(sensors),
        atmosphere=load_atmosphere(mfile, folder, manifest["atmosphere"]),
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
    edges = tuple(float(e) if isinstance(e, int | float) else si_value(e, "length") for e in given)
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
    changes = tuple((si_value(c["time"], "time"),
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
            sigma[c] = si_value(q, dim)
    return sigma


# The columns of a campaign's parameter table (`campaign.parameter_table`; the canopies'
# covariates follow them), and one a population derives from them: no covariate is named
# as one.
TABLE_COLUMNS = ("test", "parameter", "name", "parachute", "type", "stage", "forebody",
                 "cluster_size", "line_length", "position", "value", "std", "unit")
RESERVED_COLUMNS = (*TABLE_COLUMNS, "line_length_ratio")


def canopy_covariates(manifest: dict[str, Any], file: str = MANIFEST
                      ) -> dict[str, dict[str, str | float]]:
    """Per canopy name, what a campaign's population may be regressed on or grouped by
    beyond the canopy's type, line length and vehicle: its `position` in the cluster (its
    name where the manifest gives none), the test's `covariates` and the canopy's own.
    None of it enters the model.  InputError where a covariate is named as a column of the
    parameter table or given at both the test's and the canopy's level."""
    shared = dict(manifest.get("covariates", {}))
    clash = [n for n in shared if n in RESERVED_COLUMNS]
    if clash:
        raise InputError(file, f"covariates.{clash[0]}", "a covariate name other than the "
                         f"parameter table's columns ({', '.join(RESERVED_COLUMNS)})")
    out = {}
    for i, chute in enumerate(manifest["parachutes"]):
        own = dict(chute.get("covariates", {}))
        for name in own:
            if name in RESERVED_COLUMNS or name in shared:
                raise InputError(file, f"parachutes[{i}].covariates.{name}",
                                 "a covariate name other than the parameter table's columns "
                                 "and the test's covariates")
        out[chute["name"]] = {"position": str(chute.get("position", chute["name"])),
                              **shared, **own}
    return out

