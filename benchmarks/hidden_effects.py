"""Benchmark: `discover` on `drogue` data with effects hidden, one seed each.

The `drogue` problem (20 s, two Drogues, three stages, GPS + IMU + two load
cells) is simulated with effects the baseline model lacks, fitted with the
baseline model from the offline reduction, and handed to `discover`:

* each library effect hidden in turn: added_mass, elastic_riser,
  loadcell_friction, gps_lag (as `diagnosis_cost.py`), deployment_load
  (2,000 lbf per Drogue), imu_bias (0.03 g), loadcell_bias (1 kN);
* effects the library lacks (`tests/plugins/`): breathing (1.5 Hz, 4 % of
  CdS), tension_loss (15 % at the peak load), wind_shear (a shear layer,
  0.03 /s at 6,800 m);
* two at once (gps_lag + added_mass), and none.

Printed per case: the chain (each step's effect, chi-square/dof and wall time
of the diagnosis that found it), how it ended, the plug-ins proposed and
the total wall time; at the end a table of all cases, with the chi-square
tail probability of the last fit (P(chi-square on its dof above it)), the
ending's state and the effects the last model keeps that the truth lacks.

    python benchmarks/hidden_effects.py [--cases added_mass breathing ...] [--seed N]
                                        [--stop-at-stand-ins]

`--stop-at-stand-ins` keeps the earlier diagnosis, which refits only the
`--confirm` leading score tests even where every effect they confirm is
implausible (`diagnosis.confirm_past_stand_ins` is skipped).
"""

from __future__ import annotations

import resource
import tempfile
from pathlib import Path

import harness
import numpy as np
from diagnosis_cost import DROGUES, hidden_cases, simulated_fit
from scipy.stats import chi2

from cpas_ocp.discrepancy import diagnosis as diagnosis_module
from cpas_ocp.discrepancy.discovery import Discovery, DiscoveryStep, discover
from cpas_ocp.io.model_spec import baseline_spec
from cpas_ocp.physics.effects import AddedMass, DeploymentLoad, Effect, SensorBias, SensorLag
from cpas_ocp.physics.effects import baseline_effects as baseline
from cpas_ocp.physics.effects.registry import load_plugin
from cpas_ocp.physics.units import LBF

PLUGINS = Path(__file__).parents[1] / "tests" / "plugins"
# The Drogues' peak riser load in `drogue` (N), for a tension loss of 15 % there.
PEAK_LOAD_N = 45_000.0


def plugin(name: str, folder: Path = PLUGINS, **options: float) -> Effect:
    """The effect of the plug-in file `folder`/`name`.py built with `options`."""
    path = folder / f"{name}.py"
    return next(iter(load_plugin(path).values())).build(options, str(path), "benchmark")


def cases() -> dict[str, tuple[list[Effect], dict[str, float]]]:
    """Truth model and the hidden effects' true values, per case."""
    base = baseline()
    out = dict(hidden_cases())
    out |= {
        "deployment_load": ([*base[:3], DeploymentLoad(), *base[3:]],
                            {"deployment_load[drogue]": 2000.0 * LBF}),
        "imu_bias": ([*base, SensorBias.imu()], {"bias[imu,load_factor]": 0.03}),
        "loadcell_bias": ([*base, SensorBias.load_cell()],
                          {f"bias[riser_{c},tension]": 1000.0 for c in DROGUES}),
        "breathing": ([base[0], plugin("breathing", frequency=1.5), *base[1:]],
                      {"breathing_frequency": 1.5,
                       **{f"breathing_cos[{c}]": 0.04 for c in DROGUES}}),
        "tension_loss": ([*base, plugin("tension_loss")],
                         {f"tension_loss[{c}]": 0.15 / PEAK_LOAD_N for c in DROGUES}),
        "wind_shear": ([plugin("wind_shear"), *base], {"shear_rate": 0.03}),
        "gps_lag+added_mass": ([*base, AddedMass(), SensorLag.gps()],
                               {"lag[gps]": 0.1,
                                **{f"added_mass_factor[{c}]": 1.4 for c in DROGUES}}),
    }
    return out


