"""Pilot parachute deployment: mortar, tether, Main bag lift and Main deployment (paper Sec. V).

A Pilot is mortared from the vehicle, inflates at the end of its riser, and
pulls the Main deployment bag out; the Main's risers and lines then pay out
of the bag until the Main bag strips.  Pilots carry no usable load data, so
the paper reconstructs them by timing: the mortar speed sets the Pilot's bag
strip, its fill constant the Main bag lift, its steady drag area the Main
bag strip.  This effect is the riser model of every canopy in the test (each
a Pilot with its Main in the vehicle) and predicts those three events.

Motion is along the line e from the vehicle toward the trailing Pilot (the
vehicle's drag direction), as with elastic risers; the mortar's actual
sideways throw is folded into its axial speed.  Two bodies trail the
vehicle: the Pilot at separation s (m) and the Main bag at the Main's
deployed length x (m), each with its rate; all are zero until the mortar
fires at the observed ``mortar_fire`` time t_m.

* Mortar: over MORTAR_STROKE_S after t_m the pack is pushed to
  s' = ``mortar_speed[P]`` (m/s) by a smooth impulse; the vehicle feels the
  recoil, -m_p ds'/dt along e.
* Pilot riser: length L_r (`riser_length`, m) from the Main bag to the Pilot
  canopy, a tension-only spring-damper T = k (s - x - L_r) + c (s' - x') with
  k = m_p (2 pi f)^2 and c = 2 zeta m_p 2 pi f.  The Pilot bag strips, and
  its inflation starts, when the riser comes taut: the effect constrains
  s - x - L_r captured at ``t_start[P,stage1]`` to zero.
* Pilot: m_p s'' = D_p - T + m_p (g - a_v).e, with D_p the drag of the pack
  (`pack_cds`) and canopy at the Pilot's airspeed V - s'.
* Main bag lift at the end of the Pilot's fill, t_lift = t_i + t_f (the
  paper's timing definition; ``rise_end[P,stage1]``).  Until then the bag is
  held in the vehicle (x = 0, counted in the vehicle's mass) and the vehicle
  feels T.  From then on (a C2 smoothstep over LIFT_S) the bag, of mass
  M_b - m(x) (`main_bag_mass`, kg) and drag area `main_bag_cds`, is pulled
  by T: (M_b - m(x)) x'' = T + D_b + (M_b - m(x)) (g - a_v).e.
* Mass-flow deployment (Mains): the Main's risers and lines leave the bag
  with cumulative mass m(x) (`mass_per_length`, kg/m, plus Gaussian mass
  concentrations `concentrations` [[x_j (m), m_j (kg)], ...] of width
  `concentration_width`, m: links, connector rings).  Each element leaves at
  the bag's speed and is brought to the vehicle's, so after bag lift the
  vehicle feels the momentum flux m'(x) x'^2 along e, with load spikes as
  the concentrations pay out; the bag loses the mass at its own speed and
  feels no force from it.
* The Main bag strips when x reaches the deployed length `main_length` (m).

Parameters: ``mortar_speed[P]`` (m/s).  Quantities written: ``separation[P]``
(m), ``tension[P]`` (N, the Pilot riser), ``deployment_flux[P]`` (N),
``main_bag_mass[P]`` (kg, what is left in the bag),
``riser_gap[P]`` (s - x - L_r, m), ``main_line_gap[P]`` (x - L_main, m),
``bag_strip_time[P]`` and ``main_bag_lift_time[P]`` (s).  Events predicted: the Pilot's
``bag_strip``, ``main_bag_lift`` and ``main_bag_strip``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING

import casadi as ca

from cpas_ocp.errors import InputError
from cpas_ocp.physics.effects.base import Capture, Constraint, Effect, EventTiming, State
from cpas_ocp.physics.effects.rigid_riser import tension_only
from cpas_ocp.physics.inflation import smoothstep
from cpas_ocp.physics.parameters import Parameter, param_name
from cpas_ocp.physics.units import G0

if TYPE_CHECKING:
    from cpas_ocp.physics.flight_test import FlightTest, Parachute
    from cpas_ocp.physics.model_context import ModelContext

MORTAR_STROKE_S = 0.03  # duration of the mortar's push on the pack (s)
LIFT_S = 0.1  # duration of the switch from a held to a pulled Main bag (s)
MORTAR_SPEED_BOUNDS_M_S = (2.0, 100.0)
MORTAR_SPEED_GUESS_M_S = 30.0  # without a mortar fire and a bag strip to time it (m/s)
LENGTH_ROUNDING_M = 0.05  # width of the smooth max(x, 0) of the deployed length (m)
SPEED_ROUNDING_M_S = 0.1  # width of the smooth max(x', 0) of the deployment speed (m/s)


def _positive(x: ca.SX, width: float) -> ca.SX:
    """Smooth max(x, 0): (x + sqrt(x^2 + width^2)) / 2."""
    return 0.5 * (x + ca.sqrt(x**2 + width**2))


@dataclass(frozen=True)
class PilotDeployment(Effect):
    """Mortared Pilots that lift their Main bag and deploy the Main, with the event times.

    Lengths in m, masses in kg, drag areas in m^2, frequency in Hz.
    """

    riser_length: float = 12.0
    pack_cds: float = 0.05
    riser_frequency: float = 5.0
    riser_damping_ratio: float = 0.5
    main_bag_mass: float = 140.0
    main_bag_cds: float = 0.3
    main_length: float = 50.0
    mass_per_length: float = 0.6
    concentrations: tuple[tuple[float, float], ...] = ()
    concentration_width: float = 0.5
    name: str = "pilot_deployment"

    def __post_init__(self) -> None:
        positive = ("riser_length", "riser_frequency", "riser_damping_ratio", "main_bag_mass",
                    "main_length", "concentration_width")
        for label in positive:
            value = getattr(self, label)
            if not isinstance(value, int | float) or value <= 0:
                raise ValueError(f"{label} must be a positive number; got {value!r}")
        for label in ("pack_cds", "main_bag_cds", "mass_per_length"):
            value = getattr(self, label)
            if not isinstance(value, int | float) or value < 0:
                raise ValueError(f"{label} must be a number >= 0; got {value!r}")
        pairs = tuple(tuple(float(v) for v in pair) for pair in self.concentrations)
        if any(len(pair) != 2 or not 0 <= pair[0] <= self.main_length or pair[1] < 0
               for pair in pairs):
            raise ValueError("concentrations must be [position (m) within main_length, "
                             "mass (kg) >= 0] pairs")
        if self.paid_out_mass(self.main_length) >= self.main_bag_mass:
            raise ValueError("the Main's risers and lines must weigh less than main_bag_mass")
        object.__setattr__(self, "concentrations", pairs)

    def paid_out_mass(self, x: ca.SX | float) -> ca.SX | float:
        """Cumulative mass m(x) (kg) of the Main's risers and lines paid out at length x (m)."""
        width = self.concentration_width * math.sqrt(2.0)
        out = self.mass_per_length * x
        for position, mass in self.concentrations:
            out = out + 0.5 * mass * (ca.erf((x - position) / width) + math.erf(position / width))
        return out

    def mass_per_length_at(self, x: ca.SX | float) -> ca.SX | float:
        """m'(x) (kg/m): the derivative of `paid_out_mass`."""
        width = self.concentration_width
        out = self.mass_per_length + 0.0 * x
        for position, mass in self.concentrations:
            out = out + mass / (width * math.sqrt(2.0 * math.pi)) * ca.exp(
                -0.5 * ((x - position) / width) ** 2)
        return out

    def parameters(self, test: FlightTest) -> list[Parameter]:
        """The mortar speed of each Pilot, by default the riser length over the observed
        time from mortar fire to bag strip (drag on the pack makes the truth higher)."""
        out = []
        for c in test.parachutes:
            fire, strip = test.event("mortar_fire", c.name), test.event("bag_strip", c.name)
            speed = MORTAR_SPEED_GUESS_M_S
            if fire is not None and strip is not None and strip.time > fire.time:
                speed = self.riser_length / (strip.time - fire.time)
            lo, hi = MORTAR_SPEED_BOUNDS_M_S
            out.append(Parameter(param_name("mortar_speed", c.name), "m/s",
                                 min(max(speed, lo), hi), lo, hi, scale=30.0,
                                 description="mortar ejection speed of the pack along the riser"))
        return out

    def states(self, test: FlightTest) -> list[State]:
        out = []
        for c in test.parachutes:
            out += [State(param_name(n, c.name), 1, unit, 10.0, pinned=True)
                    for n, unit in (("separation", "m"), ("separation_rate", "m/s"),
                                    ("deployed", "m"), ("deployed_rate", "m/s"))]
        return out

    def captures(self, test: FlightTest) -> list[Capture]:
        return [Capture(param_name("riser_gap", c.name), param_name("t_start", c.name,
                                                                    c.stages[0]),
                        param_name("riser_gap", c.name), "m") for c in test.parachutes]

    def event_timings(self, test: FlightTest) -> list[EventTiming]:
        out = []
        for c in test.parachutes:
            out += [EventTiming("bag_strip", c.name, time=param_name("bag_strip_time", c.name)),
                    EventTiming("main_bag_lift", c.name,
                                time=param_name("main_bag_lift_time", c.name)),
                    EventTiming("main_bag_strip", c.name,
                                crossing=param_name("main_line_gap", c.name))]
        return out

    def constraints(self, ctx: ModelContext) -> list[Constraint]:
        """The Pilot's inflation starts at its bag strip: separation L_r at t_start."""
        return [Constraint(f"{c.name} bag strip at the start of inflation",
                           ctx.c[param_name("riser_gap", c.name)], 0.0, 0.0)
                for c in ctx.test.parachutes]

    def forces(self, ctx: ModelContext) -> None:
        e = ctx.q["drag_direction"]
        for chute in ctx.test.parachutes:
            ctx.separate_body(chute.name, self.name)
            s, s_dot, x, x_dot = (ctx.x[param_name(n, chute.name)] for n in (
                "separation", "separation_rate", "deployed", "deployed_rate"))
            omega = 2.0 * math.pi * self.riser_frequency
            gap = s - x - self.riser_length
            tension = tension_only(chute.dry_mass * omega * (
                omega * gap + 2.0 * self.riser_damping_ratio * (s_dot - x_dot)))
            lifted = self._lifted(ctx, chute)
            deployed = _positive(x, LENGTH_ROUNDING_M)
            flux = self.mass_per_length_at(deployed) * _positive(x_dot, SPEED_ROUNDING_M_S) ** 2
            recoil = -chute.dry_mass * self._mortar_push(ctx, chute)
            ctx.forces.append(((1.0 - lifted) * tension + lifted * flux + recoil) * e)
            # The Main bag leaves the vehicle's mass at bag lift, less what has paid out.
            bag_mass = ctx.q[param_name("main_bag_mass", chute.name)] = (
                self.main_bag_mass - self.paid_out_mass(deployed))
            ctx.mass = ctx.mass - lifted * bag_mass
            ctx.q[param_name("separation", chute.name)] = s
            ctx.q[param_name("deployment_flux", chute.name)] = lifted * flux
            ctx.q[param_name("tension", chute.name)] = tension
            ctx.q[param_name("riser_gap", chute.name)] = gap
            ctx.q[param_name("main_line_gap", chute.name)] = x - self.main_length
            ctx.q[param_name("bag_strip_time", chute.name)] = ctx.p[
                param_name("t_start", chute.name, chute.stages[0])]
            ctx.q[param_name("main_bag_lift_time", chute.name)] = self._lift_time(ctx, chute)

    def observations(self, ctx: ModelContext) -> None:
        e = ctx.q["drag_direction"]
        a_v = ctx.q["specific_force"] + ca.vertcat(0.0, 0.0, -G0)
        relative_gravity = ca.dot(ca.vertcat(0.0, 0.0, -G0) - a_v, e)
        airspeed = ctx.q["airspeed"]
        for chute in ctx.test.parachutes:
            s_dot, x_dot = (ctx.x[param_name(n, chute.name)] for n in (
                "separation_rate", "deployed_rate"))
            tension = ctx.q[param_name("tension", chute.name)]
            # Dynamic pressure at the Pilot and at the bag, which trail at s' and x'.
            q_pilot = ctx.q["dynamic_pressure"] * ((airspeed - s_dot) / airspeed) ** 2
            q_bag = ctx.q["dynamic_pressure"] * ((airspeed - x_dot) / airspeed) ** 2
            canopy = ca.dot(ctx.q[param_name("drag", chute.name)], e) / ctx.q["dynamic_pressure"]
            pilot = ((canopy + self.pack_cds) * q_pilot - tension) / chute.dry_mass
            bag = (tension + self.main_bag_cds * q_bag) / ctx.q[param_name("main_bag_mass",
                                                                         chute.name)]
            fired = self._fired(ctx, chute)
            lifted = self._lifted(ctx, chute)
            ctx.xdot[param_name("separation", chute.name)] = s_dot
            ctx.xdot[param_name("separation_rate", chute.name)] = (
                self._mortar_push(ctx, chute) + fired * (pilot + relative_gravity))
            ctx.xdot[param_name("deployed", chute.name)] = x_dot
            ctx.xdot[param_name("deployed_rate", chute.name)] = lifted * (bag + relative_gravity)

    # --- event timing ------------------------------------------------------------------

    def _mortar_time(self, ctx: ModelContext, chute: Parachute) -> float:
        event = ctx.test.event("mortar_fire", chute.name)
        if event is None:
            raise InputError(str(ctx.test.path / "manifest.json") if ctx.test.path else
                             "manifest", "events", f"a mortar_fire event for {chute.name} "
                             "(the pilot_deployment effect starts the Pilot there)")
        return event.time

    def _fired(self, ctx: ModelContext, chute: Parachute) -> ca.SX:
        """0 before the mortar fires, 1 once its stroke is over (C2)."""
        t_m = self._mortar_time(ctx, chute)
        return smoothstep(2.0 * (ctx.t - t_m) / MORTAR_STROKE_S - 1.0)

    def _mortar_push(self, ctx: ModelContext, chute: Parachute) -> ca.SX:
        """The mortar's acceleration of the pack (m/s^2): it integrates to the mortar speed."""
        speed = ctx.p[param_name("mortar_speed", chute.name)]
        return speed * ca.jacobian(self._fired(ctx, chute), ctx.t)

    def _lift_time(self, ctx: ModelContext, chute: Parachute) -> ca.SX:
        rise_end = param_name("rise_end", chute.name, chute.stages[0])
        if rise_end not in ctx.q:
            raise ValueError("list the pilot_deployment effect after canopy_inflation: the "
                             "Main bag lifts at the end of the Pilot's fill")
        return ctx.q[rise_end]

    def _lifted(self, ctx: ModelContext, chute: Parachute) -> ca.SX:
        """0 while the Main bag is in the vehicle, 1 once the Pilot has lifted it (C2)."""
        return smoothstep(2.0 * (ctx.t - self._lift_time(ctx, chute)) / LIFT_S)
