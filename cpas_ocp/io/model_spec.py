"""The effect set of a reconstruction and which of its parameters are estimated.

A manifest's optional ``model`` block (or a model file given on the command
line) says which effects make up the model, in composition order, which
plug-in files define further effects, which parameters are held at given
values (``fix``) and which parameters that are fixed by default are estimated
(``free``, e.g. the forebody drag area ``CdS_V``)::

    "model": {
      "effects": ["canopy_inflation", "forebody_drag",
                  {"effect": "elastic_riser", "frequency": 8.0},
                  "added_mass", "drag_scale", "loadcell_scale", "gps", "imu", "load_cell"],
      "fix": {"riser_damping_ratio[drogue1]": 0.3,
              "CdS_V": {"value": 200, "unit": "ft^2"}},
      "plugins": ["breathing.py"],
      "priors": {"CdS[drogue1,stage3]": {"value": 226, "sigma": 6, "unit": "ft^2"}}
    }

A prior is an independent measurement of a free parameter (a drag area from
wind-tunnel or earlier flight tests, say): it adds ((value - p) / sigma)^2
to the chi-square, and appears among the residuals as the pseudo-sensor
``priors``.  Within one test a wake deficit (PRF) and the drag areas enter
only as their product; a prior on the free-stream drag area separates them.

Without a block the baseline effect set is used, with every estimable
parameter free except those fixed by default (`Parameter.free_by_default`:
``CdS_V``, which comes from the aerodynamic database, and fly-out angles).
Every mistake raises InputError naming the file and the field.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from cpas_ocp.errors import InputError
from cpas_ocp.io.flight_test import MANIFEST
from cpas_ocp.io.json_files import read_json, validate_block
from cpas_ocp.physics.effects import baseline_effects
from cpas_ocp.physics.effects.base import Effect
from cpas_ocp.physics.effects.registry import (
    BASELINE,
    BUILTIN,
    SENSOR_EFFECTS,
    EffectType,
    load_plugin,
)
from cpas_ocp.physics.flight_test import FlightTest
from cpas_ocp.physics.model import Model
from cpas_ocp.physics.units import conversion

RISER_MODELS = ("rigid_riser", "elastic_riser", "pilot_deployment")


@dataclass(frozen=True)
class ModelSpec:
    """Effects in composition order, fixed values as given, extra free names, and their source.

    `fix` keeps the values as written ({value, unit} or a number in the
    parameter's SI unit); `fixed_values` converts them once the model's
    parameters, and so their units, are known.
    """

    effects: tuple[Effect, ...]
    fix: dict[str, Any] = field(default_factory=dict)
    free: tuple[str, ...] = ()
    source: str = "(baseline)"
    priors: dict[str, Any] = field(default_factory=dict)

    @property
    def effect_names(self) -> list[str]:
        return [e.name for e in self.effects]

    def model(self, test: FlightTest) -> Model:
        """The composed model; a composition error is reported against the model's source."""
        try:
            model = Model(test, self.effects)
        except ValueError as exc:
            raise InputError(self.source, "model.effects", str(exc)) from None
        except KeyError as exc:
            raise InputError(self.source, "model.effects",
                             f"effects listed so that each finds what it uses; none before "
                             f"it provides {exc}") from None
        names = set(model.parameter_names)
        for i, name in enumerate(self.free):
            if name not in names or not model.parameter(name).estimable:
                raise InputError(self.source, f"model.free[{i}]",
                                 f"an estimable parameter of this model; got {name!r}")
        for name in self.fix:
            if name not in names:
                raise InputError(self.source, f"model.fix.{name}",
                                 "a parameter of this model (see the parameter table)")
            if name in self.free:
                raise InputError(self.source, f"model.fix.{name}",
                                 "a parameter either fixed or freed, not both")
        for name, given in self.priors.items():
            if name not in names or not model.parameter(name).estimable:
                raise InputError(self.source, f"model.priors.{name}",
                                 "an estimable parameter of this model")
            if name in self.fix:
                raise InputError(self.source, f"model.priors.{name}",
                                 "a parameter that is estimated, not fixed")
            if not given["sigma"] > 0:
                raise InputError(self.source, f"model.priors.{name}.sigma",
                                 f"a positive number; got {given['sigma']}")
        for name, value in self.fixed_values(model).items():
            prm = model.parameter(name)
            if not prm.lower <= value <= prm.upper:
                raise InputError(self.source, f"model.fix.{name}",
                                 f"a value in [{prm.lower:g}, {prm.upper:g}] {prm.unit} (SI); "
                                 f"got {value:g}")
        return model

    def fixed_values(self, model: Model) -> dict[str, float]:
        """The `fix` entries in SI, converted with each parameter's declared unit."""
        out = {}
        for name, given in self.fix.items():
            prm = model.parameter(name)
            if isinstance(given, int | float):
                out[name] = float(given)
                continue
            value, unit = float(given["value"]), given["unit"]
            out[name] = value * _conversion(unit, prm.unit, self.source, f"model.fix.{name}.unit")
        return out

    def prior_values(self, model: Model) -> dict[str, tuple[float, float]]:
        """The priors as (value, sigma) in each parameter's SI unit."""
        out = {}
        for name, given in self.priors.items():
            unit = given.get("unit", model.parameter(name).unit)
            factor = _conversion(unit, model.parameter(name).unit, self.source,
                                 f"model.priors.{name}.unit")
            out[name] = (float(given["value"]) * factor, float(given["sigma"]) * factor)
        return out

    def free_names(self, model: Model) -> list[str]:
        """Parameters to estimate: those free by default minus `fix`, plus those named `free`."""
        fixed = set(self.fix)
        return [p.name for p in model.parameters
                if p.name not in fixed
                and ((p.estimable and p.free_by_default) or p.name in self.free)]


def _conversion(unit: str, si_unit: str, file: str, field_path: str) -> float:
    """The factor from `unit` to the parameter's `si_unit` (`units.conversion`: the same
    dimension); InputError naming `field_path` of `file` where the dimensions differ (a
    dimensionless factor fixed in m/s^2 or g)."""
    factor = conversion(unit, si_unit)
    if factor is None:
        raise InputError(file, field_path, f"a unit of the parameter's dimension, convertible "
                         f"to {si_unit!r}; got {unit!r}")
    return factor


def baseline_spec() -> ModelSpec:
    """The baseline effect set with default options."""
    return ModelSpec(tuple(baseline_effects()))


def spec_from_effects(effects: Sequence[Effect]) -> ModelSpec:
    """A spec around an effect list built in code (nothing fixed beyond the defaults)."""
    return ModelSpec(tuple(effects), source="(effects given in code)")


def spec_from_block(block: dict[str, Any] | None, file: str, base_dir: Path,
                    plugins: dict[str, EffectType] | None = None,
                    allow_external: bool = False) -> ModelSpec:
    """Resolve a validated `model` block; plug-in paths are relative to `base_dir`;
    `plugins` are effects registered beforehand (from files named on the command line).

    A plug-in is Python code run with the user's rights, and a test folder may
    come from anyone: a plug-in the block names must lie inside `base_dir`
    (symbolic links resolved), unless `allow_external` (the command line's
    --allow-external-plugins)."""
    if block is None:
        return baseline_spec()
    registry: dict[str, EffectType] = {**BUILTIN, **(plugins or {})}
    for i, rel in enumerate(block.get("plugins", [])):
        path = base_dir / rel
        if not allow_external and not path.resolve().is_relative_to(base_dir.resolve()):
            raise InputError(file, f"model.plugins[{i}]", f"a plug-in inside {base_dir} "
                             f"(plug-ins are code run with your rights); {rel!r} lies outside "
                             "it: give --allow-external-plugins to run it")
        try:
            entries = load_plugin(path)
        except InputError as exc:  # said against the model that names the plug-in too
            raise InputError(exc.file, exc.field, f"{exc.expectation} (named by {file}: "
                             f"model.plugins[{i}])") from None
        for name, entry in entries.items():
            if name in registry:
                raise InputError(file, f"model.plugins[{i}]",
                                 f"effects with new names; {name!r} is already "
                                 f"registered by {registry[name].source}")
            registry[name] = entry
    names: list[str] = []
    effects: list[Effect] = []
    for i, item in enumerate(block.get("effects", BASELINE)):
        path = f"model.effects[{i}]"
        name, options = (item, {}) if isinstance(item, str) else (
            item["effect"], {k: v for k, v in item.items() if k != "effect"})
        if name not in registry:
            raise InputError(file, path, f"a registered effect ({', '.join(sorted(registry))});"
                                         f" got {name!r}")
        if name in names:
            raise InputError(file, path, f"each effect once; {name!r} is listed twice")
        names.append(name)
        effects.append(registry[name].build(options, file, path))
    risers = [n for n in names if n in RISER_MODELS]
    if len(risers) > 1:
        raise InputError(file, "model.effects", f"one riser model; got {' and '.join(risers)}")
    return ModelSpec(tuple(effects), dict(block.get("fix", {})), tuple(block.get("free", [])),
                     file, dict(block.get("priors", {})))


def spec_of_test(test: FlightTest, allow_external: bool = False) -> ModelSpec:
    """The model a test folder's manifest declares; where it lists no effects (no model
    block, an empty one, or one with only ``fix``, ``free`` or ``priors``), the baseline with
    the measurement effect of every sensor kind the test has (an altimeter-only log is
    fitted to its altimeter), under the block's fixes, frees and priors;
    `allow_external` as in `spec_from_block`."""
    base = test.path if test.path is not None else Path()
    block = test.manifest.get("model")
    if block is None or "effects" not in block:
        kinds = dict.fromkeys(s.kind for s in test.sensors)
        extra = [SENSOR_EFFECTS[k] for k in kinds if SENSOR_EFFECTS[k] not in BASELINE]
        block = {**(block or {}), "effects": [*BASELINE, *extra]}
    return spec_from_block(block, str(base / MANIFEST), base, allow_external=allow_external)


def unfitted_sensors(test: FlightTest, model: Model) -> list[str]:
    """The test's sensors that no effect of `model` predicts (their data are not fitted).

    Raises InputError naming the manifest's model block where that is every sensor: a fit
    to no data is no reconstruction."""
    out = [s.name for s in test.sensors if s.name not in model.outputs]
    if out and len(out) == len(test.sensors):
        base = test.path if test.path is not None else Path()
        wanted = sorted({SENSOR_EFFECTS[s.kind] for s in test.sensors})
        raise InputError(str(base / MANIFEST), "model.effects",
                         f"an effect that predicts the sensors' readings ({', '.join(wanted)}); "
                         f"no effect listed predicts any of {', '.join(out)}")
    return out


def load_model_file(path: str | Path, plugins: dict[str, EffectType] | None = None,
                    allow_external: bool = False) -> ModelSpec:
    """A model block stored on its own in a JSON file (`cpas-ocp reconstruct --model FILE`);
    `plugins` and `allow_external` as in `spec_from_block`."""
    path = Path(path)
    block = read_json(path, "an existing JSON model file")
    validate_block(block, "model.schema.json", str(path), prefix="model")
    return spec_from_block(block, str(path), path.parent, plugins, allow_external)


def _jsonable(value: Any) -> Any:
    """An effect option as JSON holds it: tuples as lists, numpy scalars as numbers."""
    if isinstance(value, tuple | list):
        return [_jsonable(v) for v in value]
    if isinstance(value, dict):
        return {str(k): _jsonable(v) for k, v in value.items()}
    if isinstance(value, np.generic):
        return value.item()
    return value


def model_block(spec: ModelSpec, plugins: dict[str, EffectType] | None = None
                ) -> dict[str, Any]:
    """The model block that makes `spec` again (`spec_from_block`), for a model file: each
    effect by its registered name with the options that differ from what the name alone
    builds, and the spec's fixed values, extra free names and priors.  A plug-in effect
    (registered from `plugins`) is named only: the file reading the block registers it
    with --plugin."""
    registry: dict[str, EffectType] = {**BUILTIN, **(plugins or {})}
    items: list[Any] = []
    for effect in spec.effects:
        kind = registry.get(effect.name)
        if kind is None:
            raise ValueError(f"effect {effect.name!r} is not registered: no model file names it")
        plain = kind.build({}, "(model block)", "effects")
        options = {o: _jsonable(getattr(effect, o)) for o in kind.options()
                   if getattr(effect, o) != getattr(plain, o)}
        items.append({"effect": effect.name, **options} if options else effect.name)
    block: dict[str, Any] = {"effects": items}
    for key, value in (("fix", spec.fix), ("free", list(spec.free)), ("priors", spec.priors)):
        if value:
            block[key] = _jsonable(value)
    return block
