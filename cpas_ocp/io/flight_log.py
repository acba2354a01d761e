"""Real flight logs into test folders: a flight card plus a flight-computer log.

A *flight card* (JSON; the built-in ones are problems with ``"kind":
"flight_log"``) holds what the log does not: the vehicle's descent mass and
forebody drag area, the parachutes and the flight state that deploys each,
the launch site (elevation, surface air density, lapse rate or ``"gps"``),
the model block to reconstruct with, and the published nominal drag areas
to compare against.

`import_flight` turns a cleaned log (`flight_record.FlightRecord`, from any
reader: `altus_metrum`, `cats_vega`, `column_map`) and a card into a test
folder:

* the card's deployments name flight states (``drogue``, ``main``): the
  log's own where it logged states, else the events `flight_events`
  detects in the accelerometer and the altimeter (the charge near apogee,
  or apogee itself, is ``drogue``, the next ``main``);
* phase: from the first deployment to touchdown (`flight_events.touchdown`:
  the altitude has stopped falling and the accelerometer is at rest), less
  `TOUCHDOWN_MARGIN_S`; a log that ends before touchdown ends the phase at
  its end, and the import says so;
* events: each deployment as a ``mortar_fire`` of its canopy, with the state
  machine's timing sigma `EVENT_SIGMA_S` or the detector's sigma;
* every series runs `SERIES_MARGIN_S` beyond the phase, so that each
  covers it;
* ``baro.csv``: pressure altitude (m); samples from `EVENT_SIGMA_S` before to
  `EJECTION_EXCLUDE_S` after a deployment are left out (the ejection charge's pressure pulse reads
  as a 150 m jump in one sample);
* ``gps_altitude.csv``: GPS altitude (m MSL) at each new fix with at least
  four satellites;
* ``accelerometer.csv`` (where the log has an accelerometer): axial
  acceleration (m/s^2, 1 g subtracted), fitted by the `axial_accelerometer`
  effect, less the charge samples and, in each
  later canopy's opening, the samples above the drag ceiling
  (`drag_ceiling`: the shock cord's snatch, which no drag model makes; the
  largest is the full-open event below);
* a ``full_open`` event for each later canopy whose opening the
  accelerometer shows (`opening_peak`): the time of the largest axial
  specific force in the `OPENING_WINDOW_S` after the charge, with one
  accelerometer sample interval as its sigma.  On a hobby rocket that peak
  is the snatch of the elastic shock cord, which comes when the canopy, full,
  has stopped ahead of the vehicle: the peak marks full open to within a
  sample (it lies anywhere between two) and needs no attitude (the axis
  swinging against the riser scales the reading, not its timing).  The first
  canopy's is not taken: it opens near apogee, where the load barely rises;
* the site atmosphere (`atmosphere.SiteAtmosphere`): the pad pressure (median
  before launch), the temperature from the card's surface density
  (T = p / (R rho)), and the lapse rate from the card or, with ``"gps"``,
  fitted to the GPS fixes of the descent (`fit_lapse_rate`; in boost the
  receiver lags the vehicle by tens of metres);
* noise sigmas from the data: the altimeter's per canopy phase, from its
  scatter about the local trend (`scatter_sigma`; under a 30 m/s drogue the
  static pressure swings by metres over seconds), the GPS altitude's from the
  lapse-rate fit's residuals.  A later canopy's altimeter sigma applies from
  the time its descent has settled (`settled_time`), not from its deployment:
  until then the vehicle still falls fast and is jerked about by the opening,
  and the static port errs as it did under the canopy before.  The
  accelerometer's sigma is the RMS of its scatter about the local trend
  (`scatter_rms`: the swing's jolts are part of the swing), under each
  canopy's steady descent and apart over each later canopy's opening (from
  the charge until the descent has settled, at least `OPENING_WINDOW_S`),
  where the shock cord bounces the body by g's within a sample.

The folder is written to a temporary sibling and moved into place only once
it loads, so a failed import leaves nothing behind.
"""

from __future__ import annotations

import dataclasses
import json
import shutil
import tempfile
from dataclasses import dataclass, field
from importlib import resources
from itertools import pairwise
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd
from scipy.optimize import minimize_scalar
from scipy.signal import savgol_filter

from cpas_ocp.errors import InputError
from cpas_ocp.io.altus_metrum import AltusLog
from cpas_ocp.io.flight_events import (
    CLUSTER_GAP_S,
    DROGUE_WINDOW_S,
    FlightEvent,
    detect_events,
    sample_interval,
    second_difference_sigma,
)
from cpas_ocp.io.flight_record import FlightRecord, enu_about, pressure_of_altitude
from cpas_ocp.io.flight_test import FORMAT, MANIFEST, load_test, validate_manifest
from cpas_ocp.io.json_files import check_magnitudes, read_json, validate_block
from cpas_ocp.io.plausibility import (
    MAX_DESCENT_M_S,
    MAX_SPEED_M_S,
    check_boost,
    check_pad_air,
    check_speed,
    check_steady_accelerometer,
)
from cpas_ocp.io.problems import problem_names
from cpas_ocp.io.strict_json import json_text
from cpas_ocp.physics.atmosphere import (
    ISA_LAPSE_K_M,
    R_AIR,
    SiteAtmosphere,
    StandardAtmosphere,
    pressure_altitude,
)
from cpas_ocp.physics.effects.canopy_inflation import MAX_CD
from cpas_ocp.physics.effects.registry import SENSOR_EFFECTS
from cpas_ocp.physics.units import FACTORS, G0

TOUCHDOWN_MARGIN_S = 0.5  # phase ends this long before the detected touchdown (s)
EVENT_SIGMA_S = 0.1  # timing sigma of a flight-state change (one descent sample, s)
MIN_EVENT_SIGMA_S = 1e-6  # least event sigma a manifest states (its times' resolution, s)
EJECTION_EXCLUDE_S = 0.3  # altimeter samples left out after an ejection charge (s)
MIN_ACCEL_SIGMA = 0.1  # floor of the accelerometer noise sigma (m/s^2)
MIN_BARO_SIGMA_M = 0.3  # floor of the altimeter noise sigma (the pressure resolution, m)
LAPSE_BOUNDS_K_M = (0.002, 0.0098)  # search range of a fitted lapse rate (to the dry adiabat)
SCATTER_WINDOW_S = 8.0  # window of the local trend a sensor's scatter is taken about (s)
SERIES_MARGIN_S = 1.5  # series extend this far beyond the phase: a 1 Hz GPS covers it (s)
RATE_WINDOW_S = 2.0  # window of the local descent rate that tells when a canopy has settled (s)
SETTLED_RATE_FACTOR = 1.25  # settled: the local rate within this factor of the steady one
STEADY_RATE_S = 10.0  # the settled descent rate under a canopy is taken over this long (s)
OPENING_WINDOW_S = 3.0  # an opening-load peak is looked for this long after the charge (s)
OPENING_BASELINE_S = 5.0  # the steady reading before a charge is taken over this long (s)
OPENING_PEAK_SIGMAS = 5.0  # a peak counts when this many scatter sigmas off the steady reading
MIN_DESCENT_S = 5.0  # a log must go on this long after the first deployment to be fitted (s)
MIN_DESCENT_SAMPLES = 20  # ... with this many altimeter samples
ACF_FLOOR = 0.05  # a noise's autocorrelation counts until it first falls below this
LAUNCH_RISE_M = 10.0  # launch: the altitude has risen this far above its lowest so far (m) ...
LAUNCH_LEAD_S = 1.0  # ... and the pad's samples end this long before that (s)
MIN_PAD_SAMPLES = 10  # the pad's level is their median where the log has this many
STUCK_RUN_S = 2.0  # a reading repeated exactly for this long (s) ...
STUCK_RUN_SAMPLES = 10  # ... and this many samples is a dead channel
CLIP_RUN_SAMPLES = 3  # a channel's extreme reading met this often is its range's end: clipped
ASSUMED_CD = 0.75  # drag coefficient on pi D_o^2 / 4 of a canopy whose card gives no diameter
DEFAULT_DRY_MASS_FRACTION = 0.005  # of the vehicle's mass: a canopy's where the card gives none


