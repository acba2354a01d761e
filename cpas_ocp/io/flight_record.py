"""The cleaned log every rocketry-log reader produces, and what readers share.

A reader (`altus_metrum`, `cats_vega`, `column_map`) turns one flight
computer's file into a `FlightRecord`; `flight_log.import_flight` turns a
record and a flight card into a test folder and reads nothing else.

The record holds, on one time base (s):

* ``samples``: ``time``, ``pressure`` (Pa), ``altitude`` (m, the pressure
  altitude: the standard-atmosphere altitude of the measured pressure) and
  ``acceleration`` (m/s^2, along the vehicle axis, nose positive, with 1 g
  subtracted: 0 at rest on the pad, -9.8 in free fall), NaN where a row has
  no reading of that sensor (barometer and accelerometer may tick apart);
* ``gnss``: ``time``, ``latitude``, ``longitude`` (deg) and, where the
  receiver gives them, ``gps_altitude`` (m above mean sea level) and the
  velocities ``v_east``, ``v_north``, ``v_up`` (m/s), one row per new fix;
  `enu_about` places the fixes east/north/up about the pad;
* ``states``: the first time of each flight state the computer logged
  (boost, coast, drogue, main, landed), empty where it logged none;
* ``channels``: which column (and unit) each series came from, named in errors;
* ``recorder``: what the log says made it; ``dropped``: what the reader left
  out and why (rows counted per reason); ``notes``: anything else to report.
"""

from __future__ import annotations

import csv
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pandas as pd

from cpas_ocp.errors import InputError
from cpas_ocp.io.json_files import MAX_MAGNITUDE
from cpas_ocp.physics.atmosphere import StandardAtmosphere, pressure_altitude
from cpas_ocp.physics.units import G0

SAMPLE_COLUMNS = ("time", "pressure", "altitude", "acceleration")
GNSS_COLUMNS = ("time", "latitude", "longitude", "gps_altitude")
MIN_SATELLITES = 4  # a GNSS fix needs four satellites for a position with an altitude
EARTH_RADIUS_M = 6371008.8  # mean Earth radius (m): east/north over a few km to < 0.5 %
BOOST_AXIS_G = 2.0  # an axis counts as boosting where it reads this many g above rest
BOOST_RUN = 3  # ... for this many samples in a row


PAD_REST_G = 0.2  # on the pad the specific force's magnitude is 1 g within this (g)


@dataclass(frozen=True)
class Channel:
    """Where one series of a record came from, for the errors that name it: the log's
    column(s) (``"pressure column 'p'"``), the unit it was read in, the units of its kind
    the log might have meant instead (name: SI factor) and the offset (SI) subtracted after
    scaling (one g from an accelerometer that reads +1 g at rest)."""

    column: str
    unit: str
    units: dict[str, float]
    offset: float = 0.0
    altitude: bool = False  # an altimeter's altitude column, not a pressure column

    def reread(self, value: float, unit: str) -> float:
        """`value` (SI, as the record holds it) as it reads had the column been in `unit`."""
        return (value + self.offset) * self.units[unit] / self.units[self.unit] - self.offset

    def hint(self, plausible: Callable[[str], bool]) -> str:
        """``"is the unit hPa, not Pa?"`` for the first other unit (of a different factor)
        for which `plausible(unit)`; a plea to check the column and its unit where none."""
        for unit, factor in self.units.items():
            if factor != self.units[self.unit] and plausible(unit):
                return f"is the unit {unit}, not {self.unit}?"
        return "is it the right column, in the unit declared?"


# What a record's series are named in errors where its reader says nothing more.
DEFAULT_CHANNELS = {"time": Channel("time", "s", {"s": 1.0}),
                    "pressure": Channel("pressure", "Pa", {"Pa": 1.0}),
                    "acceleration": Channel("acceleration", "m/s^2", {"m/s^2": 1.0})}


@dataclass(frozen=True)
class FlightRecord:
    """One cleaned flight log; see the module docstring for the columns and units."""

    path: Path
    recorder: str
    samples: pd.DataFrame
    gnss: pd.DataFrame = field(default_factory=lambda: pd.DataFrame(columns=GNSS_COLUMNS))
    states: dict[str, float] = field(default_factory=dict)
    dropped: dict[str, int] = field(default_factory=dict)
    notes: tuple[str, ...] = ()
    # Where the time, pressure (or altitude) and acceleration came from (`Channel`).
    channels: dict[str, Channel] = field(default_factory=dict)

    def channel(self, name: str) -> Channel:
        """The `Channel` of series `name` (time, pressure, acceleration)."""
        return self.channels.get(name, DEFAULT_CHANNELS[name])

    @property
    def has_gps_altitude(self) -> bool:
        """Whether any fix carries an altitude (m above mean sea level)."""
        return "gps_altitude" in self.gnss.columns and bool(self.gnss["gps_altitude"].notna()
                                                            .any())

    def gps_fixes(self) -> pd.DataFrame:
        """The fixes with an altitude: time (s), latitude, longitude (deg), altitude (m MSL)."""
        if not self.has_gps_altitude:
            return pd.DataFrame(columns=list(GNSS_COLUMNS))
        return self.gnss.dropna(subset=["gps_altitude"])[list(GNSS_COLUMNS)].reset_index(
            drop=True)


