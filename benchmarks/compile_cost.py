"""Benchmark: what native code costs a first run, this tree against an earlier revision.

`cpas-ocp reconstruct` of the `drogue` test (simulated once, seed 4 unless
`--seed`) is run, each time in a fresh process, three ways per tree:

* **cold**: with an empty compile cache (a new `CPAS_OCP_CACHE` folder): the
  run compiles every native function it uses;
* **warm**: again with the cache the cold run filled (once the compilers it
  left at work have ended: a short first run compiles after it ends);
* **vm**: with `CPAS_OCP_COMPILE=0`, CasADi's virtual machine only.

The earlier revision (`--baseline`, by default the last commit before the
chained Jacobians) is checked out into a temporary git worktree and run with
its own tree first on the import path.  Printed per tree and way: the wall
time, the peak resident memory of the run's process and of its largest
compiler, the native code the run left in the cache (libraries, MB), and the
ratios cold / warm and cold / vm.  Extra effects (`--effects added_mass
gps_lag`) are added to the manifest's model through a model file, to see how
the cost grows with the model's richness.

    python benchmarks/compile_cost.py [--baseline REV] [--seed N] [--effects NAME ...]
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import harness
from revisions import ROOT, code_at

BASELINE = "f0045d2"  # the per-block SX Jacobians, compiled whole
WAYS = ("cold", "warm", "vm")
# One command in a fresh process, then its peak memory and that of its largest child (a
# compiler), as the last line of its output.
PROGRAM = """
import json, resource, sys
from cpas_ocp.cli import main
status = main(sys.argv[1:])
peak = {who: resource.getrusage(what).ru_maxrss / 1e6 for who, what in
        (("self_gb", resource.RUSAGE_SELF), ("children_gb", resource.RUSAGE_CHILDREN))}
print(json.dumps(peak))
sys.exit(status)
"""


def run(tree: Path, test: Path, model: Path | None, cache: Path, way: str, out: Path
        ) -> tuple[float, float, float]:
    """Wall time (s), peak memory of the run (GB) and of its largest child (GB) of one
    `cpas-ocp reconstruct` in `tree`."""
    env = {**os.environ, "PYTHONPATH": str(tree), "CPAS_OCP_CACHE": str(cache)}
    if way == "vm":
        env["CPAS_OCP_COMPILE"] = "0"
    args = [sys.executable, "-c", PROGRAM, "reconstruct", str(test), "--out", str(out)]
    if model is not None:
        args += ["--model", str(model)]
    timer = harness.Timer()
    with timer("run"):
        done = subprocess.run(args, cwd=tree, env=env, capture_output=True, text=True)
    if done.returncode != 0:
        raise SystemExit(f"{tree}: reconstruct ({way}) failed:\n{done.stderr[-2000:]}")
    peaks = json.loads(done.stdout.strip().splitlines()[-1])
    return timer["run"], peaks["self_gb"], peaks["children_gb"]


def compilers_done(cache: Path, limit_s: float = 600.0) -> float:
    """Wait until no compiler's folder is left in the cache (a compile a run left behind
    has ended); the seconds waited."""
    timer = harness.Timer()
    while list(cache.glob(".cpas-cg-*")) and timer.elapsed() < limit_s:
        time.sleep(0.2)
    return timer.elapsed()


def cache_size(cache: Path) -> tuple[int, float]:
    """Libraries in the cache and their size (MB)."""
    libs = list(cache.glob("*.so")) if cache.exists() else []
    return len(libs), sum(p.stat().st_size for p in libs) / 1e6


BASELINE_EFFECTS = ["canopy_inflation", "forebody_drag", "rigid_riser", "drag_scale",
                    "loadcell_scale"]
SENSORS = ["gps", "imu", "load_cell"]


def model_file(folder: Path, effects: list[str]) -> Path | None:
    """A model file adding `effects` to the baseline model (a sensor's lag, bias or friction
    after the sensors, the others before them), or None."""
    if not effects:
        return None
    on_sensors = [e for e in effects if any(w in e for w in ("lag", "bias", "friction"))]
    physics = [e for e in effects if e not in on_sensors]
    path = folder / "model.json"
    path.write_text(json.dumps({"effects": [*BASELINE_EFFECTS, *physics, *SENSORS,
                                            *on_sensors]}))
    return path


def main() -> None:
    parser = harness.parser(__doc__, seed=4, seed_help="seed of the simulated drogue test")
    parser.add_argument("--baseline", default=BASELINE, help="the revision to compare with")
    parser.add_argument("--effects", nargs="*", default=[],
                        help="library effects added to the baseline model")
    args = parser.parse_args()
    results: dict[str, dict] = {}
    with (tempfile.TemporaryDirectory(prefix="cpas-ocp-compile-") as tmp,
          code_at(args.baseline) as old_tree):
        root = Path(tmp)
        test = root / "drogue"
        subprocess.run([sys.executable, "-c", "import sys; from cpas_ocp.cli import main; "
                        "sys.exit(main(sys.argv[1:]))", "simulate", "drogue", "--out",
                        str(test), "--seed", str(args.seed)], check=True, cwd=ROOT,
                       capture_output=True, env={**os.environ, "PYTHONPATH": str(ROOT)})
        model = model_file(root, args.effects)
        print(f"reconstruct drogue (seed {args.seed}), model: baseline "
              f"{' + '.join(args.effects)}".rstrip())
        print(f"{'tree':10s} {'way':5s} {'wall (s)':>9s} {'run GB':>7s} {'cc GB':>6s} "
              f"{'libs':>5s} {'MB':>6s}")
        for name, tree in (("baseline", old_tree), ("this tree", ROOT)):
            cache = root / f"cache-{name.replace(' ', '-')}"
            out = results[name] = {}
            for way in WAYS:
                seconds, run_gb, cc_gb = run(tree, test, model, cache, way,
                                             root / f"out-{name}-{way}")
                libs, mb = cache_size(cache)
                out[way] = {"wall_s": seconds, "run_gb": run_gb, "compiler_gb": cc_gb,
                            "libraries": libs, "mb": mb}
                print(f"{name:10s} {way:5s} {seconds:9.1f} {run_gb:7.2f} {cc_gb:6.2f} "
                      f"{libs:5d} {mb:6.1f}", flush=True)
                if way == "cold":  # the warm run finds what the cold one left compiling
                    waited = compilers_done(cache)
                    libs, mb = cache_size(cache)
                    out["compilers_after_cold"] = {"waited_s": waited, "libraries": libs,
                                                   "mb": mb}
                    print(f"{name:10s} compilers still at work after the cold run: "
                          f"{waited:.1f} s more; then {libs} libraries, {mb:.1f} MB",
                          flush=True)
            out["cold_over_warm"] = harness.ratio(out["cold"]["wall_s"], out["warm"]["wall_s"])
            out["cold_over_vm"] = harness.ratio(out["cold"]["wall_s"], out["vm"]["wall_s"])
            print(f"{name:10s} cold / warm {out['cold_over_warm']:.2f}, "
                  f"cold / vm {out['cold_over_vm']:.2f}", flush=True)
    harness.report("compile_cost", baseline=args.baseline, effects=args.effects, trees=results)


if __name__ == "__main__":
    main()
