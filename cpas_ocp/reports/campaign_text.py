"""Many tests in the terminal: a campaign's outcomes, each canopy type and stage's Monte
Carlo model, and the peak loads the dispersed cases reach."""

from __future__ import annotations

from collections.abc import Sequence

from cpas_ocp.campaign.campaign import TestOutcome
from cpas_ocp.campaign.dispersion_study import DispersionModel
from cpas_ocp.campaign.peak_load_study import StageLoads
from cpas_ocp.campaign.population_study import PopulationDispersion
from cpas_ocp.estimation.estimator import Fit
from cpas_ocp.physics.units import LBF


def campaign_text(outcomes: Sequence[TestOutcome]) -> str:
    """One line per test: status, iterations, chi^2/dof and wall time, or the failure."""
    lines = [f"{len(outcomes)} tests, {sum(o.ok for o in outcomes)} reconstructed, "
             f"{sum(not o.ok for o in outcomes)} failed"]
    for o in outcomes:
        if o.ok:
            lines.append(f"  ok      {o.name:28s} {o.iterations:4d} iterations, chi^2/dof "
                         f"{o.chi_square_per_dof:.3f}, {len(o.rows)} parameters, "
                         f"{o.wall_s:.1f} s")
        else:
            lines.append(f"  FAILED  {o.name:28s} ({o.kind}) {o.message}")
    return "\n".join(lines)


def dispersion_model_text(model: DispersionModel) -> str:
    """A canopy type and stage's Monte Carlo model: each parameter's dispersion, the hull
    (or what bounds the draws without one) and, for a model drawn from the fitted
    population, the population and its between-test sigmas."""
    lines = [f"{model.label}: {model.tests} tests"]
    lines += [f"  {d}" for d in model.dispersions.values()]
    if model.hull is not None:
        lines.append(f"  hull of ({', '.join(model.hull_names)}) grown by "
                     f"{100 * model.hull.growth:.0f} %, {len(model.hull.vertices)} vertices")
    else:
        lines.append(f"  {model.note or 'no hull'}: the caps alone bound the draws")
    text = "\n".join(lines)
    if isinstance(model, PopulationDispersion) and model.population is not None:
        group = model.population
        sd = ", ".join(f"{p} {group.fit.tau[p].value:.3g} (point estimates "
                       f"{group.point_spread[j]:.3g})" for j, p in enumerate(group.data.names))
        text += (f"\n  cases drawn from the population N(mu, Omega) of {group.label} "
                 f"({group.data.n} openings), inside the caps and the hull above (from the "
                 f"point estimates); between-test sigma in log space: {sd}")
    return text


def stage_loads_text(result: StageLoads) -> str:
    """A canopy stage's Monte Carlo peak loads: the cases flown, the fitted values' peak,
    and the quantile table (tension in lbf and N, load factor in g)."""
    nominal = result.nominal.tension[0]
    loads = result.loads
    lines = [f"{result.cases.label} ({result.cases.type}; {len(result.cases.cases):,} cases "
             f"from {result.cases.file.name}; {loads.t1 - loads.t0:.2f} s from "
             f"t_i = {loads.t0:.3f} s): fitted values peak at {nominal / LBF:,.0f} lbf, "
             f"{result.nominal.load_factor[0]:.2f} g",
             f"  {'quantile':>8s} {'tension lbf':>12s} {'tension N':>12s} {'load g':>8s}"]
    for row in result.quantiles().itertuples():
        lines.append(f"  {row.quantile:8.3f} {row.peak_tension_lbf:12,.0f} "
                     f"{row.peak_tension_N:12,.0f} {row.peak_load_factor:8.3f}")
    return "\n".join(lines)


def monte_carlo_text(fit: Fit, results: Sequence[StageLoads]) -> str:
    """The reconstruction's status line and each stage's quantile table."""
    head = (f"reconstruction: {fit.solver.status}, {fit.solver.iterations} iterations, "
            f"chi^2/dof {fit.chi_square / fit.dof:.3f}")
    return "\n\n".join([head, *(stage_loads_text(r) for r in results)])
