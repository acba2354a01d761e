"""Canopy drag-area growth through the reefing stages (paper Eqs. 5, 6), and canopy drag.

For every canopy and every stage this effect declares the steady drag area
CdS_i (m^2) and the inflation start time t_i (s); infinite-mass canopies add
the over-inflation factor Ck, the peak fill constant n_p, the shape exponent
expopen and the settling time t_k (s); finite-mass canopies add the fill
constant n and expopen.  The start airspeed V_i of each stage is captured from
the trajectory at t_i.  Drag areas here are the aerodynamic ones the
trajectory feels, pressure recovery included (PRF * CdS in the paper's terms).

Quantities written: ``cds[P]`` (m^2), ``drag[P]`` (N, 3-vector, against the
air-relative velocity), ``rise_end[P,S]`` (s: t_i plus the fill time t_f,
finite mass, or the time to peak t_fp, infinite mass) and
``stage_weight[P,S]`` (the weight of stage S in
the canopy's sensor gains: 1 through the stage, handed to the next stage
along a C2 smoothstep that spans the next stage's rise, from its start t_i to
its peak or full fill; the first stage also covers the time before
inflation).  Handing over through the rise rather than at t_i keeps every
prediction smooth in t_i: a gain that jumped at t_i would let a few samples
around the jump set the start time to a precision the data do not hold.

A canopy open at the start of the phase (`Parachute.open_at_start`: a steady
descent picked up after the opening) has neither start time nor shape: its
drag area is the steady CdS (m^2) throughout, or, with altitude bands, one
steady value per band, ``CdS[P,S,band1]`` (lowest) and up, handed from one
to the next along a C2 smoothstep over +-BAND_BLEND_M about each edge (a
step would make the dynamics discontinuous in altitude and the fit
non-smooth).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import casadi as ca

from cpas_ocp.errors import InputError
from cpas_ocp.physics.effects.base import Capture, Effect, EventTiming
from cpas_ocp.physics.inflation import (
    fill_length,
    fill_time,
    finite_mass_cds,
    infinite_mass_cds,
    smoothstep,
    stage_started,
)
from cpas_ocp.physics.parameters import Parameter, param_name, split_name

if TYPE_CHECKING:
    from cpas_ocp.physics.flight_test import Event, FlightTest, Parachute
    from cpas_ocp.physics.model_context import ModelContext

# Delay from mortar fire to inflation start used only when no bag-strip or
# line-stretch observation exists (s).
MORTAR_TO_INFLATION_S = 0.5
# Lower bound of a captured start airspeed in the estimation problem (m/s); the fill
# time n L / V_i divides by it.
MIN_START_AIRSPEED = 0.01
# Upper bound of a stage's drag coefficient on the nominal area S_o = pi D_o^2 / 4.
# Ringsails reach about 0.9 and hobby-rocket canopies are sold at Cd 1.5-2.2; a
# fitted system drag area also carries what hangs under the canopy.
MAX_CD = 3.0
# Half-width (m) of the blend between a canopy's drag areas in adjacent altitude bands.
BAND_BLEND_M = 10.0


def steady_parameter_names(chute: Parachute) -> tuple[str, ...]:
    """The steady drag-area parameters of a canopy open at the start: ``CdS[P,S]``, or one
    ``CdS[P,S,band]`` per altitude band (lowest first)."""
    stage = chute.stages[-1]
    if chute.band_names:
        return tuple(param_name("CdS", chute.name, stage, b) for b in chute.band_names)
    return (param_name("CdS", chute.name, stage),)


def banded_cds(altitude: ca.SX | float, edges: tuple[float, ...],
               values: list[ca.SX | float]) -> ca.SX:
    """Drag area (m^2) piecewise constant in altitude (m): values[k] between edges k-1 and
    k, each edge blended over +-BAND_BLEND_M by a C2 smoothstep."""
    cds = values[0]
    for edge, below, above in zip(edges, values, values[1:], strict=False):
        cds = cds + (above - below) * smoothstep((altitude - edge) / BAND_BLEND_M)
    return cds


@dataclass(frozen=True)
class CanopyInflation(Effect):
    """Drag-area growth of every canopy and the drag it produces.

    `start_window` (s): how far each inflation start time may move from its
    observed event (bag strip or disreef) when estimated; a first stage seeded
    from its canopy's mortar fire alone (no bag strip or line stretch observed)
    never starts before that fire (less the event's sigma).  `start_shifts`
    (s, by start-time name, e.g. ``{"t_start[drogue1,stage2]": -1.0}``) moves
    a window's centre, and the start's first guess, off its event: set where
    the data press a start time against its window (`result_claim`), or by a
    user who knows an event's time is off.  The phase's ends and the mortar
    fire still bound every window.
    """

    start_window: float = 1.0
    start_shifts: Mapping[str, float] = field(default_factory=dict)
    name: str = "canopy_inflation"

    def __post_init__(self) -> None:
        if not self.start_window > 0.0:
            raise ValueError(f"start_window must be positive (s); got {self.start_window!r}")
        for key, shift in self.start_shifts.items():
            if split_name(key)[0] != "t_start" or not math.isfinite(shift):
                raise ValueError(f"start_shifts maps start times t_start[P,S] to finite "
                                 f"shifts in seconds; got {key!r}: {shift!r}")

    def parameters(self, test: FlightTest) -> list[Parameter]:
        starts = {param_name("t_start", c.name, s) for c in test.parachutes for s in c.stages}
        unknown = sorted(set(self.start_shifts) - starts)
        if unknown:
            raise ValueError(f"start_shifts names {', '.join(unknown)}, not a start time of "
                             f"this test ({', '.join(sorted(starts))})")
        out = []
        for chute in test.parachutes:
            s_o = math.pi * chute.diameter**2 / 4.0
            if chute.open_at_start:
                out += [Parameter(name, "m^2", 0.5 * s_o, 1e-3 * s_o, MAX_CD * s_o,
                                  description="steady drag area of the open canopy"
                                  + (f" in altitude {split_name(name)[1][-1]}"
                                     if chute.band_names else ""),
                                  scale=0.5 * s_o, physical_lower=True)
                        for name in steady_parameter_names(chute)]
                continue
            n_stages = len(chute.stages)
            for k, stage in enumerate(chute.stages):
                idx = (chute.name, stage)
                out.append(Parameter(param_name("CdS", *idx), "m^2",
                                     0.5 * s_o * (k + 1) / n_stages, 1e-3 * s_o, MAX_CD * s_o,
                                     description="steady drag area of the stage",
                                     scale=0.5 * s_o * (k + 1) / n_stages,
                                     physical_lower=True))
                if chute.inflation == "infinite_mass":
                    out += [
                        Parameter(param_name("Ck", *idx), "1", 1.3, 1.0, 3.0,
                                  description="over-inflation factor", scale=1.0,
                                  physical_lower=True),
                        Parameter(param_name("n_p", *idx), "1", 6.0, 0.3, 40.0,
                                  description="peak fill constant (diameters to peak)", scale=5.0),
                        Parameter(param_name("expopen", *idx), "1", 2.0, 0.3, 6.0,
                                  description="opening shape exponent", scale=1.0),
                        Parameter(param_name("t_k", *idx), "s", 0.3, 0.01, 3.0,
                                  description="settling time after the peak", scale=0.3,
                                  physical_lower=True),
                    ]
                else:
                    out += [
                        Parameter(param_name("n", *idx), "1", 8.0, 0.3, 60.0,
                                  description="fill constant (diameters to full stage)", scale=5.0),
                        Parameter(param_name("expopen", *idx), "1", 1.0, 0.3, 6.0,
                                  description="opening shape exponent", scale=1.0),
                    ]
                name = param_name("t_start", *idx)
                observed = self.observed_start(test, chute, k)
                # The phase's ends, and the mortar fire where it alone seeds the start, are
                # physical limits; the window about the (shifted) event is a guess.
                earliest = test.t_start
                mortar = test.event("mortar_fire", chute.name) if k == 0 else None
                if mortar is not None and observed == mortar.time + MORTAR_TO_INFLATION_S:
                    # Seeded from the mortar (or ejection charge) alone: the canopy does not
                    # start to inflate before it fires; the event's timing sigma is allowed.
                    earliest = max(earliest, mortar.time - mortar.sigma)
                shift = self.start_shifts.get(name, 0.0)
                t0 = min(max(observed + shift, earliest), test.t_end) if shift else observed
                lo = max(earliest, t0 - self.start_window)
                hi = min(test.t_end, t0 + self.start_window)
                out.append(Parameter(name, "s", t0, lo, hi,
                                     description="inflation start time", scale=1.0,
                                     physical_lower=bool(lo == earliest),
                                     physical_upper=bool(hi == test.t_end)))
        return out

    def captures(self, test: FlightTest) -> list[Capture]:
        return [Capture(param_name("V_start", c.name, s), param_name("t_start", c.name, s),
                        "airspeed", "m/s", lower=MIN_START_AIRSPEED)
                for c in test.parachutes if not c.open_at_start for s in c.stages]

    def event_timings(self, test: FlightTest) -> list[EventTiming]:
        """A stage is full open (finite mass) or at its peak area (infinite mass) at
        ``rise_end`` = t_i + t_f: an observed ``full_open`` measures the start time and
        fill constant together."""
        return [EventTiming("full_open", c.name, s, time=param_name("rise_end", c.name, s))
                for c in test.parachutes if not c.open_at_start for s in c.stages]

    @staticmethod
    def start_event(test: FlightTest, chute: Parachute, k: int) -> Event | None:
        """The observed event that seeds the start of `chute`'s stage k: its bag strip or
        line stretch (else its mortar fire) for the first stage, its disreef for a later
        one; None where the test holds none of them."""
        if k == 0:
            for name in ("bag_strip", "line_stretch", "mortar_fire"):
                event = test.event(name, chute.name)
                if event is not None:
                    return event
            return None
        return test.event("disreef", chute.name, chute.stages[k])

    @staticmethod
    def observed_start(test: FlightTest, chute: Parachute, k: int) -> float:
        """The observed time a stage starts inflating: bag strip / line stretch or disreef,
        or MORTAR_TO_INFLATION_S after the mortar fire where only that was observed."""
        event = CanopyInflation.start_event(test, chute, k)
        if event is not None:
            return event.time + (MORTAR_TO_INFLATION_S if event.name == "mortar_fire" else 0.0)
        stage = chute.stages[k]
        expected = ("a bag_strip, line_stretch or mortar_fire event" if k == 0
                    else f"a disreef event into {stage}")
        raise InputError(str(test.path / "manifest.json") if test.path else "manifest",
                         "events", f"{expected} for {chute.name} (it seeds the start time of "
                         f"{stage})")

    def forces(self, ctx: ModelContext) -> None:
        for chute in ctx.test.parachutes:
            if chute.open_at_start:
                values = [ctx.p[n] for n in steady_parameter_names(chute)]
                cds = banded_cds(ctx.x["position"][2], chute.altitude_bands, values)
                ctx.q[param_name("stage_weight", chute.name, chute.stages[0])] = ca.SX(1.0)
            else:
                cds = self._inflating_cds(ctx, chute)
            ctx.q[param_name("cds", chute.name)] = cds
            ctx.q[param_name("drag", chute.name)] = (
                cds * ctx.q["dynamic_pressure"] * ctx.q["drag_direction"])

    @staticmethod
    def _inflating_cds(ctx: ModelContext, chute: Parachute) -> ca.SX:
        """Drag area (m^2) of a canopy deploying in the phase, through its stages' curves;
        writes each stage's ``rise_end`` and ``stage_weight``."""
        t, p = ctx.t, ctx.p
        cds_o = p[param_name("CdS", chute.name, chute.stages[-1])]
        starts = [p[param_name("t_start", chute.name, s)] for s in chute.stages]
        started = [stage_started(t, start) for start in starts]
        # The inputs of each stage's law (Eq. 5, and Eq. 6 for infinite mass).
        laws: list[dict[str, ca.SX]] = []
        # Weight with which each stage's sensor gains apply: 1 before the next
        # stage starts, handing over smoothly through the next stage's rise.
        arrivals: list[ca.SX] = []
        prev = ca.SX(0.0)
        for k, stage in enumerate(chute.stages):
            idx = (chute.name, stage)
            steady = p[param_name("CdS", *idx)]
            law = {"t_start": starts[k], "cds_prev": prev, "cds": steady,
                   "expopen": p[param_name("expopen", *idx)],
                   "length": fill_length(chute.fill_length, chute.diameter, prev, steady,
                                         cds_o),
                   "v_start": ctx.c[param_name("V_start", *idx)]}
            if chute.inflation == "infinite_mass":
                law |= {"ck": p[param_name("Ck", *idx)], "n_p": p[param_name("n_p", *idx)],
                        "t_k": p[param_name("t_k", *idx)]}
                constant = law["n_p"]
            else:
                law["n"] = p[param_name("n", *idx)]
                constant = law["n"]
            rise = fill_time(constant, law["length"], law["v_start"])
            ctx.q[param_name("rise_end", *idx)] = starts[k] + rise
            laws.append(law)
            prev = steady
            arrivals.append(1.0 if k == 0 else
                            smoothstep(2.0 * (t - starts[k]) / rise - 1.0))
        # The curve of the last stage started applies.  Its inputs are selected
        # first and the law evaluated once: selecting whole curves would evaluate
        # every stage's law (and its derivatives) at every time, although only one
        # ever applies; the value and every derivative are the same.
        current = laws[0]
        for k in range(1, len(laws)):
            current = {key: ca.if_else(started[k], value, current[key])
                       for key, value in laws[k].items()}
        curve = (infinite_mass_cds(t, **current) if chute.inflation == "infinite_mass"
                 else finite_mass_cds(t, **current))
        any_started = started[0]
        for flag in started[1:]:
            any_started = ca.logic_or(any_started, flag)
        cds = ca.if_else(any_started, curve, 0.0)
        # reached[k]: how far the canopy has come into stage k (a product, so that
        # the weights below sum to one even when a stage starts before the rise
        # of the previous one has ended).
        reached = [arrivals[0]]
        for a in arrivals[1:]:
            reached.append(reached[-1] * a)
        reached.append(0.0)
        for k, stage in enumerate(chute.stages):
            ctx.q[param_name("stage_weight", chute.name, stage)] = reached[k] - reached[k + 1]
        return cds
