"""`cpas-ocp reduce`: a test folder's offline reduction as a table, a plot and a guess.

What an engineer checks before any fit: the IMU drag area (paper Eq. 2), each
riser's drag area (Eq. 3), the per-stage scale factor that reconciles them, and
the initial guess that the estimator will start from.  Everything here comes
from the test folder alone.
"""

from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import pandas as pd

from cpas_ocp.estimation.reduction import Reduction, reduce_and_guess, stage_starts
from cpas_ocp.io.model_spec import ModelSpec
from cpas_ocp.io.output_folder import atomic_folder
from cpas_ocp.io.strict_json import json_text
from cpas_ocp.physics.flight_test import FlightTest
from cpas_ocp.physics.model import Model
from cpas_ocp.reports.display_units import DisplayUnits, display_units, pretty
from cpas_ocp.reports.figure_files import write_figure


def reduction_frame(red: Reduction) -> pd.DataFrame:
    """The reduced curves on the IMU time base, SI (s, Pa, m/s, g, m^2)."""
    cols = {"time_s": red.t, "dynamic_pressure_Pa": red.dynamic_pressure,
            "airspeed_m_s": red.airspeed, "load_factor_g": red.load_factor,
            "cds_imu_m2": red.cds_imu}
    cols.update({f"cds_riser_{name}_m2": v for name, v in red.cds_riser.items()})
    return pd.DataFrame(cols)


def guess_table(model: Model, guess: dict[str, float], units: DisplayUnits) -> str:
    """Terminal table of the initial guess of every estimable parameter, in `units`."""
    lines = [f"{'parameter':30s} {'initial':>11s}  unit"]
    for prm in model.parameters:
        if prm.estimable:
            unit, k = units.of_si(prm.unit)
            lines.append(f"{prm.name:30s} {guess[prm.name] * k:11.5g}  {unit}")
    return "\n".join(lines)


def write_reduction(test: FlightTest, out: str | Path, spec: ModelSpec,
                    units: DisplayUnits | None = None) -> tuple[Path, Model, dict[str, float]]:
    """Reduce `test`, write reduction.csv, initial_guess.json (both SI) and reduction.png
    (drag areas in `units`, default the test's own) to `out`.

    The guess covers the parameters of the model `spec` describes and holds its fixed values.
    """
    shown = units or display_units(test)
    model = spec.model(test)
    guess, red = reduce_and_guess(test, model, spec.fixed_values(model))
    out = Path(out)
    with atomic_folder(out, "initial_guess.json") as tmp:
        reduction_frame(red).to_csv(tmp / "reduction.csv", index=False)
        units = {p.name: p.unit for p in model.parameters}
        (tmp / "initial_guess.json").write_text(json_text({
            "test": test.name,
            "parameters": {n: {"value": guess[n], "unit": units[n]}
                           for n in units if model.parameter(n).estimable},
            "stage_groups": [{"stage": g.stage, "canopies": list(g.canopies),
                              "window_s": list(g.window), "scale": g.scale}
                             for g in red.groups],
        }))
        write_figure(reduction_axes(test, red, stage_starts(test, guess), shown).figure, None,
                     tmp / "reduction.png")
    return out, model, guess


def reduction_axes(test: FlightTest, red: Reduction, starts: dict[tuple[str, str], float],
                   units: DisplayUnits, ax: plt.Axes | None = None) -> plt.Axes:
    """The offline reduction's drag areas (Eq. 2 from the IMU, Eq. 3 from each riser and
    their sum) in `units`, the steady windows shaded with their stage scale, the start
    times from the events dashed; into `ax` (else a new figure's); the axis."""
    area = units.factor("area")
    ax = ax if ax is not None else plt.subplots(figsize=(10, 4.5))[1]
    ax.plot(red.t, red.cds_imu * area, lw=0.6, color="0.4", label="IMU, Eq. 2 (total)")
    if red.cds_riser:
        ax.plot(red.t, sum(red.cds_riser.values()) * area, lw=0.6, color="C0",
                label="risers summed, Eq. 3")
    for k, (name, curve) in enumerate(red.cds_riser.items()):
        ax.plot(red.t, curve * area, lw=0.5, color=f"C{k + 1}", label=f"riser {name}")
    for group in red.groups:
        a, b = group.window
        ax.axvspan(a, b, color="C2", alpha=0.08)
        ax.text(0.5 * (a + b), 0.98, f"{group.label}\nscale {group.scale:.3f}",
                transform=ax.get_xaxis_transform(), ha="center", va="top", fontsize=8)
    for t0 in starts.values():
        ax.axvline(t0, color="C2", lw=0.6, ls="--")
    ax.set_xlabel("time [s]  (dashed: start times from the events; shaded: steady windows)")
    ax.set_ylabel(f"drag area [{pretty(units.unit('area'))}]")
    ax.set_title(f"{test.name}: offline reduction")
    ax.legend(loc="upper left", fontsize=8)
    return ax
