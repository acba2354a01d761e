"""Monte Carlo inputs from a campaign: each canopy type and stage's parameter dispersions,
bounded by the grown convex hull of its inflation parameters.

From the campaign's parameter table (`campaign.parameter_table`) the
parameters of one parachute type and stage are pooled over the tests.  Each
dispersed parameter gets a capped distribution (`distributions.fit_dispersion`:
normal, lognormal or uniform by AIC, capped 10 % of the test range beyond the
extremes).  The inflation-shape parameters that the paper bounds together,
(Ck, n_p, expopen) for infinite-mass canopies and (n, expopen) for finite
mass, get a convex hull of the test points grown by the engineering factor
(10 %, 15 % for Pilots; `hulls.Hull.grow`); Monte Carlo cases draw them
together and redraw any combination outside the grown hull
(`hulls.sample_in_hull`), the other parameters independently.  Parameters
that are constant over the tests (a Pilot's expopen held at 1) leave the hull;
with fewer varying shape parameters than two, or fewer tests than the hull's
dimension plus one, the caps alone bound the draws.

Start times and the instrument factors (drag and load-cell scales, sensor
lags and biases) belong to one test, not to the canopy, and are not dispersed.

Where the campaign folder also holds its stages table (stages.csv), each
type and stage gets the drag-area envelope of its cases against the tests'
curves and the extreme corners (`drag_area_envelope`).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pandas as pd

from cpas_ocp.campaign.distributions import Dispersion, fit_dispersion, generator
from cpas_ocp.campaign.hulls import (
    ENGINEERING_FACTOR,
    PILOT_ENGINEERING_FACTOR,
    DegenerateHull,
    Hull,
    sample_in_hull,
)
from cpas_ocp.errors import InputError
from cpas_ocp.io.json_files import MAX_MAGNITUDE

DISPERSED = ("CdS", "Ck", "n_p", "n", "expopen", "t_k")
HULL_PARAMETERS = (("Ck", "n_p", "expopen"), ("n", "expopen"))
# Pooled tests below which a canopy type and stage is not dispersed (a distribution fitted
# to fewer values says little).
MIN_TESTS = 5


@dataclass
class DispersionModel:
    """The Monte Carlo input model of one parachute type and stage.

    `hull` is the grown hull of `hull_names` (None where the caps alone bound
    the draws); `tests` the number of tests pooled.
    """

    type: str
    stage: str
    tests: int
    dispersions: dict[str, Dispersion]
    hull_names: tuple[str, ...]
    hull: Hull | None
    test_points: pd.DataFrame
    note: str = ""  # why a hull was not drawn where one was asked for

    @property
    def label(self) -> str:
        return f"{self.type} {self.stage}"

    def draw(self, n: int, seed: int) -> pd.DataFrame:
        """`n` cases, every parameter a column (SI), reproducible by `seed`."""
        rng = generator(seed)
        out = {}
        if self.hull is not None:
            sample = sample_in_hull(self.hull, n, rng,
                                    [self.dispersions[k] for k in self.hull_names])
            out.update({k: sample.points[:, i] for i, k in enumerate(self.hull_names)})
        for name, dispersion in self.dispersions.items():
            if name not in out:
                out[name] = dispersion.sample(n, rng)
        return pd.DataFrame(out)[list(self.dispersions)]


def dispersion_models(table: pd.DataFrame, min_tests: int = MIN_TESTS
                      ) -> tuple[list[DispersionModel], list[str]]:
    """A model per parachute type and stage with at least `min_tests` tests, and a note per
    group left out."""
    rows = table[table.parameter.isin(DISPERSED) & (table.parachute != "")]
    models, skipped = [], []
    for (kind, stage), group in rows.groupby(["type", "stage"], sort=True):
        points = group.pivot_table(index=["test", "parachute"], columns="parameter",
                                   values="value").dropna(axis=1)
        if len(points) < min_tests:
            skipped.append(f"{kind} {stage}: {len(points)} canopies, fewer than {min_tests}")
            continue
        varying = [c for c in points.columns if np.ptp(points[c].to_numpy()) > 0.0]
        if not varying:
            skipped.append(f"{kind} {stage}: no parameter varies over its {len(points)} "
                           "canopies")
            continue
        dispersions = {c: fit_dispersion(c, points[c].to_numpy()) for c in varying}
        hull_names = next((h for h in HULL_PARAMETERS if set(h) <= set(varying)), ())
        if not hull_names:
            shape = [c for c in ("n", "n_p", "Ck", "expopen") if c in varying]
            hull_names = tuple(shape) if len(shape) >= 2 else ()
        hull, note = None, ""
        if hull_names and len(points) > len(hull_names):
            factor = PILOT_ENGINEERING_FACTOR if kind == "pilot" else ENGINEERING_FACTOR
            try:
                hull = Hull.from_points(points[list(hull_names)].to_numpy(),
                                        list(hull_names)).grow(factor)
            except DegenerateHull as exc:  # the tests' points lie on a line or a plane
                note = f"no hull of ({', '.join(hull_names)}): {exc}"
        models.append(DispersionModel(str(kind), str(stage), len(points), dispersions,
                                      tuple(hull_names) if hull else (), hull, points, note))
    return models, skipped


def _read_table(path: Path, what: str) -> pd.DataFrame:
    """A campaign table from Parquet or CSV (UTF-8, a byte-order mark allowed, empty cells
    NaN); InputError saying `what` was expected where it cannot be read."""
    from cpas_ocp.errors import InputError
    try:
        if path.suffix == ".parquet":
            return pd.read_parquet(path)
        return pd.read_csv(path, keep_default_na=False, na_values=[""], encoding="utf-8-sig")
    except (OSError, ValueError) as exc:  # pandas' parse and decode errors are ValueErrors
        raise InputError(str(path), "(file)", f"{what} ({type(exc).__name__}: "
                         f"{str(exc).splitlines()[0][:200]})") from None


# Parameters whose every value is positive (a drag area, an over-inflation factor, a fill
# constant, an opening exponent, a time to full open): the dispersed ones; and the units
# of the quantities no sign can flip (areas, masses).
POSITIVE_UNITS = ("m^2", "ft^2", "kg", "lb", "lbm", "slug")


def _where(path: Path, row: int) -> str:
    """A table row as its reader finds it: a CSV's line (the header is line 1), a Parquet
    table's row."""
    return f"line {row + 2}" if path.suffix != ".parquet" else f"row {row + 1}"


