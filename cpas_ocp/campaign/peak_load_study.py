"""Monte Carlo peak loads of a reconstructed test: the dispersed cases of each canopy stage
flown through the test's fitted model, in chunks on local processes or a Dask cluster.

`cpas-ocp dispersions` writes, per parachute type and stage, the Monte Carlo
cases of its inflation parameters (``cases_<type>_<stage>.parquet``: CdS in
m^2, Ck, n_p or n, expopen, t_k in s).  Here every canopy stage of one test
whose type and stage have such a file is flown once per case from the fit's
state at the stage's start (`peak_loads.fly_stage`: the model's RK4 step,
4 ms), every other parameter and the start airspeed held at the fit's
values.  The result per canopy stage is the distribution of the peak riser
tension of that canopy (N, lbf) and of the system's peak load factor (g):
its quantiles, the per-case table and a histogram with the exceedance
curve.

The cases of all stages are cut into chunks of at most `MAX_CHUNK` and
handed to `parallel.run_tasks` (the campaign's machinery).  A chunk carries
plain numbers (`peak_loads.StageStart`) and the test folder's path; the
worker rebuilds the model from the folder (milliseconds) and flies the
chunk, so the local and the Dask paths run the same code on the same
numbers.  A case's result does not depend on the chunk it is flown in.
"""

from __future__ import annotations

import functools
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pandas as pd

from cpas_ocp.campaign.parallel import run_tasks
from cpas_ocp.campaign.peak_loads import (
    DEFAULT_STEP_S,
    PeakLoads,
    StageStart,
    fly_stage,
    stage_start,
)
from cpas_ocp.errors import InputError
from cpas_ocp.estimation.estimator import Fit
from cpas_ocp.io.flight_test import MANIFEST, load_test
from cpas_ocp.physics.flight_test import FlightTest
from cpas_ocp.physics.model import Model
from cpas_ocp.physics.parameters import param_name
from cpas_ocp.physics.units import LBF
from cpas_ocp.progress import progress_line

MAX_CHUNK = 1000  # cases per task: about 4 s of flight for a Drogue stage
QUANTILES = (0.0, 0.01, 0.1, 0.5, 0.9, 0.99, 0.999, 1.0)
MARKER = "montecarlo.md"


def cases_file(kind: str, stage: str) -> str:
    """The name `cpas-ocp dispersions` gives the cases of a parachute type and stage."""
    return f"cases_{kind}_{stage}.parquet"


@dataclass
class StageCases:
    """The Monte Carlo cases (SI columns, one row a case) for one canopy stage of the test."""

    parachute: str
    type: str
    stage: str
    file: Path
    cases: pd.DataFrame

    @property
    def label(self) -> str:
        return f"{self.parachute} {self.stage}"


@dataclass
class StageLoads:
    """The peak loads of one canopy stage over its cases, and those of the fitted values."""

    cases: StageCases
    loads: PeakLoads
    nominal: PeakLoads

    def table(self) -> pd.DataFrame:
        """Per case: its index in the cases file, its parameters, peak tension in N and lbf,
        peak load factor (g)."""
        out = self.cases.cases.reset_index(names="case")
        out["peak_tension_N"] = self.loads.tension
        out["peak_tension_lbf"] = self.loads.tension / LBF
        out["peak_load_factor"] = self.loads.load_factor
        return out

    def quantiles(self, q: tuple[float, ...] = QUANTILES) -> pd.DataFrame:
        """Quantiles (0: the least case, 1: the largest) of peak tension (N, lbf) and of
        peak load factor (g), each taken over the cases on its own."""
        tension = np.quantile(self.loads.tension, q)
        return pd.DataFrame({"quantile": q, "peak_tension_N": tension,
                             "peak_tension_lbf": tension / LBF,
                             "peak_load_factor": np.quantile(self.loads.load_factor, q)})


def read_cases(path: Path, limit: int | None = None) -> pd.DataFrame:
    """The first `limit` cases (all if None) of a cases file; InputError unless every value is
    a finite positive number (drag areas, factors, fill constants and times all are)."""
    try:
        cases = pd.read_parquet(path)
    except (OSError, ValueError) as exc:
        raise InputError(str(path), "(file)", f"a Parquet table of cases ({exc})") from None
    if limit is not None:
        cases = cases.iloc[:limit]
    if cases.empty or cases.shape[1] == 0:
        raise InputError(str(path), "(table)", "at least one case and one parameter column")
    for column in cases.columns:
        values = pd.to_numeric(cases[column], errors="coerce").to_numpy(dtype=float)
        bad = np.flatnonzero(~(np.isfinite(values) & (values > 0.0)))
        if bad.size:
            raise InputError(str(path), str(column), f"finite positive numbers; row "
                             f"{bad[0] + 1} holds {cases[column].iloc[bad[0]]!r}"
                             + (f" ({bad.size} such rows)" if bad.size > 1 else ""))
    return cases.astype(float)


def match_cases(test: FlightTest, folder: str | Path, limit: int | None = None
                ) -> list[StageCases]:
    """The cases of every canopy stage of `test` whose type and stage have a cases file in
    `folder`; InputError when the folder is missing or nothing matches."""
    return match_canopies([(c.name, c.type, tuple(c.stages)) for c in test.parachutes],
                          folder, test.name, limit)


