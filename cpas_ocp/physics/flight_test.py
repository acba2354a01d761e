"""The description of one test phase, in SI: the vehicle, its canopies and their stages, the
observed events, the sensors with their series and noise, and the atmosphere.

These are the domain types every layer above reads: the model's effects build
their physics from them, the estimator fits their series, and `io` reads and
validates the files of a test folder into them (`io.flight_test.load_test`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from cpas_ocp.physics.atmosphere import Atmosphere
from cpas_ocp.physics.units import G0

# Channels of each sensor kind and the dimension of each column.
SENSOR_COLUMNS: dict[str, dict[str, str]] = {
    "gps": {"time": "time", "east": "length", "north": "length", "up": "length",
            "v_east": "velocity", "v_north": "velocity", "v_up": "velocity"},
    "imu_load_factor": {"time": "time", "load_factor": "load_factor"},
    "load_cell": {"time": "time", "tension": "force"},
    "baro": {"time": "time", "altitude": "length"},
    "gps_altitude": {"time": "time", "up": "length"},
    "axial_accelerometer": {"time": "time", "acceleration": "acceleration"},
}
# Noise groups of each sensor kind: group -> (dimension, channels it covers).
SIGMA_GROUPS: dict[str, dict[str, tuple[str, tuple[str, ...]]]] = {
    "gps": {"position": ("length", ("east", "north", "up")),
            "velocity": ("velocity", ("v_east", "v_north", "v_up"))},
    "imu_load_factor": {"load_factor": ("load_factor", ("load_factor",))},
    "load_cell": {"tension": ("force", ("tension",))},
    "baro": {"altitude": ("length", ("altitude",))},
    "gps_altitude": {"altitude": ("length", ("up",))},
    "axial_accelerometer": {"acceleration": ("acceleration", ("acceleration",))},
}


@dataclass(frozen=True)
class Vehicle:
    """Test vehicle: suspended mass (kg) without canopies, forebody drag area (m^2)."""

    name: str
    mass: float
    forebody_cds: float


@dataclass(frozen=True)
class Parachute:
    """One canopy: nominal diameter D_o (m), dry mass m_p (kg), its stages in order, and the
    suspension-line length L_s (m) where the manifest gives it (None otherwise; the model
    does not use it: campaigns group drag areas by it, paper Tables 2-3).

    `open_at_start`: the canopy is open and steady when the phase starts (a descent picked
    up after its opening); it has one stage, no deployment event and no inflation curve,
    only its steady drag area.  `altitude_bands` (m MSL, strictly increasing, only for such
    a canopy): the altitudes at which that drag area changes, piecewise constant in
    altitude, one value per band (`band_names`)."""

    name: str
    type: str
    diameter: float
    dry_mass: float
    inflation: str
    fill_length: str
    stages: tuple[str, ...]
    line_length: float | None = None
    open_at_start: bool = False
    altitude_bands: tuple[float, ...] = ()

    @property
    def band_names(self) -> tuple[str, ...]:
        """Band labels, lowest first (band1 below the first edge); none without bands."""
        if not self.altitude_bands:
            return ()
        return tuple(f"band{k + 1}" for k in range(len(self.altitude_bands) + 1))

    def band_range(self, band: str) -> tuple[float, float]:
        """Altitudes (m) bounding `band` (-inf below the lowest edge, inf above the top)."""
        k = self.band_names.index(band)
        edges = (-math.inf, *self.altitude_bands, math.inf)
        return edges[k], edges[k + 1]


@dataclass(frozen=True)
class Event:
    """An observed event (video, pyro log) at `time` s with standard deviation `sigma` s."""

    name: str
    parachute: str
    stage: str | None
    time: float
    sigma: float


# Samples on either side whose mean sets a sample's relative noise when fitting.
NEIGHBOUR_SAMPLES = 5


@dataclass(frozen=True)
class Sensor:
    """One sensor's series in SI, with per-channel noise sigma (SI) and relative noise."""

    name: str
    kind: str
    parachute: str | None
    file: str
    data: pd.DataFrame
    sigma: dict[str, float]
    sigma_relative: float = 0.0
    # (time (s), channel -> sigma (SI)): from each time on, these channels' absolute
    # sigma changes (an altimeter under a fast drogue is noisier than under a main).
    sigma_changes: tuple[tuple[float, dict[str, float]], ...] = ()

    @property
    def channels(self) -> tuple[str, ...]:
        return tuple(c for c in SENSOR_COLUMNS[self.kind] if c != "time")

    @property
    def time(self) -> np.ndarray:
        return self.data["time"].to_numpy()

    def absolute_sigma(self, channel: str) -> np.ndarray:
        """Per-sample absolute sigma (SI), with the scheduled changes applied."""
        out = np.full(len(self.data), self.sigma[channel])
        t = self.time
        for t_from, sigmas in sorted(self.sigma_changes, key=lambda c: c[0]):
            if channel in sigmas:
                out[t >= t_from] = sigmas[channel]
        return out

    def noise_sigma(self, channel: str, values: np.ndarray) -> np.ndarray:
        """Per-sample sigma: absolute and relative parts added in quadrature."""
        return np.sqrt(self.absolute_sigma(channel) ** 2
                       + (self.sigma_relative * np.abs(values)) ** 2)

    def weighting_sigma(self, channel: str) -> np.ndarray:
        """Per-sample sigma for fitting the measured series: the relative part at the
        mean of the NEIGHBOUR_SAMPLES samples on either side, leaving the sample out.

        Taken at the measured value itself, the relative part would weight every
        sample by its own noise (readings that came out high count less) and bias
        a fitted scale low by about 2 sigma_rel^2 (0.08 % at 2 % noise: 2 standard
        deviations of the 120 s `main3` drag scale factors).  The neighbours'
        noise is independent of the sample's, so the weights carry no bias, and
        the true value over +-5 samples (+-0.05 s at 100 Hz) differs little.
        """
        values = self.data[channel].to_numpy()
        if self.sigma_relative == 0.0 or values.size < 3:
            return self.noise_sigma(channel, values)
        k = NEIGHBOUR_SAMPLES
        padded = np.pad(values, k, mode="reflect" if values.size > k else "edge")
        window = np.convolve(padded, np.ones(2 * k + 1), mode="valid")
        return self.noise_sigma(channel, (window - values) / (2 * k))


@dataclass
class FlightTest:
    """One test phase, everything in SI."""

    name: str
    path: Path | None
    vehicle: Vehicle
    parachutes: tuple[Parachute, ...]
    events: tuple[Event, ...]
    sensors: tuple[Sensor, ...]
    atmosphere: Atmosphere
    t_start: float
    t_end: float
    description: str = ""
    label: str = ""
    manifest: dict[str, Any] = field(default_factory=dict, repr=False)

    def parachute(self, name: str) -> Parachute:
        return next(p for p in self.parachutes if p.name == name)

    @property
    def weight(self) -> float:
        """Weight of the suspended system (N): vehicle and canopies' dry mass times g0."""
        return (self.vehicle.mass + sum(p.dry_mass for p in self.parachutes)) * G0

    def event(self, name: str, parachute: str, stage: str | None = None) -> Event | None:
        for e in self.events:
            if e.name == name and e.parachute == parachute and (stage is None or e.stage == stage):
                return e
        return None

    def sensors_of(self, kind: str) -> tuple[Sensor, ...]:
        return tuple(s for s in self.sensors if s.kind == kind)