def check_numbers(table: pd.DataFrame, path: Path, column: str, what: str,
                  missing: bool = False, positive: pd.Series | bool = False,
                  integer: bool = False) -> None:
    """Column `column` of a campaign table read from `path` as finite numbers of magnitude
    at most MAX_MAGNITUDE (as a manifest's: beyond it no quantity of a test, and squares
    overflow) in place (NaN only where `missing` allows a blank), above zero in the rows
    `positive` marks (a drag area, a mass, a diameter: a negative one is no quantity, and a
    Monte Carlo case drawn about it flies nothing), whole numbers where `integer`;
    InputError naming the file, the row and the column where one is not, `what` saying
    what the column holds.  A CSV holds text that reads as numbers; a Parquet table holds
    numbers as numbers, so a text cell there ("21.3" in a string column) is refused."""
    cells = table[column]
    values = pd.to_numeric(cells, errors="coerce").astype(float)
    blank = cells.isna()
    bad = (values.isna() & ~(blank & missing)) | (values.abs() > MAX_MAGNITUDE)
    if integer:
        bad |= values.notna() & (values != np.round(values))
    text = (cells.map(lambda v: isinstance(v, str)) if path.suffix == ".parquet"
            else pd.Series(False, table.index))
    sign = positive if isinstance(positive, pd.Series) else pd.Series(positive, table.index)
    low = sign.to_numpy(bool) & (values <= 0.0).to_numpy(bool)
    for rows, expected in ((text.to_numpy(bool), f"a number, not text ({what})"),
                           (bad.to_numpy(bool), f"a finite {'whole ' if integer else ''}"
                            f"number of magnitude at most {MAX_MAGNITUDE:g}"
                            f"{' or a blank' if missing else ''} ({what})"),
                           (low, f"a number above zero ({what})")):
        if rows.any():
            row = int(np.flatnonzero(rows)[0])
            raise InputError(str(path), f"{_where(path, row)}, {column}",
                             f"{expected}; got {str(cells.iloc[row])!r}")
    table[column] = values


def check_names(table: pd.DataFrame, path: Path, column: str, what: str,
                allowed: tuple[str, ...] = ()) -> None:
    """Column `column` of a campaign table read from `path` as text in every row (one of
    `allowed` where given); InputError naming the file, the row and the column of the
    first blank (or unknown) cell, `what` saying what the column holds."""
    text = table[column].astype("string").str.strip()
    bad = text.isna() | (text == "")
    if allowed:
        bad |= ~text.isin(allowed)
    if bad.any():
        row = int(np.flatnonzero(bad.to_numpy(bool))[0])
        expected = f"one of {', '.join(allowed)}" if allowed else "a name"
        raise InputError(str(path), f"{_where(path, row)}, {column}",
                         f"{expected} ({what}); got {str(table[column].iloc[row])!r}")
    table[column] = text.astype(str)


