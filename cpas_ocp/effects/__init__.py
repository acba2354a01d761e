"""Effect plug-ins: one file per physical or sensor effect.

`BASELINE` is the effect set of the walking-skeleton Drogue model: canopy
inflation and drag, forebody drag, canopies with their dry mass on rigid
risers, per-stage drag scale and per-canopy load-cell scale, and the GPS, IMU
and load-cell measurement models.  Order matters only in that the sensors
come after the effects that set their gains.  Further effects (`AddedMass`)
are added to the list where a problem needs them; sensor errors
(`SensorBias`, `SensorLag`) go after the sensors they modify.  `ElasticRiser`
replaces `RigidRiser` (see `with_elastic_risers`); `PilotDeployment` is the
riser model of a Pilot phase, from mortar fire to Main bag strip.
"""

from .added_mass import AddedMass
from .base import Capture, Constraint, Effect, EventTiming, State
from .canopy_inflation import CanopyInflation
from .deployment_load import DeploymentLoad
from .drag_scale import DragScale
from .elastic_riser import ElasticRiser
from .fly_out import FlyOut
from .forebody_drag import ForebodyDrag
from .loadcell_friction import LoadCellFriction
from .loadcell_scale import LoadCellScale
from .pilot_deployment import PilotDeployment
from .registry import BASELINE, BUILTIN
from .rigid_riser import RigidRiser
from .sensor_bias import SensorBias
from .sensor_lag import SensorLag
from .sensors import GpsSensor, ImuSensor, LoadCellSensor
from .wake_deficit import WakeDeficit


def baseline_effects() -> list[Effect]:
    """A fresh list of the baseline effects (`registry.BASELINE`), in composition order."""
    return [BUILTIN[name].build({}, "(baseline)", name) for name in BASELINE]


def with_elastic_risers(effects: list[Effect]) -> list[Effect]:
    """`effects` with every `RigidRiser` replaced by an `ElasticRiser` of default properties."""
    return [ElasticRiser() if isinstance(e, RigidRiser) else e for e in effects]


__all__ = [
    "AddedMass",
    "CanopyInflation",
    "Capture",
    "Constraint",
    "DeploymentLoad",
    "DragScale",
    "Effect",
    "ElasticRiser",
    "EventTiming",
    "FlyOut",
    "ForebodyDrag",
    "GpsSensor",
    "ImuSensor",
    "LoadCellFriction",
    "LoadCellScale",
    "LoadCellSensor",
    "PilotDeployment",
    "RigidRiser",
    "SensorBias",
    "SensorLag",
    "State",
    "WakeDeficit",
    "baseline_effects",
    "with_elastic_risers",
]
