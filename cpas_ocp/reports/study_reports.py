"""The output folders of the campaign studies: Monte Carlo dispersions (`cpas-ocp
dispersions`) and Monte Carlo peak loads (`cpas-ocp montecarlo`).

The studies compute (`campaign.dispersion_study`, `campaign.drag_area_envelope`,
`campaign.peak_load_study`); these functions write what they computed, with the
figures of `reports.plots`, which take the studies' results as plain data.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence
from pathlib import Path

import pandas as pd

from cpas_ocp.campaign.campaign import (
    TestOutcome,
    covariance_table,
    failure_table,
    parameter_table,
    stage_table,
)
from cpas_ocp.campaign.configuration_ratios import campaign_ratios
from cpas_ocp.campaign.dispersion_study import DispersionModel
from cpas_ocp.campaign.drag_area_envelope import drag_area_envelope, stage_conditions
from cpas_ocp.campaign.peak_load_study import MARKER, StageLoads
from cpas_ocp.campaign.population_study import PopulationDispersion
from cpas_ocp.estimation.estimator import Fit
from cpas_ocp.io.output_folder import atomic_folder
from cpas_ocp.io.strict_json import json_text
from cpas_ocp.reports.campaign_text import campaign_text, dispersion_model_text, monte_carlo_text
from cpas_ocp.reports.plots import (
    plot_dispersion_histograms,
    plot_drag_area_envelope,
    plot_hull_projections,
    plot_peak_loads,
)


def write_dispersions(models: list[DispersionModel], skipped: list[str], cases: int, seed: int,
                      out: str | Path, table: pd.DataFrame | None = None,
                      stages: pd.DataFrame | None = None) -> Path:
    """Per model: cases_<type>_<stage>.parquet (`cases` draws, seed `seed` + its index),
    its hull and histogram figures and, given the campaign's parameter `table` and its
    `stages` table, the drag-area envelope (envelope_<type>_<stage>.csv and .png);
    dispersions.json and dispersions.md for all."""
    out = Path(out)
    summary = []
    with atomic_folder(out, "dispersions.json") as tmp:
        for i, model in enumerate(models):
            draws = model.draw(cases, seed + i)
            stem = f"{model.type}_{model.stage}"
            draws.to_parquet(tmp / f"cases_{stem}.parquet", index=False)
            figures = [plot_dispersion_histograms(model, draws, tmp / f"histograms_{stem}.png")]
            if model.hull is not None:
                figures.append(plot_hull_projections(model, draws, tmp / f"hull_{stem}.png"))
            envelope = None
            if table is not None and stages is not None:
                cond = stage_conditions(stages, table, model.type, model.stage)
                envelope = cond and drag_area_envelope(model, draws, cond)
            if envelope is not None:
                envelope.bands.to_csv(tmp / f"envelope_{stem}.csv", index=False)
                figures.append(plot_drag_area_envelope(envelope, tmp / f"envelope_{stem}.png"))
            summary.append({
                "type": model.type, "stage": model.stage, "tests": model.tests,
                "drawn_from": (f"population of {model.population.label}"
                               if isinstance(model, PopulationDispersion)
                               and model.population is not None else "point estimates"),
                "cases": cases, "seed": seed + i,
                "dispersions": {k: dataclasses.asdict(d) for k, d in model.dispersions.items()},
                "hull": None if model.hull is None else {
                    "parameters": list(model.hull_names), "growth": model.hull.growth,
                    "vertices": model.hull.vertices.tolist(), "volume": model.hull.volume},
                "envelope": None if envelope is None else {
                    "cases": envelope.cases, "conditions": dataclasses.asdict(envelope.conditions),
                    "flight_points_inside": envelope.flight_inside(),
                    "corners_outside_hull": [c for c, inside in zip(
                        envelope.corner_labels, envelope.corner_inside, strict=True)
                        if inside is False]},
                "figures": [f.name for f in figures]})
        (tmp / "dispersions.json").write_text(json_text({"models": summary, "skipped": skipped}))
        (tmp / "dispersions.md").write_text(
            "# Monte Carlo dispersions\n\n```\n"
            + "\n\n".join(dispersion_model_text(m) for m in models)
            + ("\n\nnot dispersed:\n" + "\n".join(skipped) if skipped else "") + "\n```\n\n"
            + "".join(f"![{f}]({f})\n\n" for s in summary for f in s["figures"]))
    return out


def write_monte_carlo(fit: Fit, results: list[StageLoads], tmp: Path) -> list[Path]:
    """Into the (temporary) output folder: per canopy stage quantiles_<P>_<S>.csv,
    peak_loads_<P>_<S>.parquet and peak_loads_<P>_<S>.png; montecarlo.md for all."""
    figures = []
    for r in results:
        stem = f"{r.cases.parachute}_{r.cases.stage}"
        r.quantiles().to_csv(tmp / f"quantiles_{stem}.csv", index=False)
        r.table().to_parquet(tmp / f"peak_loads_{stem}.parquet", index=False)
        figures.append(plot_peak_loads(r, tmp / f"peak_loads_{stem}.png"))
    (tmp / MARKER).write_text(
        f"# Monte Carlo peak loads of {fit.test.name}\n\n```\n{monte_carlo_text(fit, results)}\n"
        "```\n\n" + "".join(f"![{f.name}]({f.name})\n\n" for f in figures))
    return figures


def write_campaign(outcomes: Sequence[TestOutcome], out: str | Path) -> Path:
    """Write parameters.csv and parameters.parquet (the table), stages.csv (STAGE_COLUMNS),
    covariances.csv (COVARIANCE_COLUMNS), failures.csv, the drag-area ratios between
    configurations (ratios_forebody.csv, ratios_cluster_size.csv; where the line length
    varies, ratios_line_length.csv and ratios_cluster_size_by_line_length.csv) and
    campaign.md atomically."""
    out = Path(out)
    table = parameter_table(outcomes)
    failures = failure_table(outcomes)
    with atomic_folder(out, "parameters.csv") as tmp:
        table.to_csv(tmp / "parameters.csv", index=False)
        table.to_parquet(tmp / "parameters.parquet", index=False)
        stage_table(outcomes).to_csv(tmp / "stages.csv", index=False)
        covariance_table(outcomes).to_csv(tmp / "covariances.csv", index=False)
        failures.to_csv(tmp / "failures.csv", index=False)
        text = campaign_text(outcomes)
        for by, ratios in campaign_ratios(table).items():
            ratios.to_csv(tmp / f"ratios_{by}.csv", index=False)
            text += f"\n\nmean steady drag areas by {by}:\n" + ratios.to_string(index=False)
        (tmp / "campaign.md").write_text(text + "\n")
    return out
