"""Writing the figures: a reconstruction's and a campaign's dispersions, with the package of
revision REV (default `BEFORE`) and with this tree's.

Every figure is laid out with `tight_layout` and written as PNG at 110 dpi.  At REV
the layout left a placeholder layout engine on the figure, for which `savefig`
drew the whole figure a second time (its renderer off) before drawing it to the
file, and each dispersion histogram was a patch per bin (60 of them per
parameter).  Now the engine is dropped once the axes are placed
(`reports.figure_files.write_figure`) and a histogram is one filled outline.

Per case, in a fresh process per call (`revisions.compare_cases`, the two trees
alternately, `--repeat` times): the figures written three times over (the fastest
kept) and a digest of their decoded pixels, so that an unchanged picture shows
as the same digest on both sides.

Cases: `drogue` simulated with `--seed` and fitted once per call, untimed (its
sensor, residual-by-window, drag-area and event figures, as `reconstruct` draws
them); the 25-test synthetic campaign of the suite (`dispersions` with 2,000
cases: per canopy type its histograms, hull projections and drag-area envelope).

    python benchmarks/figure_cost.py [--against REV] [--seed 1] [--repeat 3]
"""

from __future__ import annotations

import hashlib
import sys
import tempfile
from collections.abc import Callable
from pathlib import Path

import harness
from iteration_cost import make_test
from revisions import ROOT, compare_cases

BEFORE = "073f79c"
TIMES = 3


def _pixel_digest(folder: Path) -> str:
    """The first 12 hex digits of a digest of every PNG's decoded pixels under `folder`."""
    import matplotlib.image as mpimg

    digest = hashlib.sha256()
    for png in sorted(folder.rglob("*.png")):
        digest.update(png.name.encode())
        digest.update(mpimg.imread(png).tobytes())
    return digest.hexdigest()[:12]


def _report_figures(folder: Path) -> Callable[[Path], int]:
    """A function writing `reconstruct`'s figures of the fitted test `folder` into a folder."""
    from cpas_ocp.api.reconstruction import as_test, build, fit_estimator, model_of
    from cpas_ocp.inference.phase_windows import phase_windows
    from cpas_ocp.reports import plots

    test = as_test(str(folder))
    fit = fit_estimator(build(test, model_of(test))).fit
    windows = phase_windows(fit)

    def write(out: Path) -> int:
        paths = [*plots.plot_sensors(fit, out), *plots.plot_sensor_residuals(fit, windows, out),
                 plots.plot_drag_areas(fit, out), plots.plot_events(fit, out)]
        return sum(p is not None for p in paths)
    return write


def _dispersion_figures(campaign: Path) -> Callable[[Path], int]:
    """A function writing `dispersions`' folder of `campaign` (2,000 cases, seed 1)."""
    from cpas_ocp.api.campaigns import dispersions

    def write(out: Path) -> int:
        dispersions(campaign, out / "cases", 2000, 1)
        return len(list((out / "cases").glob("*.png")))
    return write


def figures(folder: str) -> dict:
    """The fastest of `TIMES` writings of the case's figures: wall time, how many and the
    digest of their pixels."""
    case = Path(folder)
    write = (_report_figures(case) if (case / "manifest.json").exists()
             else _dispersion_figures(case))
    timer = harness.Timer()
    for k in range(TIMES):
        with tempfile.TemporaryDirectory() as tmp:
            with timer("write"):
                count = write(Path(tmp))
            if k == 0:
                digest = _pixel_digest(Path(tmp))
    return {"wall_s": min(timer.laps["write"]), "figures": count, "pixels": digest}


def cases(root: Path, seed: int) -> dict[str, Path]:
    """The simulated `drogue` folder and the synthetic campaign folder, by name."""
    sys.path.insert(0, str(ROOT))
    from tests.campaign.test_dispersion_study import _table
    from tests.campaign.test_drag_area_envelope import stage_table

    campaign = root / "campaign"
    campaign.mkdir()
    table = _table()
    table.to_parquet(campaign / "parameters.parquet", index=False)
    stage_table(table).to_csv(campaign / "stages.csv", index=False)
    return {"drogue report": Path(make_test("drogue", seed, root)), "dispersions": campaign}


def main() -> int:
    parser = harness.parser(__doc__, seed=1, seed_help="seed of the simulated drogue test")
    parser.add_argument("--against", metavar="REV", default=BEFORE)
    parser.add_argument("--repeat", type=int, default=3)
    args = parser.parse_args()
    compare_cases("figure_cost", "figures", lambda root: cases(root, args.seed), args.against,
                  lambda r: f"{r['wall_s']:6.2f} s, {r['figures']} figures, pixels "
                            f"{r['pixels']}", repeat=args.repeat)
    return 0


if __name__ == "__main__":
    sys.exit(main())
