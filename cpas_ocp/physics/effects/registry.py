"""Effects by name: what a manifest's `model` block (or a model file) may list.

Every built-in effect is registered under its `name`.  A plug-in file (a
Python file defining `Effect` subclasses) registers its classes the same way,
so a manifest names a user's effect exactly like a library one.  An entry
may carry preset options (the load-cell bias is `SensorBias` on the load-cell
channel); options given in the manifest override them and must be
constructor arguments of the class.
"""

from __future__ import annotations

import dataclasses
import difflib
import importlib.util
import inspect
import sys
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from cpas_ocp.errors import InputError, PluginError
from cpas_ocp.physics.effects.added_mass import AddedMass
from cpas_ocp.physics.effects.axial_accelerometer import AxialAccelerometer
from cpas_ocp.physics.effects.base import Effect
from cpas_ocp.physics.effects.canopy_inflation import CanopyInflation
from cpas_ocp.physics.effects.deployment_load import DeploymentLoad
from cpas_ocp.physics.effects.drag_law_terms import DragLawTerms
from cpas_ocp.physics.effects.drag_scale import DragScale
from cpas_ocp.physics.effects.elastic_riser import ElasticRiser
from cpas_ocp.physics.effects.fly_out import FlyOut
from cpas_ocp.physics.effects.forebody_drag import ForebodyDrag
from cpas_ocp.physics.effects.loadcell_friction import LoadCellFriction
from cpas_ocp.physics.effects.loadcell_scale import LoadCellScale
from cpas_ocp.physics.effects.pilot_deployment import PilotDeployment
from cpas_ocp.physics.effects.plugin_guard import HOOKS, guard_hooks, plugin_failure
from cpas_ocp.physics.effects.rigid_riser import RigidRiser
from cpas_ocp.physics.effects.sensor_bias import SensorBias
from cpas_ocp.physics.effects.sensor_lag import SensorLag
from cpas_ocp.physics.effects.sensors import (
    BaroSensor,
    GpsAltitudeSensor,
    GpsSensor,
    ImuSensor,
    LoadCellSensor,
)
from cpas_ocp.physics.effects.wake_deficit import WakeDeficit
from cpas_ocp.physics.effects.wind_process import WindProcess


@dataclass(frozen=True)
class EffectType:
    """A registered effect: its class and the options it is built with by default.

    `candidate`: the diagnosis score-tests it as a missing effect.  The wind
    process is not one yet: its score test adds a parameter per knot and
    component, and a process that absorbs any slow residual would stand in for
    the effects the diagnosis is meant to tell apart; it is added by a model
    block.
    """

    name: str
    cls: type[Effect]
    preset: dict[str, Any] = field(default_factory=dict)
    source: str = "cpas_ocp"
    candidate: bool = True

    @property
    def summary(self) -> str:
        """First line of the class docstring, else of its module's (dataclasses invent one)."""
        doc = inspect.getdoc(self.cls) or ""
        if not doc or doc.startswith(f"{self.cls.__name__}("):
            doc = inspect.getdoc(sys.modules.get(self.cls.__module__)) or ""
        return doc.split("\n")[0]

    def options(self) -> list[str]:
        """Constructor arguments a manifest may set (the registered name is not one)."""
        if dataclasses.is_dataclass(self.cls):
            names = [f.name for f in dataclasses.fields(self.cls) if f.init]
        else:
            sig = inspect.signature(self.cls.__init__)
            names = [p for p in sig.parameters if p != "self"]
        return [n for n in names if n != "name"]

    def build(self, options: dict[str, Any], file: str, field_path: str) -> Effect:
        """An instance with `options` over the preset; InputError naming an unknown option."""
        allowed = self.options()
        for key in options:
            if key not in allowed:
                listed = ", ".join(allowed) if allowed else "none"
                raise InputError(file, f"{field_path}.{key}",
                                 f"an option of effect {self.name!r} ({listed})")
        kwargs = {**self.preset, **options}
        if dataclasses.is_dataclass(self.cls) and "name" in {f.name for f in
                                                             dataclasses.fields(self.cls)}:
            kwargs["name"] = self.name
        try:
            return self.cls(**kwargs)
        except (TypeError, ValueError, AttributeError, KeyError) as exc:
            raise InputError(file, field_path, f"valid options of {self.name!r}: {exc}") from None
        except BaseException as exc:  # a plug-in's constructor failing in its own code
            if self.source == "cpas_ocp" or not plugin_failure(exc):
                raise
            raise PluginError(self.source, f"{self.cls.__name__}.__init__",
                              f"raised {type(exc).__name__}: {exc}") from None


