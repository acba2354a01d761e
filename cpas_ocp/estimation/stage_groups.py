"""Which canopies start a stage together, and the steady window of each such group.

A CPAS cluster names its canopies' stages alike: two Drogues mortared together
both open "stage1" and reef into "stage2", and the offline reduction shares the
cluster's drag area equally among them.  A shared name alone is no cluster,
though: a rocket-log card that gives no stages names each canopy's one stage
"open", the drogue's at apogee and the main's tens of seconds later.  So
canopies form a cluster when their first stages share a name AND their start
times coincide: differ by no more than

    max(SETTLE_S, 3 * hypot(sigma_a, sigma_b)),

sigma the observed start events' timing sigmas (s).  SETTLE_S is the time the
reduction waits after a start before it reads a drag area as steady: a canopy
that starts within it of another never shows a steady drag area of its own
before the other's joins it, so the reduction cannot tell the two apart and the
cluster's equal shares are all it can say; the sigma term keeps together
starts whose difference the events do not resolve (3 sigma of the difference of
two independent times).  A CPAS cluster's canopies open within a few tenths of
a second (mortared 0.1 s apart, bag strips 0.15 s apart in the built-in
problems); a rocket's drogue and main open tens of seconds apart.

Each stage of a cluster is one `StageGroup`: its canopies, and its steady
window, from its last canopy's start plus SETTLE_S (from the start itself for
a canopy open at the phase's start) to the first start of any other group
after its own first start (the phase's end if none).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from cpas_ocp.physics.effects.canopy_inflation import CanopyInflation
from cpas_ocp.physics.flight_test import FlightTest, Parachute

SETTLE_S = 1.0  # time after a stage start before its drag area counts as steady (s)
START_SIGMAS = 3.0  # starts closer than this many sigmas of their difference coincide


@dataclass(frozen=True)
class StageGroup:
    """Stage `stage` of the canopies `canopies` (a cluster's, or one canopy's), started
    together; its steady window [a, b] (s) and the reduction's scale factor over it (IMU
    drag area over the summed riser drag areas; 1 where not measured)."""

    stage: str
    canopies: tuple[str, ...]
    window: tuple[float, float]
    scale: float = 1.0

    @property
    def label(self) -> str:
        """E.g. ``stage1 (drogue1+drogue2)``."""
        return f"{self.stage} ({'+'.join(self.canopies)})"


def start_sigma(test: FlightTest, chute: Parachute) -> float:
    """Timing sigma (s) of the event that seeds `chute`'s first start; 0 for a canopy open
    at the phase's start (it starts with the phase) or one without such an event."""
    event = None if chute.open_at_start else CanopyInflation.start_event(test, chute, 0)
    return 0.0 if event is None else event.sigma


def starts_coincide(dt: float, sigma_a: float, sigma_b: float) -> bool:
    """Whether two starts `dt` s apart, observed with sigmas `sigma_a`, `sigma_b` (s), are
    one cluster's opening (the module's tolerance)."""
    return abs(dt) <= max(SETTLE_S, START_SIGMAS * math.hypot(sigma_a, sigma_b))


def clusters(test: FlightTest, starts: dict[tuple[str, str], float]
             ) -> list[tuple[Parachute, ...]]:
    """The canopies grouped into clusters (first stages of one name whose starts
    `starts[(canopy, stage)]` (s) coincide, chained), in the manifest's order within a
    cluster, the clusters in the order of their earliest first start."""
    sigma = {c.name: start_sigma(test, c) for c in test.parachutes}
    groups: list[list[Parachute]] = []
    for chute in test.parachutes:
        t0 = starts[(chute.name, chute.stages[0])]
        joined = [g for g in groups if g[0].stages[0] == chute.stages[0] and any(
            starts_coincide(t0 - starts[(c.name, c.stages[0])], sigma[c.name], sigma[chute.name])
            for c in g)]
        merged = [c for g in joined for c in g] + [chute]
        groups = [g for g in groups if all(g is not j for j in joined)] + [merged]
    order = {c.name: k for k, c in enumerate(test.parachutes)}
    ordered = [tuple(sorted(g, key=lambda c: order[c.name])) for g in groups]
    return sorted(ordered, key=lambda g: (min(starts[(c.name, c.stages[0])] for c in g),
                                          order[g[0].name]))


def stage_groups(test: FlightTest, starts: dict[tuple[str, str], float]) -> list[StageGroup]:
    """Every cluster's every stage with its steady window (s), from the start times
    `starts[(canopy, stage)]` (s); in cluster order, each cluster's stages in order."""
    settle = {(c.name, s): 0.0 if c.open_at_start else SETTLE_S
              for c in test.parachutes for s in c.stages}
    out = []
    for cluster in clusters(test, starts):
        for stage in dict.fromkeys(s for c in cluster for s in c.stages):
            names = tuple(c.name for c in cluster if stage in c.stages)
            keys = {(name, stage) for name in names}
            first = min(starts[k] for k in keys)
            begin = max(starts[k] + settle[k] for k in keys)
            later = [t for k, t in starts.items() if k not in keys and t > first]
            end = min(later) if later else test.t_end
            out.append(StageGroup(stage, names, (begin, max(end, begin))))
    return out
