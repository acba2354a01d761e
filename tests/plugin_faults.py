"""Plug-in files that fail in their own code, for the tests of how such failures are reported.

`faulty_plugin` writes an effect plug-in (``gust``: a drag change ``gust_k`` on every canopy,
zero by default) whose every hook works except one, which raises an exception of a given
kind or returns NaN; or whose import itself raises.
"""

from __future__ import annotations

from pathlib import Path

from cpas_ocp.physics.effects.plugin_guard import CALLED

# What a failing hook does: raise one of these (built from the name) or return NaN.
FAULTS = ("ZeroDivisionError", "KeyError", "ValueError", "TypeError", "RuntimeError",
          "AttributeError", "AssertionError", "RecursionError", "KeyboardInterrupt",
          "SystemExit", "GeneratorExit", "NaN")
# Where it fails: at import, or in one of the hooks the library calls.
PLACES = ("import", *CALLED)

_TEMPLATE = '''from dataclasses import dataclass

import numpy as np

from cpas_ocp.physics.effects import Effect
from cpas_ocp.physics.parameters import Parameter

PLACE, FAULT = {place!r}, {fault!r}


def _fault():
    if FAULT == "NaN":
        return float("nan")
    raise {{"SystemExit": SystemExit(3)}}.get(FAULT) or __builtins__[FAULT]("planted fault")


if PLACE == "import":
    _fault()


def _hook(name, value):
    return _fault() if name == PLACE else value


@dataclass(frozen=True)
class Gust(Effect):
    """A drag change gust_k on every canopy (the test of a plug-in failing)."""

    name: str = "gust"

    def parameters(self, test):
        return _hook("parameters", [Parameter("gust_k", "1", 0.0, -0.5, 0.5, scale=0.1,
                                              description="drag change")])

    def states(self, test):
        return _hook("states", [])

    def captures(self, test):
        return _hook("captures", [])

    def event_timings(self, test):
        return _hook("event_timings", [])

    def state_guess(self, test, t, values):
        return _hook("state_guess", {{}})

    def forces(self, ctx):
        if PLACE == "forces":
            return _fault()
        for chute in ctx.test.parachutes:
            ctx.scale_drag(chute.name, 1.0 + ctx.p["gust_k"], self.name,
                           ("axial_fraction", "riser_force"))
        return None

    def observations(self, ctx):
        return _hook("observations", None)

    def constraints(self, ctx):
        return _hook("constraints", [])

    def penalties(self, ctx):
        return _hook("penalties", {{}})

    def process_priors(self, test):
        return _hook("process_priors", {{}})

    def null_values(self, test):
        return _hook("null_values", {{"gust_k": 0.0}})

    def plausible(self, test):
        return _hook("plausible", {{"gust_k": (-0.3, 0.3)}})
'''


def faulty_plugin(path: Path, place: str, fault: str) -> Path:
    """Write at `path` the ``gust`` plug-in failing with `fault` at `place` (see the module
    docstring); a `place` that is none of PLACES for one that works."""
    path.write_text(_TEMPLATE.format(place=place, fault=fault))
    return path
