"""Benchmark: a 100 Hz, 10-minute rocket descent imported and reconstructed, this tree
against an earlier revision.

A seeded point-mass flight (the generator of `cpas_ocp/io/example_flight.py`:
a 16.9 kg rocket boosted to about 6.2 km above the pad, a 4 m^2 drogue at
apogee, a 12 m^2 main at 300 m above the pad about eight minutes later, then
touchdown) is written as a column-mapped log: time in ms, pressure in hPa and
a three-axis accelerometer in g at 100 Hz, the ejection charges' pressure
pulses and jolts included.  `cpas-ocp import --columns MAP --card CARD`
turns it into a test folder (barometer and axial accelerometer, about 60,000
samples each) and `cpas-ocp reconstruct` fits it and writes the report.  Both
commands are timed in a fresh process per code tree, the earlier revision
(`--baseline`, by default the last commit before the grid from the dynamics
coarsened past 0.25 s) checked out into a temporary git worktree.  Each tree
first builds the NLP once in another process, which compiles its model
functions into an empty cache (printed: a first run on a machine pays it
once), so that the timed run measures the reconstruction itself.

Printed per tree: the import's and the reconstruction's wall time, the
shooting grid's nodes, the solver's status and iterations, chi-square per
degree of freedom, and the canopies' drag areas against the truth in reported
sigmas; then the ratios (baseline / this tree).  A baseline that runs past
`--timeout` seconds is stopped and its ratio printed as a lower bound.

    python benchmarks/long_descent.py [--baseline REV] [--seed N] [--timeout S]
                                      [--thrust N] [--no-baseline]
    python benchmarks/long_descent.py --per-iteration TEST_DIR

The wall times of whole runs meet whatever else the machine runs; the
second form alternates this grid and the one-step grid (intervals capped at
MAX_STEP_S, the earlier grid) in one process and prints seconds per
iteration.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from benchmarks import harness  # noqa: E402
from benchmarks.revisions import PRELUDE, code_at  # noqa: E402
from cpas_ocp.io.example_flight import fly  # noqa: E402
from tests.io.test_rocket_log_import import CARD, COLUMN_MAP, write_mapped  # noqa: E402

BASELINE = "bac75cc"  # the grid capped at 0.25 s steps
THRUST_N = 6500.0  # boost thrust (N, 2.5 s): apogee about 6.1 km above the pad
CDS_TRUE = {"drogue": 4.0, "main": 12.0}  # the canopies' full drag areas (m^2)
DIAMETER_IN = {"drogue": 72, "main": 120}  # nominal diameters on the card (in)
MODEL = ["canopy_inflation", "forebody_drag", "rigid_riser", "baro", "axial_accelerometer"]


def write_long_log(folder: Path, seed: int, thrust_n: float = THRUST_N) -> dict[str, float]:
    """The seeded 100 Hz log (log.csv), its column map (map.json) and flight card
    (card.json) in `folder`; returns the flight's event times (s)."""
    flight = fly(thrust_n=thrust_n, drogue_delay_s=0.0, cds=CDS_TRUE)
    folder.mkdir(parents=True, exist_ok=True)
    write_mapped(flight, folder / "log.csv", seed=seed)
    (folder / "map.json").write_text(json.dumps(COLUMN_MAP))
    card = json.loads(json.dumps(CARD))
    card["name"] = "long_descent"
    for chute in card["parachutes"]:
        chute["diameter"] = {"value": DIAMETER_IN[chute["name"]], "unit": "in"}
    card["model"] = {"effects": MODEL}
    (folder / "card.json").write_text(json.dumps(card))
    return flight.events


# Run in a fresh process per code tree (`revisions.PRELUDE` points cpas_ocp at it):
# argv = folder with log.csv, map.json and card.json, then "warm" (import and build the
# NLP only: the compiled model functions land in the cache) or "time".  Prints one JSON line.
CHILD = r"""
import json, sys, time, contextlib, io
from pathlib import Path
from cpas_ocp.cli import main
folder, mode = Path(sys.argv[1]), sys.argv[2]
out = folder / mode
quiet = io.StringIO()
t0 = time.perf_counter()
with contextlib.redirect_stdout(quiet):
    code = main(["import", str(folder / "log.csv"), "--columns", str(folder / "map.json"),
                 "--card", str(folder / "card.json"), "--out", str(out / "test")])
t1 = time.perf_counter()
if mode == "warm":
    from cpas_ocp.estimation.estimator import Estimator
    from cpas_ocp.io.flight_test import load_test
    Estimator(load_test(out / "test"))
    print(json.dumps({"code": code, "build_s": time.perf_counter() - t1}))
    raise SystemExit
with contextlib.redirect_stdout(quiet):
    code += main(["reconstruct", str(out / "test"), "--out", str(out / "report")])
t2 = time.perf_counter()
result = json.loads((out / "report" / "result.json").read_text())
grid = next((line for line in quiet.getvalue().splitlines() if "shooting grid" in line), "")
print(json.dumps({"code": code, "import_s": t1 - t0, "reconstruct_s": t2 - t1,
                  "grid": grid.strip(), "result": result}))
"""