def enu_about(gnss: pd.DataFrame, pad: tuple[float, float, float] | None = None
              ) -> pd.DataFrame:
    """East, north (m) of each fix about the pad (the first fix unless `pad` gives latitude,
    longitude (deg) and altitude (m)), and up (m) where the fixes have an altitude: the
    local tangent plane, x = R cos(lat0) dlon, y = R dlat (good to well under a metre over
    the few kilometres a rocket drifts)."""
    if gnss.empty:
        return pd.DataFrame(columns=["time", "east", "north", "up"])
    first = gnss.iloc[0]
    lat0, lon0, h0 = pad if pad is not None else (
        float(first["latitude"]), float(first["longitude"]),
        float(first["gps_altitude"]) if "gps_altitude" in gnss else float("nan"))
    lat, lon = np.radians(gnss["latitude"].to_numpy(float)), gnss["longitude"].to_numpy(float)
    out = pd.DataFrame({"time": gnss["time"].to_numpy(float),
                        "east": EARTH_RADIUS_M * np.cos(np.radians(lat0))
                        * np.radians(lon - lon0),
                        "north": EARTH_RADIUS_M * (lat - np.radians(lat0))})
    if "gps_altitude" in gnss:
        out["up"] = gnss["gps_altitude"].to_numpy(float) - h0
    return out


def samples_frame(time: np.ndarray, pressure: np.ndarray | None,
                  acceleration: np.ndarray | None) -> pd.DataFrame:
    """The record's sample table from time (s), pressure (Pa) and axial acceleration (m/s^2,
    1 g subtracted); either sensor may be absent (None) or NaN where it did not read."""
    n = len(time)
    p = np.full(n, np.nan) if pressure is None else np.asarray(pressure, float)
    return pd.DataFrame({"time": np.asarray(time, float), "pressure": p,
                         "altitude": np.asarray(pressure_altitude(p), float),
                         "acceleration": np.full(n, np.nan) if acceleration is None
                         else np.asarray(acceleration, float)})


def new_fixes(gnss: pd.DataFrame) -> tuple[pd.DataFrame, int]:
    """Rows of `gnss` that hold a new fix (position changed, no NaN latitude/longitude), and
    how many repeats and gaps were left out: loggers repeat the last fix between fixes."""
    ok = gnss[["latitude", "longitude"]].notna().all(axis=1)
    g = gnss[ok]
    cols = [c for c in ("latitude", "longitude", "gps_altitude") if c in g.columns]
    new = (g[cols].diff().abs().sum(axis=1) > 0).to_numpy().copy()
    if new.size:
        new[0] = True
    return g[new].reset_index(drop=True), int(len(gnss) - new.sum())


def axial_from_axes(path: str, axes: pd.DataFrame, axis: str, unit_factor: float,
                    field_name: str) -> tuple[np.ndarray, str]:
    """Axial acceleration (m/s^2, 1 g subtracted) from a three-axis accelerometer.

    `axes` holds the readings (one column per axis, in the unit whose SI factor is
    `unit_factor`) of the specific force: +1 g along the up axis at rest.  `axis` is
    ``"+x"``, ``"-y"``, ... (the column name with its sign) or ``"auto"``: the axis
    whose reading changes most from rest in the boost (the largest boost acceleration
    along it), signed so that the boost reads positive.  The axial reading is the signed
    axis less one g.  Returns the readings and the axis used (``"-y"``, ...)."""
    si = axes.to_numpy(float) * unit_factor
    names = list(axes.columns)
    if axis == "auto":
        sign, k = _boost_axis(path, si, field_name)
        chosen = f"{'+-'[sign < 0]}{names[k]}"
    else:
        sign = -1.0 if axis.startswith("-") else 1.0
        name = axis.lstrip("+-")
        if name not in names:
            raise InputError(path, field_name, f"one of {', '.join(names)} with a sign, or "
                             f"'auto'; got {axis!r}")
        k = names.index(name)
        chosen = f"{'+-'[sign < 0]}{name}"
    return sign * si[:, k] - G0, chosen


