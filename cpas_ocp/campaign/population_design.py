"""The design of the next test averaged over a population of canopies.

A plan names a folder of Monte Carlo cases (`cpas-ocp dispersions`, best drawn from
the fitted population at the planned configuration: `--population --at ...`).  Each
planned canopy's stages take their parameters from the cases of their type and
stage, each canopy its own rows (two Drogues of one type are two openings), and the
plan's candidates are predicted at each such parameter set
(`inference.flight_test_design.predict_over`).
"""

from __future__ import annotations

from collections.abc import Callable

from cpas_ocp.campaign.peak_load_study import match_canopies
from cpas_ocp.errors import InputError
from cpas_ocp.inference.flight_test_design import SpreadPrediction, predict_over
from cpas_ocp.io.flight_test_plan import TestPlan
from cpas_ocp.physics.parameters import param_name


def population_draws(plan: TestPlan) -> tuple[list[dict[str, float]], list[str]]:
    """`plan.population_draws` parameter sets (name -> SI value) for the planned test's
    canopies from the cases folder the plan names, and a note per canopy stage left at its
    nominal values (its type and stage have no cases).  InputError naming the plan's field
    where the folder holds too few cases."""
    assert plan.population_cases is not None
    chutes = [(c["name"], c["type"], tuple(c["stages"]))
              for c in plan.problem.manifest["parachutes"]]
    n = plan.population_draws
    stages = match_canopies(chutes, plan.population_cases, plan.problem.name)
    found = {(s.parachute, s.stage) for s in stages}
    notes = [f"{name} {stage}: no cases of type {kind}; at its nominal values"
             for name, kind, ss in chutes for stage in ss if (name, stage) not in found]
    # each canopy of a type its own rows: the first canopy rows 0..n-1, the next n..2n-1
    order: dict[str, int] = {}
    offsets = {}
    for name, kind, _ in chutes:
        offsets[name] = order.get(kind, 0)
        order[kind] = offsets[name] + n
    draws: list[dict[str, float]] = [{} for _ in range(n)]
    for s in stages:
        rows = s.cases.iloc[offsets[s.parachute]:offsets[s.parachute] + n]
        if len(rows) < n:
            raise InputError(plan.path, "population.draws", f"at most the cases {s.file} "
                             f"holds for {n} draws of each canopy of type {s.type} "
                             f"({len(s.cases)} cases for {order[s.type] // n} canopies)")
        for k, (_, row) in enumerate(rows.iterrows()):
            draws[k].update({param_name(str(c), s.parachute, s.stage): float(v)
                             for c, v in row.items()})
    return draws, notes


def design_over_population(plan: TestPlan, progress: Callable[[str], None] | None = None
                           ) -> SpreadPrediction:
    """Every candidate of `plan` predicted over the parameter sets its population cases give
    (`population_draws`)."""
    draws, notes = population_draws(plan)
    return predict_over(plan, draws, f"{plan.population_draws} cases per canopy from "
                        f"{plan.population_cases}", notes, progress)
