"""A reconstruction's fitted canopies as RocketPy parachutes (`cpas-ocp rocketpy`).

RocketPy is the flight simulator rocketry users fly their designs in.  Its `Parachute`
adds a drag area ``cd_s`` (m^2) to the rocket's descent ``lag`` seconds after its
``trigger`` fires ("apogee", or a height in m above the ground level, checked
``sampling_rate`` times a second), and its `rocketpy.stochastic.StochasticParachute` draws
``cd_s`` and ``lag`` from normals ``(value, sigma)`` for its Monte Carlo.  This module
builds both with RocketPy's own classes (never writing its file formats) from a
reconstruction that is a result and its test folder:

* ``cd_s``: the fitted drag area CdS[P,S] of the canopy's one stage, with the sigma of the
  fit's covariance (a drag area the model held fixed has sigma 0, and a note);
* ``trigger``: "apogee" for a canopy open when the record starts, or deployed near apogee
  (within the import's window about the apogee it found: `flight_log.held_openings`);
  else the height above the pad at its deployment (its `mortar_fire` event): the
  altimeter's pressure altitude read then (a fitted altimeter lag later, less a fitted
  altimeter bias), turned into height through the test's site atmosphere, less the pad's
  elevation.  RocketPy's height trigger fires on the way down once the rocket is below it;
  its ground level is its Environment's elevation, the pad's;
* ``lag``: the fitted inflation start t_start[P,S] less the deployment's time, with the
  sigma of t_start (0 where the model has no start for the canopy; a start before the
  recorded deployment is carried as 0, with a note).  RocketPy's canopy has its whole
  ``cd_s`` from the lag's end, where the fit's fills over n D_o / V from t_start.

RocketPy is imported only where its objects are built: the package never needs it, and
the command writes a script (`export_script`) that builds them where RocketPy is
installed (``pip install "cpas-ocp[rocketpy]"``).
"""

from __future__ import annotations

import importlib
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from cpas_ocp.errors import InputError
from cpas_ocp.io.flight_test import load_test
from cpas_ocp.io.import_reports import import_flight_events
from cpas_ocp.io.json_files import read_json
from cpas_ocp.io.output_folder import atomic_folder
from cpas_ocp.io.rocket_model import held_openings
from cpas_ocp.io.strict_json import json_text
from cpas_ocp.physics.atmosphere import SiteAtmosphere, geometric_altitude
from cpas_ocp.physics.flight_test import FlightTest
from cpas_ocp.physics.parameters import param_name
from cpas_ocp.precision import with_sigma

if TYPE_CHECKING:
    from cpas_ocp.api.reconstruction import Reconstruction

# How often RocketPy checks a trigger (Hz): its own default (`Rocket.add_parachute`), the
# barometer rate of the flight computers that fire the charges.
SAMPLING_RATE_HZ = 100.0

# The files the command writes, the first marking an earlier export it may replace.
EXPORT_FILES = ("parachutes.json", "parachutes.py")

INSTALL = 'RocketPy is not installed: pip install "cpas-ocp[rocketpy]" (or rocketpy>=1.3)'


@dataclass(frozen=True)
class ExportedCanopy:
    """One canopy as RocketPy takes it: drag area and its sigma (m^2), trigger ("apogee"
    or a height above the pad, m), lag after the trigger and its sigma (s), the
    deployment's time on the log's clock (s; None for a canopy open when the record
    starts), and notes on what was taken how."""

    name: str
    cd_s: float
    cd_s_std: float
    trigger: str | float
    lag: float
    lag_std: float
    deployment_s: float | None
    notes: tuple[str, ...] = ()

    def parachute_arguments(self, sampling_rate_hz: float) -> dict[str, Any]:
        """The keyword arguments of `rocketpy.Parachute` (name, cd_s, trigger,
        sampling_rate, lag)."""
        return {"name": self.name, "cd_s": self.cd_s, "trigger": self.trigger,
                "sampling_rate": sampling_rate_hz, "lag": self.lag}

    def stochastic_arguments(self) -> dict[str, Any]:
        """The keyword arguments of `rocketpy.stochastic.StochasticParachute` besides the
        parachute: cd_s and lag as (value, sigma), normal."""
        return {"cd_s": (self.cd_s, self.cd_s_std), "lag": (self.lag, self.lag_std)}

    def as_dict(self) -> dict[str, Any]:
        return {"name": self.name, "cd_s_m2": self.cd_s, "cd_s_std_m2": self.cd_s_std,
                "trigger": self.trigger,
                "trigger_kind": "apogee" if self.trigger == "apogee" else "height_agl_m",
                "lag_s": self.lag, "lag_std_s": self.lag_std,
                "deployment_s": self.deployment_s, "notes": list(self.notes)}