def _boost_axis(path: str, si: np.ndarray, field_name: str) -> tuple[float, int]:
    """(sign, index) of the axis with the largest boost acceleration: the largest departure
    from its rest reading held for `BOOST_RUN` samples (a rolling minimum, so that one
    glitch does not choose).  The rest is the median over the pad: the log's leading
    samples whose specific force has the magnitude of gravity (within `PAD_REST_G`, until
    `BOOST_RUN` samples in a row depart from it); a log
    that does not start at rest (or has too few such samples) takes the first tenth of the
    log.  (The first tenth alone, on a short log whose pad time is brief, reaches into the
    boost and can turn the sign.)  An axis with no reading there (an export whose cells
    are all blank) has no rest and cannot be the boost's: its median is not taken of
    nothing."""
    magnitude = np.sqrt(np.nansum(si**2, axis=1))
    off = pd.Series(~(np.abs(magnitude - G0) < PAD_REST_G * G0)).astype(float)
    moving = np.flatnonzero(off.rolling(BOOST_RUN).min().to_numpy() == 1.0)
    pad = int(moving[0]) - BOOST_RUN + 1 if moving.size else si.shape[0]
    head = si[:pad] if pad >= 10 else si[: max(10, si.shape[0] // 10)]
    rest = np.array([np.median(col[np.isfinite(col)]) if np.isfinite(col).any() else np.nan
                     for col in head.T])
    dev = pd.DataFrame(si - rest)
    held_up = dev.rolling(BOOST_RUN).min().max().to_numpy()
    held_down = -dev.rolling(BOOST_RUN).max().min().to_numpy()
    best = np.fmax(held_up, held_down)
    if not np.isfinite(best).any() or np.nanmax(best) < BOOST_AXIS_G * G0:
        raise InputError(path, field_name, f"'auto' needs a boost the accelerometer reads "
                         f"({BOOST_AXIS_G:g} g above rest on one axis for {BOOST_RUN} "
                         "samples); give the axis and sign instead")
    k = int(np.nanargmax(best))
    return (1.0 if held_up[k] >= held_down[k] else -1.0), k


def pressure_of_altitude(altitude_m: np.ndarray) -> np.ndarray:
    """Pressure (Pa) whose pressure altitude is `altitude_m` (m): the inverse of
    `pressure_altitude`, for loggers that write the altitude and not the pressure."""
    return np.asarray(StandardAtmosphere().pressure(np.asarray(altitude_m, float)),
                      float).ravel()


def read_table(path: Path, what: str, sep: str | None = None, skip_rows: int = 0
               ) -> pd.DataFrame:
    """A CSV table with a header row (after `skip_rows` lines), every column kept as text
    stripped of padding; `sep` None sniffs the delimiter (comma, semicolon, tab).
    InputError naming the file for a missing, unreadable or empty one; `what` says what
    the file should have been."""
    if not path.is_file():
        raise InputError(str(path), "(file)", f"an existing {what}")
    try:
        table = pd.read_csv(path, sep=sep, engine="python", skiprows=skip_rows, dtype=str,
                            skipinitialspace=True, encoding="utf-8-sig")
    except (pd.errors.ParserError, pd.errors.EmptyDataError, UnicodeDecodeError,
            csv.Error) as exc:
        raise InputError(str(path), "(csv)", f"a {what} with a header row ({exc})") from None
    table.columns = [str(c).strip() for c in table.columns]
    if table.empty:
        raise InputError(str(path), "(rows)", f"a {what} with data rows; it has none")
    return table


def numeric(table: pd.DataFrame, path: Path, column: str, field_name: str,
            header_line: int = 1) -> np.ndarray:
    """Column `column` of `table` as numbers (blank or ``nan``: NaN, a reading missing);
    InputError naming the line of the first entry that is neither, or that is infinite or
    beyond `MAX_MAGNITUDE` (no sensor reads 1e308 of anything: a damaged cell), the header
    row being line `header_line` of the file."""
    text = table[column].astype("string").str.strip()
    values = pd.to_numeric(text, errors="coerce").astype(float)
    bad = values.isna() & text.notna() & (text != "") & (text.str.lower() != "nan")
    wild = values.notna() & ~(values.abs() <= MAX_MAGNITUDE)
    for rows, what in ((bad, "a number"), (wild, f"a finite number of magnitude at most "
                                                 f"{MAX_MAGNITUDE:g}")):
        if rows.any():
            row = int(np.flatnonzero(rows.to_numpy())[0])
            raise InputError(str(path), f"line {row + header_line + 1}, {column}",
                             f"{what} ({field_name}); got {text.iloc[row]!r}")
    return values.to_numpy(float)


def positive(values: np.ndarray, path: Path, column: str, field_name: str,
             header_line: int = 1) -> np.ndarray:
    """`values` (column `column` of the table read from `path`, NaN where blank) unchanged
    where every reading is above zero; InputError naming the line of the first that is not
    (a pressure of zero or below has no pressure altitude)."""
    bad = np.flatnonzero(~np.isnan(values) & (values <= 0.0))
    if bad.size:
        raise InputError(str(path), f"line {int(bad[0]) + header_line + 1}, {column}",
                         f"a value above zero ({field_name}); got {values[bad[0]]:g}")
    return values


def time_ordered(frame: pd.DataFrame) -> tuple[pd.DataFrame, int, int]:
    """`frame` without rows lacking a time, sorted by time, a repeated time stamp keeping
    its first row; with the counts of rows without a time and of repeated stamps."""
    no_time = frame["time"].isna()
    ordered = frame[~no_time].sort_values("time", kind="stable")
    repeated = ordered["time"].duplicated(keep="first")
    return (ordered[~repeated].reset_index(drop=True), int(no_time.sum()),
            int(repeated.sum()))