def run_tree(code: Path, folder: Path, timeout: float) -> tuple[float, dict | None]:
    """The cold build's seconds (compiling the model functions into an empty cache) and
    the timed child's JSON for the code tree `code` on the log in `folder` (None past
    `timeout`)."""
    import os
    import subprocess
    import tempfile
    with tempfile.TemporaryDirectory() as cache:
        env = {**os.environ, "CPAS_OCP_CACHE": cache}
        outs = []
        for mode in ("warm", "time"):
            try:
                out = subprocess.run([sys.executable, "-c", PRELUDE + CHILD, str(code),
                                      str(folder), mode, str(ROOT)], env=env, cwd=folder,
                                     capture_output=True, text=True, timeout=timeout,
                                     check=False)
            except subprocess.TimeoutExpired:
                outs.append(None)
                continue
            if out.returncode:
                raise RuntimeError(f"the run with the code in {code} failed:\n"
                                   f"{out.stderr[-3000:]}")
            outs.append(json.loads(out.stdout.strip().splitlines()[-1]))
    return (outs[0] or {}).get("build_s", float("nan")), outs[1]


def per_iteration(folder: Path, iterations: int = 20, repeats: int = 2) -> dict:
    """Seconds per solver iteration on the imported folder's NLP with this tree's grid and
    with the grid's intervals capped at one RK4 step (`shooting_grid.MAX_INTERVAL_S` =
    MAX_STEP_S, the earlier grid), alternating in one process so that both meet the
    same load: `iterations` iterations from the reduction, `repeats` times each.  Return
    the figures printed."""
    import cpas_ocp.estimation.shooting_grid as grid
    from cpas_ocp.errors import SolverFailure
    from cpas_ocp.estimation.estimator import Estimator
    from cpas_ocp.io.flight_test import load_test
    test = load_test(folder)
    estimators = {}
    for label, cap in (("this grid", grid.MAX_INTERVAL_S), ("one-step grid", grid.MAX_STEP_S)):
        saved, grid.MAX_INTERVAL_S = grid.MAX_INTERVAL_S, cap
        try:
            estimators[label] = Estimator(test)
        finally:
            grid.MAX_INTERVAL_S = saved
    seconds: dict[str, list[float]] = {label: [] for label in estimators}
    timer = harness.Timer()
    for _ in range(repeats):
        for label, est in estimators.items():
            try:
                with timer(label):
                    done = est.solve(max_iter=iterations).solver.iterations
            except SolverFailure as exc:
                done = exc.iterations
            seconds[label].append(timer[label] / max(done, 1))
    for label, est in estimators.items():
        print(f"{label}: {len(est.t)} nodes, {min(seconds[label]):.3f} s per iteration "
              f"(best of {repeats})")
    ratio = harness.ratio(min(seconds["one-step grid"]), min(seconds["this grid"]))
    print(f"per iteration: ratio {ratio:.2f}")
    return {"nodes": {label: len(est.t) for label, est in estimators.items()},
            "s_per_iteration": {label: min(s) for label, s in seconds.items()},
            "one_step_over_this_grid": ratio}


def summary(label: str, run: dict) -> str:
    """One block of text: times, grid, solver and the drag areas against the truth."""
    res = run["result"]
    params, solver = res["parameters"], res["solver"]
    lines = [f"{label}: import {run['import_s']:.1f} s, reconstruct {run['reconstruct_s']:.1f} s",
             f"  {run['grid']}",
             f"  solver: {solver['status']}, {solver['iterations']} iterations, chi2/dof "
             f"{res['fit']['chi_square_per_dof']:.3f}"]
    for chute, stage in (("drogue", "stage1"), ("main", "stage2")):
        key = f"CdS[{chute},{stage}]"
        value, sigma = params[key]["value"], params[key].get("std", float("nan"))
        lines.append(f"  {key} {value:.4f} +- {sigma:.4f} m^2 (truth {CDS_TRUE[chute]}: "
                     f"{(value - CDS_TRUE[chute]) / sigma:+.2f} sigma), start "
                     f"{params[key]['initial']:.3f}")
    for name in ("n", "expopen"):
        for chute, stage in (("drogue", "stage1"), ("main", "stage2")):
            key = f"{name}[{chute},{stage}]"
            if key in params:
                lines.append(f"  {key} {params[key]['value']:.3f}, start "
                             f"{params[key]['initial']:.3f}")
    return "\n".join(lines)


