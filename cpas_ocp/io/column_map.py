"""Reader of any rocketry flight log (CSV) through a column map (JSON).

The map (`data_schemas/column_map.schema.json`) names the log's columns:

* ``time`` (s or ms);
* ``pressure`` (Pa, hPa, mbar, kPa) or ``altitude`` (m, ft: the altimeter's
  pressure altitude, plus an ``offset`` where it logs height above the pad);
* ``acceleration``: one axial ``column`` (``sign`` -1 where the boost reads
  negative; ``gravity`` ``included``, the default, where it reads +1 g at rest
  on the pad, ``subtracted`` where it reads 0), or three ``axes`` with the
  axial ``axis`` and its sign (``"-y"``) or ``"auto"``
  (`flight_record.axial_from_axes`); in m/s^2, g or ft/s^2;
* ``gnss``: ``latitude``, ``longitude`` (deg) and optionally ``altitude``
  (m, ft above mean sea level), ``velocity`` east/north/up and
  ``satellites`` (fixes with fewer than four are left out);
* ``state``: a flight-state column, its values mapped by ``names`` to
  boost, coast, drogue, main, landed (without ``names``, values that are those
  names, in any case); other values are not states.

Each block reads its columns against the main ``time`` column, or against
its own: a block may name a ``time`` column (with its unit and an ``offset``
in s onto the main time base: a 400 Hz accelerometer logged beside a 20 Hz
altimeter, each with its own time column) and a ``file`` (a second CSV beside
the log: GNSS fixes written apart).  The sensors' samples are merged on time,
NaN where a sensor did not read.

Rows are sorted by time and a repeated time stamp keeps its first row (a
repeated sample is a repeated stamp, not equal readings); GNSS rows that
repeat the last fix, or have none (blank, or 0/0), are not fixes.  Every
problem is an InputError naming the map or the log, the field or line, and
what was expected.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from cpas_ocp.errors import InputError
from cpas_ocp.io.flight_record import (
    MIN_SATELLITES,
    Channel,
    FlightRecord,
    axial_from_axes,
    new_fixes,
    numeric,
    positive,
    pressure_of_altitude,
    read_table,
    samples_frame,
    time_ordered,
)
from cpas_ocp.io.json_files import read_json, validate_block
from cpas_ocp.physics.units import FACTORS, G0

# The flight states a state column may give (the schema's `names` targets).
FLIGHT_STATES = ("boost", "coast", "drogue", "main", "landed")
PRESSURE_UNITS = {**FACTORS["pressure"], "mbar": 100.0}


def load_column_map(path: str | Path) -> dict[str, Any]:
    """The column map in `path`, validated against its schema (InputError on the first
    field that breaks it)."""
    path = Path(path)
    return check_column_map(read_json(path, "an existing column-map JSON file"), str(path))


def check_column_map(raw: dict[str, Any], source: str) -> dict[str, Any]:
    """`raw` as a column map, validated against its schema and the rules the schema cannot
    state; InputError naming `source` and the field."""
    validate_block(raw, "column_map.schema.json", source)
    if ("pressure" in raw) == ("altitude" in raw):
        raise InputError(source, "pressure/altitude", "exactly one of the two: the "
                         "barometer's pressure column, or the altimeter's altitude column")
    accel = raw.get("acceleration")
    if accel is not None and ("column" in accel) == ("axes" in accel):
        raise InputError(source, "acceleration", "exactly one of 'column' (the axial "
                         "reading) or 'axes' with 'axis' (a two- or three-axis accelerometer)")
    return raw


@dataclass
class _Source:
    """One time base of the log: a CSV table (the log, or a file beside it) and the time
    column a block reads its columns against, in s on the main time base."""

    path: Path
    table: pd.DataFrame
    header_line: int
    time: np.ndarray


class _Sources:
    """The tables a column map reads, each file read once, and the time base of each block:
    the main ``time`` unless the block names its own ``time`` column or ``file``."""

    def __init__(self, log: Path, column_map: dict[str, Any], map_source: str) -> None:
        self.log, self.map, self.map_source = log, column_map, map_source
        self._tables: dict[Path, pd.DataFrame] = {}

    def table(self, path: Path) -> pd.DataFrame:
        if path not in self._tables:
            self._tables[path] = read_table(path, "flight-log CSV", self.map.get("delimiter"),
                                            self.map.get("skip_rows", 0))
        return self._tables[path]

    def column(self, source: _Source, name: str, field_name: str) -> np.ndarray:
        """Column `name` of the source's table as numbers; InputError naming the map's
        field where the table has no such column."""
        if name not in source.table.columns:
            raise InputError(self.map_source, field_name, f"a column of {source.path} (its "
                             f"columns: {', '.join(source.table.columns)}); got {name!r}")
        return numeric(source.table, source.path, name, field_name, source.header_line)

    def of(self, block: str) -> _Source:
        """The source of map block `block` (``"time"`` for the main time base)."""
        spec = self.map.get(block, {})
        main = self.map["time"]
        path = self.log if "file" not in spec else self.log.parent / spec["file"]
        if "file" in spec and not path.is_file():
            raise InputError(self.map_source, f"{block}.file", f"a CSV file beside the log "
                             f"(relative to {self.log.parent}); {path} does not exist")
        time = spec.get("time", main) if block != "time" else main
        field = f"{block}.time.column" if "time" in spec and block != "time" else "time.column"
        source = _Source(path, self.table(path), self.map.get("skip_rows", 0) + 1,
                         np.empty(0))
        unit = time.get("unit", main["unit"])
        source.time = (self.column(source, time["column"], field) * FACTORS["time"][unit]
                       + time.get("offset", 0.0))
        return source


def read_mapped_log(path: str | Path, column_map: dict[str, Any], map_source: str
                    ) -> FlightRecord:
    """Read the CSV log `path` (and the files beside it that the map names) through
    `column_map` (already validated; `map_source` names it in errors) into the common
    cleaned log: every sensor on its own time base, merged into one sample table."""
    path = Path(path)
    sources = _Sources(path, column_map, map_source)
    dropped = {"rows_without_time": 0, "repeated_time_stamps": 0}

    def ordered(frame: pd.DataFrame) -> pd.DataFrame:
        # A row with neither a time nor a reading is the blank tail of a shorter column.
        blank = frame["time"].isna() & frame.drop(columns="time").isna().all(axis=1)
        frame, no_time, repeated = time_ordered(frame[~blank])
        dropped["rows_without_time"] += no_time
        dropped["repeated_time_stamps"] += repeated
        return frame

    parts = []
    if "pressure" in column_map:
        spec, src = column_map["pressure"], sources.of("pressure")
        p = positive(sources.column(src, spec["column"], "pressure.column"), src.path,
                     spec["column"], "pressure.column", src.header_line)
        parts.append(ordered(pd.DataFrame({"time": src.time,
                                           "pressure": p * PRESSURE_UNITS[spec["unit"]]})))
    else:
        spec, src = column_map["altitude"], sources.of("altitude")
        h = (sources.column(src, spec["column"], "altitude.column") + spec.get("offset", 0.0)) \
            * FACTORS["length"][spec["unit"]]
        parts.append(ordered(pd.DataFrame({
            "time": src.time,
            "pressure": np.where(np.isnan(h), np.nan, pressure_of_altitude(np.nan_to_num(h)))})))
    axis_used = None
    if "acceleration" in column_map:
        src = sources.of("acceleration")
        a, axis_used = _acceleration(src, column_map["acceleration"], sources, map_source)
        parts.append(ordered(pd.DataFrame({"time": src.time, "acceleration": a})))
    merged = parts[0]
    for part in parts[1:]:
        merged = pd.merge(merged, part, on="time", how="outer", sort=True)
    if "acceleration" not in merged:
        merged["acceleration"] = np.nan
    read = merged[["pressure", "acceleration"]].notna().any(axis=1).to_numpy()
    if read.sum() < 2:
        raise InputError(str(path), "time", "numeric sample times in at least two rows")
    merged = merged[read]
    samples = samples_frame(merged["time"].to_numpy(), merged["pressure"].to_numpy(),
                            merged["acceleration"].to_numpy())
    gnss = pd.DataFrame(columns=["time", "latitude", "longitude"])
    if "gnss" in column_map:
        src = sources.of("gnss")
        g = ordered(pd.DataFrame({"time": src.time, **_gnss(column_map["gnss"], src, sources)}))
        none = (g["latitude"] == 0.0) & (g["longitude"] == 0.0)
        few = (g.pop("satellites") < MIN_SATELLITES if "satellites" in g
               else pd.Series(False, index=g.index))
        gnss, repeats = new_fixes(g[~none & ~few])
        dropped["gnss_rows_without_a_new_fix"] = repeats + int(none.sum())
        if few.any():
            dropped["gnss_fixes_with_too_few_satellites"] = int((few & ~none).sum())
    states: dict[str, float] = {}
    if "state" in column_map:
        spec, src = column_map["state"], sources.of("state")
        if spec["column"] not in src.table.columns:
            sources.column(src, spec["column"], "state.column")
        raw = src.table[spec["column"]].astype("string").str.strip().to_numpy()
        frame = ordered(pd.DataFrame({"time": src.time, "state": raw}))
        names = spec.get("names")
        for t, value in zip(frame["time"], frame["state"], strict=True):
            if pd.isna(value) or value == "":
                continue
            state = names.get(str(value)) if names is not None else str(value).lower()
            if state in FLIGHT_STATES:
                states.setdefault(state, float(t))
        if not states:  # a state block that gives none is a mistake, never ignored
            seen = sorted({str(v) for v in frame["state"] if not pd.isna(v) and v != ""})
            raise InputError(map_source, "state.names" if names is not None else
                             "state.column", "values that name flight states ("
                             + ", ".join(sorted(FLIGHT_STATES)) + ") or a 'names' map to them; "
                             f"{src.path.name}'s column {spec['column']!r} holds "
                             + (", ".join(repr(v) for v in seen[:8]) or "no value")
                             + (" ..." if len(seen) > 8 else ""))
    notes = () if axis_used is None else (f"axial accelerometer axis: {axis_used}",)
    return FlightRecord(path, column_map.get("recorder", "flight computer"), samples, gnss,
                        states, dropped, notes, mapped_channels(column_map))


def mapped_channels(column_map: dict[str, Any]) -> dict[str, Channel]:
    """The record's channels (`flight_record.Channel`) as the map declares them: each
    series' column and unit, and the other units of its kind."""
    time = column_map["time"]
    baro = "pressure" if "pressure" in column_map else "altitude"
    spec = column_map[baro]
    out = {"time": Channel(f"time column {time['column']!r}", time["unit"], FACTORS["time"]),
           "pressure": Channel(f"{baro} column {spec['column']!r}", spec["unit"],
                               PRESSURE_UNITS if baro == "pressure" else FACTORS["length"],
                               altitude=baro == "altitude")}
    accel = column_map.get("acceleration")
    if accel is not None:
        columns = accel.get("column") or "/".join(accel["axes"].values())
        included = "axes" in accel or accel.get("gravity", "included") == "included"
        out["acceleration"] = Channel(
            f"acceleration column{'s' if 'axes' in accel else ''} {columns!r}", accel["unit"],
            FACTORS["acceleration"], G0 if included else 0.0)
    return out


