"""Reader of CATS flight-computer logs (CATS Vega) as the CATS Configurator exports them.

The layout is the one of the CATS Configurator's flight-log export
(catsystems/cats-configurator, ``src/modules/flightlog.js``: "export to
CSVs", and the record fields of ``src/modules/logparser.js``): a folder
(``flight-log-export``) with one CSV per record type, each with a header row
of the record's fields, and "No data recorded" for a type without records.
Used here:

* ``imu.csv``: ``ts`` (s from lift-off), ``id`` (IMU0, IMU1, ...), ``Ax``,
  ``Ay``, ``Az`` (m/s^2, the specific force: +1 g on the up axis at rest),
  ``Gx``... (deg/s, not used);
* ``baro.csv``: ``ts``, ``id`` (BARO0, ...), ``T`` (deg C), ``P`` (Pa);
* ``flightStates.csv``: ``ts``, ``state``: the firmware's flight_fsm_e
  (cats-embedded), 3 THRUSTING, 4 COASTING, 5 DROGUE, 6 MAIN, 7 TOUCHDOWN,
  read as boost, coast, drogue, main, landed; an export without it (or with
  no state in it) has its events detected from the data, and the record's
  notes say so;
* ``gnssInfo.csv`` (optional): ``ts``, ``latitude``, ``longitude`` (deg),
  ``satellites``.

The board carries several IMUs and barometers sampled together: the readings
of one time stamp are averaged over the sensors (median).  The board's
mounting decides which accelerometer axis is the rocket's: it is found from
the boost (`flight_record.axial_from_axes`, ``"auto"``) unless given.  Time
stamps in milliseconds (the raw log's) are recognised by their 1 ms or
larger steps and converted.  The argument may be the folder or any of its
CSV files.
"""

from __future__ import annotations

from pathlib import Path

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
    read_table,
    samples_frame,
    time_ordered,
)
from cpas_ocp.physics.units import G0

STATES = {3: "boost", 4: "coast", 5: "drogue", 6: "main", 7: "landed"}
EMPTY = "No data recorded"


def _required(folder: Path, name: str, columns: tuple[str, ...]) -> pd.DataFrame:
    """`_section`, which the log must have."""
    section = _section(folder, name, columns)
    if section is None:
        raise InputError(str(folder / name), "(file)", f"the CATS export's {name} with "
                         f"records (columns {', '.join(columns)})")
    return section


def _section(folder: Path, name: str, columns: tuple[str, ...]) -> pd.DataFrame | None:
    """The numeric columns of one exported CSV, or None where it is absent or empty."""
    path = folder / name
    if not path.is_file() or path.read_text(errors="replace").strip() == EMPTY:
        return None
    table = read_table(path, f"CATS {name}", ",")
    out = {}
    for column in columns:
        if column not in table.columns:
            raise InputError(str(path), column, f"a column named {column!r} (CATS export "
                             f"{name}: {', '.join(columns)})")
        out[column] = numeric(table, path, column, column)
    return pd.DataFrame(out)


def _per_stamp(frame: pd.DataFrame) -> pd.DataFrame:
    """One row per time stamp: the median over the sensors of that stamp."""
    return frame.groupby("ts", sort=True).median().reset_index()


def read_cats_log(path: str | Path, axis: str = "auto") -> FlightRecord:
    """Read a CATS Configurator export (see the module docstring) into the common cleaned
    log; `axis` is the accelerometer's axial axis with its sign (``"+z"``...) or
    ``"auto"``."""
    path = Path(path)
    folder = path if path.is_dir() else path.parent
    imu = _required(folder, "imu.csv", ("ts", "Ax", "Ay", "Az"))
    baro = _required(folder, "baro.csv", ("ts", "P"))
    positive(baro["P"].to_numpy(float), folder / "baro.csv", "P", "pressure (Pa)")
    fsm = _section(folder, "flightStates.csv", ("ts", "state"))
    gnss = _section(folder, "gnssInfo.csv", ("ts", "latitude", "longitude", "satellites"))
    stamps = np.diff(np.unique(imu["ts"].dropna().to_numpy()))
    scale = 1e-3 if stamps.size and float(np.median(stamps)) >= 1.0 else 1.0
    imu, baro = _per_stamp(imu.dropna()), _per_stamp(baro.dropna())
    imu = imu.rename(columns={"Ax": "x", "Ay": "y", "Az": "z"})
    acceleration, used = axial_from_axes(str(folder / "imu.csv"), imu[["x", "y", "z"]], axis,
                                         1.0, "Ax/Ay/Az")
    merged = pd.merge(pd.DataFrame({"ts": imu["ts"], "acceleration": acceleration}),
                      baro[["ts", "P"]], on="ts", how="outer").sort_values("ts")
    frame, _, repeated = time_ordered(pd.DataFrame({
        "time": merged["ts"].to_numpy() * scale, "pressure": merged["P"].to_numpy(),
        "acceleration": merged["acceleration"].to_numpy()}))
    samples = samples_frame(frame["time"].to_numpy(), frame["pressure"].to_numpy(),
                            frame["acceleration"].to_numpy())
    states: dict[str, float] = {}
    if fsm is not None:
        for t, code in fsm.dropna().sort_values("ts").itertuples(index=False):
            if code == int(code) and int(code) in STATES:  # other values are no state
                states.setdefault(STATES[int(code)], float(t) * scale)
    fixes = pd.DataFrame(columns=["time", "latitude", "longitude"])
    dropped = {"repeated_time_stamps": repeated}
    if gnss is not None:
        ok = gnss["satellites"] >= MIN_SATELLITES
        g = pd.DataFrame({"time": gnss["ts"] * scale, "latitude": gnss["latitude"],
                          "longitude": gnss["longitude"]})[ok]
        fixes, repeats = new_fixes(g)
        dropped["gnss_rows_without_a_new_fix"] = repeats + int((~ok).sum())
    channels = {"time": Channel("time stamps 'ts'", "ms" if scale < 1.0 else "s",
                                {"s": 1.0, "ms": 1e-3}),
                "pressure": Channel("baro.csv column 'P'", "Pa", {"Pa": 1.0}),
                "acceleration": Channel("imu.csv columns 'Ax/Ay/Az'", "m/s^2",
                                        {"m/s^2": 1.0}, G0)}
    notes = [f"axial accelerometer axis: {used}"]
    if not states:
        held = (folder / "flightStates.csv").is_file()
        notes.append(f"the export {'records no flight states' if held else 'has no'} "
                     f"{'in ' if held else ''}flightStates.csv, so the flight events are "
                     "detected from the data")
    return FlightRecord(folder, "CATS flight computer", samples, fixes, states, dropped,
                        tuple(notes), channels)
