"""A 10 Hz logger's sub-sample fill: the shooting lattice at the sensor step against the 25 ms
cap, and a held point's solve with and without the stall rule.

For each test folder (made by `cpas-ocp import-altus`, e.g. the Prometheus logs
under the card, whose model estimates the air's motion and fits the
accelerometer), the card's model is fitted from the reduction twice in this
process: on a lattice of the fastest sensor's step (the rule before the cap)
and on the capped one (`estimation.MAX_LATTICE_STEP_S`).  Printed: nodes,
iterations, status, wall time, chi-square/dof, the main's fill constant and
start, and the wall-time ratio.  Then, from the capped fit, the main's held
expopen is refitted at 1.5 with Ipopt alone (`sensitivities=True`: a
what-if's solve, its multipliers kept) and with the stall rule
(`sensitivities=False`: a profile point's), with their iterations and wall.

    python benchmarks/fill_resolution.py FOLDER [FOLDER ...]
"""

from __future__ import annotations

import dataclasses

import harness

import cpas_ocp.estimation.fit as estimation
from cpas_ocp.errors import SolverFailure
from cpas_ocp.estimation.estimator import Estimator
from cpas_ocp.io.flight_test import load_test
from cpas_ocp.io.model_spec import spec_of_test

HELD = "expopen[main,stage2]"
MAIN = ("n[main,stage2]", "t_start[main,stage2]")


def timed_solve(est: Estimator, **kwargs) -> tuple[str, float, object]:
    """`est.solve(**kwargs)`: its line of text, wall time (s) and fit (None where it failed)."""
    timer = harness.Timer()
    try:
        with timer("solve"):
            fit = est.solve(**kwargs)
        text = (f"{fit.solver.iterations:4d} iterations, {fit.solver.status}, chi2/dof "
                f"{fit.chi_square / fit.dof:.3f}, "
                + ", ".join(f"{n} {fit.parameters[n]:.4g}" for n in MAIN if n in fit.parameters))
    except SolverFailure as exc:
        fit, text = None, f"failed: {exc.status} after {exc.iterations} iterations"
    return text, timer["solve"], fit


def main() -> int:
    parser = harness.parser(__doc__, seed=None,
                            seed_help="recorded only: nothing here is drawn at random")
    parser.add_argument("folders", nargs="+")
    args = parser.parse_args()
    cap = estimation.MAX_LATTICE_STEP_S
    results: dict[str, dict] = {}
    for folder in args.folders:
        out = results[folder] = {}
        test = load_test(folder)
        walls = {}
        capped_fit = None
        for label, step in (("sensor step", 1e9), (f"capped at {1e3 * cap:g} ms", cap)):
            estimation.MAX_LATTICE_STEP_S = step
            est = Estimator(test)
            text, wall, fit = timed_solve(est)
            walls[label] = wall
            print(f"{folder} {label}: {len(est.t)} nodes, {text}, {wall:.1f} s", flush=True)
            out[label] = {"nodes": len(est.t), "fit": text, "wall_s": wall}
            if step == cap:
                capped_fit = fit
        estimation.MAX_LATTICE_STEP_S = cap
        old, new = walls.values()
        out["wall_ratio"] = harness.ratio(old, new)
        print(f"{folder} wall ratio sensor step / capped: {out['wall_ratio']:.2f}")
        if capped_fit is None:
            continue
        spec = spec_of_test(test)
        fixed = {k: v for k, v in capped_fit.settings.fixed.items() if k != HELD}
        held = Estimator(test, spec, dataclasses.replace(
            capped_fit.settings, free=[*capped_fit.free, HELD], fixed=fixed))
        start = held.point_from(capped_fit)
        for label, sensitivities in (("Ipopt alone", True), ("with the stall rule", False)):
            text, wall, _ = timed_solve(held, start=start, bounds={HELD: (1.5, 1.5)},
                                        sensitivities=sensitivities)
            print(f"{folder} {HELD} held at 1.5, {label}: {text}, {wall:.1f} s", flush=True)
            out[f"held at 1.5, {label}"] = {"fit": text, "wall_s": wall}
    harness.report("fill_resolution", folders=results)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
