"""Reader of Altus Metrum flight-computer logs (TeleMega, TeleMetrum CSV exports).

An AltOS CSV export has one header row that starts with ``#``, values padded
with spaces, two columns both named ``altitude`` (the barometric one, then
the GPS one further right), GPS columns that repeat their last fix between
fixes, NaN runs (``speed`` before the filter converges, ``tilt`` without a
gyro), repeated time stamps, rows of other records (GPS, companion, pyro) that
carry the last sensor sample forward under a later time stamp, and sampling
that is fast in boost (100 Hz) and slow in descent (10-16 Hz).  TeleMega logs
add IMU columns (``accel_x`` ..., ``gyro_roll`` ...); TeleMetrum logs do not.

Columns used, in the units AltOS writes:

* ``time`` (s from launch), ``state_name`` (boost, coast, drogue, main, landed);
* ``pressure`` (Pa) and ``altitude`` (m): the pressure altitude, i.e. the
  standard-atmosphere altitude of the measured pressure;
* ``acceleration`` (m/s^2): axial acceleration with 1 g subtracted (0 at
  rest on the pad, -9.8 in free fall);
* the second ``altitude`` (m above mean sea level), ``latitude``,
  ``longitude`` and ``nsat``: GPS.

The reader returns the cleaned table and the flight-state events; turning
them into a test folder is `flight_log.import_flight`.
"""

from __future__ import annotations

import csv
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pandas as pd

from cpas_ocp.errors import InputError
from cpas_ocp.io.flight_test import MAX_MAGNITUDE

REQUIRED = ("time", "state_name", "pressure", "altitude", "acceleration")
# Columns of the sensor record: a row whose values all equal the previous row's repeats it.
SENSOR_COLUMNS = ("pressure", "acceleration")
GPS_COLUMNS = ("latitude", "longitude", "gps_altitude", "nsat")
IMU_COLUMNS = ("accel_x", "accel_y", "accel_z", "gyro_roll", "gyro_pitch", "gyro_yaw")
# AltOS writes 2^31 - 1 for a quantity the receiver did not report (e.g. hdop).
MISSING_SENTINEL = 2147483647.0
MIN_SATELLITES = 4  # a GPS fix needs four satellites for an altitude


@dataclass(frozen=True)
class AltusLog:
    """One cleaned log: `data` sorted by strictly increasing time, `events` the first time (s)
    of each flight state, `recorder` 'TeleMega' (IMU columns present) or 'TeleMetrum'."""

    path: Path
    recorder: str
    data: pd.DataFrame
    events: dict[str, float]
    duplicate_times: int

    def sensor_samples(self) -> pd.DataFrame:
        """Rows that hold a new sample of the barometer and accelerometer.

        AltOS writes one row per log record; the rows of the other records (GPS,
        companion, pyro) repeat the last sensor sample under their own, later, time
        stamp.  On the TeleMega log of the Prometheus flight about a quarter of the
        descent rows are such copies, 0.01-0.09 s after the sample they repeat: kept,
        they would weigh those samples twice and look like an altimeter lag.  A row
        is a copy when pressure (Pa, a resolution of a few centimetres of altitude)
        and axial acceleration both equal the previous row's.
        """
        d = self.data
        same = (d[list(SENSOR_COLUMNS)].diff() == 0).all(axis=1).to_numpy().copy()
        same[0] = False
        return d[~same].reset_index(drop=True)

    @property
    def has_gps(self) -> bool:
        return "gps_altitude" in self.data.columns

    def gps_fixes(self) -> pd.DataFrame:
        """Rows at which the GPS reported a new fix with enough satellites: time (s),
        latitude, longitude (deg) and altitude (m MSL).  Rows that repeat the previous fix
        are dropped."""
        if not self.has_gps:
            return pd.DataFrame(columns=["time", "latitude", "longitude", "gps_altitude"])
        d = self.data
        cols = ["latitude", "longitude", "gps_altitude"]
        new = (d[cols].diff().abs().sum(axis=1) > 0).to_numpy().copy()
        new[0] = True
        ok = new & (d["nsat"].to_numpy() >= MIN_SATELLITES) & d[cols].notna().all(axis=1)
        return d.loc[ok, ["time", *cols]].reset_index(drop=True)


