"""Ready-made test phases shipped in `problems/` (installed as `cpas_ocp.problem_data`).

A problem is one JSON file.  A synthetic one holds a manifest template (vehicle, parachutes,
sensors and their noise), the simulation set-up (initial state, duration,
sample rates, how observed events relate to the truth), and the synthetic
truth, in SI, under exactly the parameter names a reconstruction reports.  A
real-flight one (``"kind": "flight_log"``) is a flight card instead
(`flight_card.FlightCard`): the logs it reads and what they do not hold.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from importlib import resources
from typing import Any

from cpas_ocp.errors import InputError


@dataclass(frozen=True)
class Problem:
    name: str
    title: str
    label: str
    manifest: dict[str, Any]
    simulation: dict[str, Any]
    truth: dict[str, float]


def problem_names(kind: str = "synthetic") -> list[str]:
    """Names of the built-in problems of `kind`: 'synthetic' or 'flight_log'."""
    folder = resources.files("cpas_ocp.problem_data")
    return sorted(f.name.removesuffix(".json") for f in folder.iterdir()
                  if f.name.endswith(".json")
                  and json.loads(f.read_text()).get("kind", "synthetic") == kind)


def load_problem(name: str) -> Problem:
    """A built-in problem by name.

    A problem file may extend another (``"extends": "drogue"``): it inherits
    the manifest, simulation and truth, and gives its own title, a ``model``
    block for the manifest (the effect set its data are made with and
    reconstructed by), truth values for the parameters that block adds, and
    optionally simulation settings that replace the base's (a shorter
    ``t_end``).
    """
    names = problem_names()
    if name in problem_names("flight_log"):
        raise InputError("problem", "name", f"a synthetic problem; {name!r} is a real flight "
                         f"log (run `cpas-ocp flight {name}`)")
    if name not in names:
        raise InputError("problem", "name", f"one of {', '.join(names)}; got {name!r}")
    raw = json.loads(resources.files("cpas_ocp.problem_data").joinpath(f"{name}.json").read_text())
    if "extends" in raw:
        base = load_problem(raw["extends"])
        manifest = {**base.manifest, "name": raw["name"], "model": raw["model"]}
        simulation = {**base.simulation, **raw.get("simulation", {})}
        return Problem(raw["name"], raw["title"], raw["label"], manifest, simulation,
                       {**base.truth, **raw["truth"]["parameters"]})
    return Problem(raw["name"], raw["title"], raw["label"], raw["manifest"], raw["simulation"],
                   raw["truth"]["parameters"])