# The plug-in `discover` writes for a hidden effect the library lacks.
WRITTEN_AS = {"breathing": "drag_area_modulation", "tension_loss": "tension_gain",
              "wind_shear": "wind_profile"}


Cases = dict[str, tuple[list[Effect], dict[str, float]]]


def false_effects(truth: list[Effect], found: Discovery,
                  written_as: dict[str, str] = WRITTEN_AS) -> list[str]:
    """The effects the chain's last model keeps beyond the baseline that the `truth` lacks
    (a plug-in written for a hidden effect counts as that effect, `written_as`)."""
    base = {e.name for e in baseline()}
    named = {written_as.get(e.name, e.name) for e in truth} - base
    return sorted(set(found.steps[-1].spec.effect_names) - base - named)


def run(case: str, effects: list[Effect], values: dict[str, float], seed: int, root: Path
        ) -> tuple[Discovery, list[float], float]:
    """The discovery of one case (`drogue` simulated with `effects` at the true `values`),
    the wall time of each step's diagnosis (s), and the baseline fit's (s)."""
    fit, t_fit = simulated_fit(effects, values, seed, root / case)
    print(f"[{case}] baseline fit {t_fit:.1f} s, chi-square/dof "
          f"{fit.chi_square / fit.dof:.3f}", flush=True)
    times: list[float] = []
    timer = harness.Timer()

    def said(step: DiscoveryStep) -> None:
        times.append(timer.split("step"))
        print(f"[{case}]   step {step.label}: chi-square/dof "
              f"{step.fit.chi_square / step.fit.dof:.3f}, {times[-1]:.1f} s", flush=True)

    found = discover(fit, baseline_spec(), on_step=said)
    print(f"[{case}] ending: {found.ending()}")
    for trial in [*found.proposals, *found.refinements, *found.regressions]:
        print(f"[{case}]   {str(trial)[:400]}")
    return found, times, t_fit


def main(table: Cases | None = None, written_as: dict[str, str] = WRITTEN_AS,
         doc: str = __doc__, name: str = "hidden_effects") -> None:
    """Run `discover` on each case of `table` (default `cases()`) and print the table."""
    table = cases() if table is None else table
    parser = harness.parser(doc, seed=1, seed_help="seed of the simulated drogue tests")
    parser.add_argument("--cases", nargs="+", default=list(table), choices=list(table))
    parser.add_argument("--stop-at-stand-ins", action="store_true",
                        help="refit only the leading score tests (the earlier diagnosis)")
    args = parser.parse_args()
    if args.stop_at_stand_ins:
        diagnosis_module.confirm_past_stand_ins = lambda *args, **kwargs: None
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for case in args.cases:
            timer = harness.Timer()
            effects, values = table[case]
            found, times, t_fit = run(case, effects, values, args.seed, Path(tmp))
            last = found.steps[-1].fit
            rows.append((case, " > ".join(s.label for s in found.steps[1:]) or "-",
                         last.chi_square / last.dof, float(chi2.sf(last.chi_square, last.dof)),
                         found.state, ", ".join(false_effects(effects, found, written_as))
                         or "none",
                         t_fit, float(np.max(times)) if times else 0.0, timer.elapsed()))
    peak_gb = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1e6
    print(f"\n{'case':20s} {'chain':44s} {'chi2/dof':>8s} {'tail p':>7s} {'fit':>7s} "
          f"{'longest step':>12s} {'total':>8s}  {'ending':14s} kept, not in the truth")
    for case, chain, per_dof, tail, state, false, t_fit, longest, total in rows:
        print(f"{case:20s} {chain:44s} {per_dof:8.3f} {tail:7.2g} {t_fit:5.1f} s "
              f"{longest:10.1f} s {total:6.0f} s  {state:14s} {false}")
    print(f"peak memory of the process {peak_gb:.2f} GB")
    fields = ("case", "chain", "chi2_dof", "tail_p", "state", "kept_not_in_truth", "fit_s",
              "longest_step_s", "total_s")
    harness.report(name, stop_at_stand_ins=args.stop_at_stand_ins,
                   cases=[dict(zip(fields, row, strict=True)) for row in rows],
                   peak_gb=peak_gb)


if __name__ == "__main__":
    main()