def _acceleration(src: _Source, spec: dict[str, Any], sources: _Sources, map_source: str
                  ) -> tuple[np.ndarray, str | None]:
    """The axial reading (m/s^2, 1 g subtracted) and, for three axes, the axis used."""
    factor = FACTORS["acceleration"][spec["unit"]]
    if "column" in spec:
        a = sources.column(src, spec["column"], "acceleration.column") * factor \
            * spec.get("sign", 1)
        return (a - G0 if spec.get("gravity", "included") == "included" else a), None
    axes = pd.DataFrame({name: sources.column(src, col, f"acceleration.axes.{name}")
                         for name, col in spec["axes"].items()})
    axis = spec["axis"]
    if axis != "auto" and axis.lstrip("+-") not in axes.columns:
        raise InputError(map_source, "acceleration.axis", f"one of the axes given "
                         f"({', '.join(axes.columns)}) with its sign; got {axis!r}")
    read = axes.notna().all(axis=1).to_numpy()
    out = np.full(len(axes), np.nan)
    values, used = axial_from_axes(map_source, axes[read], axis, factor, "acceleration.axis")
    out[read] = values
    return out, used


def _gnss(spec: dict[str, Any], src: _Source, sources: _Sources) -> dict[str, np.ndarray]:
    """Latitude, longitude (deg), altitude (m), velocities (m/s) and satellite count of the
    map's GNSS."""
    out = {"latitude": sources.column(src, spec["latitude"], "gnss.latitude"),
           "longitude": sources.column(src, spec["longitude"], "gnss.longitude")}
    if "altitude" in spec:
        out["gps_altitude"] = sources.column(src, spec["altitude"]["column"],
                                             "gnss.altitude.column") \
            * FACTORS["length"][spec["altitude"]["unit"]]
    velocity = spec.get("velocity", {})
    for axis in ("east", "north", "up"):
        if axis in velocity:
            out[f"v_{axis}"] = sources.column(src, velocity[axis], f"gnss.velocity.{axis}") \
                * FACTORS["velocity"][velocity["unit"]]
    if "satellites" in spec:
        out["satellites"] = sources.column(src, spec["satellites"], "gnss.satellites")
    return out