@dataclass(frozen=True)
class RocketPyExport:
    """A reconstruction's canopies for RocketPy, in deployment order, with the trigger's
    sampling rate (Hz)."""

    test: str
    canopies: tuple[ExportedCanopy, ...]
    sampling_rate_hz: float = SAMPLING_RATE_HZ

    def parachutes(self) -> list[Any]:
        """One `rocketpy.Parachute` per canopy (``rocket.parachutes.append(p)``)."""
        rocketpy = _rocketpy()
        return [rocketpy.Parachute(**c.parachute_arguments(self.sampling_rate_hz))
                for c in self.canopies]

    def stochastic_parachutes(self) -> list[Any]:
        """One `rocketpy.stochastic.StochasticParachute` per canopy, on its `Parachute`
        (``stochastic_rocket.add_parachute(sp)``)."""
        stochastic = _rocketpy("rocketpy.stochastic")
        return [stochastic.StochasticParachute(p, **c.stochastic_arguments())
                for c, p in zip(self.canopies, self.parachutes(), strict=True)]

    def as_dict(self) -> dict[str, Any]:
        return {"test": self.test, "units": "SI: m^2, m above the pad, s, Hz",
                "sampling_rate_hz": self.sampling_rate_hz,
                "parachutes": [c.as_dict() for c in self.canopies]}

    def summary(self) -> str:
        """One line per canopy, its notes below it."""
        lines = [f"RocketPy parachutes of {self.test} (trigger checked at "
                 f"{self.sampling_rate_hz:g} Hz):"]
        for c in self.canopies:
            trigger = "at apogee" if c.trigger == "apogee" else f"at {c.trigger:.1f} m AGL"
            lines.append(f"  {c.name:<12} cd_s {with_sigma(c.cd_s, c.cd_s_std)} m^2, "
                         f"trigger {trigger}, lag {with_sigma(c.lag, c.lag_std)} s")
            lines += [f"    note: {n}" for n in c.notes]
        return "\n".join(lines)


def _rocketpy(module: str = "rocketpy") -> Any:
    """RocketPy's `module`, imported here only: the package does not need it."""
    try:
        return importlib.import_module(module)
    except ModuleNotFoundError as exc:
        if exc.name is None or exc.name.split(".")[0] != "rocketpy":
            raise
        raise ModuleNotFoundError(INSTALL, name="rocketpy") from None


def rocketpy_export(report: Reconstruction | str | Path,
                    test: FlightTest | str | Path | None = None) -> RocketPyExport:
    """The canopies of a reconstruction as RocketPy takes them (module docstring): `report`
    is a `Reconstruction` (its own test, unless `test` is given) or a report folder
    written by `cpas-ocp reconstruct` (its result.json) with `test` its test folder.  A
    reconstruction that is not a result is refused (InputError naming why)."""
    if isinstance(report, str | Path):
        where = str(Path(report) / "result.json")
        result = read_json(Path(report) / "result.json",
                           "a report folder of cpas-ocp reconstruct (holding result.json)")
        if test is None:
            raise InputError(where, "(test folder)", "the test folder the report reconstructs")
    else:
        from cpas_ocp.reports.report import result_dict
        where = f"(reconstruction of {report.fit.test.name})"
        result = {**result_dict(report.fit, report.covariance),
                  "claim": report.claim.as_dict()}
        test = report.fit.test if test is None else test
    test = test if isinstance(test, FlightTest) else load_test(test)
    require_claim(result, where)
    if result.get("test") != test.name:
        raise InputError(where, "test", f"the reconstruction of the test folder given "
                         f"({test.name!r}); it is that of {result.get('test')!r}")
    return RocketPyExport(test.name, tuple(_canopy(test, result, where, k)
                                           for k in range(len(test.parachutes))))


def require_claim(result: Mapping[str, Any], where: str) -> None:
    """InputError unless `result` (a result.json) says it is a result: a fit that is not
    one is no drag area to fly."""
    claim = result.get("claim")
    if not isinstance(claim, Mapping) or "result" not in claim:
        raise InputError(where, "claim", "a reconstruction's claim saying whether it is a "
                         "result (written by cpas-ocp reconstruct); this one has none")
    if claim["result"] is not True:
        problems = claim.get("problems") or ["(no reason given)"]
        raise InputError(where, "claim.result", f"a reconstruction that is a result, to fly "
                         f"its drag areas in RocketPy; this one is not: {problems[0]}")