def check_unique(table: pd.DataFrame, path: Path, key: list[str], what: str) -> None:
    """InputError naming the row of a campaign table read from `path` that repeats an
    earlier row's `key` columns (`what` says what a row is one of)."""
    repeated = table.duplicated(subset=key, keep="first").to_numpy(bool)
    if repeated.any():
        row = int(np.flatnonzero(repeated)[0])
        raise InputError(str(path), f"{_where(path, row)}, {'/'.join(key)}",
                         f"one row per {what}; this row repeats an earlier one's "
                         f"({', '.join(str(table[k].iloc[row]) for k in key)})")


def read_stage_table(campaign: str | Path) -> pd.DataFrame | None:
    """The campaign's stages.csv (`campaign.STAGE_COLUMNS`) in its folder, or beside its
    parameter table; None where there is none (campaigns written before it existed)."""
    from cpas_ocp.campaign.campaign import STAGE_COLUMNS
    from cpas_ocp.errors import InputError
    campaign = Path(campaign)
    path = (campaign if campaign.is_dir() else campaign.parent) / "stages.csv"
    if not path.is_file():
        return None
    stages = _read_table(path, "a campaign's stages table")
    missing = [c for c in STAGE_COLUMNS if c not in stages.columns]
    if missing:
        raise InputError(str(path), ", ".join(missing), "the columns of a campaign's stages")
    for column, what in (("test", "the test's name"), ("parachute", "the canopy's name"),
                         ("type", "the canopy's type"), ("stage", "the stage's name")):
        check_names(stages, path, column, what)
    check_names(stages, path, "inflation", "the canopy's inflation law",
                ("infinite_mass", "finite_mass"))
    check_names(stages, path, "fill_length", "the fill length's form",
                ("diameter", "growth_scaled"))
    check_numbers(stages, path, "stage_index", "the stage's order in its canopy, from 0",
                  integer=True)
    check_numbers(stages, path, "diameter", "the canopy's D_o in m", positive=True)
    check_numbers(stages, path, "line_length", "the suspension lines' length in m, blank "
                  "where none", missing=True, positive=True)
    check_numbers(stages, path, "v_start", "the stage's start airspeed in m/s, blank where "
                  "none", missing=True, positive=True)
    check_unique(stages, path, ["test", "parachute", "stage_index"], "test, canopy and stage")
    if (stages["stage_index"] < 0).any():
        row = int(np.flatnonzero((stages["stage_index"] < 0).to_numpy())[0])
        raise InputError(str(path), f"{_where(path, row)}, stage_index",
                         "the stage's order in its canopy, from 0")
    return stages


def read_parameter_table(path: str | Path) -> pd.DataFrame:
    """A campaign's parameter table from its folder (parameters.parquet, else .csv) or file."""
    from cpas_ocp.campaign.campaign import COLUMNS
    from cpas_ocp.errors import InputError
    path = Path(path)
    if path.is_dir():
        path = next((path / f for f in ("parameters.parquet", "parameters.csv")
                     if (path / f).is_file()), path / "parameters.parquet")
    if not path.is_file():
        raise InputError(str(path), "(file)", "a campaign's parameter table (cpas-ocp campaign)")
    table = _read_table(path, "a campaign's parameter table")
    if "line_length" not in table.columns:  # tables written before the column existed
        table["line_length"] = np.nan
    if "position" not in table.columns and "parachute" in table.columns:  # the same
        table["position"] = table["parachute"]
    missing = [c for c in COLUMNS if c not in table.columns]
    if missing:
        raise InputError(str(path), ", ".join(missing), "the columns of a campaign's table")
    for column, what in (("test", "the test's name"), ("parameter", "the parameter's base "
                                                                    "name"),
                         ("name", "the parameter's full name")):
        check_names(table, path, column, what)
    check_unique(table, path, ["test", "name"], "test and parameter")
    positive = table["parameter"].isin(DISPERSED) | table["unit"].isin(POSITIVE_UNITS)
    check_numbers(table, path, "value", "the reconstructed value; a drag area, mass or "
                  f"{'/'.join(DISPERSED)} above zero", positive=positive)
    check_numbers(table, path, "std", "its standard deviation, blank where undetermined",
                  missing=True)
    if (table["std"] < 0).any():
        row = int(np.flatnonzero((table["std"] < 0).to_numpy())[0])
        raise InputError(str(path), f"{_where(path, row)}, std", "a standard deviation, "
                         f"0 or more; got {table['std'].iloc[row]:g}")
    check_numbers(table, path, "cluster_size", "the canopies in the cluster", integer=True,
                  positive=True)
    check_numbers(table, path, "line_length", "the suspension lines' length in m, blank "
                  "where none", missing=True, positive=True)
    table["stage"] = table["stage"].fillna("").astype(str)
    table["parachute"] = table["parachute"].fillna("").astype(str)
    # A position read back as a number ("1" as 1.0) is the label it was written as.
    table["position"] = ["" if pd.isna(v) else str(int(v)) if isinstance(v, float)
                         and v.is_integer() else str(v) for v in table["position"]]
    return table
