"""Benchmark: a whole discovery chain on `drogue` cases, this tree against another revision.

Each case of `hidden_forms.py` named (default: the two forms the library lacks
that refinements reach, and the control where the library's form made the
data) and the case with nothing hidden is simulated once (seed 1); each tree
fits the baseline from the offline reduction and runs `discover`, in a fresh
process with a shared compile cache (compiled before the timed call), the two
trees alternately (`revisions.compare_cases`).  Printed per case: each side's
chain, chi-square/dof, ending, seconds of the chain and the process's peak
memory, and the ratio of wall times now / before.  The line a chain on a
16-20 s test should stay within: 2 minutes on 2 quiet cores and 2 GB.

    python benchmarks/discovery_revisions.py [--baseline REV] [--cases NAME ...]
                                            [--repeat N]
"""

from __future__ import annotations

import dataclasses
import resource
from pathlib import Path

import harness
from hidden_forms import forms
from revisions import compare_cases

from cpas_ocp.discrepancy.discovery import discover
from cpas_ocp.estimation.estimator import Estimator
from cpas_ocp.estimation.simulate import simulate_problem
from cpas_ocp.inference.continuation import solve as solve_with_continuation
from cpas_ocp.io.flight_test import load_test
from cpas_ocp.io.model_spec import baseline_spec
from cpas_ocp.io.problems import load_problem
from cpas_ocp.physics.effects import baseline_effects

BASELINE = "baf439f"  # the discovery loop before refinements and the sparse drag law
CASES = ("late_added_mass", "late_breathing", "added_mass_d3", "nothing_hidden")


def chain(folder: str) -> dict:
    """The baseline fit and `discover` on the test in `folder`: the chain's labels, the
    last chi-square/dof, its state, the seconds of the fit and the chain, and the
    process's peak memory (GB)."""
    timer = harness.Timer()
    with timer("wall"):
        with timer("fit"):
            fit = solve_with_continuation(Estimator(load_test(Path(folder)), baseline_spec()))
        with timer("discover"):
            found = discover(fit, baseline_spec())
    last = found.steps[-1].fit
    labels = [getattr(s, "label", s.added) for s in found.steps[1:]]
    return {"wall_s": timer["wall"], "fit_s": timer["fit"], "discover_s": timer["discover"],
            "chain": " > ".join(labels) or "-", "chi2_dof": last.chi_square / last.dof,
            "state": found.state,
            "peak_gb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1e6}


def simulated(names: list[str], seed: int):
    """A function making each case's test folder under a root folder (truth removed)."""
    table = forms()

    def make(root: Path) -> dict[str, Path]:
        out = {}
        problem = load_problem("drogue")
        for name in names:
            effects, values = table.get(name, (baseline_effects(), {}))
            folder = root / name
            simulate_problem(dataclasses.replace(problem, truth={**problem.truth, **values}),
                             folder, seed, effects=effects)
            (folder / "truth.json").unlink()
            out[name] = folder
        return out

    return make


def describe(r: dict) -> str:
    return (f"{r['chain']}, chi2/dof {r['chi2_dof']:.3f} ({r['state']}), chain "
            f"{r['discover_s']:.0f} s, {r['peak_gb']:.2f} GB")


if __name__ == "__main__":
    parser = harness.parser(__doc__, seed=1, seed_help="seed of the simulated drogue tests")
    parser.add_argument("--baseline", default=BASELINE, help="the revision to compare with")
    parser.add_argument("--cases", nargs="+", default=list(CASES),
                        choices=[*forms(), "nothing_hidden"])
    parser.add_argument("--repeat", type=int, default=1, help="timed calls per tree")
    args = parser.parse_args()
    compare_cases("discovery_revisions", "chain", simulated(args.cases, args.seed),
                  args.baseline, describe, args.repeat)
