"""A test folder's series files (one CSV per sensor, an atmosphere table) and its quantities
with units, read into SI: the declared columns, finite values, strictly increasing time,
each violation an `InputError` naming the file, the column and the expectation.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from cpas_ocp.errors import InputError
from cpas_ocp.io.json_files import MAX_MAGNITUDE
from cpas_ocp.physics.atmosphere import (
    Atmosphere,
    SiteAtmosphere,
    SoundingAtmosphere,
    StandardAtmosphere,
    TableAtmosphere,
)
from cpas_ocp.physics.units import FACTORS


def si_value(quantity: dict[str, Any], dimension: str) -> float:
    """A manifest quantity ``{"value": v, "unit": u}`` of `dimension` in SI."""
    return float(quantity["value"]) * FACTORS[dimension][quantity["unit"]]


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


def load_atmosphere(mfile: str, folder: Path, spec: dict[str, Any]) -> Atmosphere:
    """The atmosphere block `spec` of manifest `mfile`: the standard atmosphere, a site's
    (elevation, pressure, temperature and lapse rate at the ground), or a table against
    altitude (a sounding) read from its CSV in `folder`, all in SI."""
    if spec["model"] == "standard":
        return StandardAtmosphere()
    if spec["model"] == "site":
        lapse = si_value(spec["lapse_rate"], "lapse_rate") if "lapse_rate" in spec else None
        return SiteAtmosphere(si_value(spec["elevation"], "length"),
                              si_value(spec["pressure"], "pressure"),
                              si_value(spec["temperature"], "temperature"),
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
    base = si_value(spec["surface_pressure"], "pressure") if "surface_pressure" in spec else None
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
