"""A campaign: reconstruct many test folders in parallel and tabulate their parameters.

The paper's end product is not one fit but the dispersions of a campaign's
parameters (Sections IV.C, V-VII).  `run_campaign` reconstructs every test
folder under a root, each with the model its manifest declares, on local
processes or, given a scheduler address, on a Dask cluster
(dask.distributed); a test that fails (bad input, a solver that does not
converge, anything else) is reported with its reason and does not stop the
others.  `parameter_table` gives one row per test, canopy-indexed parameter
and value with its standard deviation, the canopy's type and stage, the
forebody (vehicle name), the cluster size and the canopy's suspension-line
length, in SI.  `stage_table` gives one row per test, canopy and stage with
what redrawing the stage's drag-area curve needs besides its parameters (the
stage's order, inflation law, fill-length form, D_o and the captured start
airspeed V_i), which `cpas-ocp dispersions` uses for its drag-area envelopes.
"""

from __future__ import annotations

import time
import traceback
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from cpas_ocp.campaign.parallel import run_tasks
from cpas_ocp.errors import InputError, PluginError, SolverFailure
from cpas_ocp.estimation.reduction import stage_starts
from cpas_ocp.estimation.stage_groups import clusters
from cpas_ocp.io.flight_test import MANIFEST, TABLE_COLUMNS, canopy_covariates
from cpas_ocp.physics.flight_test import Parachute
from cpas_ocp.physics.parameters import param_name, split_name
from cpas_ocp.progress import progress_line

COLUMNS = list(TABLE_COLUMNS)
# Per test, canopy and stage: what drawing the stage's drag-area curve needs beyond its
# parameters (order, inflation law, fill-length form, D_o in m, start airspeed V_i in m/s).
STAGE_COLUMNS = ["test", "parachute", "type", "stage", "stage_index", "inflation",
                 "fill_length", "diameter", "line_length", "v_start"]
# Per test, the covariance of its determined parameters (SI), one row per pair (the lower
# triangle with the diagonal): what a population fit weighs each test's estimates with.
COVARIANCE_COLUMNS = ["test", "name_a", "name_b", "covariance"]


@dataclass
class TestOutcome:
    """The reconstruction of one test folder: its table rows, or why there are none.

    `kind` is "ok", "input" (the folder breaks the test-folder contract),
    "solver" (Ipopt did not converge), "claim" (converged, but the data press
    parameters against guessed bounds: not a result, `result_claim`) or "error"
    (anything else, with the exception's type and message).  `stages` holds a row per canopy stage
    (STAGE_COLUMNS), `covariance` a row per pair of determined parameters
    (COVARIANCE_COLUMNS).
    """

    folder: str
    name: str
    kind: str
    message: str = ""
    rows: list[dict[str, Any]] = field(default_factory=list)
    stages: list[dict[str, Any]] = field(default_factory=list)
    covariance: list[dict[str, Any]] = field(default_factory=list)
    wall_s: float = 0.0
    iterations: int = 0
    chi_square_per_dof: float = float("nan")

    @property
    def ok(self) -> bool:
        return self.kind == "ok"


def find_tests(root: str | Path) -> list[Path]:
    """Every folder under `root` (itself included) that holds a manifest, sorted by path;
    InputError when there is none."""
    root = Path(root)
    if not root.is_dir():
        raise InputError(str(root), "(folder)", "an existing folder of test folders")
    found = sorted({p.parent for p in root.rglob(MANIFEST)})
    if not found:
        raise InputError(str(root), "(folder)", f"test folders, each holding a {MANIFEST}")
    return found


