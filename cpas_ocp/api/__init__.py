"""The Python interface for notebooks and scripts: every workflow of the command line as a
function, each returning a result object (the command line only parses, calls and prints).

    import cpas_ocp as co

    test = co.simulate("drogue", "drogue-test", seed=1)   # or co.load_test(folder)
    rec = co.reconstruct(test)        # solve, judge the fit, covariance
    rec.parameters                    # value, sigma, 95 % interval, unit (SI)
    rec.worst                         # where the model fits worst, one line
    rec.report("report")              # the folder `cpas-ocp reconstruct` writes
    diag = rec.diagnose()             # which effect is missing, or the residual's signature
    chain = rec.discover()            # diagnose, add, refit, ... until the residual is noise
    comp = rec.compare("model.json")  # this model against another, nested or not

A fit that did not converge raises `SolverFailure` (its status and iteration
count), never a result; a fit that converged but is not a result (a guessed bound
pressed, chi-square/dof beyond 10, a process beyond its prior, a drag area
undetermined: `result_claim`) is returned with `rec.is_result` False and
`rec.problems` saying why.  Long workflows say what they do through a `Narration`
(`progress.terminal()` on a terminal; silent by default).

The modules: `preparation` (simulate, reduce, model files, test design),
`reconstruction` (one test's fit and what follows from it), `discrepancy`
(diagnose, discover, compare from a test folder), `kept_discovery` (a discovery
kept on disk, resumed), `campaigns` (many tests, populations, a joint fit,
dispersions, Monte Carlo), `log_import` (a recorder's log into a test folder),
`flights` (a real flight's logs reconstructed and compared) and `rocketpy_export` (a
reconstruction's canopies as RocketPy parachutes).  Each name is imported
from its module when first used.
"""

from __future__ import annotations

import importlib
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from cpas_ocp.api.campaigns import (
        Campaign,
        Dispersions,
        Hierarchical,
        Joint,
        MonteCarlo,
        Population,
        dispersions,
        hierarchical,
        joint,
        monte_carlo,
        population,
        reconstruct_campaign,
    )
    from cpas_ocp.api.discrepancy import compare, diagnose, discover
    from cpas_ocp.api.flights import Flight, flight
    from cpas_ocp.api.kept_discovery import resume_discovery
    from cpas_ocp.api.log_import import import_log
    from cpas_ocp.api.preparation import (
        InitialGuess,
        design,
        effect,
        load_model,
        reduce,
        simulate,
    )
    from cpas_ocp.api.reconstruction import (
        FitOptions,
        Reconstruction,
        build,
        demo,
        fit_estimator,
        reconstruct,
        what_if,
    )
    from cpas_ocp.api.rocketpy_export import RocketPyExport, rocketpy_export
    from cpas_ocp.inference.hierarchical_fit import hierarchical_fit
    from cpas_ocp.io.flight_test import load_test
    from cpas_ocp.physics.effects import baseline_effects
    from cpas_ocp.progress import Narration, terminal
    from cpas_ocp.reports.summaries import summary

# Where each name of the interface lives.  A name is imported from its module when first
# used: a command imports only what its workflow needs (`cpas-ocp import` reads a log with
# pandas and scipy, and never loads matplotlib or the estimator).
_HOMES = {
    **dict.fromkeys(("Campaign", "Dispersions", "Hierarchical", "Joint", "MonteCarlo",
                     "Population", "dispersions", "hierarchical", "joint", "monte_carlo",
                     "population", "reconstruct_campaign"), "cpas_ocp.api.campaigns"),
    **dict.fromkeys(("compare", "diagnose", "discover"), "cpas_ocp.api.discrepancy"),
    **dict.fromkeys(("Flight", "flight"), "cpas_ocp.api.flights"),
    "import_log": "cpas_ocp.api.log_import",
    "resume_discovery": "cpas_ocp.api.kept_discovery",
    **dict.fromkeys(("InitialGuess", "design", "effect", "load_model", "reduce", "simulate"),
                    "cpas_ocp.api.preparation"),
    **dict.fromkeys(("FitOptions", "Reconstruction", "build", "demo", "fit_estimator",
                     "reconstruct", "what_if"), "cpas_ocp.api.reconstruction"),
    **dict.fromkeys(("RocketPyExport", "rocketpy_export"), "cpas_ocp.api.rocketpy_export"),
    "load_test": "cpas_ocp.io.flight_test",
    "hierarchical_fit": "cpas_ocp.inference.hierarchical_fit",
    "baseline_effects": "cpas_ocp.physics.effects",
    **dict.fromkeys(("Narration", "terminal"), "cpas_ocp.progress"),
    "summary": "cpas_ocp.reports.summaries",
}


def __getattr__(name: str) -> Any:
    """The interface's `name`, imported from its module on first use (PEP 562)."""
    if name not in _HOMES:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    value = getattr(importlib.import_module(_HOMES[name]), name)
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    """The module's names, the interface's not yet imported among them."""
    return sorted({*globals(), *_HOMES})


__all__ = ["Campaign", "Dispersions", "FitOptions", "Flight", "Hierarchical", "InitialGuess",
           "Joint",
           "MonteCarlo", "Narration", "Population", "Reconstruction", "RocketPyExport",
           "baseline_effects", "build",
           "compare", "demo", "design", "diagnose", "discover", "dispersions", "effect",
           "fit_estimator", "flight", "hierarchical", "hierarchical_fit", "import_log", "joint",
           "load_model", "load_test",
           "monte_carlo", "population", "reconstruct", "reconstruct_campaign", "reduce",
           "resume_discovery", "rocketpy_export", "simulate", "summary", "terminal",
           "what_if"]