def _builtin() -> dict[str, EffectType]:
    entries = [
        EffectType("canopy_inflation", CanopyInflation),
        EffectType("forebody_drag", ForebodyDrag),
        EffectType("wake_deficit", WakeDeficit),
        EffectType("fly_out", FlyOut),
        EffectType("rigid_riser", RigidRiser),
        EffectType("elastic_riser", ElasticRiser),
        EffectType("pilot_deployment", PilotDeployment),
        EffectType("deployment_load", DeploymentLoad),
        EffectType("added_mass", AddedMass),
        EffectType("drag_scale", DragScale),
        EffectType("loadcell_scale", LoadCellScale),
        EffectType("gps", GpsSensor),
        EffectType("imu", ImuSensor),
        EffectType("load_cell", LoadCellSensor),
        EffectType("imu_bias", SensorBias),
        EffectType("loadcell_friction", LoadCellFriction),
        EffectType("loadcell_bias", SensorBias,
                    {"kind": "load_cell", "channel": "tension", "unit": "N", "bound": 1.0e4,
                     "scale": 100.0}),
        EffectType("gps_lag", SensorLag),
        EffectType("baro", BaroSensor),
        EffectType("gps_altitude", GpsAltitudeSensor),
        EffectType("baro_bias", SensorBias,
                    {"kind": "baro", "channel": "altitude", "unit": "m", "bound": 500.0,
                     "scale": 1.0}),
        EffectType("baro_lag", SensorLag, {"kind": "baro", "max_lag": 0.5}),
        EffectType("wind_process", WindProcess, candidate=False),
        EffectType("axial_accelerometer", AxialAccelerometer, candidate=False),
        EffectType("drag_law_terms", DragLawTerms, candidate=False),
    ]
    return {e.name: e for e in entries}


BUILTIN: dict[str, EffectType] = _builtin()

# Names of the baseline effect set, in composition order.
BASELINE = ("canopy_inflation", "forebody_drag", "rigid_riser", "drag_scale", "loadcell_scale",
            "gps", "imu", "load_cell")

# The effect that predicts each sensor kind's readings (its measurement model).
SENSOR_EFFECTS = {"gps": "gps", "imu_load_factor": "imu", "load_cell": "load_cell",
                  "baro": "baro", "gps_altitude": "gps_altitude",
                  "axial_accelerometer": "axial_accelerometer"}


def load_plugin(path: Path) -> dict[str, EffectType]:
    """The `Effect` subclasses defined in the Python file `path`, by their `name`.

    A file that does not import, or defines no effect, is the user's mistake
    and raises InputError naming it.
    """
    if not path.is_file():
        raise InputError(str(path), "(file)", "an existing Python file defining Effect subclasses")
    module_name = f"cpas_ocp_plugin_{abs(hash(str(path.resolve())))}"
    spec = importlib.util.spec_from_file_location(module_name, path)
    if spec is None or spec.loader is None:
        raise InputError(str(path), "(file)", "an importable Python file")
    module = importlib.util.module_from_spec(spec)
    sys.modules[module_name] = module
    try:
        spec.loader.exec_module(module)
    except BaseException as exc:  # any failure inside the user's file is an input error
        sys.modules.pop(module_name, None)
        if not plugin_failure(exc):  # a real signal
            raise
        raise InputError(str(path), "(python)",
                         f"an importable file; importing it raised {type(exc).__name__}: {exc}"
                         ) from None
    found = {}
    for obj in vars(module).values():
        if (inspect.isclass(obj) and issubclass(obj, Effect) and obj is not Effect
                and obj.__module__ == module_name):
            name = getattr(obj, "name", "effect")
            if name == "effect":
                raise InputError(str(path), obj.__name__, "an Effect subclass with its own `name`")
            _check_hooks(path, obj)
            guard_hooks(obj, path)
            found[name] = EffectType(name, obj, source=str(path))
    if not found:
        raise InputError(str(path), "(python)", "at least one Effect subclass")
    return found


def load_plugins(paths: Sequence[str | Path]) -> dict[str, EffectType]:
    """The effects of the plug-in files `paths` (`load_plugin` each), by name."""
    out: dict[str, EffectType] = {}
    for path in paths:
        out.update(load_plugin(Path(path)))
    return out


# The hooks through which an effect changes a prediction or chi-square.
ACTING_HOOKS = ("forces", "observations", "constraints", "penalties")


def _check_hooks(path: Path, effect: type[Effect]) -> None:
    """Refuse a plug-in effect that would contribute nothing: one whose method names look
    like a hook misspelt (`force` for `forces`), or that overrides none of the hooks
    through which an effect acts.  Either way the model would accept it silently and
    report it as an effect that changes nothing."""
    for attr, value in vars(effect).items():
        if attr.startswith("_") or not callable(value) or attr in HOOKS:
            continue
        close = difflib.get_close_matches(attr, HOOKS, n=1, cutoff=0.75)
        if close:
            raise InputError(str(path), f"{effect.__name__}.{attr}",
                             f"the hook name {close[0]!r} (hooks: {', '.join(HOOKS)})")
    if all(getattr(effect, hook) is getattr(Effect, hook) for hook in ACTING_HOOKS):
        raise InputError(str(path), effect.__name__,
                         f"an effect that overrides at least one of {', '.join(ACTING_HOOKS)}: "
                         "without, it changes no prediction")
