"""What an import of a flight log records beside the test folder (`import.json`): the
shock-cord snatches left out of the accelerometer, the card's nominal drag areas, and the
import's summary.
"""


from __future__ import annotations

import dataclasses
import json
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from cpas_ocp.io.flight_events import (
    FlightEvent,
)
from cpas_ocp.physics.atmosphere import (
    SiteAtmosphere,
)
from cpas_ocp.physics.units import FACTORS, G0


@dataclass(frozen=True)
class Snatch:
    """A later canopy's opening as the accelerometer read it against the drag ceiling
    (`drag_ceiling`): the ceiling (m/s^2, an axial reading), the samples above it left
    out as the shock cord's snatch, and the largest of them (m/s^2) with its time (s)."""

    ceiling_m_s2: float
    samples_left_out: int
    largest_m_s2: float | None
    at_s: float | None

    def __str__(self) -> str:
        head = f"drag ceiling of the axial reading {self.ceiling_m_s2 / G0:.1f} g"
        if self.largest_m_s2 is None:
            return head + ", no sample above it"
        return (head + f"; {self.samples_left_out} sample(s) above it left out as the shock "
                f"cord's snatch, the largest {self.largest_m_s2 / G0:.1f} g at {self.at_s:.2f} s")


def _import_report(folder: Path | None, key: str) -> Any:
    """Entry `key` of the import report (``import.json``) of the test folder `folder`; None
    for a folder that was not imported, or whose report lacks it or was edited out of
    shape (the reports then only lack what it would have said)."""
    report = None if folder is None else folder / "import.json"
    if report is None or not report.is_file():
        return None
    try:
        return json.loads(report.read_text()).get(key)
    except (ValueError, AttributeError):
        return None


def import_snatches(folder: Path | None) -> dict[str, Snatch]:
    """The snatches an import left out of the test folder `folder` (its ``import.json``);
    empty where it holds none (`_import_report`)."""
    try:
        return {name: Snatch(**fields)
                for name, fields in (_import_report(folder, "snatch") or {}).items()}
    except (TypeError, AttributeError):
        return {}


def import_nominal(folder: Path | None) -> dict[str, dict[str, Any]]:
    """The card's nominal drag areas an import kept in the test folder `folder` (its
    ``import.json``): ``{parameter: {value, unit, source}}``; empty where it holds none, or
    an entry that is not such an area."""
    nominal = _import_report(folder, "nominal")
    if not isinstance(nominal, dict):
        return {}
    return {name: spec for name, spec in nominal.items() if isinstance(spec, dict)
            and isinstance(spec.get("value"), int | float) and spec.get("unit") in FACTORS["area"]}


def nominal_area(spec: dict[str, Any]) -> float:
    """A nominal drag area of `import_nominal` in SI (m^2)."""
    return float(spec["value"]) * FACTORS["area"][spec["unit"]]


def import_deployments(folder: Path | None) -> dict[str, dict[str, Any]]:
    """Per canopy, what the import's deployment forensics found in the log of the test
    folder `folder` (its ``import.json``): ``{canopy: {verdict, sentence, ...}}``; empty
    where it holds none, or an entry without a verdict and a sentence."""
    found = _import_report(folder, "deployments")
    if not isinstance(found, dict):
        return {}
    return {name: entry for name, entry in found.items() if isinstance(entry, dict)
            and isinstance(entry.get("verdict"), str) and isinstance(entry.get("sentence"), str)}


def import_turned_over(folder: Path | None) -> list[tuple[float, float]]:
    """Where the import of the test folder `folder` found the body turned over (its
    ``import.json``'s ``turned_over_s``): (first, last) times (s); empty where it found
    none, or the folder was not imported."""
    found = _import_report(folder, "turned_over_s")
    try:
        return [(float(a), float(b)) for a, b in found]
    except (TypeError, ValueError):
        return []


def import_flight_events(folder: Path | None) -> dict[str, FlightEvent]:
    """The flight events an import found for the test folder `folder` (its ``import.json``:
    apogee, the charges, touchdown, each with its time and sigma in s); empty for a folder
    that was not imported, or whose report lacks them (`_import_report`)."""
    try:
        return {name: FlightEvent(float(e["time_s"]), float(e["sigma_s"]), str(e["source"]))
                for name, e in (_import_report(folder, "flight_events") or {}).items()}
    except (TypeError, KeyError, ValueError, AttributeError):
        return {}


@dataclass(frozen=True)
class ImportSummary:
    """What an import did, for the import report (`import.json`)."""

    recorder: str
    phase: tuple[float, float]
    events: dict[str, float]
    site: SiteAtmosphere
    lapse_fit: tuple[float, float, float] | None
    baro_sigma_m: list[float]
    samples: dict[str, int]
    dropped: dict[str, int]
    accel_sigma: list[float] = field(default_factory=list)  # m/s^2, per segment
    snatches: dict[str, Snatch] = field(default_factory=dict)  # per later canopy
    flight_events: dict[str, FlightEvent] = field(default_factory=dict)  # time, sigma, source
    notes: list[str] = field(default_factory=list)
    nominal: dict[str, dict[str, Any]] = field(default_factory=dict)  # the card's, as given
    # Per canopy: whether it opened, from the log alone (`deployment_forensics`).
    deployments: dict[str, dict[str, Any]] = field(default_factory=dict)
    # The channel that reads the descent (``baro``, or ``gps_altitude`` where the
    # barometer's file stops in the air), and the GNSS altitude's sigma (m) where it does.
    descent_channel: str = "baro"
    gnss_sigma_m: float | None = None
    # Where the axial accelerometer reads the body turned over: (first, last) times (s).
    turned_over: list[tuple[float, float]] = field(default_factory=list)

    def to_dict(self) -> dict[str, Any]:
        return {"recorder": self.recorder, "phase_s": list(self.phase), "events_s": self.events,
                "site": {"elevation_m": self.site.elevation_m,
                         "pressure_pa": self.site.pressure_pa,
                         "temperature_k": self.site.temperature_k,
                         "lapse_rate_k_km": 1e3 * self.site.lapse_rate_k_m},
                "lapse_fit": None if self.lapse_fit is None else
                {"lapse_rate_k_km": 1e3 * self.lapse_fit[0], "gps_offset_m": self.lapse_fit[1],
                 "residual_sigma_m": self.lapse_fit[2]},
                "baro_sigma_m": self.baro_sigma_m, "accel_sigma_m_s2": self.accel_sigma,
                "snatch": {k: dataclasses.asdict(v) for k, v in self.snatches.items()},
                "flight_events": {k: {"time_s": e.time, "sigma_s": e.sigma, "source": e.source}
                                  for k, e in self.flight_events.items()},
                "notes": self.notes, "samples": self.samples, "dropped": self.dropped,
                "nominal": self.nominal, "deployments": self.deployments,
                "descent_channel": self.descent_channel, "gnss_sigma_m": self.gnss_sigma_m,
                "turned_over_s": [list(span) for span in self.turned_over]}