def reconstruct_folder(folder: str) -> TestOutcome:
    """Reconstruct one test folder with its manifest's model; never raises (a picklable
    top-level function, run in a worker process)."""
    from cpas_ocp.estimation.estimator import Estimator
    from cpas_ocp.inference.reconstruction import fit_and_claim
    from cpas_ocp.io.flight_test import load_test
    t0 = time.perf_counter()
    name = Path(folder).name
    try:
        test = load_test(folder)
        name = test.name
        done = fit_and_claim(Estimator(test))
        fit, cov, claim = done.fit, done.covariance, done.claim
        if not claim.is_result:
            return TestOutcome(folder, name, "claim", "; ".join(claim.problems()),
                               wall_s=time.perf_counter() - t0)
    except (InputError, PluginError) as exc:
        return TestOutcome(folder, name, "input", str(exc), wall_s=time.perf_counter() - t0)
    except SolverFailure as exc:
        return TestOutcome(folder, name, "solver", str(exc), wall_s=time.perf_counter() - t0)
    except Exception as exc:  # a campaign reports every failure and carries on
        where = traceback.extract_tb(exc.__traceback__)[-1]
        return TestOutcome(folder, name, "error",
                           f"{type(exc).__name__}: {exc} (at {Path(where.filename).name}:"
                           f"{where.lineno})", wall_s=time.perf_counter() - t0)
    std = cov.std
    chutes = {c.name: c for c in test.parachutes}
    # A cluster is the canopies opened together (`stage_groups.clusters`, from the fitted
    # starts): a rocket's drogue and main, tens of seconds apart, each fly alone.
    cluster_of = {c.name: len(group) for group in clusters(
        test, stage_starts(test, fit.parameters)) for c in group}
    stages = {s for c in test.parachutes for s in c.stages}
    covariates = canopy_covariates(test.manifest) if test.manifest else {}
    rows = []
    for pname in fit.free:
        base, index = split_name(pname)
        chute = chutes.get(index[0]) if index else None
        stage = next((i for i in index if i in stages), "")
        rows.append({"test": test.name, "parameter": base, "name": pname,
                     "parachute": chute.name if chute else "", "type": chute.type if chute else "",
                     "stage": stage, "forebody": test.vehicle.name,
                     "cluster_size": cluster_of[chute.name] if chute else len(test.parachutes),
                     "line_length": _line_length(chute),
                     "position": covariates.get(chute.name, {}).get("position", chute.name)
                     if chute else "",
                     **({k: v for k, v in covariates.get(chute.name, {}).items()
                         if k != "position"} if chute else {}),
                     "value": fit.parameters[pname],
                     "std": std.get(pname, np.nan), "unit": fit.model.parameter(pname).unit})
    stage_rows = [{"test": test.name, "parachute": c.name, "type": c.type, "stage": s,
                   "stage_index": k, "inflation": c.inflation, "fill_length": c.fill_length,
                   "diameter": c.diameter, "line_length": _line_length(c),
                   "v_start": fit.captures.get(param_name("V_start", c.name, s), np.nan)}
                  for c in test.parachutes for k, s in enumerate(c.stages)]
    determined = [i for i, n in enumerate(cov.names) if n in std]
    covariance = [{"test": test.name, "name_a": cov.names[a], "name_b": cov.names[b],
                   "covariance": float(cov.matrix[a, b])}
                  for i, a in enumerate(determined) for b in determined[: i + 1]]
    return TestOutcome(folder, test.name, "ok", rows=rows, stages=stage_rows,
                       covariance=covariance, wall_s=time.perf_counter() - t0,
                       iterations=fit.solver.iterations,
                       chi_square_per_dof=fit.chi_square / fit.dof)


def _line_length(chute: Parachute | None) -> float:
    """The canopy's suspension-line length (m), NaN where the manifest gives none; rounded to
    0.1 mm so that lengths given in different units group together."""
    if chute is None or chute.line_length is None:
        return np.nan
    return round(chute.line_length, 4)


def run_campaign(folders: Sequence[str | Path], workers: int = 2, scheduler: str | None = None,
                 progress: bool = False) -> list[TestOutcome]:
    """Reconstruct `folders` on `workers` local processes, or on the Dask cluster at
    `scheduler` (an address such as ``tcp://host:8786``); outcomes in the order of
    `folders`.  With `progress`, a line on stderr counts finished and failed tests."""
    paths = [str(Path(f)) for f in folders]
    outcomes: dict[str, TestOutcome] = {}
    with progress_line("tests reconstructed", len(paths), progress) as advance:
        for _, outcome in run_tasks(reconstruct_folder, paths, workers, scheduler):
            outcomes[outcome.folder] = outcome
            advance(f"{sum(not o.ok for o in outcomes.values())} failed")
    return [outcomes[p] for p in paths]


def parameter_table(outcomes: Sequence[TestOutcome]) -> pd.DataFrame:
    """One row per test and estimated parameter (SI), in the columns of COLUMNS, then a
    column per covariate the manifests name (`flight_test.canopy_covariates`; blank where
    a test's manifest does not give it)."""
    rows = [r for o in outcomes if o.ok for r in o.rows]
    extra = list(dict.fromkeys(k for r in rows for k in r if k not in COLUMNS))
    return pd.DataFrame(rows, columns=COLUMNS + extra)


def stage_table(outcomes: Sequence[TestOutcome]) -> pd.DataFrame:
    """One row per reconstructed test, canopy and stage, in the columns of STAGE_COLUMNS."""
    return pd.DataFrame([r for o in outcomes if o.ok for r in o.stages], columns=STAGE_COLUMNS)


def covariance_table(outcomes: Sequence[TestOutcome]) -> pd.DataFrame:
    """One row per reconstructed test and pair of its determined parameters, in the
    columns of COVARIANCE_COLUMNS."""
    return pd.DataFrame([r for o in outcomes if o.ok for r in o.covariance],
                        columns=COVARIANCE_COLUMNS)


def failure_table(outcomes: Sequence[TestOutcome]) -> pd.DataFrame:
    """One row per failed test: folder, name, kind of failure and its message."""
    return pd.DataFrame([{"folder": o.folder, "test": o.name, "kind": o.kind,
                          "message": o.message} for o in outcomes if not o.ok],
                        columns=["folder", "test", "kind", "message"])
