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

from cpas_ocp.physics.effects.added_mass import AddedMass
from cpas_ocp.physics.effects.base import (
    Capture,
    Constraint,
    Effect,
    EventTiming,
    Refinement,
    State,
)
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
from cpas_ocp.physics.effects.registry import BASELINE, BUILTIN
from cpas_ocp.physics.effects.rigid_riser import RigidRiser
from cpas_ocp.physics.effects.sensor_bias import SensorBias
from cpas_ocp.physics.effects.sensor_lag import SensorLag
from cpas_ocp.physics.effects.sensors import GpsSensor, ImuSensor, LoadCellSensor
from cpas_ocp.physics.effects.wake_deficit import WakeDeficit


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
    "DragLawTerms",
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
    "Refinement",
    "RigidRiser",
    "SensorBias",
    "SensorLag",
    "State",
    "WakeDeficit",
    "baseline_effects",
    "with_elastic_risers",
]
