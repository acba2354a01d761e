"""The rocketry-log formats `cpas-ocp import` reads, each into a `flight_record.FlightRecord`.

``altus``: an Altus Metrum AltOS CSV export (`altus_metrum`); ``cats``: a CATS
Configurator flight-log export (`cats_vega`); any other CSV log through a
column map (`column_map`).
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import Any

from cpas_ocp.errors import InputError
from cpas_ocp.io.altus_metrum import read_altus_log
from cpas_ocp.io.cats_vega import read_cats_log
from cpas_ocp.io.column_map import check_column_map, load_column_map, read_mapped_log
from cpas_ocp.io.flight_record import FlightRecord

FORMATS: dict[str, Callable[[Path], FlightRecord]] = {
    "altus": lambda path: read_altus_log(path).record(),
    "cats": read_cats_log,
}


def read_flight_log(path: str | Path, log_format: str | None = None,
                    column_map: str | Path | dict[str, Any] | None = None,
                    map_source: str | None = None) -> FlightRecord:
    """The cleaned log of `path`, read as the built-in `log_format` or through the column
    map `column_map` (exactly one of the two): a map file, or a map already read (a card's
    inline map), which errors name as `map_source`."""
    path = Path(path)
    if (log_format is None) == (column_map is None):
        raise InputError("(command line)", "--format/--columns", "one of the two: a built-in "
                         f"format ({', '.join(FORMATS)}) or a column map (JSON)")
    if isinstance(column_map, dict):
        source = map_source or "(column map)"
        return read_mapped_log(path, check_column_map(column_map, source), source)
    if column_map is not None:
        return read_mapped_log(path, load_column_map(column_map), str(column_map))
    if log_format not in FORMATS:
        raise InputError("(command line)", "--format", f"one of {', '.join(FORMATS)} (or "
                         f"--columns MAP.json for any other log); got {log_format!r}")
    if not path.exists():
        raise InputError(str(path), "(file)", f"an existing {log_format} flight log")
    return FORMATS[log_format](path)
