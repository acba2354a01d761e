"""Benchmark: forward Monte Carlo of the Drogue's disreef stage (drogue1, stage2), 10,000
cases through the fitted model, against one case flown the same way in the same process.

Prints the seconds of each, the ratio, the per-case cost and the peak-load quantiles.
`python benchmarks/peak_load_monte_carlo.py [--cases 10000] [--seed 1]` (about a minute).
"""

from __future__ import annotations

import tempfile
from pathlib import Path

import harness
import numpy as np
import pandas as pd

from cpas_ocp.campaign.peak_loads import stage_peak_loads
from cpas_ocp.estimation.estimator import Estimator
from cpas_ocp.estimation.simulate import simulate_problem
from cpas_ocp.io.flight_test import load_test
from cpas_ocp.io.problems import load_problem
from cpas_ocp.physics.parameters import param_name

SHAPE = ("CdS", "Ck", "n_p", "expopen", "t_k")


def main() -> None:
    ap = harness.parser(__doc__, seed=1, seed_help="seed of the test and of the cases")
    ap.add_argument("--cases", type=int, default=10_000)
    args = ap.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        simulate_problem(load_problem("drogue"), Path(tmp) / "test", args.seed)
        fit = Estimator(load_test(Path(tmp) / "test")).solve()
    fitted = {b: fit.parameters[param_name(b, "drogue1", "stage2")] for b in SHAPE}
    rng = np.random.default_rng(args.seed)
    cases = pd.DataFrame({b: v * (1 + 0.05 * rng.standard_normal(args.cases))
                          for b, v in fitted.items()})
    timer = harness.Timer()
    with timer("one"):
        stage_peak_loads(fit, "drogue1", "stage2", cases.iloc[:1])
    with timer("many"):
        result = stage_peak_loads(fit, "drogue1", "stage2", cases)
    one, many = timer["one"], timer["many"]
    print(f"1 case: {one:.2f} s; {args.cases} cases: {many:.1f} s; ratio "
          f"{harness.ratio_text(many, one, '.1f')} ({1e3 * many / args.cases:.2f} ms per case)")
    quantiles = {q: v / 4.4482216 for q, v in result.quantiles().items()}
    print("peak tension quantiles (lbf):",
          ", ".join(f"{q:g}: {v:,.0f}" for q, v in quantiles.items()))
    harness.report("peak_load_monte_carlo", cases=args.cases, one_case_s=one, all_cases_s=many,
                   ratio=harness.ratio(many, one), ms_per_case=1e3 * many / args.cases,
                   peak_tension_lbf=quantiles)


if __name__ == "__main__":
    main()
