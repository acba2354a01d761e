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

import importlib
import importlib.util
from typing import Any


def __getattr__(name: str) -> Any:
    """The interface's names (`cpas_ocp.api.__all__`), imported on first use: the command
    line starts without loading the solver, the statistics and the figures it may not
    need.  A subpackage's or module's name is left to the import system."""
    if name == "__all__" or not (name.startswith("_")
                                 or importlib.util.find_spec(f"{__name__}.{name}")):
        api = importlib.import_module(f"{__name__}.api")
        if name == "__all__":
            return api.__all__
        if name in api.__all__:
            return getattr(api, name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