@dataclass(frozen=True)
class FlightCard:
    """What a flight log does not hold; see the module docstring."""

    name: str
    title: str
    label: str
    data_folder: str
    logs: tuple[str, ...]
    vehicle: dict[str, Any]
    parachutes: tuple[dict[str, Any], ...]
    site: dict[str, Any]
    model: dict[str, Any]
    nominal: dict[str, dict[str, Any]]
    source: str
    events: dict[str, dict[str, Any]] = field(default_factory=dict)
    data_format: str | None = None  # the logs' built-in format, for `flight`
    # or their column map: a file relative to the card's folder, or the map inline
    data_columns: str | dict[str, Any] | None = None


def card_from_dict(raw: dict[str, Any], source: str) -> FlightCard:
    """A card from its JSON object; InputError naming the field that breaks
    `data_schemas/flight_card.schema.json` (or whose numbers are beyond any test's).

    The canopies' optional fields are filled in here (`canopy_defaults`), and the vehicle's
    forebody drag area is 0 where the card gives none (the canopies' drag areas then carry
    the body's), so that the manifest the import writes states every value it was built
    with."""
    validate_block(raw, "flight_card.schema.json", source)
    check_magnitudes(raw, source)
    data = raw.get("data", {})
    return FlightCard(raw["name"], raw.get("title", raw["name"]), raw.get("label", ""),
                      data.get("folder", ""), tuple(data.get("logs", ())),
                      {"forebody_cds": {"value": 0.0, "unit": "m^2"}, **raw["vehicle"]},
                      tuple(canopy_defaults(raw["parachutes"], raw["vehicle"], source)),
                      raw["site"], raw.get("model") or {}, raw.get("nominal", {}), source,
                      raw.get("events", {}), data.get("format"), data.get("columns"))


def canopy_defaults(parachutes: list[dict[str, Any]], vehicle: dict[str, Any], source: str
                    ) -> list[dict[str, Any]]:
    """The card's canopies with what they leave out filled in: ``type`` drogue for the
    first and main for the others, ``inflation`` finite mass, one stage ``open``, and a
    ``dry_mass`` of `DEFAULT_DRY_MASS_FRACTION` of the vehicle's (a canopy's mass only adds
    to the descent mass it flies with).  A missing ``diameter`` stays missing: the import
    takes it from the descent (`canopy_diameters`)."""
    out = []
    for i, chute in enumerate(parachutes):
        if chute.get("open_at_start"):
            raise InputError(source, f"parachutes[{i}].open_at_start", "a canopy the log sees "
                             "deploy (a flight card's canopies each open at an event of the "
                             "log; open_at_start is for a test folder whose phase begins "
                             "under an open canopy)")
        if len(chute.get("stages", ())) > 1:
            raise InputError(source, f"parachutes[{i}].stages", "one stage: the import finds "
                             "no disreef events in a rocket log")
        filled = {"type": "drogue" if i == 0 else "main", "inflation": "finite_mass",
                  "stages": ["open"], **chute}
        if "dry_mass" not in chute:
            mass = _si(vehicle.get("mass"), "mass", source, "vehicle.mass")
            filled["dry_mass"] = {"value": round(DEFAULT_DRY_MASS_FRACTION * mass, 4),
                                  "unit": "kg"}
        out.append(filled)
    return out


def load_card(name_or_path: str) -> FlightCard:
    """A built-in flight card by problem name, or a card file."""
    path = Path(name_or_path)
    if path.suffix == ".json":
        return card_from_dict(read_json(path, "an existing flight-card JSON file"), str(path))
    names = problem_names("flight_log")
    if name_or_path not in names:
        raise InputError("flight card", "name", f"a card file (.json) or one of "
                         f"{', '.join(names)}; got {name_or_path!r}")
    raw = json.loads(resources.files("cpas_ocp.problem_data")
                     .joinpath(f"{name_or_path}.json").read_text())
    return card_from_dict(raw, f"problems/{name_or_path}.json")


def _si(q: dict[str, Any], dim: str, source: str, field: str) -> float:
    """The quantity `q` ({value, unit}) of dimension `dim` in SI; InputError naming `field`
    of `source` where it is no such quantity."""
    unit = q.get("unit") if isinstance(q, dict) else None
    value = q.get("value") if isinstance(q, dict) else None
    if not isinstance(unit, str) or unit not in FACTORS[dim] \
            or not isinstance(value, int | float) or isinstance(value, bool):
        raise InputError(source, field, f"{{value, unit}} with a {dim} unit "
                         f"({', '.join(sorted(FACTORS[dim]))})")
    return float(q["value"]) * FACTORS[dim][unit]


def fit_lapse_rate(fixes: pd.DataFrame, pressure: pd.Series, times: pd.Series,
                   elevation: float, p0: float, t0: float) -> tuple[float, float, float]:
    """The lapse rate (K/m) that makes the site atmosphere's altitude of the measured
    pressure match the GPS altitudes, with a constant GPS offset.

    Returns (lapse rate, GPS offset (m), residual standard deviation (m)).
    Least squares over every fix; the offset is profiled out (its estimate is
    the mean difference).
    """
    p_at = np.interp(fixes["time"], times, pressure)
    h_gps = fixes["gps_altitude"].to_numpy()

    def residual(lapse: float) -> np.ndarray:
        site = SiteAtmosphere(elevation, p0, t0, lapse)
        d = h_gps - site.altitude_at_pressure(p_at)
        return d - d.mean()

    best = minimize_scalar(lambda lapse: float(np.sum(residual(lapse) ** 2)),
                           bounds=LAPSE_BOUNDS_K_M, method="bounded",
                           options={"xatol": 1e-6})
    lapse = float(best.x)
    site = SiteAtmosphere(elevation, p0, t0, lapse)
    offset = float(np.mean(h_gps - site.altitude_at_pressure(p_at)))
    return lapse, offset, float(np.std(residual(lapse), ddof=2))