def _header(path: Path) -> list[str]:
    """Column names of the first line without its '#', the second 'altitude' renamed
    'gps_altitude' (and any later repeat suffixed with its position)."""
    try:
        with path.open(newline="", encoding="utf-8-sig") as f:
            first = next(csv.reader(f), None)
    except UnicodeDecodeError as exc:
        raise InputError(str(path), f"byte {exc.start}",
                         "an AltOS CSV export (UTF-8 text; this file is not)") from None
    if not first or not first[0].startswith("#"):
        raise InputError(str(path), "line 1", "an AltOS CSV header row starting with '#'")
    names = [c.strip() for c in first]
    names[0] = names[0].lstrip("#").strip()
    counts: dict[str, int] = {}
    out = []
    for name in names:
        k = counts.get(name, 0)
        counts[name] = k + 1
        out.append(name if k == 0 else "gps_altitude" if name == "altitude" and k == 1
                   else f"{name}_{k + 1}")
    return out


def read_altus_log(path: str | Path) -> AltusLog:
    """Read and clean an AltOS CSV export (see the module docstring for the quirks handled).

    Rows are sorted by time and a repeated time stamp keeps its first row;
    missing-value sentinels become NaN.  InputError names the file and the
    column for a file that is not such a log.
    """
    path = Path(path)
    if not path.is_file():
        raise InputError(str(path), "(file)", "an existing Altus Metrum CSV log")
    names = _header(path)
    try:
        raw = pd.read_csv(path, skiprows=1, header=None, names=names, skipinitialspace=True,
                          low_memory=False, encoding="utf-8-sig")
    except (pd.errors.ParserError, UnicodeDecodeError) as exc:
        raise InputError(str(path), "(csv)", f"comma-separated AltOS rows ({exc})") from None
    for column in REQUIRED:
        if column not in raw.columns:
            raise InputError(str(path), column, f"a column named {column!r} (an AltOS CSV "
                             "export of a TeleMega or TeleMetrum flight)")
    data = raw.copy()
    for column in data.columns:
        if column not in ("state_name", "call"):
            data[column] = pd.to_numeric(data[column], errors="coerce")
    data = data.replace(MISSING_SENTINEL, np.nan)
    states = data["state_name"].astype("string").str.strip()
    empty = (states.fillna("") == "").to_numpy(dtype=bool)
    if empty.any():
        row = int(np.flatnonzero(empty)[0])
        raise InputError(str(path), f"line {row + 2}, state_name",
                         "a flight state in every row (AltOS writes one); this row has none")
    data["state_name"] = states.astype(str)
    numbers = data.drop(columns=["state_name", "call"], errors="ignore")
    wild = ~(numbers.abs() <= MAX_MAGNITUDE) & numbers.notna()
    if wild.any().any():
        row, column = next((r, c) for r, c in zip(*np.nonzero(wild.to_numpy()), strict=True))
        raise InputError(str(path), f"line {row + 2}, {numbers.columns[column]}",
                         f"a finite reading of magnitude at most {MAX_MAGNITUDE:g}; got "
                         f"{numbers.iat[row, column]!r}")
    bad_time = data["time"].isna()
    if bad_time.all() or len(data) < 2:
        raise InputError(str(path), "time", "numeric sample times in at least two rows")
    data = data[~bad_time].sort_values("time", kind="stable")
    repeated = data["time"].duplicated(keep="first")
    data = data[~repeated].reset_index(drop=True)
    events = {}
    for state in data["state_name"].unique():
        events[state] = float(data.loc[data["state_name"] == state, "time"].iloc[0])
    recorder = "TeleMega" if all(c in data.columns for c in IMU_COLUMNS) else "TeleMetrum"
    return AltusLog(path, recorder, data, events, int(repeated.sum()))
