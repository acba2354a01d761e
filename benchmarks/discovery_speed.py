"""Benchmark: the wall time of each `discover` step on `drogue`, this tree against an earlier
revision, same cases and seed, one after the other on this machine.

The earlier revision (`--baseline`, by default the last commit before the
discovery's speed work) is checked out into a temporary git worktree and
`benchmarks/hidden_effects.py` run there and here, each in a fresh process
with its own tree first on the import path.  Printed per case and step: the
effect the step added (or dropped), chi-square/dof in each tree (the chains
must agree: a speed-up that changes the answer is not one), the wall time of
each and their ratio (baseline / this tree), then the totals.

A step's time runs from one diagnosed model of the chain to the next: the
diagnosis (score tests, confirming refits, residual tests), the refit from the
offline reduction where the nested refit still misfits, the plug-ins proposed
from a signature and their tests, and the refits that drop stand-ins.
Compiled model functions are cached per machine (`estimation/compiled.py`);
run it once before timing so neither tree pays for compiling.

    python benchmarks/discovery_speed.py [--baseline REV] [--cases wind_shear ...] [--seed N]
"""

from __future__ import annotations

import os
import re
import subprocess
import sys
from pathlib import Path

import harness
from revisions import ROOT, code_at

BASELINE = "eaa37b4"  # docs/validation.md's figures before the speed work
STEP = re.compile(r"^\[(?P<case>[^\]]+)\]\s+step (?P<label>.+): chi-square/dof "
                  r"(?P<per_dof>[\d.]+), (?P<seconds>[\d.]+) s$")
FIT = re.compile(r"^\[(?P<case>[^\]]+)\] baseline fit (?P<seconds>[\d.]+) s")


def run(tree: Path, case: str, seed: int) -> tuple[float, list[tuple[str, float, float]]]:
    """The baseline fit's wall time and each step's (label, chi-square/dof, wall time) of
    `hidden_effects.py` for `case` in `tree`."""
    env = {**os.environ, "PYTHONPATH": str(tree)}
    out = subprocess.run([sys.executable, str(tree / "benchmarks" / "hidden_effects.py"),
                          "--cases", case, "--seed", str(seed)], cwd=tree, env=env,
                         capture_output=True, text=True, check=True).stdout
    fit = next(float(m["seconds"]) for line in out.splitlines() if (m := FIT.match(line)))
    steps = [(m["label"], float(m["per_dof"]), float(m["seconds"]))
             for line in out.splitlines() if (m := STEP.match(line))]
    return fit, steps


def main() -> None:
    parser = harness.parser(__doc__, seed=1, seed_help="seed of the simulated drogue tests")
    parser.add_argument("--baseline", default=BASELINE, help="the revision to compare with")
    parser.add_argument("--cases", nargs="+", default=["wind_shear", "gps_lag+added_mass"])
    args = parser.parse_args()
    cases = {}
    with code_at(args.baseline) as old_tree:
        totals = [0.0, 0.0]
        for case in args.cases:
            (old_fit, old), (new_fit, new) = (run(old_tree, case, args.seed),
                                              run(ROOT, case, args.seed))
            same = [a[0] for a in old] == [b[0] for b in new]
            print(f"\n[{case}] baseline fit {old_fit:.1f} s -> {new_fit:.1f} s"
                  + ("" if same else "; the chains differ"))
            print(f"  {'step':26s} {'chi2/dof':>17s} {'wall time (s)':>17s} {'ratio':>6s}")
            steps = []
            for k in range(max(len(old), len(new))):
                a = old[k] if k < len(old) else ("-", float("nan"), float("nan"))
                b = new[k] if k < len(new) else ("-", float("nan"), float("nan"))
                label = a[0] if a[0] == b[0] else f"{a[0]} | {b[0]}"
                steps.append({"step": label, "chi2_dof": [a[1], b[1]], "wall_s": [a[2], b[2]],
                              "ratio": harness.ratio(a[2], b[2])})
                print(f"  {label:26s} {a[1]:8.3f} {b[1]:8.3f} {a[2]:8.1f} {b[2]:8.1f} "
                      f"{steps[-1]['ratio']:6.2f}")
            t_old, t_new = sum(s[2] for s in old), sum(s[2] for s in new)
            print(f"  {'all steps':26s} {'':17s} {t_old:8.1f} {t_new:8.1f} "
                  f"{harness.ratio_text(t_old, t_new, '6.2f')}; longest step "
                  f"{max(s[2] for s in old):.1f} -> {max(s[2] for s in new):.1f} s")
            cases[case] = {"fit_s": [old_fit, new_fit], "same_chain": same, "steps": steps,
                           "all_steps_s": [t_old, t_new], "ratio": harness.ratio(t_old, t_new)}
            totals[0] += t_old
            totals[1] += t_new
        ratio = harness.ratio(totals[0], totals[1])
        print(f"\nall cases: {totals[0]:.0f} s -> {totals[1]:.0f} s, ratio "
              f"{ratio:.2f} (baseline {args.baseline})")
    harness.report("discovery_speed", baseline=args.baseline, cases=cases,
                   all_cases_s=totals, ratio=ratio)


if __name__ == "__main__":
    main()