def _scatter(t: np.ndarray, values: np.ndarray) -> np.ndarray | None:
    """`values` less their local quadratic trend over SCATTER_WINDOW_S (a Savitzky-Golay
    filter on a uniform resampling); None where the samples span too short a time."""
    grid = np.arange(t[0], t[-1], 0.1)
    window = min(int(SCATTER_WINDOW_S / 0.1) // 2 * 2 + 1, len(grid) // 2 * 2 - 1)
    if window < 5:
        return None
    return values - np.interp(t, grid, savgol_filter(np.interp(grid, t, values), window, 2))


def scatter_sigma(t: np.ndarray, values: np.ndarray) -> float:
    """Robust sigma (1.4826 MAD) of `values` about their local quadratic trend over
    SCATTER_WINDOW_S (`_scatter`).

    Unlike the second differences this counts disturbances correlated over a
    few seconds, such as the static-pressure swings of a rocket swinging under
    a fast drogue, as noise; the descent itself (speed changing over tens of
    seconds) stays in the trend."""
    r = _scatter(t, values)
    if r is None:
        return second_difference_sigma(values)
    return float(1.4826 * np.median(np.abs(r - np.median(r))))


def integrated_time(r: np.ndarray) -> float:
    """The integrated autocorrelation time (samples) of the residual series `r`:
    1 + 2 sum_k rho_k, the sum over the lags before rho first falls below `ACF_FLOOR` or
    below 2/sqrt(n), the band within which white noise's sample autocorrelation of n
    samples stays (so that chance correlations of a white series do not add up); 1 for
    fewer than 20 samples."""
    if r.size < MIN_DESCENT_SAMPLES:
        return 1.0
    r = r - r.mean()
    var = float(np.dot(r, r))
    if var == 0.0:
        return 1.0
    floor = max(ACF_FLOOR, 2.0 / np.sqrt(r.size))
    total = 1.0
    for k in range(1, r.size // 4):
        rho = float(np.dot(r[:-k], r[k:])) / var
        if rho < floor:
            break
        total += 2.0 * rho
    return total


def correlation_length(t: np.ndarray, values: np.ndarray) -> int:
    """The integrated autocorrelation time (`integrated_time`, rounded, samples) of
    `values`' scatter about their local trend (`_scatter`): the number of samples that
    carry as much information as one independent sample.  1 for white noise or too few
    samples (under 80)."""
    r = _scatter(t, values)
    if r is None or r.size < 4 * MIN_DESCENT_SAMPLES:
        return 1
    return max(1, round(integrated_time(r)))


def settled(t: np.ndarray, steady_end: float = np.inf) -> np.ndarray:
    """Which of the times `t` (s, one canopy's segment) lie in its settled descent: the
    later half of the span up to `steady_end` (the next canopy's charge, or the phase's
    end).  An opening's deceleration or the landing, which a local quadratic trend does
    not follow, would read there as correlated noise."""
    end = min(float(t[-1]), steady_end)
    return (t >= 0.5 * (t[0] + end)) & (t <= end)


def block_sigma(blocks: pd.DataFrame, steady_end: float = np.inf) -> float:
    """The noise sigma to weigh block means (`independent_blocks`) by: their robust
    scatter about the local trend (`scatter_sigma`) times the square root of their own
    integrated autocorrelation time in the settled descent (`settled`).  Adjacent blocks
    of a correlated noise still share its tail (for an AR(1) noise in blocks of its
    integrated time, adjacent means correlate at 0.36), and weighing them as independent
    would state sigmas too small by that root."""
    t, values = blocks["time"].to_numpy(float), blocks.iloc[:, 1].to_numpy(float)
    steady = settled(t, steady_end)
    r = _scatter(t[steady], values[steady]) if steady.sum() >= 2 else None
    tail = 1.0 if r is None else max(1.0, integrated_time(r))
    return scatter_sigma(t, values) * float(np.sqrt(tail))


def independent_blocks(frame: pd.DataFrame, steady_end: float = np.inf
                       ) -> tuple[pd.DataFrame, int]:
    """`frame` (``time`` s and one channel) averaged in consecutive blocks of
    `correlation_length` samples, each block's mean at its mean time, blocks never spanning
    a gap (a left-out charge window: over 1.5 sample intervals); with the block size.  The
    correlation is measured in the settled descent (`settled`, up to `steady_end`).

    Block means of correlated noise are nearly independent, weighed at `block_sigma`: a
    fit that weighs every raw sample at the raw scatter would
    count each piece of information that many times over, and state sigmas that many
    times too small.  Over a block (well under a second) the descent's curvature moves the
    mean from the mid-time value by a·L²/24, centimetres against metres of noise."""
    if len(frame) < 2:
        return frame.reset_index(drop=True), 1
    t = frame["time"].to_numpy(float)
    steady = settled(t, steady_end)
    size = correlation_length(t[steady], frame.iloc[:, 1].to_numpy(float)[steady])
    if size <= 1:
        return frame.reset_index(drop=True), 1
    run = np.r_[0, np.cumsum(np.diff(t) > 1.5 * sample_interval(t))]
    position = np.zeros(t.size, dtype=int)
    for r in np.unique(run):
        sel = run == r
        position[sel] = np.arange(sel.sum()) // size
    keys = run * (t.size + 1) + position
    return frame.groupby(keys, sort=True).mean().reset_index(drop=True), size


def scatter_rms(t: np.ndarray, values: np.ndarray) -> float:
    """RMS of `values` about their local quadratic trend over SCATTER_WINDOW_S (`_scatter`):
    the sigma of a disturbance whose tails belong to it.  An accelerometer on a body
    swinging under its canopy reads jolts of g when the swing reverses (both Prometheus
    recorders read +2.5 to +3 g at 148.6-148.8 s under a drogue whose median reading is
    -1.65 g): part of the swing, not glitches, so its variance, not a robust spread of
    its middle, is the noise (under the drogue, 4.6 m/s^2 against 3.5 robust)."""
    r = _scatter(t, values)
    if r is None:
        return second_difference_sigma(values)
    return float(np.sqrt(np.mean(r**2)))


def settled_time(t: np.ndarray, altitude: np.ndarray, t_from: float, t_to: float) -> float:
    """When the descent after a deployment at `t_from` has settled (s): the first time from
    which the local descent rate (slope of a line through `RATE_WINDOW_S` of altitude
    samples, m/s) stays within `SETTLED_RATE_FACTOR` of the steady rate (the median local
    rate over the second half of [`t_from`, `t_to`]) for a further window.  `t_from`
    where the samples are too few to tell."""
    centres = np.arange(t_from + RATE_WINDOW_S / 2, t_to - RATE_WINDOW_S / 2, RATE_WINDOW_S / 2)
    rates = np.array([_slope(t, altitude, c - RATE_WINDOW_S / 2, c + RATE_WINDOW_S / 2)
                      for c in centres])
    late = centres >= 0.5 * (t_from + t_to)
    if not np.isfinite(rates[late]).any():
        return t_from
    steady = abs(float(np.nanmedian(rates[late])))
    ok = np.abs(rates) <= SETTLED_RATE_FACTOR * steady
    for i in range(centres.size - 2):
        if ok[i] and ok[i + 1] and ok[i + 2]:
            return float(centres[i] - RATE_WINDOW_S / 2)
    return t_from


def _slope(t: np.ndarray, values: np.ndarray, lo: float, hi: float) -> float:
    """Slope (per s) of a line through the samples in [lo, hi]; NaN with fewer than 4."""
    m = (t >= lo) & (t <= hi)
    if m.sum() < 4:
        return float("nan")
    return float(np.polyfit(t[m] - lo, values[m], 1)[0])


def drag_ceiling(t: np.ndarray, height: np.ndarray, density: np.ndarray, t_charge: float,
                 t_settled: float, t_next: float) -> float | None:
    """The largest axial reading (m/s^2, one g subtracted) the canopies' drag can give in
    the opening that follows a charge at `t_charge`, from the altimeter alone.

    Once settled (from `t_settled`, over STEADY_RATE_S or to `t_next`) the open
    canopies carry the weight at the descent rate v_s, so their full drag area is
    2 m g / (rho_s v_s^2).  No opening pulls more than that area at the speed v_c
    the vehicle had at the charge (the rate over RATE_WINDOW_S before it): a
    specific force of g (rho_c v_c^2) / (rho_s v_s^2), and an axial reading of
    at most that less one g (the axis's cosine to the force is at most 1).  A
    reading above it is the shock cord's snatch, the elastic cord giving back the
    energy it stored as the canopy stopped ahead of the vehicle, which no drag
    model makes.  `height` (m) and `density` (kg/m^3) are the altimeter's
    samples at times `t`.  None where the rates cannot be told."""
    early = t_charge - EVENT_SIGMA_S
    v_c = -_slope(t, height, early - RATE_WINDOW_S, early)
    end = min(t_settled + STEADY_RATE_S, t_next)
    v_s = -_slope(t, height, t_settled, end)
    if not (v_c > 0.0 and v_s > 0.0):
        return None
    at_charge = (t >= early - RATE_WINDOW_S) & (t <= early)
    settled = (t >= t_settled) & (t <= end)
    ratio = float(np.mean(density[at_charge]) / np.mean(density[settled]))
    return G0 * ratio * (v_c / v_s) ** 2 - G0


@dataclass(frozen=True)
class Snatch:
    """A later canopy's opening as the accelerometer read it against the drag ceiling
    (`drag_ceiling`): the ceiling (m/s^2, an axial reading), the samples above it left
    out as the shock cord's snatch, and the largest of them (m/s^2) with its time (s)."""

    ceiling_m_s2: float
    samples_left_out: int
    largest_m_s2: float | None
    at_s: float | None

    def text(self) -> str:
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

    def text(self) -> str:
        """A few lines for the terminal."""
        events = ", ".join(f"{k} {v:.2f} s" for k, v in self.events.items())
        lines = [f"{self.recorder} log: phase {self.phase[0]:.2f}-{self.phase[1]:.2f} s; {events}",
                 f"site: {self.site.elevation_m:.0f} m, {self.site.pressure_pa:.0f} Pa, "
                 f"{self.site.temperature_k:.1f} K, lapse rate "
                 f"{1e3 * self.site.lapse_rate_k_m:.2f} K/km"]
        if self.lapse_fit is not None:
            lines.append(f"  (lapse rate fitted to the GPS fixes: GPS offset "
                         f"{self.lapse_fit[1]:+.1f} m, residual sigma {self.lapse_fit[2]:.1f} m)")
        lines.append("altimeter sigma per canopy phase: "
                     + ", ".join(f"{s:.2f} m" for s in self.baro_sigma_m))
        if self.accel_sigma:
            lines.append("accelerometer sigma per steady descent and opening (the swing "
                         "counted): " + ", ".join(f"{s:.2f} m/s²" for s in self.accel_sigma))
        for name, snatch in self.snatches.items():
            lines.append(f"{name}'s opening: {snatch.text()}")
        if self.flight_events:
            lines.append("flight events: " + ", ".join(
                f"{k} {e.time:.2f} ± {e.sigma:.2f} s ({e.source})"
                for k, e in self.flight_events.items()))
        lines.extend(f"note: {n}" for n in self.notes)
        lines.append("samples: " + ", ".join(f"{k} {v}" for k, v in self.samples.items())
                     + "; dropped: " + ", ".join(f"{k} {v}" for k, v in self.dropped.items()))
        return "\n".join(lines)

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
                "nominal": self.nominal}


def dead_samples(t: np.ndarray, values: np.ndarray, clipped: bool = False) -> np.ndarray:
    """Which samples a channel did not measure: runs of one exact reading repeated for at
    least `STUCK_RUN_S` and `STUCK_RUN_SAMPLES` samples (a dead or zeroed channel: a real
    sensor's noise, or a descent of metres per second, changes the reading within that),
    and with `clipped`, every sample at the channel's largest or smallest reading where that
    exact reading comes `CLIP_RUN_SAMPLES` times or more (the sensor's range: the force went
    beyond it; a real peak of a noisy channel is not matched to the last digit).  `t` in
    s."""
    if values.size < 2:
        return np.zeros(values.size, dtype=bool)
    change = np.flatnonzero(np.diff(values) != 0.0) + 1
    first, end = np.r_[0, change], np.r_[change, values.size]  # runs [first, end)
    run = end - first
    dead_run = (run >= STUCK_RUN_SAMPLES) & (t[end - 1] - t[first] >= STUCK_RUN_S)
    dead = np.repeat(dead_run, run)
    if clipped:
        for rail in (values.max(), values.min()):
            at_rail = values == rail
            if at_rail.sum() >= CLIP_RUN_SAMPLES:
                dead |= at_rail
    return dead


def dead_note(channel: str, t: np.ndarray, values: np.ndarray, unit: str) -> str:
    """A sentence on the samples `dead_samples` left out of `channel`."""
    readings = ", ".join(f"{v:g}" for v in np.unique(values)[:3])
    return (f"{channel}: {t.size} samples between {t.min():.2f} and {t.max():.2f} s left out: "
            f"the channel repeats one reading ({readings} {unit}) for {STUCK_RUN_S:g} s or "
            "more, or sits at its range's end: it did not measure there")


def descent_drag_areas(deploy: dict[str, float], parachutes: list[dict[str, Any]],
                       card: FlightCard, site: SiteAtmosphere, t: np.ndarray, h: np.ndarray,
                       t_end: float) -> dict[str, float]:
    """Each canopy's own drag area (m^2) as its steady descent shows it; NaN where none can
    be told.  Under the canopies open in a canopy's steady descent (the second half of the
    span from its settled time to the next deployment or `t_end`) the drag carries the
    weight: the drag area open is 2 m g / (rho v^2) at that descent rate v and air density
    rho (`site` at the mean pressure altitude `h`, m, of those samples at times `t`, s), m
    the flown mass; the canopy's own is that less what the earlier canopies showed (all of
    it where that is not less: a canopy cut away).  The forebody's drag area is in the
    first canopy's."""
    mass = _si(card.vehicle.get("mass"), "mass", card.source, "vehicle.mass") + sum(
        _si(c["dry_mass"], "mass", card.source, "parachutes.dry_mass") for c in parachutes)
    order = sorted(deploy, key=deploy.__getitem__)
    areas = []
    for k, name in enumerate(order):
        t_to = deploy[order[k + 1]] if k + 1 < len(order) else t_end
        mid = 0.5 * (settled_time(t, h, deploy[name], t_to) + t_to)
        rate = -_slope(t, h, mid, t_to)
        sel = (t >= mid) & (t <= t_to)
        if not rate > 0.0:
            areas.append(float("nan"))
            continue
        altitude = site.altitude_at_pressure(pressure_of_altitude(h[sel]))
        rho = float(np.mean(np.asarray(site.density(altitude), float)))
        areas.append(2.0 * mass * G0 / (rho * rate**2))
    own = {}
    for k, name in enumerate(order):
        before = areas[k - 1] if k > 0 else 0.0
        own[name] = areas[k] - before if np.isfinite(before) and areas[k] > before \
            else areas[k]
    return own


def canopy_diameters(parachutes: list[dict[str, Any]], areas: dict[str, float],
                     card: FlightCard) -> list[str]:
    """Fill in the diameter D_o of each canopy whose card gives none from its descent drag
    area (`descent_drag_areas`): the diameter whose area pi D_o^2 / 4 gives it at Cd
    `ASSUMED_CD`.  D_o sets the fill time's length scale and the drag area's upper bound
    (`canopy_inflation.MAX_CD` pi D_o^2 / 4), which the report names where a fit presses it.
    Returns a note per canopy filled in, and per canopy whose card's diameter bounds its
    drag area below what its descent shows (the fit would press that bound).  InputError
    naming the card's field where a diameter is missing and no steady descent under the
    canopy can be told."""
    notes = []
    for i, chute in enumerate(parachutes):
        name, own = chute["name"], areas[chute["name"]]
        if "diameter" in chute:
            d = _si(chute["diameter"], "length", card.source, f"parachutes[{i}].diameter")
            bound = MAX_CD * np.pi * d**2 / 4.0
            if np.isfinite(own) and own > bound:
                notes.append(f"{name}: the card's diameter {d:.2f} m bounds its drag area at "
                             f"{bound:.3f} m^2 ({MAX_CD:g} pi D_o^2 / 4), below the {own:.3f} "
                             "m^2 its steady descent shows: check the diameter (or leave it "
                             "out to take it from the descent)")
            continue
        if not (np.isfinite(own) and own > 0.0):
            raise InputError(card.source, f"parachutes[{i}].diameter", f"a value: {name}'s "
                             "diameter cannot be taken from the log, which shows no steady "
                             "descent under it")
        diameter = float(np.sqrt(4.0 * own / (np.pi * ASSUMED_CD)))
        chute["diameter"] = {"value": round(diameter, 4), "unit": "m"}
        notes.append(f"{name}: no diameter in the card; D_o {diameter:.2f} m from the steady "
                     f"descent under it (drag area {own:.3f} m^2 at Cd {ASSUMED_CD:g}); its "
                     f"drag area is bounded at {MAX_CD:g} pi D_o^2 / 4 = "
                     f"{MAX_CD * np.pi * diameter**2 / 4.0:.3f} m^2")
    return notes


# The rocket-log model where the card lists no effects: the air's vertical motion (an
# Ornstein-Uhlenbeck process with a 1 m/s prior, knots every 4 s: a rocket's descent rate
# of metres per second is moved by the air as much as by its canopy), the canopies' drag on
# a rigid riser, the altimeter, and the other sensors' effects where the folder has them.
# The altimeter's bias and lag only with a second sensor: against the altimeter alone a
# bias is the initial altitude and a lag a shift of every event, which no fit can tell.
ROCKET_EFFECTS: tuple[str | dict[str, Any], ...] = (
    {"effect": "wind_process", "components": ["up"], "knot_s": 4.0, "tau_s": 20.0,
     "sigma_vertical": 1.0},
    "canopy_inflation", "forebody_drag", "rigid_riser", "baro")
ALTIMETER_ERRORS = ("baro_bias", "baro_lag")
# Held opening shape of a canopy deployed near apogee (the effect's default fill constant,
# linear growth): its fill time n D_o / V_i divides by the small speed at deployment, and
# no sensor of a rocket log resolves that opening.  A later canopy whose opening no
# accelerometer reads has its shape exponent held (linear growth): the altimeter sees the
# opening's duration, not the curve's shape.
HELD_FILL_CONSTANT = 8.0
HELD_EXPOPEN = 1.0
MIN_START_WINDOW_S = 2.0  # least half-width of an inflation start's window about its event


def held_openings(deploy: dict[str, float], events: dict[str, FlightEvent]) -> list[str]:
    """Canopies deployed within `flight_events.DROGUE_WINDOW_S` of apogee (after it, or
    before it by less than apogee's sigma plus a second), whose opening shape the default
    model holds."""
    if "apogee" not in events:
        return []
    top = events["apogee"]
    return [name for name, t in deploy.items()
            if top.time - top.sigma - 1.0 <= t <= top.time + DROGUE_WINDOW_S]


def rocket_model(block: dict[str, Any], sensor_kinds: list[str],
                 canopies: list[tuple[str, str]], held: list[str],
                 deploy_sigma: dict[str, float], still_air: bool = False) -> dict[str, Any]:
    """The manifest's model block: the card's where it lists effects; else `ROCKET_EFFECTS`
    with the sensors' (`sensor_kinds`) and, with a second sensor, the altimeter's errors;
    each start window at least three of its deployment's sigmas (and `MIN_START_WINDOW_S`);
    the opening shape (n, expopen) of the canopies named in `held` held at
    `HELD_FILL_CONSTANT`, `HELD_EXPOPEN`, and without an accelerometer every canopy's
    expopen (`canopies`: each canopy's name and first stage); the card's own fixes, frees
    and priors win.  `still_air` leaves the air's motion out."""
    if "effects" in block:
        return block
    window = max(MIN_START_WINDOW_S, *(3.0 * s for s in deploy_sigma.values()))
    effects = [{"effect": "canopy_inflation", "start_window": round(window, 3)}
               if e == "canopy_inflation" else e for e in ROCKET_EFFECTS
               if not (still_air and isinstance(e, dict) and e["effect"] == "wind_process")]
    others = [SENSOR_EFFECTS[k] for k in dict.fromkeys(sensor_kinds) if k != "baro"]
    effects += [*(ALTIMETER_ERRORS if others else ()), *others]
    fix: dict[str, Any] = {}
    accelerometer = "axial_accelerometer" in sensor_kinds
    for name, stage in canopies:
        if name in held:
            fix[f"n[{name},{stage}]"] = HELD_FILL_CONSTANT
        if name in held or not accelerometer:
            fix[f"expopen[{name},{stage}]"] = HELD_EXPOPEN
    return {**block, "effects": effects, "fix": {**fix, **block.get("fix", {})}}


TEMPERATURE_UNITS = {"K": (1.0, 0.0), "degC": (1.0, 273.15), "degF": (5.0 / 9.0, 255.372222)}


def pad_temperature(site: dict[str, Any], p0: float, elevation: float, source: str
                    ) -> tuple[float, str]:
    """The air temperature on the pad (K) and where it came from: the card's
    ``temperature``, or its ``surface_density`` with the pad pressure `p0` (Pa) through the
    gas law T = p / (R rho), or the standard atmosphere's at the site's `elevation` (m)."""
    if "temperature" in site:
        scale, offset = TEMPERATURE_UNITS[site["temperature"]["unit"]]
        t0 = scale * float(site["temperature"]["value"]) + offset
        if not t0 > 0.0:
            raise InputError(source, "site.temperature", f"a temperature above absolute zero; "
                             f"got {t0:.2f} K")
        return t0, f"pad temperature {t0:.1f} K from the card's site.temperature"
    if "surface_density" in site:
        rho0 = _si(site["surface_density"], "density", source, "site.surface_density")
        t0 = p0 / (R_AIR * rho0)
        return t0, (f"pad temperature {t0:.1f} K from the card's surface density "
                    f"{rho0:.3f} kg/m^3 and the pad pressure (T = p / (R rho))")
    standard = StandardAtmosphere()
    t0 = float(standard.pressure(elevation)) / (R_AIR * float(standard.density(elevation)))
    return t0, (f"pad temperature {t0:.1f} K: the standard atmosphere's at {elevation:.0f} m "
                "(the card gives neither site.temperature nor site.surface_density)")


def pad_pressure(baro: pd.DataFrame, events: dict[str, FlightEvent], card: FlightCard
                 ) -> tuple[float, str]:
    """The air pressure on the pad (Pa) and a sentence saying where it came from.

    The card's ``site.pressure`` where it gives one; else the median of the barometer's
    samples before launch, launch being the boost the accelerometer saw or, without one,
    `LAUNCH_LEAD_S` before the altitude first stands `LAUNCH_RISE_M` above its lowest
    reading so far (a log that starts on the pad); where fewer than `MIN_PAD_SAMPLES`
    precede it (the log starts at launch), the lowest reading before the rise: the
    recorder's first samples, taken as the rocket left the pad."""
    if "pressure" in card.site:
        p0 = _si(card.site["pressure"], "pressure", card.source, "site.pressure")
        return p0, f"pad pressure {p0:.0f} Pa from the card's site.pressure"
    t, h = baro["time"].to_numpy(), baro["altitude"].to_numpy()
    rise = np.flatnonzero(h - np.minimum.accumulate(h) > LAUNCH_RISE_M)
    k_rise = int(rise[0]) if rise.size else len(h) - 1
    t_launch = events["boost"].time if "boost" in events else float(t[k_rise]) - LAUNCH_LEAD_S
    pad = baro[baro["time"] < t_launch]
    if len(pad) >= MIN_PAD_SAMPLES:
        p0 = float(pad["pressure"].median())
        return p0, (f"pad pressure {p0:.0f} Pa: the median of the {len(pad)} barometer "
                    f"samples before launch ({t_launch:.2f} s)")
    k = int(np.argmin(h[:k_rise + 1]))
    p0 = float(baro["pressure"].iloc[k])
    return p0, (f"pad pressure {p0:.0f} Pa: the log starts at launch (only {len(pad)} "
                f"samples before it), so the pad is its lowest reading before the climb, "
                f"at {t[k]:.2f} s; give site.pressure in the card where that is not the pad")


def card_events(card: FlightCard, baro: pd.DataFrame, pad_altitude: float,
                events: dict[str, FlightEvent]) -> dict[str, FlightEvent]:
    """The events the card gives (``events``): at a time, or where the descent first
    crosses below a height above the pad after apogee (a main fired by an altimeter at
    its set height), the crossing interpolated between the barometer's samples; each with
    the card's sigma.  InputError naming the card's field where the descent never comes
    down to that height, or the time lies outside the log."""
    out: dict[str, FlightEvent] = {}
    for name, spec in card.events.items():
        field_name = f"events.{name}"
        sigma = _si(spec["sigma"], "time", card.source, f"{field_name}.sigma")
        if "time" in spec:
            t_event = _si(spec["time"], "time", card.source, f"{field_name}.time")
            first, last = float(baro["time"].iloc[0]), float(baro["time"].iloc[-1])
            if not first <= t_event <= last:
                raise InputError(card.source, f"{field_name}.time", f"a time the log covers "
                                 f"(its altimeter reads from {first:.2f} to {last:.2f} s, on "
                                 f"the log's own clock); got {t_event:.2f} s")
            out[name] = FlightEvent(t_event, sigma, "the card")
            continue
        height = _si(spec["altitude"], "length", card.source, f"{field_name}.altitude")
        t, h = baro["time"].to_numpy(), baro["altitude"].to_numpy() - pad_altitude
        top = events["apogee"].time if "apogee" in events else float(t[np.argmax(h)])
        below = np.flatnonzero((t > top) & (h <= height))
        if below.size == 0 or below[0] == 0:
            after = h[t > top]
            raise InputError(card.source, f"{field_name}.altitude", f"a height above the pad "
                             f"the descent passes below; after apogee at {top:.2f} s the log "
                             f"reads {float(after.min()) if after.size else float('nan'):.1f}"
                             " m at the lowest")
        k = int(below[0])
        if not h[k - 1] > height:
            raise InputError(card.source, f"{field_name}.altitude", f"a height below apogee, "
                             f"which the log reads {float(np.max(h)):.1f} m above the pad; got "
                             f"{height:.1f} m")
        frac = (h[k - 1] - height) / (h[k - 1] - h[k])
        out[name] = FlightEvent(float(t[k - 1] + frac * (t[k] - t[k - 1])), sigma,
                                f"the card: the {height:.0f} m crossing")
    return out


def flight_events(record: FlightRecord) -> tuple[dict[str, FlightEvent], list[str]]:
    """The record's flight events with their sigmas: its logged states (sigma
    `EVENT_SIGMA_S`) where it has them, with apogee from the altimeter where they hold
    none, else those `detect_events` finds; touchdown (``landed``) always detected from the
    data, never taken from a state or the log's end.  Notes say what could not be found."""
    detected, notes = detect_events(record.samples)
    if record.states:
        events = {name: FlightEvent(t, EVENT_SIGMA_S, "flight state")
                  for name, t in record.states.items() if name != "landed"}
        for name in ("apogee", "landed"):  # the altimeter's, where the log logged no such state
            if name in detected and name not in events:
                events[name] = detected[name]
        notes = [n for n in notes if "touchdown" in n]
    else:
        events = detected
    if "landed" not in events:
        notes.append("no touchdown found: the log ends while the vehicle still descends")
    return events, notes


def check_charges_deploy(events: dict[str, FlightEvent], deploy: dict[str, float],
                         card: FlightCard, src: str, logged_states: bool) -> None:
    """InputError naming the card's canopies where the log `src` shows an ejection charge
    (`flight_events.detect_events`: the drogue's and the main's, found in the data, not a
    logged state, which a computer logs whether or not a canopy is rigged to it) that
    deploys none of them: no canopy's deployment time (s, `deploy`) lies within
    `CLUSTER_GAP_S` or three of the charge's sigmas of it.  The card has too few canopies
    (or the log is another flight's): the phase would hold an opening no model term makes."""
    if logged_states:
        return
    for name in ("drogue", "main"):
        charge = events.get(name)
        if charge is None or charge.source.startswith("apogee"):
            continue
        if all(abs(t - charge.time) > max(CLUSTER_GAP_S, 3.0 * charge.sigma)
               for t in deploy.values()):
            deployed = ", ".join(f"{n} at {t:.2f} s" for n, t in deploy.items())
            raise InputError(card.source, "parachutes", f"a canopy for each ejection charge "
                             f"the log shows; {src} shows one at {charge.time:.2f} s "
                             f"({charge.source}) that deploys none of the card's "
                             f"{len(deploy)} ({deployed})")


def import_flight(log: FlightRecord | AltusLog, card: FlightCard, out: str | Path,
                  still_air: bool = False) -> ImportSummary:
    """Write the test folder of `log` under `card` to `out` (see the module docstring);
    `still_air`: the default model (`rocket_model`) without the air's motion."""
    out = Path(out)
    record = log if isinstance(log, FlightRecord) else log.record()
    samples = record.samples
    src = str(record.path)
    baro = samples[["time", "altitude", "pressure"]].dropna()
    if len(baro) < 20:
        raise InputError(src, "pressure", "a barometer (pressure or altitude) read in at "
                         f"least 20 samples; the log has {len(baro)}")
    check_speed(record, baro["time"].to_numpy(), baro["altitude"].to_numpy(), MAX_SPEED_M_S,
                "no rocket is faster in the lower atmosphere")
    check_boost(record, samples)
    events, notes = flight_events(record)
    p0, pad_note = pad_pressure(baro, events, card)
    pad_altitude = float(pressure_altitude(p0))
    notes.append(pad_note)
    site_spec = card.site
    elevation = _si(site_spec.get("elevation"), "length", card.source, "site.elevation")
    t0, t0_note = pad_temperature(site_spec, p0, elevation, card.source)
    check_pad_air(record, p0, t0, "card" if "temperature" in site_spec else
                  "density" if "surface_density" in site_spec else "standard", elevation,
                  card.source, "pressure" in site_spec)
    events.update(card_events(card, baro, pad_altitude, events))
    deploy: dict[str, float] = {}
    deploy_sigma: dict[str, float] = {}
    kind = "a flight state of the log" if record.states else \
        "an event detected in the log (it has no flight states)"
    deploying = {name: e for name, e in events.items() if name != "landed"}
    for i, chute in enumerate(card.parachutes):
        state = chute["deployment"]
        if state not in deploying:
            listed = ", ".join(f"{n} {e.time:.2f} ± {e.sigma:.2f} s ({e.source})"
                               for n, e in deploying.items())
            raise InputError(card.source, f"parachutes[{i}].deployment",
                             f"{kind} {src} that deploys {chute['name']}, or one the card's "
                             f"'events' gives (found: {listed or 'none'}); got {state!r}")
        # Each canopy's opening is told apart by its own event (its charge, its snatch).
        if any(card.parachutes[j]["deployment"] == state for j in range(i)):
            raise InputError(card.source, f"parachutes[{i}].deployment",
                             f"an event no other canopy of the card deploys at; "
                             f"{state!r} deploys an earlier one too")
        deploy[chute["name"]] = events[state].time
        deploy_sigma[chute["name"]] = events[state].sigma
    check_charges_deploy(events, deploy, card, src, bool(record.states))
    t_begin = min(deploy.values())
    descent = baro[baro["time"] > t_begin]
    if len(descent) < MIN_DESCENT_SAMPLES or \
            float(descent["time"].max()) - t_begin < MIN_DESCENT_S:
        span = float(descent["time"].max()) - t_begin if len(descent) else 0.0
        raise InputError(src, "(time)", f"a descent of at least {MIN_DESCENT_S:g} s and "
                         f"{MIN_DESCENT_SAMPLES} altimeter samples after the first deployment "
                         f"({min(deploy, key=deploy.__getitem__)} at {t_begin:.2f} s) to fit; "
                         f"the log ends {span:.2f} s after it, with {len(descent)} samples")
    if "landed" in events:
        t_down = events["landed"].time
        ground = baro[(baro["time"] >= t_down) & (baro["time"] <= t_down + 3.0)]["altitude"]
        notes.append(f"touchdown at {t_down:.2f} s, {float(ground.median()) - pad_altitude:+.1f}"
                     " m (pressure altitude) from the pad")
    else:
        t_down = float(baro["time"].iloc[-1])
        notes.append(f"the log ends at {t_down:.2f} s, "
                     f"{float(baro['altitude'].iloc[-1]) - pad_altitude:.1f} m above the pad: "
                     "the phase ends at the log's end")
    t_end = t_down - TOUCHDOWN_MARGIN_S
    if not record.gnss.empty:
        last = enu_about(record.gnss).iloc[-1]
        notes.append(f"GNSS: {len(record.gnss)} fixes, the last {last['east']:+.0f} m east, "
                     f"{last['north']:+.0f} m north of the first (the descent is fitted "
                     "vertically: horizontal positions are not written to the folder)")
    # Series run SERIES_MARGIN_S beyond the phase so that every sensor covers it (the
    # estimator uses the samples inside the phase only).
    lo, hi = t_begin - SERIES_MARGIN_S, t_end + SERIES_MARGIN_S
    in_phase = (baro["time"] >= lo) & (baro["time"] <= hi)
    near_charge = np.zeros(len(baro), dtype=bool)
    for t_dep in deploy.values():
        near_charge |= ((baro["time"] >= t_dep - EVENT_SIGMA_S)
                        & (baro["time"] <= t_dep + EJECTION_EXCLUDE_S)).to_numpy()
    baro_phase = baro[in_phase.to_numpy() & ~near_charge]
    dead_baro = dead_samples(baro_phase["time"].to_numpy(), baro_phase["altitude"].to_numpy())
    if dead_baro.any():
        notes.append(dead_note("altimeter", baro_phase["time"].to_numpy()[dead_baro],
                               baro_phase["altitude"].to_numpy()[dead_baro], "m"))
        baro_phase = baro_phase[~dead_baro]

    check_speed(record, baro_phase["time"].to_numpy(), baro_phase["altitude"].to_numpy(),
                MAX_DESCENT_M_S, "no canopy descends faster")
    notes.append(t0_note)
    lapse_spec = site_spec.get("lapse_rate", {"value": 1e3 * ISA_LAPSE_K_M, "unit": "K/km"})
    fixes = record.gps_fixes()
    lapse_fit = None
    if lapse_spec == "gps":
        descent = fixes[(fixes["time"] >= t_begin) & (fixes["time"] <= t_down)]
        if len(descent) < 10:
            raise InputError(card.source, "site.lapse_rate", f"a value: 'gps' needs GPS "
                             f"fixes in the descent, and {src} has {len(descent)}")
        lapse_fit = fit_lapse_rate(descent, baro["pressure"], baro["time"], elevation, p0, t0)
        lapse = lapse_fit[0]
    else:
        lapse = _si(lapse_spec, "lapse_rate", card.source, "site.lapse_rate")
        if not 0.0 < lapse <= LAPSE_BOUNDS_K_M[1]:
            raise InputError(card.source, "site.lapse_rate", f"a lapse rate above 0 and at "
                             f"most the dry adiabat's {1e3 * LAPSE_BOUNDS_K_M[1]:g} K/km (or "
                             f"'gps'); got {1e3 * lapse:g} K/km")
        if record.has_gps_altitude:
            notes.append("the GNSS altitudes are not fitted: the card's lapse rate is given "
                         "('gps' fits it to them and fits them)")
    site = SiteAtmosphere(elevation, p0, t0, lapse)
    # One altimeter sigma per canopy phase, from the scatter about the local trend; a later
    # phase's from the time its descent has settled.
    t_baro, h_baro = baro_phase["time"].to_numpy(), baro_phase["altitude"].to_numpy()
    starts = sorted(deploy.values())
    bounds = [starts[0], *(settled_time(t_baro, h_baro, a, b)
                           for a, b in pairwise([*starts[1:], t_end])), t_end]
    parachutes = [dict(c) for c in card.parachutes]
    notes += canopy_diameters(parachutes, descent_drag_areas(deploy, parachutes, card, site,
                                                             t_baro, h_baro, t_end), card)
    # The altimeter's noise is correlated over a fraction of a second (a recorder's filter,
    # the static port's pressure swings as the vehicle swings): each canopy phase's samples
    # are averaged in blocks as long as that correlation (`independent_blocks`), so that the
    # fit weighs what the altimeter measured independently, and each sigma is the scatter of
    # the block means.
    edges = [lo, *bounds[1:-1], hi + 1.0]
    parts, baro_sigmas = [], []
    for (a, b), name, steady_end in zip(pairwise(edges), sorted(deploy, key=deploy.__getitem__),
                                        [*starts[1:], t_end], strict=True):
        part = baro_phase[(baro_phase["time"] >= a) & (baro_phase["time"] < b)]
        blocks, size = independent_blocks(part[["time", "altitude"]], steady_end)
        parts.append(blocks)
        if size > 1:
            seconds = size * sample_interval(part["time"].to_numpy())
            notes.append(f"altimeter under the {name} (from {a:.2f} s): noise correlated over "
                         f"{size} samples ({seconds:.2f} s), averaged in blocks of that "
                         f"length: {len(part)} samples -> {len(blocks)}")
        if len(blocks) < MIN_DESCENT_SAMPLES:  # too short a segment: the whole phase's
            blocks, steady_end = independent_blocks(baro_phase[["time", "altitude"]])[0], t_end
        baro_sigmas.append(max(MIN_BARO_SIGMA_M, block_sigma(blocks, steady_end)))
    baro_blocks = pd.concat(parts, ignore_index=True)

    fixes_phase = fixes[(fixes["time"] >= lo) & (fixes["time"] <= hi)]
    accel = samples[["time", "acceleration"]].dropna()
    dead_accel = dead_samples(accel["time"].to_numpy(), accel["acceleration"].to_numpy(),
                              clipped=True)
    accel_in = ((accel["time"] >= lo) & (accel["time"] <= hi)).to_numpy()
    if (dead_accel & accel_in).any():
        notes.append(dead_note("accelerometer", accel["time"].to_numpy()[dead_accel & accel_in],
                               accel["acceleration"].to_numpy()[dead_accel & accel_in],
                               "m/s^2"))
    accel = accel[accel_in & ~dead_accel]
    check_steady_accelerometer(record, accel["acceleration"].to_numpy())
    full_open = {name: peak for name, t in deploy.items() if t > t_begin
                 and (peak := opening_peak(accel, t)) is not None}
    # The accelerometer loses the same charge windows as the altimeter (the charge's jolt
    # is no force of the flight) and, in each later canopy's opening, the samples above the
    # drag ceiling (the shock cord's snatch; its time is the full-open event).
    accel_charge = np.zeros(len(accel), dtype=bool)
    for t_dep in deploy.values():
        accel_charge |= ((accel["time"] >= t_dep - EVENT_SIGMA_S)
                         & (accel["time"] <= t_dep + EJECTION_EXCLUDE_S)).to_numpy()
    accel = accel[~accel_charge]
    density = np.asarray(site.density(site.altitude_at_pressure(
        baro_phase["pressure"].to_numpy())), dtype=float).ravel()
    later = sorted((t, name) for name, t in deploy.items() if t > starts[0])
    snatches: dict[str, Snatch] = {}
    snatch = np.zeros(len(accel), dtype=bool)
    # A later canopy's opening lasts from its charge until its descent has settled, and at
    # least the OPENING_WINDOW_S its load peak is looked for in.
    # The next deployment (or the phase's end) after each later canopy's.
    nexts = [*starts[1:], t_end][1:]
    opening_ends = [min(max(t_settled, t_charge + OPENING_WINDOW_S), t_next) for t_charge,
                    t_settled, t_next in zip(starts[1:], bounds[1:-1], nexts, strict=True)]
    for (t_charge, name), t_settled, t_open, t_next in zip(
            later, bounds[1:-1], opening_ends, nexts, strict=True):
        ceiling = drag_ceiling(t_baro, h_baro, density, t_charge, t_settled, t_next)
        opening = (accel["time"] >= t_charge) & (accel["time"] < t_open)
        if ceiling is None or not opening.any():  # no accelerometer reading of the opening
            continue
        above = ((accel["time"] >= t_charge) & (accel["time"] < t_open)
                 & (accel["acceleration"] > ceiling)).to_numpy()
        left_out = accel[above]
        k = int(np.argmax(left_out["acceleration"])) if above.any() else None
        snatches[name] = Snatch(ceiling, int(above.sum()),
                                None if k is None else float(left_out["acceleration"].iloc[k]),
                                None if k is None else float(left_out["time"].iloc[k]))
        snatch |= above
    accel = accel[~snatch]
    # A sigma per segment from the scatter about a local trend (the body's swing about its
    # mean attitude is noise of this sensor): under each canopy's steady descent, and
    # apart in each later canopy's opening.
    accel_bounds = [*sorted({*starts, *opening_ends} - {t_end}), t_end]
    accel_sigmas = []
    # A test folder's sensors each cover the whole phase: an accelerometer that stops
    # reading inside it (dead, or logged in the boost only) is left out.
    has_accel = len(accel) >= 10 and float(accel["time"].min()) <= t_begin + SERIES_MARGIN_S \
        and float(accel["time"].max()) >= t_end - SERIES_MARGIN_S
    if not has_accel:
        accel_bounds = []
        span = (f" (its samples there span {accel['time'].min():.2f}-"
                f"{accel['time'].max():.2f} s, not the phase {t_begin:.2f}-{t_end:.2f} s)"
                if len(accel) else "")
        notes.append(f"no accelerometer over the log's phase{span}: the folder has the "
                     "altimeter only")
    for a, b in pairwise(accel_bounds):
        part = accel[(accel["time"] >= a) & (accel["time"] < b)]
        accel_sigmas.append(max(MIN_ACCEL_SIGMA, scatter_rms(
            part["time"].to_numpy(), part["acceleration"].to_numpy()) if len(part) > 10
            else second_difference_sigma(accel["acceleration"].to_numpy())))
    files = {"baro.csv": baro_blocks}
    sensors: list[dict[str, Any]] = [
        {"name": "baro", "kind": "baro", "file": "baro.csv",
         "columns": {"time": "s", "altitude": "m"},
         "sigma": {"altitude": {"value": round(baro_sigmas[0], 3), "unit": "m"}},
         "sigma_after": [{"time": {"value": round(t, 3), "unit": "s"},
                          "sigma": {"altitude": {"value": round(sig, 3), "unit": "m"}}}
                         for t, sig in zip(bounds[1:-1], baro_sigmas[1:], strict=True)]}]
    if has_accel:
        files["accelerometer.csv"] = accel
        sensors.append({
            "name": "accelerometer", "kind": "axial_accelerometer",
            "file": "accelerometer.csv", "columns": {"time": "s", "acceleration": "m/s^2"},
            "sigma": {"acceleration": {"value": round(accel_sigmas[0], 3), "unit": "m/s^2"}},
            "sigma_after": [{"time": {"value": round(t, 3), "unit": "s"},
                             "sigma": {"acceleration": {"value": round(sig, 3),
                                                        "unit": "m/s^2"}}}
                            for t, sig in zip(accel_bounds[1:-1], accel_sigmas[1:],
                                              strict=True)]})
    if lapse_fit is not None and len(fixes_phase) >= 2:
        files["gps_altitude.csv"] = fixes_phase[["time", "gps_altitude"]].rename(
            columns={"gps_altitude": "up"})
        sensors.append({"name": "gps_altitude", "kind": "gps_altitude",
                        "file": "gps_altitude.csv", "columns": {"time": "s", "up": "m"},
                        "sigma": {"altitude": {"value": round(lapse_fit[2], 3), "unit": "m"}}})
    manifest = {
        "format": FORMAT,
        "name": card.name,
        "description": f"{card.title}: {record.recorder} log {record.path.name}",
        "label": card.label,
        "vehicle": card.vehicle,
        "parachutes": [{k: v for k, v in c.items() if k != "deployment"}
                       for c in parachutes],
        "events": [event_entry("mortar_fire", name, t, deploy_sigma[name])
                   for name, t in deploy.items()]
                  + [event_entry("full_open", name, t, sigma)
                     for name, (t, sigma) in full_open.items()],
        "sensors": sensors,
        "atmosphere": {"model": "site",
                       "elevation": {"value": elevation, "unit": "m"},
                       "pressure": {"value": round(p0, 2), "unit": "Pa"},
                       "temperature": {"value": round(t0, 3), "unit": "K"},
                       "lapse_rate": {"value": round(1e3 * lapse, 4), "unit": "K/km"}},
        "phase": {"start": {"value": instant(t_begin), "unit": "s"},
                  "end": {"value": round(t_end, 3), "unit": "s"}},
        "model": rocket_model(card.model, [s["kind"] for s in sensors],
                              [(c["name"], c["stages"][0]) for c in parachutes
                               if not c.get("open_at_start")],
                              held_openings(deploy, events), deploy_sigma, still_air),
    }
    try:
        validate_manifest(manifest, card.source)
    except InputError as exc:
        raise blamed(exc, card.source, src, MANIFEST) from None
    summary = ImportSummary(
        record.recorder, (t_begin, t_end),
        {**deploy, **{f"{name} full open": t for name, (t, _) in full_open.items()},
         "touchdown": t_down}, site, lapse_fit,
        baro_sigmas, {name: len(frame) for name, frame in files.items()},
        {**record.dropped,
         "ejection_charge_samples": int((in_phase.to_numpy() & near_charge).sum()),
         "ejection_charge_accelerometer_samples": int(accel_charge.sum()),
         "snatch_samples_above_drag_ceiling": int(snatch.sum())},
        accel_sigmas, snatches, events, [*record.notes, *notes], card.nominal)
    _write_folder(out, manifest, files, summary, card.source, src)
    return summary


# Manifest fields the import copies from the card; the others it derives from the log.
CARD_FIELDS = ("name", "label", "vehicle", "parachutes", "model")


def blamed(exc: InputError, card_source: str, log_source: str, written: str) -> InputError:
    """What the test folder's loading refused in the file `written` of an import, named
    against where it came from: the card (the manifest's vehicle, canopies and model) or
    the log (the phase, events, sensors, atmosphere)."""
    if written == MANIFEST and exc.field.startswith(CARD_FIELDS):
        return InputError(card_source, exc.field, f"{exc.expectation} (in the manifest the "
                          "card makes)")
    return InputError(log_source, f"(imported as {written}: {exc.field})", exc.expectation)


def instant(t: float) -> float:
    """A time (s) as the manifest states it, to the microsecond: the phase's start and the
    first deployment, rounded alike, stay equal."""
    return round(t, 6)


def event_entry(name: str, parachute: str, t: float, sigma: float) -> dict[str, Any]:
    """A manifest event of `parachute` at `t` (s) with its timing `sigma` (s): the time to
    the microsecond and the sigma to four significant digits, never below `MIN_EVENT_SIGMA_S`
    (a detected event's sigma is a sample interval, a quarter of a millisecond at 4 kHz,
    which rounding to the millisecond made 0)."""
    return {"name": name, "parachute": parachute, "time": {"value": instant(t), "unit": "s"},
            "sigma": {"value": max(MIN_EVENT_SIGMA_S, float(f"{sigma:.4g}")), "unit": "s"}}


def _write_folder(out: Path, manifest: dict[str, Any], files: dict[str, pd.DataFrame],
                  summary: ImportSummary, card_source: str, log_source: str) -> None:
    """Write into a temporary sibling, check that it loads, then move it to `out`.  What the
    loading refuses in the manifest is named against where it came from: the card (its
    vehicle, canopies and model) or the log (the phase, events, sensors, atmosphere)."""
    if out.exists() and any(out.iterdir()):
        raise InputError(str(out), "(folder)", "a new or empty folder for the test")
    out.parent.mkdir(parents=True, exist_ok=True)
    tmp = Path(tempfile.mkdtemp(prefix=f".{out.name}-", dir=out.parent))
    try:
        for name, frame in files.items():
            frame.to_csv(tmp / name, index=False)
        (tmp / MANIFEST).write_text(json.dumps(manifest, indent=2) + "\n")
        (tmp / "import.json").write_text(json_text(summary.to_dict()))
        try:
            load_test(tmp)
        except InputError as exc:
            written = Path(exc.file)
            if written.parent != tmp:
                raise
            raise blamed(exc, card_source, log_source, written.name) from None
        if out.exists():
            out.rmdir()
        tmp.rename(out)
    finally:
        if tmp.exists():
            shutil.rmtree(tmp)


def descent_load_factor_peak(accel: pd.DataFrame, t_from: float, t_to: float
                             ) -> tuple[float, float]:
    """Largest axial specific force (g) between `t_from` and `t_to` (s) and its time (s).

    The logger's axial acceleration has 1 g subtracted, so the specific force
    along the axis is (a + g0) / g0; its magnitude is a lower bound on the
    load factor (the axis need not point along the riser)."""
    sel = accel[(accel["time"] >= t_from) & (accel["time"] <= t_to)]
    if sel.empty:
        raise ValueError(f"no accelerometer samples in [{t_from}, {t_to}] s")
    f = np.abs(sel["acceleration"].to_numpy() + G0) / G0
    k = int(np.argmax(f))
    return float(f[k]), float(sel["time"].iloc[k])


def opening_peak(accel: pd.DataFrame, t_charge: float) -> tuple[float, float] | None:
    """(time, sigma) in s of the opening-load peak after the charge at `t_charge` (s): the
    largest axial specific force from `EJECTION_EXCLUDE_S` to `OPENING_WINDOW_S` after it
    (`descent_load_factor_peak`; the charge's own jolt comes first), sigma the median
    sample interval.  None where the peak stands fewer than `OPENING_PEAK_SIGMAS` scatter
    sigmas (1.4826 MAD) off the median reading of the `OPENING_BASELINE_S` before the
    charge, or where the accelerometer has too few samples there to tell."""
    lo, hi = t_charge + EJECTION_EXCLUDE_S, t_charge + OPENING_WINDOW_S
    before = accel[(accel["time"] >= t_charge - OPENING_BASELINE_S)
                   & (accel["time"] < t_charge - EVENT_SIGMA_S)]["acceleration"].to_numpy()
    after = accel["time"][(accel["time"] >= lo) & (accel["time"] <= hi)].to_numpy()
    if before.size < 10 or after.size < 3:
        return None
    peak, t_peak = descent_load_factor_peak(accel, lo, hi)
    steady = float(np.median(before))
    scatter = max(MIN_ACCEL_SIGMA, 1.4826 * float(np.median(np.abs(before - steady))))
    if abs(peak * G0 - abs(steady + G0)) < OPENING_PEAK_SIGMAS * scatter:
        return None
    return t_peak, float(np.median(np.diff(after)))
