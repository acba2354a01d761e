"""cpas-ocp: parachute drop tests reconstructed by optimal estimation.

Each test phase is one multiple-shooting NLP (CasADi, Ipopt) whose decision
variables are the inflation parameters, scale factors and start times and
whose objective is the sigma-weighted GPS, IMU and riser residuals.  The
package follows the data: `physics` (the test description, atmosphere,
inflation laws, effects, the model) <- `io` (test folders, logs, model files
read into it) <- `estimation` (reduction, NLP, solve, covariance) <-
`inference` (is it a result, profiles, what-if, model comparison) <-
`discrepancy` (diagnosis, discovery) and `campaign` (many tests, dispersions,
Monte Carlo) <- `reports` <- `api` (the workflows) <- `cli` (the command line
over them); each imports only those before it.

The Python interface (`cpas_ocp.api`), for notebooks:

    import cpas_ocp as co
    test = co.simulate("drogue", "drogue-test", seed=1)   # or co.load_test(folder)
    rec = co.reconstruct(test)        # a notebook shows its parameter table
    rec.parameters, rec.worst, rec.criteria, print(rec.summary())
    rec.report("report"); rec.diagnose(); rec.discover(); rec.compare("model.json")
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

__all__ = ["Campaign", "Dispersions", "Joint", "MonteCarlo", "Population", "Reconstruction",
           "campaign", "design", "dispersions", "fit_estimator", "import_log", "joint",
           "load_model", "load_test", "monte_carlo", "population", "reconstruct", "simulate"]

if TYPE_CHECKING:
    from cpas_ocp.api import (
        Campaign,
        Dispersions,
        Joint,
        MonteCarlo,
        Population,
        Reconstruction,
        campaign,
        design,
        dispersions,
        fit_estimator,
        import_log,
        joint,
        load_model,
        load_test,
        monte_carlo,
        population,
        reconstruct,
        simulate,
    )


def __getattr__(name: str) -> Any:
    """The interface's names, imported on first use (the command line starts without
    loading the solver, the statistics and the figures it may not need)."""
    if name in __all__:
        from cpas_ocp import api
        return getattr(api, name)
    raise AttributeError(f"module 'cpas_ocp' has no attribute {name!r}")