def match_canopies(canopies: Sequence[tuple[str, str, tuple[str, ...]]], folder: str | Path,
                   whose: str, limit: int | None = None) -> list[StageCases]:
    """The cases of every stage of `canopies` ((name, type, stages), the canopies of the test
    `whose`) whose type and stage have a cases file in `folder`; InputError when the folder
    is missing or nothing matches."""
    folder = Path(folder)
    if not folder.is_dir():
        raise InputError(str(folder), "(folder)", "a dispersions folder holding "
                         "cases_<type>_<stage>.parquet (cpas-ocp dispersions)")
    found = []
    for name, kind, stages in canopies:
        for stage in stages:
            path = folder / cases_file(kind, stage)
            if path.is_file():
                found.append(StageCases(name, kind, stage, path, read_cases(path, limit)))
    if not found:
        wanted = sorted({cases_file(kind, s) for _, kind, stages in canopies for s in stages})
        present = sorted(p.name for p in folder.glob("cases_*.parquet")) or ["none"]
        raise InputError(str(folder), "cases_<type>_<stage>.parquet",
                         f"a cases file for a canopy stage of {whose} ({', '.join(wanted)}); "
                         f"found {', '.join(present)}")
    return found


def check_columns(model: Model, stages: list[StageCases]) -> None:
    """InputError naming the cases file and column that is not a parameter of its stage."""
    names = set(model.parameter_names)
    for s in stages:
        for column in s.cases.columns:
            if param_name(column, s.parachute, s.stage) not in names:
                known = sorted(n.split("[")[0] for n in names
                               if n.endswith(f"[{s.parachute},{s.stage}]"))
                raise InputError(str(s.file), str(column), f"a parameter of {s.label} "
                                 f"({', '.join(known)})")


@dataclass(frozen=True)
class Chunk:
    """One task: fly `cases` from `start` through the model of the test folder `folder`."""

    folder: str
    start: StageStart
    cases: pd.DataFrame
    step: float


def fly_chunk(chunk: Chunk) -> PeakLoads:
    """Peak loads of one chunk (a picklable top-level function, run in a worker)."""
    manifest = Path(chunk.folder) / MANIFEST
    return fly_stage(_model(chunk.folder, manifest.stat().st_mtime_ns), chunk.start,
                     chunk.cases, chunk.step)


@functools.lru_cache(maxsize=4)
def _model(folder: str, stamp: int) -> Model:
    """The model a folder's manifest declares, built once per process and manifest version."""
    from cpas_ocp.io.model_spec import spec_of_test
    test = load_test(folder)
    return spec_of_test(test).model(test)


def chunk_sizes(n: int, workers: int) -> list[int]:
    """Split n cases into at least `workers` chunks of at most MAX_CHUNK, as even as can be."""
    count = max(min(workers, n), -(-n // MAX_CHUNK))
    return [len(part) for part in np.array_split(np.arange(n), count)]


def run_monte_carlo(fit: Fit, stages: list[StageCases], workers: int = 2,
                    scheduler: str | None = None, step: float = DEFAULT_STEP_S,
                    progress: bool = False) -> list[StageLoads]:
    """Fly every stage's cases (chunked over `workers` local processes, or on the Dask
    scheduler at `scheduler`) and, in this process, the fit's own values once per stage.

    Every chunk also flies the fit's own values first: a worker whose model differs from
    this process's (another cpas-ocp version, another copy of the test folder) gives
    another peak for them, and the run stops with an InputError naming the folder rather
    than return peaks of a different model."""
    if fit.test.path is None:
        raise ValueError("the Monte Carlo rebuilds the model from the test folder; this fit "
                         "has none")
    folder = str(Path(fit.test.path).resolve())
    chunks: list[Chunk] = []
    owner: list[int] = []
    starts, nominals = [], []
    for k, s in enumerate(stages):
        start = stage_start(fit, s.parachute, s.stage)
        fitted = pd.DataFrame({c: [fit.parameters[param_name(c, s.parachute, s.stage)]]
                               for c in s.cases.columns})
        starts.append(start)
        nominals.append(fly_stage(fit.model, start, fitted, step))
        first = 0
        for size in chunk_sizes(len(s.cases), workers):
            cases = pd.concat([fitted, s.cases.iloc[first:first + size]], ignore_index=True)
            chunks.append(Chunk(folder, start, cases, step))
            owner.append(k)
            first += size
    results: list[PeakLoads | None] = [None] * len(chunks)
    total = sum(len(c.cases) - 1 for c in chunks)
    with progress_line("cases flown", total, progress) as advance:
        for done, (i, loads) in enumerate(run_tasks(fly_chunk, chunks, workers, scheduler), 1):
            expected = nominals[owner[i]].tension[0]
            if not np.isclose(loads.tension[0], expected, rtol=1e-9, atol=0.0):
                raise InputError(folder, "(model)", f"the same model in every worker; a "
                                 f"worker flies the fitted values to {loads.tension[0]:.6g} N "
                                 f"against {expected:.6g} N here (another cpas-ocp version "
                                 "or another copy of the test folder on the workers?)")
            results[i] = loads
            advance(f"{done}/{len(chunks)} chunks", done=len(chunks[i].cases) - 1)
    out = []
    for k, s in enumerate(stages):
        parts = [r for r, o in zip(results, owner, strict=True) if o == k and r is not None]
        start = starts[k]
        merged = PeakLoads(s.parachute, s.stage, start.t0, start.t1,
                           np.concatenate([r.tension[1:] for r in parts]),
                           np.concatenate([r.load_factor[1:] for r in parts]))
        out.append(StageLoads(s, merged, nominals[k]))
    return out
