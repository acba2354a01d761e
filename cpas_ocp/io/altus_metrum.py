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

The reader returns the cleaned table and the flight-state events; `AltusLog.record`
gives the common cleaned log (`flight_record.FlightRecord`) that
`flight_log.import_flight` turns into a test folder.

What made the log is told by the name AltOS gives its exports
(``telemega-serial-6583-flight-0003.csv``: product, serial, flight) and the
``serial`` column; a log renamed or converted says "Altus Metrum" (the IMU
columns tell nothing: a converted log may carry them empty).
"""

from __future__ import annotations

import csv
import re
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pandas as pd

from cpas_ocp.errors import InputError
from cpas_ocp.io.flight_record import MIN_SATELLITES, Channel, FlightRecord, new_fixes
from cpas_ocp.io.json_files import MAX_MAGNITUDE

REQUIRED = ("time", "state_name", "pressure", "altitude", "acceleration")
# Columns a new sensor record changes: the barometer, the accelerometers, the IMU, and the
# flight computer's filter (height, speed), which it steps at every sensor sample.  A row
# whose values in all of them equal the previous row's is another record's (GPS, voltages,
# pyro, state) repeating that sample.  Voltages, GPS and state are left out: those records
# change them.
SENSOR_COLUMNS = ("pressure", "acceleration", "altitude", "height", "speed", "temperature",
                  "accel_x", "accel_y", "accel_z", "gyro_roll", "gyro_pitch", "gyro_yaw",
                  "mag_x", "mag_y", "mag_z", "tilt")
GPS_COLUMNS = ("latitude", "longitude", "gps_altitude", "nsat")
# The columns the record's series come from, in the units AltOS writes.
CHANNELS = {"time": Channel("column 'time'", "s", {"s": 1.0}),
            "pressure": Channel("column 'pressure'", "Pa", {"Pa": 1.0}),
            "acceleration": Channel("column 'acceleration'", "m/s^2", {"m/s^2": 1.0})}
# AltOS writes 2^31 - 1 for a quantity the receiver did not report (e.g. hdop).
MISSING_SENTINEL = 2147483647.0
# AltOS names an export <product>-serial-<serial>-flight-<flight>.csv.
EXPORT_NAME = re.compile(r"^(?P<product>[a-z]+)-serial-(?P<serial>\d+)-flight-(?P<flight>\d+)",
                         re.IGNORECASE)
PRODUCTS = {p.lower(): p for p in ("TeleMega", "TeleMetrum", "EasyMega", "EasyMini",
                                   "TeleMini", "EasyTimer", "EasyMotor", "TeleDongle")}


@dataclass(frozen=True)
class AltusLog:
    """One cleaned log: `data` sorted by strictly increasing time, `events` the first time (s)
    of each flight state, `recorder` the product the export's name gives ('TeleMega', ...)
    or 'Altus Metrum'."""

    path: Path
    recorder: str
    data: pd.DataFrame
    events: dict[str, float]
    duplicate_times: int
    serial: str = ""

    def sensor_samples(self) -> pd.DataFrame:
        """Rows that hold a new sample of the barometer and accelerometer.

        AltOS writes one row per log record; the rows of the other records (GPS,
        companion, pyro) repeat the last sensor sample under their own, later, time
        stamp.  On the TeleMega log of the Prometheus flight about a quarter of the
        descent rows are such copies, 0.01-0.09 s after the sample they repeat: kept,
        they would weigh those samples twice and look like an altimeter lag.  A row
        is a copy when every `SENSOR_COLUMNS` value it has equals the previous row's
        (NaN equal to NaN).  Equal pressure and acceleration alone do not make a
        copy: at 100 Hz in the boost the TeleMetrum of the Prometheus flight reads
        the same pressure (1 Pa steps) and acceleration in 41 consecutive pairs of
        real samples, whose filter speed differs.
        """
        d = self.data
        return d[~self._repeats()].reset_index(drop=True)

    def _repeats(self) -> np.ndarray:
        """Per row: True where it repeats the previous row's sensor record (see
        `sensor_samples`)."""
        d = self.data
        x = d[[c for c in SENSOR_COLUMNS if c in d.columns]]
        same = ((x.diff() == 0) | (x.isna() & x.shift().isna())).all(axis=1).to_numpy().copy()
        same[0] = False
        return same

    @property
    def has_gps(self) -> bool:
        return "gps_altitude" in self.data.columns

    def gps_fixes(self) -> pd.DataFrame:
        """Rows at which the GPS reported a new fix with enough satellites: time (s),
        latitude, longitude (deg) and altitude (m MSL).  Rows that repeat the previous fix
        are dropped."""
        return self._fixes()[0]

    def _fixes(self) -> tuple[pd.DataFrame, int, int]:
        """(new fixes with enough satellites, rows with too few, repeats between fixes)."""
        cols = ["time", "latitude", "longitude", "gps_altitude"]
        if not self.has_gps:
            return pd.DataFrame(columns=cols), 0, 0
        d = self.data
        enough = (d["nsat"].to_numpy(float) >= MIN_SATELLITES)
        fixes, repeats = new_fixes(d.loc[enough, cols])
        return fixes, int((~enough).sum()), repeats

    def record(self) -> FlightRecord:
        """The common cleaned log: the sensor samples, the new GPS fixes with enough
        satellites, the flight states, and what was left out."""
        samples = self.sensor_samples()[["time", "pressure", "altitude", "acceleration"]]
        fixes, few, repeats = self._fixes()
        label = f"{self.recorder} serial {self.serial}" if self.serial else self.recorder
        return FlightRecord(self.path, label, samples, fixes, dict(self.events),
                            {"repeated_time_stamps": self.duplicate_times,
                             "repeated_sensor_rows": int(self._repeats().sum()),
                             "gps_fixes_with_too_few_satellites": few,
                             "gps_repeats_between_fixes": repeats}, channels=CHANNELS)


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
    named = EXPORT_NAME.match(path.name)
    recorder = PRODUCTS.get(named["product"].lower(), "Altus Metrum") if named else "Altus Metrum"
    serials = data["serial"].dropna().unique() if "serial" in data.columns else []
    serial = str(int(serials[0])) if len(serials) == 1 else named["serial"] if named else ""
    return AltusLog(path, recorder, data, events, int(repeated.sum()), serial)