def summary_figures(run: dict) -> dict:
    """What `summary` prints of a run, as numbers."""
    res = run["result"]
    params = res["parameters"]
    return {"import_s": run["import_s"], "reconstruct_s": run["reconstruct_s"],
            "grid": run["grid"], "status": res["solver"]["status"],
            "iterations": res["solver"]["iterations"],
            "chi2_dof": res["fit"]["chi_square_per_dof"],
            "drag_areas_m2": harness.estimates_text(
                (key, params[key]["value"], params[key].get("std"))
                for key in ("CdS[drogue,stage1]", "CdS[main,stage2]"))}


def main() -> None:
    parser = harness.parser(__doc__, seed=1, seed_help="seed of the log's sensor noise")
    parser.add_argument("--baseline", default=BASELINE, help="the revision to compare with")
    parser.add_argument("--no-baseline", action="store_true", help="time this tree only")
    parser.add_argument("--thrust", type=float, default=THRUST_N, help="boost thrust (N)")
    parser.add_argument("--timeout", type=float, default=1800.0,
                        help="stop a tree's run after this many seconds")
    parser.add_argument("--folder", type=Path, default=None,
                        help="where to write the log and the folders (default: a temporary one)")
    parser.add_argument("--per-iteration", type=Path, default=None, metavar="TEST_DIR",
                        help="only time solver iterations on an imported folder, this grid "
                             "against the one-step grid (`per_iteration`)")
    args = parser.parse_args()
    if args.per_iteration is not None:
        harness.report("long_descent", per_iteration=per_iteration(args.per_iteration))
        return
    import tempfile
    with tempfile.TemporaryDirectory(prefix="cpas-ocp-long-descent-") as tmp:
        base = args.folder or Path(tmp)
        runs, builds, ratios = {}, {}, {}
        trees = [("this tree", None)]
        trees += [] if args.no_baseline else [(f"baseline {args.baseline}", args.baseline)]
        for label, revision in trees:
            folder = base / label.replace(" ", "_").replace(",", "")
            events = write_long_log(folder, args.seed, args.thrust)
            with code_at(revision) as code:
                build_s, run = run_tree(code, folder, args.timeout)
            runs[label], builds[label] = run, build_s
            print(f"{label}: first build, compiling into an empty cache: {build_s:.1f} s")
            if run is None:
                print(f"{label}: stopped after {args.timeout:.0f} s", flush=True)
            else:
                print(summary(label, run), flush=True)
        print(f"flight: drogue {events['drogue']:.1f} s, main {events['main']:.1f} s, "
              f"touchdown {events['landed']:.1f} s (100 Hz, seed {args.seed})")
        base_label = next((label for label in runs if label.startswith("baseline")), None)
        base_run = runs.get(base_label) if base_label else None
        for label, this in runs.items():
            if base_label is None or label == base_label or this is None:
                continue
            run = base_run
            print(f"{base_label} / {label}:")
            for part in ("import_s", "reconstruct_s"):
                if run is None:
                    total = this["import_s"] + this["reconstruct_s"]
                    ratios[label] = {"import_and_reconstruct_above": harness.ratio(
                        args.timeout, total)}
                    print(f"  import + reconstruct: ratio > "
                          f"{ratios[label]['import_and_reconstruct_above']:.1f}")
                    break
                ratios.setdefault(label, {})[part] = harness.ratio(run[part], this[part])
                print(f"  {part[:-2]}: ratio {ratios[label][part]:.2f} "
                      f"({run[part]:.1f} s / {this[part]:.1f} s)")
    harness.report("long_descent", baseline=None if args.no_baseline else args.baseline,
                   events_s=events, first_build_s=builds,
                   runs={label: None if r is None else summary_figures(r)
                         for label, r in runs.items()},
                   baseline_over_tree=ratios)


if __name__ == "__main__":
    main()
