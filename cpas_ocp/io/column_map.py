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
  (m, ft above mean sea level) and ``velocity`` east/north/up;
* ``state``: a flight-state column, its values mapped by ``names`` to
  boost, coast, drogue, main, landed (without ``names``, values that are those
  names, in any case); other values are not states.

Rows are sorted by time and a repeated time stamp keeps its first row (a
repeated sample is a repeated stamp, not equal readings); GNSS rows that
repeat the last fix, or have none (blank, or 0/0), are not fixes.  Every
problem is an InputError naming the map or the log, the field or line, and
what was expected.
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from cpas_ocp.errors import InputError
from cpas_ocp.io.flight_record import (
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
from cpas_ocp.io.flight_test import read_json, validate_block
from cpas_ocp.physics.units import FACTORS, G0

# The flight states a state column may give (the schema's `names` targets).
FLIGHT_STATES = ("boost", "coast", "drogue", "main", "landed")
PRESSURE_UNITS = {**FACTORS["pressure"], "mbar": 100.0}
Column = Callable[[str, str], np.ndarray]  # a log column by name, its map field for errors


def load_column_map(path: str | Path) -> dict[str, Any]:
    """The column map in `path`, validated against its schema (InputError on the first
    field that breaks it)."""
    path = Path(path)
    raw = read_json(path, "an existing column-map JSON file")
    validate_block(raw, "column_map.schema.json", str(path))
    if ("pressure" in raw) == ("altitude" in raw):
        raise InputError(str(path), "pressure/altitude", "exactly one of the two: the "
                         "barometer's pressure column, or the altimeter's altitude column")
    accel = raw.get("acceleration")
    if accel is not None and ("column" in accel) == ("axes" in accel):
        raise InputError(str(path), "acceleration", "exactly one of 'column' (the axial "
                         "reading) or 'axes' with 'axis' (a two- or three-axis accelerometer)")
    return raw


def read_mapped_log(path: str | Path, column_map: dict[str, Any], map_source: str
                    ) -> FlightRecord:
    """Read the CSV log `path` through `column_map` (already validated; `map_source` names
    it in errors) into the common cleaned log."""
    path = Path(path)
    table = read_table(path, "flight-log CSV", column_map.get("delimiter"),
                       column_map.get("skip_rows", 0))

    def column(name: str, field_name: str) -> np.ndarray:
        if name not in table.columns:
            raise InputError(map_source, field_name, f"a column of {path} (its columns: "
                             f"{', '.join(table.columns)}); got {name!r}")
        return numeric(table, path, name, field_name, column_map.get("skip_rows", 0) + 1)

    spec = column_map["time"]
    frame = pd.DataFrame({"time": column(spec["column"], "time.column")
                          * FACTORS["time"][spec["unit"]]})
    if "pressure" in column_map:
        spec = column_map["pressure"]
        frame["pressure"] = positive(column(spec["column"], "pressure.column"), path,
                                     spec["column"], "pressure.column",
                                     column_map.get("skip_rows", 0) + 1) \
            * PRESSURE_UNITS[spec["unit"]]
    else:
        spec = column_map["altitude"]
        h = (column(spec["column"], "altitude.column") + spec.get("offset", 0.0)) \
            * FACTORS["length"][spec["unit"]]
        frame["pressure"] = np.where(np.isnan(h), np.nan, pressure_of_altitude(np.nan_to_num(h)))
    axis_used = None
    if "acceleration" in column_map:
        frame["acceleration"], axis_used = _acceleration(table, column_map["acceleration"],
                                                         column, map_source)
    gnss_cols = _gnss(column_map.get("gnss"), column)
    for name, values in gnss_cols.items():
        frame[name] = values
    states_raw = None
    if "state" in column_map:
        name = column_map["state"]["column"]
        if name not in table.columns:
            column(name, "state.column")
        states_raw = table[name].astype("string").str.strip()
        frame["state"] = states_raw.to_numpy()
    frame, no_time, repeated = time_ordered(frame)
    if len(frame) < 2:
        raise InputError(str(path), "time", "numeric sample times in at least two rows")
    sensors = frame[["pressure", "acceleration"] if "acceleration" in frame else ["pressure"]]
    read = sensors.notna().any(axis=1).to_numpy()
    samples = samples_frame(frame["time"].to_numpy()[read], frame["pressure"].to_numpy()[read],
                            frame["acceleration"].to_numpy()[read]
                            if "acceleration" in frame else None)
    dropped = {"rows_without_time": no_time, "repeated_time_stamps": repeated}
    gnss = pd.DataFrame(columns=["time", "latitude", "longitude"])
    if gnss_cols:
        g = frame[["time", *gnss_cols]]
        none = (g["latitude"] == 0.0) & (g["longitude"] == 0.0)
        gnss, repeats = new_fixes(g[~none])
        dropped["gnss_rows_without_a_new_fix"] = repeats + int(none.sum())
    states: dict[str, float] = {}
    if states_raw is not None:
        names = column_map["state"].get("names")
        for t, value in zip(frame["time"], frame["state"], strict=True):
            if pd.isna(value) or value == "":
                continue
            state = names.get(str(value)) if names is not None else str(value).lower()
            if state in FLIGHT_STATES:
                states.setdefault(state, float(t))
    notes = () if axis_used is None else (f"axial accelerometer axis: {axis_used}",)
    return FlightRecord(path, column_map.get("recorder", "flight computer"), samples, gnss,
                        states, dropped, notes)


def _acceleration(table: pd.DataFrame, spec: dict[str, Any], column: Column, map_source: str
                  ) -> tuple[np.ndarray, str | None]:
    """The axial reading (m/s^2, 1 g subtracted) and, for three axes, the axis used."""
    factor = FACTORS["acceleration"][spec["unit"]]
    if "column" in spec:
        a = column(spec["column"], "acceleration.column") * factor * spec.get("sign", 1)
        return (a - G0 if spec.get("gravity", "included") == "included" else a), None
    axes = pd.DataFrame({name: column(col, f"acceleration.axes.{name}")
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


def _gnss(spec: dict[str, Any] | None, column: Column) -> dict[str, np.ndarray]:
    """Latitude, longitude (deg), altitude (m) and velocities (m/s) of the map's GNSS."""
    if spec is None:
        return {}
    out = {"latitude": column(spec["latitude"], "gnss.latitude"),
           "longitude": column(spec["longitude"], "gnss.longitude")}
    if "altitude" in spec:
        out["gps_altitude"] = column(spec["altitude"]["column"], "gnss.altitude.column") \
            * FACTORS["length"][spec["altitude"]["unit"]]
    velocity = spec.get("velocity", {})
    for axis in ("east", "north", "up"):
        if axis in velocity:
            out[f"v_{axis}"] = column(velocity[axis], f"gnss.velocity.{axis}") \
                * FACTORS["velocity"][velocity["unit"]]
    return out
