"""A body-fixed axial accelerometer under canopy (a rocket's flight computer).

The accelerometer reads the specific force f along the body's axis; Altus
Metrum loggers report it with one g subtracted, so a body at rest reads 0 and
one in free fall -g0.  Under a canopy the body hangs from its shock cord and
swings; its mean attitude differs by canopy (a rocket often hangs sideways
or nose down under a drogue and nose up under a main).  The model is

    reading = c(t) |f| - g0,   c(t) = (sum_P c_P CdS_P(t) + C_0) / (sum_P CdS_P(t) + C_0),

c_P = ``axis_cos[P]`` (1, in [-1, 1]) the mean cosine between the body's
axis and the specific force while canopy P carries the drag, handed over as
the canopies' drag areas grow; C_0 = 1e-3 m^2 gives the body's own axis
(cosine 1) before any canopy opens.  |f| is the model's specific force, so
the openings' load peaks are predicted by the same drag that flies the
trajectory: the accelerometer times and sizes the openings.  The swing is
not modelled; its scatter about the mean attitude is noise of the sensor,
whose sigma the importer takes per canopy phase from the scatter about a
local trend (`log_noise.scatter_sigma`), not from the white-noise floor.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import casadi as ca

from cpas_ocp.physics.effects.base import Effect
from cpas_ocp.physics.parameters import Parameter, param_name
from cpas_ocp.physics.units import G0

if TYPE_CHECKING:
    from cpas_ocp.physics.flight_test import FlightTest
    from cpas_ocp.physics.model_context import ModelContext

KIND = "axial_accelerometer"
BODY_CDS = 1e-3  # m^2: the weight of the body's own axis before any canopy opens


@dataclass(frozen=True)
class AxialAccelerometer(Effect):
    """Axial accelerometer: ``c(t) |f| - g0`` (m/s^2), ``axis_cos[P]`` per canopy."""

    name: str = "axial_accelerometer"

    def parameters(self, test: FlightTest) -> list[Parameter]:
        if not test.sensors_of(KIND):
            return []
        return [Parameter(param_name("axis_cos", c.name), "1", 1.0, -1.0, 1.0, scale=0.5,
                          physical_lower=True, physical_upper=True,
                          description="mean cosine of the body's axis to the specific force "
                                      "under the canopy")
                for c in test.parachutes]

    def observations(self, ctx: ModelContext) -> None:
        sensors = ctx.test.sensors_of(KIND)
        if not sensors:
            return
        weighted, total = ca.SX(BODY_CDS), ca.SX(BODY_CDS)
        for chute in ctx.test.parachutes:
            cds = ctx.q[param_name("cds", chute.name)]
            weighted += ctx.p[param_name("axis_cos", chute.name)] * cds
            total += cds
        # |f| smoothed at zero (1 mm/s^2): a body in free fall with no drag has f = 0 exactly,
        # where the norm's derivative is not a number.
        magnitude = ca.sqrt(ca.sumsqr(ctx.q["specific_force"]) + 1e-6)
        reading = weighted / total * magnitude - G0
        for s in sensors:
            ctx.y[s.name] = {"acceleration": reading}