def _fitted(result: Mapping[str, Any], name: str) -> tuple[float, float | None, bool] | None:
    """Parameter `name` of a result.json: (value, sigma or None where the fit gives none,
    whether it was held fixed); None where the model has no such parameter."""
    if name in (result.get("parameters") or {}):
        entry = result["parameters"][name]
        return float(entry["value"]), entry.get("std"), False
    if name in (result.get("fixed") or {}):
        return float(result["fixed"][name]["value"]), 0.0, True
    return None


def _values(result: Mapping[str, Any]) -> dict[str, float]:
    """Every parameter's value of a result.json, free and fixed (SI)."""
    return {n: float(e["value"]) for block in ("fixed", "parameters")
            for n, e in (result.get(block) or {}).items()}


def _canopy(test: FlightTest, result: Mapping[str, Any], where: str, k: int
            ) -> ExportedCanopy:
    """Canopy `k` of `test` as RocketPy takes it (module docstring)."""
    chute = test.parachutes[k]
    field = f"parachutes[{k}]"
    if len(chute.stages) != 1 or chute.altitude_bands:
        raise InputError(_manifest(test), f"{field}.stages", "one stage and no altitude "
                         f"bands: RocketPy's Parachute has one drag area, {chute.name} has "
                         f"{len(chute.stages)} stage(s) and {len(chute.altitude_bands)} "
                         "band edge(s)")
    stage = chute.stages[0]
    notes: list[str] = []
    cds_name = param_name("CdS", chute.name, stage)
    cds = _fitted(result, cds_name)
    if cds is None:
        raise InputError(where, "parameters", f"{cds_name}, the drag area of the test's "
                         f"canopy {chute.name}")
    if cds[1] is None:
        raise InputError(where, f"parameters.{cds_name}.std", "a drag area the data "
                         "determine, with a sigma for RocketPy's Monte Carlo (it is at a "
                         "bound or undetermined)")
    if cds[2]:
        notes.append(f"{cds_name} was held fixed in the fit: sigma 0")
    trigger, at, why = deployment_trigger(test, _values(result), chute.name)
    notes += why
    lag, lag_std = _lag(result, param_name("t_start", chute.name, stage), at, notes)
    return ExportedCanopy(chute.name, cds[0], float(cds[1]), trigger, lag, lag_std, at,
                          tuple(notes))


def _lag(result: Mapping[str, Any], start_name: str, deployed: float | None,
         notes: list[str]) -> tuple[float, float]:
    """The lag (s) from the deployment at `deployed` to the fitted start `start_name`, and
    its sigma: 0 where either is missing (a missing start noted); at least 0 (noted)."""
    start = _fitted(result, start_name)
    if deployed is None:  # open from the record's start: its trigger's note says so
        return 0.0, 0.0
    if start is None:
        notes.append(f"the model has no inflation start {start_name}: lag 0")
        return 0.0, 0.0
    value, std, fixed = start
    if std is None or fixed:
        notes.append(f"{start_name} has no sigma in the fit: the lag's sigma is 0")
    lag = value - deployed
    if lag < 0.0:
        notes.append(f"{start_name} ({value:.3f} s) precedes the recorded deployment "
                     f"({deployed:.3f} s) by {-lag:.3f} s: lag 0")
        lag = 0.0
    std = float(std or 0.0)
    if lag < 2.0 * std:
        notes.append(f"the lag's sigma {std:.3f} s lets RocketPy's normal draw negative lags "
                     "(it asks for lags that stay positive): give StochasticParachute a "
                     "narrower lag where the fit cannot tell the start")
    return lag, std


def _manifest(test: FlightTest) -> str:
    return str(test.path / "manifest.json") if test.path is not None else f"({test.name})"


def deployment_trigger(test: FlightTest, values: Mapping[str, float], name: str
                       ) -> tuple[str | float, float | None, list[str]]:
    """Canopy `name`'s RocketPy trigger ("apogee", or its deployment's height above the
    pad, m), the deployment's time (s; None where it was open when the record started)
    and notes.  `values` are the fit's parameters (the altimeter's bias and lag)."""
    chute = test.parachute(name)
    if chute.open_at_start:
        return "apogee", None, ["open when the record starts (its deployment is not in the "
                                "log): taken as deployed at apogee"]
    event = test.event("mortar_fire", name)
    if event is None:
        raise InputError(_manifest(test), "events", f"a mortar_fire event of canopy {name}: "
                         "its deployment, which RocketPy's trigger is taken from")
    if held_openings({name: event.time}, import_flight_events(test.path)):
        return "apogee", event.time, []
    height = deployment_height(test, values, event.time)
    return height, event.time, [f"deployed at {event.time:.2f} s, {height:.1f} m above the "
                                "pad by the altimeter"]


