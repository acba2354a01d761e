"""A known rocket flight, and the log an Altus Metrum flight computer writes of it: a recorder
log to learn `cpas-ocp import` on before flying one's own (`example_log`), and the seeded
truth the import's tests compare with.

The flight: a 16.31 kg airframe (with a 0.1 kg drogue and a 0.5 kg main aboard) boosted
vertically by 900 N for 2.5 s from a pad 1,401 m above sea level, a 24 in drogue
(CdS 0.467 m^2) fired `drogue_delay_s` after apogee and a 72 in main (CdS 5.78 m^2) at
300 m above the pad, touching down on ground 7 m above the pad.  Vertical point-mass
physics, integrated at 2 ms:

    m dv/dt = T - m g - 1/2 rho(h) v|v| (CdS_body + sum_c CdS_c(t)),

each canopy's drag area growing linearly over its fill (0.6 s drogue, 1.2 s main) from
0.3 s after its charge, through a site atmosphere from the surface density (1.001 kg/m^3)
and a lapse rate of 8 K/km.  The axis stays vertical, so the axial specific force is
(T - drag) / m.  The logger sees the pressure with 2 Pa noise (5 Pa in `example_log`) and
the axial acceleration with 0.3 m/s^2 noise, each ejection charge's pressure pulse and jolt,
the main's snatch and the landing's impact.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from cpas_ocp.physics.atmosphere import SiteAtmosphere, pressure_altitude
from cpas_ocp.physics.units import G0

SITE = SiteAtmosphere.from_surface_density(1401.0, 86300.0, 1.001, 0.008)
RATE_HZ = 100.0  # Hz, the logged sample rate
MASS = 16.31  # kg, vehicle without canopies
DRY_MASS = {"drogue": 0.1, "main": 0.5}  # kg, the canopies (flown from the launch)
FLOWN = MASS + sum(DRY_MASS.values())
CDS_BODY = 0.012  # m^2, the rocket's forebody drag area
CDS = {"drogue": 0.467, "main": 5.78}  # m^2, the canopies' full drag areas
FILL_S = {"drogue": 0.6, "main": 1.2}  # s from the canopy's line stretch to full open
LINE_STRETCH_S = 0.3  # s from the charge to the canopy starting to fill
THRUST_N, BURN_S = 900.0, 2.5
DROGUE_DELAY_S = 1.0  # the charge fires this long after apogee
MAIN_AGL_M = 300.0
GROUND_M = 7.0  # the landing site is this far above the pad
P_NOISE_PA, A_NOISE = 2.0, 0.3  # barometer (Pa) and accelerometer (m/s^2) noise sigmas
# The site atmosphere tabulated every metre above the pad (linear between: < 1 mPa off).
H_TABLE = np.arange(-50.0, 12000.0, 1.0)
P_TABLE = np.asarray(SITE.pressure(SITE.elevation_m + H_TABLE), dtype=float)
RHO_TABLE = np.asarray(SITE.density(SITE.elevation_m + H_TABLE), dtype=float)


@dataclass(frozen=True)
class Flight:
    """The truth: samples at the logged rate (time s, height above the pad m, vertical
    velocity m/s, axial specific force m/s^2) and the event times (s)."""

    t: np.ndarray
    h: np.ndarray
    v: np.ndarray
    f: np.ndarray
    events: dict[str, float]


def fly(seconds_after_touchdown: float = 10.0, thrust_n: float = THRUST_N,
        drogue_delay_s: float = DROGUE_DELAY_S, cds: dict[str, float] | None = None,
        main_agl_m: float = MAIN_AGL_M, rate_hz: float = RATE_HZ,
        chutes: tuple[str, ...] = ("drogue", "main")) -> Flight:
    """Integrate m dv/dt = T - m g - 1/2 rho v|v| CdS(t) at 2 ms (deterministic), the canopies'
    drag areas growing linearly over their fill from LINE_STRETCH_S after their charge; the
    vehicle's axis stays vertical, so the axial specific force is (T - drag) / m.

    `thrust_n` (N, for BURN_S) sets the apogee, `drogue_delay_s` (s) the first canopy's
    charge after apogee, `cds` (m^2) the canopies' full drag areas (0 for a canopy that does
    not open), `main_agl_m` (m above the pad) the second canopy's charge, and `rate_hz` (Hz)
    the logged sample rate; the canopies flown are `chutes` (a single main fired at apogee:
    ``("main",)``).
    """
    cds_full = CDS if cds is None else cds
    dt = 2e-3
    t, h, v = -2.0, 0.0, 0.0
    charge: dict[str, float] = {}
    events = {"boost": 0.0, "coast": BURN_S}
    rows = []
    apogee = None
    landed = None
    while landed is None or t < landed + seconds_after_touchdown:
        thrust = thrust_n if 0.0 <= t < BURN_S else 0.0
        cds_now = CDS_BODY + sum(
            cds_full[c] * min(max((t - tc - LINE_STRETCH_S) / FILL_S[c], 0.0), 1.0)
            for c, tc in charge.items())
        rho = float(np.interp(h, H_TABLE, RHO_TABLE))
        drag = -0.5 * rho * v * abs(v) * cds_now
        on_ground = landed is not None or (t < 0.0)
        f = (thrust + drag) / FLOWN if not on_ground else G0
        rows.append((t, h, v, f))
        if not on_ground:
            v += (f - G0) * dt
            h += v * dt
        t = round(t + dt, 6)
        if apogee is None and t > BURN_S and v < 0.0:
            apogee = t
            events["apogee"] = t
        if apogee is not None and chutes[0] not in charge and t >= apogee + drogue_delay_s:
            charge[chutes[0]] = t
        if len(chutes) > 1 and chutes[0] in charge and chutes[1] not in charge \
                and h <= main_agl_m and v < 0:
            charge[chutes[1]] = t
        if landed is None and apogee is not None and h <= GROUND_M:
            h, v, landed = GROUND_M, 0.0, t
    every = round(1.0 / (rate_hz * dt))
    a = np.array(rows)[::every]
    events.update(charge)
    events["landed"] = landed
    return Flight(a[:, 0], a[:, 1], a[:, 2], a[:, 3], events)


def sensor_readings(flight: Flight, seed: int, p_noise_pa: float = P_NOISE_PA
                    ) -> tuple[np.ndarray, np.ndarray]:
    """Pressure (Pa, noise sigma `p_noise_pa`) and axial reading (m/s^2, 1 g subtracted)
    with noise drawn from `seed`, the ejection charges' pressure pulses and jolts, the
    main's snatch and the landing's impact."""
    rng = np.random.default_rng(seed)
    p = np.interp(flight.h, H_TABLE, P_TABLE)
    p += rng.normal(0.0, p_noise_pa, p.size)
    a = flight.f - G0 + rng.normal(0.0, A_NOISE, p.size)
    landed = flight.t >= flight.events["landed"]
    a[landed] = -G0 + rng.normal(0.0, A_NOISE, int(landed.sum()))  # lying on its side
    charges = [name for name in ("drogue", "main") if name in flight.events]
    for name in charges:
        k = _index(flight, flight.events[name])
        p[k:k + 3] += (900.0, 400.0, 150.0)  # the charge's gas at the static port
        a[k:k + 2] += (8.0 * G0, -5.0 * G0)
    if len(charges) > 1:  # the shock cord's snatch of the later canopy
        a[_index(flight, flight.events[charges[1]] + 1.0)] += 14.0 * G0
    a[_index(flight, flight.events["landed"])] += 12.0 * G0  # the impact
    return p, a


def _index(flight: Flight, t: float) -> int:
    return int(np.searchsorted(flight.t, t - 1e-9))


def sample_time(flight: Flight, t: float) -> float:
    """The first sample at or after `t` (s): where a logger can first see an event."""
    return float(flight.t[_index(flight, t)])


ALTUS_HEADER = ("#version,serial,flight,call,time,state,state_name,acceleration,pressure,"
                "altitude,height,speed,temperature,accel_x,accel_y,accel_z,nsat,latitude,"
                "longitude,altitude,hdop")


def write_altus(flight: Flight, path: Path, seed: int, p_noise_pa: float = P_NOISE_PA
                ) -> tuple[int, int]:
    """An AltOS export of the flight (states from the truth, the landed state 4 s late as
    AltOS decides it), pressure in whole Pa and acceleration in 0.5 m/s^2 steps (so that
    real samples repeat both readings; the filter's speed tells them apart), and a GPS
    record's row after every 100th sample repeating it.  Returns the number of those
    repeating rows, and of real samples that by chance repeat every reading of the
    previous one, the filter's height and speed included (no reader can tell those).
    The pressure's noise sigma is `p_noise_pa` (Pa)."""
    p, a = sensor_readings(flight, seed, p_noise_pa)
    p, a = np.round(p), np.round(a * 2.0) / 2.0
    # The flight computer's filter steps its speed at every sample, at rest too.
    speed = np.round(flight.v + np.random.default_rng(seed + 30).normal(0.0, 0.05, p.size), 2)
    logged = flight.t >= -0.3 - 1e-9
    same = np.all(np.diff(np.c_[p, a, speed, np.round(flight.h, 2)][logged], axis=0) == 0,
                  axis=1)
    ev = flight.events
    order = [("boost", -np.inf), ("coast", ev["coast"]), ("drogue", ev["drogue"]),
             ("main", ev["main"]), ("landed", ev["landed"] + 4.0)]
    lines, copies = [ALTUS_HEADER], 0
    for k, t in enumerate(flight.t):
        if t < -0.3:
            continue
        state = [name for name, t0 in order if t >= t0 - 1e-9][-1]
        lat = 32.94 + 2e-6 * max(t, 0.0)
        row = (f"6, 1234, 2,N0CALL, {t:8.2f}, 3, {state:>7s}, {a[k]:7.2f}, {p[k]:9.2f}, "
               f"{float(pressure_altitude(p[k])):8.2f}, {flight.h[k]:8.2f}, {speed[k]:8.2f}, "
               f"30.0, 0.0, 0.0, 0.0, 9, {lat:12.7f}, -106.9000000, "
               f"{SITE.elevation_m + flight.h[k]:7.1f},2147483647.0")
        lines.append(row)
        if k % 100 == 50:
            lines.append(row.replace(f"{t:8.2f}", f"{t + 0.005:8.3f}", 1)
                         .replace(", 9, ", ", 10, ", 1))
            copies += 1
    path.write_text("\n".join(lines) + "\n")
    return copies, int(same.sum())


def card(fmt: str | None = None) -> dict[str, Any]:
    """The flight card a flyer writes for this rocket from the flight-card page: the
    airframe's mass and drag area, each canopy's diameter, dry mass and the charge that
    deploys it, the launch site, and the model (the canopies' inflation, the forebody's
    drag, a rigid riser, the barometer); with `fmt`, the card's ``data.format`` too."""
    return {
        "name": "example_rocket", "kind": "flight_log", "title": "a known rocket flight",
        "data": {"folder": "", "logs": [], **({"format": fmt} if fmt else {})},
        "vehicle": {"name": "rocket", "mass": {"value": MASS, "unit": "kg"},
                    "forebody_cds": {"value": CDS_BODY, "unit": "m^2"}},
        "parachutes": [
            {"name": "drogue", "type": "drogue", "deployment": "drogue",
             "diameter": {"value": 24, "unit": "in"},
             "dry_mass": {"value": DRY_MASS["drogue"], "unit": "kg"},
             "inflation": "finite_mass", "stages": ["stage1"]},
            {"name": "main", "type": "main", "deployment": "main",
             "diameter": {"value": 72, "unit": "in"},
             "dry_mass": {"value": DRY_MASS["main"], "unit": "kg"},
             "inflation": "finite_mass", "stages": ["stage2"]}],
        "site": {"elevation": {"value": 1401, "unit": "m"},
                 "surface_density": {"value": 1.001, "unit": "kg/m^3"},
                 "lapse_rate": {"value": 8.0, "unit": "K/km"}},
        "model": {"effects": ["canopy_inflation", "forebody_drag", "rigid_riser", "baro"]},
    }


EXAMPLE_P_NOISE_PA = 5.0  # Pa (about 0.5 m): a flying altimeter's scatter, its port's
# airflow included, above the import's 0.3 m resolution floor


def example_log(folder: str | Path, seed: int = 1, main_opens: bool = True,
                rate_hz: float = 20.0, p_noise_pa: float = EXAMPLE_P_NOISE_PA) -> Path:
    """Write a known flight's Altus Metrum log (`flight.csv`, as AltOS exports it, at
    `rate_hz` Hz, pressure noise sigma `p_noise_pa` Pa, noise drawn from `seed`) and its
    flight card (`card.json`) into `folder`, and return the folder.  With `main_opens`
    False the main's charge fires at 300 m and the canopy never inflates: the rocket lands
    under its drogue, as recoveries do fail."""
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    cds = CDS if main_opens else {**CDS, "main": 0.0}
    write_altus(fly(cds=cds, rate_hz=rate_hz), folder / "flight.csv", seed, p_noise_pa)
    (folder / "card.json").write_text(json.dumps(card("altus"), indent=1) + "\n")
    return folder
