"""Events off by more than the start window: does the fit recover the truth, or say it cannot?

For each seed of the `drogue` problem (`--seeds` of them, from `--seed` on) the
events are moved off the truth and the phase is fitted as `reconstruct` does
(`continuation.solve_checked`).
Two cases, each beyond the 1 s window about each event:

- ``late``: every event `--offset` s late (their order kept);
- ``disreefs``: the disreef events alternately `--offset` s late and early
  (bag strips right; moving those both ways breaks the events' order, which
  the input check refuses).

Per seed it prints how the fit ended (a result, not a result, or a solver
failure), chi-square/dof, the window moves, the largest start-time error
against the truth (s) and in sigma, and the wall time; with `--baseline`,
also the plain fit (`continuation.solve`, no claim, no moves) in the same
process, which is what the tool reported before.

With `--against REV`, each checked fit is also made with the package of git revision
REV, each side in a process of its own (`revisions.call_at`, models compiled first
into one cache), and the wall-time ratio now/REV is printed: `--against 4d88856`
measures the window moves made before the restarts against the restarts first.

    python benchmarks/events_offset.py [--seeds 10] [--offset 1.5] [--baseline] [--seed 1]
                                       [--against REV]
"""

from __future__ import annotations

import json
import sys
import tempfile
from pathlib import Path

import harness
from revisions import ROOT, call_at, code_at

from cpas_ocp.errors import SolverFailure
from cpas_ocp.estimation.estimator import Estimator, Fit
from cpas_ocp.estimation.simulate import simulate_problem
from cpas_ocp.inference.continuation import solve, solve_checked
from cpas_ocp.io.flight_test import load_test
from cpas_ocp.io.problems import load_problem


def shifted_folder(root: Path, seed: int, case: str, offset: float) -> tuple[Path, dict]:
    """Simulate `drogue` for `seed` and move its events as `case` says; the truth apart."""
    folder = root / f"{case}{seed}"
    simulate_problem(load_problem("drogue"), folder, seed)
    truth = json.loads((folder / "truth.json").read_text())["parameters"]
    (folder / "truth.json").unlink()
    manifest = json.loads((folder / "manifest.json").read_text())
    k = 0
    for event in manifest["events"]:
        if case == "late":
            event["time"]["value"] += offset
        elif event["name"] == "disreef":
            event["time"]["value"] += offset * (-1) ** k
            k += 1
    (folder / "manifest.json").write_text(json.dumps(manifest, indent=2))
    return folder, truth


def start_errors(est: Estimator, fit: Fit, truth: dict) -> tuple[float, float]:
    """Largest |t_start - truth| (s) and the largest in sigma (NaN where every start time
    sits on a bound, without a sigma)."""
    std = est.covariance(fit).std
    names = [n for n in fit.free if n.startswith("t_start")]
    errors = {n: abs(fit.parameters[n] - truth[n]) for n in names}
    return max(errors.values()), max((errors[n] / std[n] for n in names if std.get(n)),
                                     default=float("nan"))


def run(folder: Path, truth: dict, checked: bool) -> tuple[str, dict]:
    """One fit of `folder` (`solve_checked`, or the plain `solve`): its line and figures."""
    timer = harness.Timer()
    try:
        with timer("fit"):
            est = Estimator(load_test(folder))
            if checked:
                est, fit, claim = solve_checked(est)
            else:
                fit, claim = solve(est), None
    except SolverFailure as exc:
        return (f"solver failure ({exc.status}, {exc.iterations} iterations)  "
                f"{timer['fit']:5.1f} s"), {"ending": f"solver failure ({exc.status})",
                                            "iterations": exc.iterations,
                                            "wall_s": timer["fit"]}
    wall = timer["fit"]
    err_s, err_z = start_errors(est, fit, truth)
    verdict = ("converged (reported as a result)" if claim is None else
               claim.verdict() + ("" if claim.is_result else " (exit 4)"))
    moves = len({m.parameter for m in claim.moves}) if claim else 0
    rounds = len({(m.chi_square_before) for m in claim.moves}) if claim else 0
    return (f"{verdict:32s} chi2/dof {fit.chi_square / fit.dof:7.2f}  windows moved {moves} "
            f"in {rounds} refits  max |dt| {err_s:.3f} s ({err_z:6.1f} sigma)  {wall:5.1f} s"
            ), {"ending": verdict, "chi2_dof": fit.chi_square / fit.dof, "windows_moved": moves,
                "refits": rounds, "max_start_error_s": err_s, "max_start_error_sigma": err_z,
                "wall_s": wall}


def checked_fit(folder: str, truth: dict) -> dict:
    """The figures of `solve_checked` on `folder` (for `call_at`)."""
    return run(Path(folder), truth, checked=True)[1]


def against(folder: Path, truth: dict, revision: str, cache: Path) -> str:
    """The checked fit with REV's package and with this tree's, each in its own process:
    both endings, chi-square/dof and the wall-time ratio."""
    sides = {}
    for label, rev in ((revision, revision), ("now", None)):
        with code_at(rev) as code:
            sides[label] = call_at(code if rev else ROOT, "events_offset", "checked_fit",
                                   str(folder), truth, cache=cache)
    old, new = sides[revision], sides["now"]
    return (f"{revision}: {old['ending']}, chi2/dof {old.get('chi2_dof', float('nan')):.4f}, "
            f"{old['wall_s']:.1f} s; now: {new['ending']}, chi2/dof "
            f"{new.get('chi2_dof', float('nan')):.4f}, {new['wall_s']:.1f} s; "
            f"ratio {new['wall_s'] / old['wall_s']:.2f}")


def main() -> int:
    parser = harness.parser(__doc__, seed=1, seed_help="the first drogue seed")
    parser.add_argument("--seeds", type=int, default=10)
    parser.add_argument("--offset", type=float, default=1.5)
    parser.add_argument("--baseline", action="store_true")
    parser.add_argument("--against", metavar="REV", default=None)
    args = parser.parse_args()
    fits: dict[str, list[dict]] = {}
    with tempfile.TemporaryDirectory() as tmp:
        if args.against:
            for seed in range(args.seed, args.seed + args.seeds):
                for case in ("late", "disreefs"):
                    folder, truth = shifted_folder(Path(tmp), seed, case, args.offset)
                    print(f"  {case} seed {seed:2d} "
                          f"{against(folder, truth, args.against, Path(tmp) / 'cache')}",
                          flush=True)
            return 0
        for case in ("late", "disreefs"):
            print(f"== {case}: events {args.offset} s off (window 1 s)", flush=True)
            for seed in range(args.seed, args.seed + args.seeds):
                folder, truth = shifted_folder(Path(tmp), seed, case, args.offset)
                for label, checked in (("before", False), ("now", True)):
                    if checked or args.baseline:
                        text, figures = run(folder, truth, checked)
                        print(f"  seed {seed:2d} {label + ':':7s} {text}", flush=True)
                        fits.setdefault(case, []).append({"seed": seed, "path": label,
                                                          **figures})
    harness.report("events_offset", offset_s=args.offset, fits=fits)
    return 0


if __name__ == "__main__":
    sys.exit(main())