def deployment_height(test: FlightTest, values: Mapping[str, float], t: float) -> float:
    """The height (m) above the pad at time `t` (s) by the test's first altimeter: its
    pressure altitude read at t + lag (interpolated between samples), less its bias, the
    altimeter's fitted lag[X] and bias[X,altitude] where `values` hold them; turned into
    height through the site atmosphere (whose elevation is the pad's)."""
    if not isinstance(test.atmosphere, SiteAtmosphere):
        raise InputError(_manifest(test), "atmosphere.model", "a site atmosphere (the pad's "
                         "elevation and air), from which a deployment's height above ground "
                         "is measured for RocketPy's trigger")
    altimeters = test.sensors_of("baro")
    if not altimeters:
        raise InputError(_manifest(test), "sensors", "a baro sensor, whose reading at a "
                         "deployment gives its height for RocketPy's trigger")
    baro = altimeters[0]
    read_at = t + values.get(param_name("lag", baro.name), 0.0)
    times = baro.time
    if not times[0] <= read_at <= times[-1]:
        raise InputError(_manifest(test), f"sensors[{baro.name}]", f"altimeter samples "
                         f"around the deployment at {t:.2f} s; they cover {times[0]:.2f}-"
                         f"{times[-1]:.2f} s")
    reading = float(np.interp(read_at, times, baro.data["altitude"].to_numpy()))
    reading -= values.get(param_name("bias", baro.name, "altitude"), 0.0)
    height = float(geometric_altitude(test.atmosphere, np.asarray(reading)))
    return height - test.atmosphere.elevation_m


def export_script(export: RocketPyExport) -> str:
    """A Python script that builds the export's parachutes with RocketPy, the numbers
    written in: PARACHUTES (rocketpy.Parachute) and STOCHASTIC_PARACHUTES
    (rocketpy.stochastic.StochasticParachute), each a dict by canopy name."""
    def call(kind: str, arguments: Mapping[str, Any], first: str = "") -> str:
        return f"{kind}({first}" + ", ".join(f"{k}={v!r}" for k, v in arguments.items()) + ")"

    chutes, stochastic = [], []
    for c in export.canopies:
        chutes += [f"    # {note}" for note in c.notes]
        chutes.append(f"    {c.name!r}: "
                      f"{call('Parachute', c.parachute_arguments(export.sampling_rate_hz))},")
        on = f"PARACHUTES[{c.name!r}], "
        stochastic.append(f"    {c.name!r}: "
                          f"{call('StochasticParachute', c.stochastic_arguments(), on)},")
    return "\n".join([
        f'"""RocketPy parachutes of the reconstruction of {export.test} (cpas-ocp rocketpy).',
        "",
        "cd_s: the fitted drag area (m^2), with its 1-sigma in the stochastic parachutes;",
        "trigger: \"apogee\", or the deployment's height above the pad (m, RocketPy's ground",
        "level: its Environment's elevation); lag: from the trigger to the fitted inflation",
        "start (s).  Add them with rocket.parachutes.append(PARACHUTES[name]), and",
        "stochastic_rocket.add_parachute(STOCHASTIC_PARACHUTES[name]) for a Monte Carlo.",
        '"""',
        "",
        "from rocketpy import Parachute",
        "from rocketpy.stochastic import StochasticParachute",
        "",
        "PARACHUTES = {", *chutes, "}",
        "",
        "STOCHASTIC_PARACHUTES = {", *stochastic, "}",
        "",
        'if __name__ == "__main__":',
        "    for name, chute in PARACHUTES.items():",
        '        print(f"{name}: cd_s {chute.cd_s} m^2, trigger {chute.trigger!r}, '
        'lag {chute.lag} s")',
        ""])


def write_export(export: RocketPyExport, out: str | Path) -> Path:
    """Write parachutes.json (the numbers) and parachutes.py (`export_script`) to the
    folder `out`, all or nothing; the folder."""
    out = Path(out)
    with atomic_folder(out, EXPORT_FILES[0]) as tmp:
        (tmp / EXPORT_FILES[0]).write_text(json_text(export.as_dict()))
        (tmp / EXPORT_FILES[1]).write_text(export_script(export))
    return out
