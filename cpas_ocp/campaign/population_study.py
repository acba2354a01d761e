"""The population of each canopy type and stage from a campaign's tables, and its groupings.

A campaign (`cpas-ocp campaign`) writes, per test, every parameter with its
standard deviation (parameters.csv) and the covariance of its determined
parameters (covariances.csv).  Here the parameters of one canopy type and stage
(the openings: one per test and canopy) are gathered with their covariance into
a `population_model.PopulationData` and fitted: the population mean mu (with
the covariates' effects), the between-test covariance Omega, and each
opening's shrunken estimate and pull.

Which openings form one population is a decision the paper made by eye
(pooling FBCP with Drogue first stages, comparing line-length ratios, cluster
sizes and forebodies, Figures 16 and 33).  Here it is a test: for every column
of the test table that takes two or more values within a population (forebody,
cluster size, line length and, where types are pooled, the type), the
openings are fitted as one population and as one per value, and the
likelihood ratio says whether they differ (`population_model.grouping_test`).

Start times and the instrument factors (drag and load-cell scales) belong to a
test, not to a canopy, and are left out, as in `dispersion_study`.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pandas as pd

from cpas_ocp.campaign.dispersion_study import (
    DISPERSED,
    DispersionModel,
    check_names,
    check_numbers,
)
from cpas_ocp.campaign.distributions import generator
from cpas_ocp.campaign.nested_population import NestedData, NestedFit, fit_nested
from cpas_ocp.campaign.population_model import (
    GroupingTest,
    PopulationData,
    PopulationFit,
    PopulationInputError,
    fit_population,
    grouping_test,
)
from cpas_ocp.errors import InputError
from cpas_ocp.io.flight_test import RESERVED_COLUMNS

# The columns of the parameter table a population may be grouped or regressed on (the
# line-length ratio L_s / D_o where the campaign's stages table gives each D_o, the
# canopy's position in the cluster); the covariates the manifests name follow them in
# the table (`covariate_columns`).
COVARIATE_COLUMNS = ("type", "forebody", "cluster_size", "line_length", "line_length_ratio",
                     "position")


def covariate_columns(table: pd.DataFrame) -> tuple[str, ...]:
    """The columns of `table` a population may be regressed on or grouped by: the built-in
    ones, then every column the manifests' covariates added (`flight_test.canopy_covariates`)."""
    extra = [c for c in table.columns if c not in RESERVED_COLUMNS]
    return (*COVARIATE_COLUMNS, *extra)


def with_line_length_ratio(table: pd.DataFrame, stages: pd.DataFrame | None) -> pd.DataFrame:
    """The parameter table with the column line_length_ratio, each canopy's suspension-line
    length over its nominal diameter D_o (from the stages table; blank without one)."""
    table = table.copy()
    if stages is None:
        table["line_length_ratio"] = np.nan
        return table
    diameter = stages.groupby(["test", "parachute"]).diameter.first()
    keys = pd.MultiIndex.from_arrays([table.test, table.parachute])
    table["line_length_ratio"] = (table.line_length.to_numpy(float)
                                  / diameter.reindex(keys).to_numpy(float)).round(4)
    return table


class TooFewOpenings(Exception):
    """A canopy type and stage with too few openings for a population: left out, with
    this message as the note."""


@dataclass
class PopulationGroup:
    """The population of one canopy type and stage (or of several pooled), fitted.

    `point_spread` is the standard deviation of the point estimates about their
    least-squares mean (with the same covariates) in the model's space: the
    spread a method that ignores each test's uncertainty would disperse.  `notes`
    say what was left out and why.
    """

    label: str
    members: tuple[tuple[str, str], ...]  # (type, stage) pooled
    fit: PopulationFit
    point_spread: np.ndarray
    groupings: list[GroupingTest] = field(default_factory=list)
    notes: list[str] = field(default_factory=list)
    units: dict[str, str] = field(default_factory=dict)  # parameter -> its SI unit
    # A row per opening (in the order of `data.openings`): its test and table columns.
    covariates: pd.DataFrame = field(default_factory=pd.DataFrame)
    # Per covariate of the mean, per parameter: the share of the between-test variance it
    # explains (`explained_spread`).
    explained: dict[str, np.ndarray] = field(default_factory=dict)
    # Where tests fly two or more of its canopies: the spread split into the test's and
    # the canopy's (`nested_population`), each test's canopies one observation.
    nested: NestedFit | None = None

    @property
    def data(self) -> PopulationData:
        return self.fit.data

    def median(self, name: str) -> float:
        """The population median of parameter `name` in SI at the covariates' reference
        (the intercept): exp(mu) in log space, mu otherwise."""
        j = self.data.names.index(name)
        mu = float(self.fit.beta[j, 0])
        return float(np.exp(mu)) if self.data.log[j] else mu


def read_covariance_table(campaign: str | Path) -> pd.DataFrame | None:
    """The campaign's covariances.csv (`campaign.COVARIANCE_COLUMNS`) in its folder or
    beside its parameter table; None where there is none (campaigns written before it)."""
    from cpas_ocp.campaign.campaign import COVARIANCE_COLUMNS
    campaign = Path(campaign)
    path = (campaign if campaign.is_dir() else campaign.parent) / "covariances.csv"
    if not path.is_file():
        return None
    try:
        cov = pd.read_csv(path)
    except (pd.errors.ParserError, pd.errors.EmptyDataError, UnicodeDecodeError) as exc:
        raise InputError(str(path), "(file)", f"a campaign's covariance table: {exc}") from None
    missing = [c for c in COVARIANCE_COLUMNS if c not in cov.columns]
    if missing:
        raise InputError(str(path), ", ".join(missing), "the columns of a campaign's "
                         "covariance table")
    for column in ("test", "name_a", "name_b"):
        check_names(cov, path, column, "a test or parameter name")
    check_numbers(cov, path, "covariance", "a covariance in SI")
    return cov


def _opening_covariance(names: Sequence[str], stds: Sequence[float],
                        pairs: dict[tuple[str, str], float] | None) -> np.ndarray:
    """The covariance of one opening's parameters `names` (SI): from the test's pairs where
    the campaign wrote them, else the diagonal of `stds`."""
    k = len(names)
    if pairs is None:
        return np.diag(np.square(stds))
    V = np.empty((k, k))
    for a in range(k):
        for b in range(k):
            V[a, b] = pairs.get((names[a], names[b]), pairs.get((names[b], names[a]), np.nan))
    return V


def _design(openings: pd.DataFrame, covariates: Sequence[str], where: str
            ) -> tuple[np.ndarray, tuple[str, ...]]:
    """The design matrix: an intercept, each numeric covariate about its mean, each other
    covariate as indicators of its values after the first (sorted); each column named
    after its covariate (`covariate_of`)."""
    columns, names = [np.ones(len(openings))], ["intercept"]
    for c in covariates:
        values = openings[c]
        if values.isna().any():
            raise InputError(where, c, "a value for every opening of the population; "
                             f"blank for test {openings.loc[values.isna(), 'test'].iloc[0]}")
        levels = sorted(values.unique(), key=str)
        if len(levels) < 2:
            raise InputError(where, c, f"a covariate with two or more values over the "
                             f"openings; every opening has {levels[0]}")
        if pd.api.types.is_numeric_dtype(values):
            x = values.to_numpy(float)
            columns.append(x - x.mean())
            names.append(f"{c} (per unit, about {x.mean():.4g})")
        else:
            for level in levels[1:]:
                columns.append((values == level).to_numpy(float))
                names.append(f"{c}={level}")
    return np.column_stack(columns), tuple(names)


def covariate_of(column: str) -> str:
    """The covariate a design column belongs to: `c` of "c=level" or "c (per unit, ...)"."""
    return column.split("=")[0].split(" (per unit")[0]


def _gather(rows: pd.DataFrame, parameters: Sequence[str] | None
            ) -> tuple[pd.DataFrame, list[str], list[str]]:
    """Per opening (test, parachute): its value, std and full name of each parameter kept.
    A parameter undetermined or absent in more than half the openings is left out, then
    every opening lacking one of those kept; `notes` say which."""
    wanted = [p for p in (parameters or DISPERSED) if p in set(rows.parameter)]
    rows = rows[rows.parameter.isin(wanted)]
    index = ["test", "parachute"]
    value = rows.pivot_table(index=index, columns="parameter", values="value", aggfunc="first")
    std = rows.pivot_table(index=index, columns="parameter", values="std", aggfunc="first")
    std = std.reindex_like(value)
    notes, kept = [], []
    for p in wanted:
        ok = value[p].notna() & std[p].notna() & (std[p] > 0)
        if ok.mean() > 0.5:
            kept.append(p)
        else:
            notes.append(f"{p} left out: determined in {int(ok.sum())} of {len(ok)} openings")
    whole = (value[kept].notna() & std[kept].notna() & (std[kept] > 0)).all(axis=1)
    for key in value.index[~whole]:
        notes.append(f"{key[0]} {key[1]} left out: not every parameter determined")
    return rows.set_index(index).loc[value.index[whole]].reset_index(), kept, notes


def population_data(rows: pd.DataFrame, covariances: pd.DataFrame | None,
                    parameters: Sequence[str] | None, covariates: Sequence[str],
                    where: str, by_position: bool = False
                    ) -> tuple[PopulationData, pd.DataFrame, list[str],
                               dict[str, np.ndarray] | None]:
    """The openings of `rows` (parameter-table rows of the population) as PopulationData,
    positive parameters in log space; their covariate columns (a row per opening); notes
    on what was left out; and per test the covariance of all its openings' estimates in
    the same space (`_test_blocks`; None without every pair in covariances.csv).  With
    `by_position`, the canopy's position joins the covariates where the openings fly in
    two or more positions (`_with_position`)."""
    kept_rows, names, notes = _gather(rows, parameters)
    if not names:
        raise InputError(where, "parameter", "a canopy parameter determined in most openings")
    by_test = None if covariances is None else {
        t: {(a, b): c for a, b, c in zip(g.name_a, g.name_b, g.covariance, strict=True)}
        for t, g in covariances.groupby("test")}
    ys, Vs, labels, openings, fulls = [], [], [], [], []
    for (test, chute), g in kept_rows.groupby(["test", "parachute"], sort=True):
        g = g.set_index("parameter").loc[names]
        full = list(g["name"])
        fulls.append(full)
        V = _opening_covariance(full, g["std"].to_numpy(float),
                                None if by_test is None else by_test.get(test, {}))
        if not np.isfinite(V).all():
            raise InputError(where, "covariances.csv", f"every pair of {test}'s parameters "
                             f"{', '.join(full)}; some are missing")
        ys.append(g["value"].to_numpy(float))
        Vs.append(V)
        labels.append(f"{test} {chute}")
        openings.append({c: g[c].iloc[0] if c in g else np.nan
                         for c in covariate_columns(rows)} | {"test": test})
    y, V = np.array(ys), np.array(Vs)
    log = tuple(bool((y[:, j] > 0).all()) for j in range(len(names)))
    blocks = None if by_test is None else _test_blocks(
        [o["test"] for o in openings], fulls, y, V, log, by_test)
    for j, is_log in enumerate(log):
        if is_log:
            V[:, j, :] /= y[:, j, None]
            V[:, :, j] /= y[:, j, None]
            y[:, j] = np.log(y[:, j])
    frame = pd.DataFrame(openings)
    if len(ys) < len(covariates) + 3:
        raise TooFewOpenings(f"{len(ys)} openings with every parameter determined; a "
                             f"population with {len(covariates)} covariate(s) needs at "
                             f"least {len(covariates) + 3}")
    if by_position and "position" not in covariates:
        covariates, note = _with_position(frame, covariates)
        notes += [note] if note else []
    X, columns = _design(frame, covariates, where)
    if covariances is None:
        notes.append("covariances.csv not found: each test's parameters taken as "
                     "uncorrelated (the campaign was written before it kept them)")
    try:
        data = PopulationData(tuple(names), tuple(labels), y, V, X, columns, log)
    except PopulationInputError as exc:
        raise InputError(where, "openings", str(exc)) from None
    return data, frame, notes, blocks


def _test_blocks(tests: Sequence[str], fulls: Sequence[Sequence[str]], y: np.ndarray,
                 V: np.ndarray, log: Sequence[bool],
                 pairs: dict[str, dict[tuple[str, str], float]]
                 ) -> dict[str, np.ndarray] | None:
    """Per test, the covariance (SI `V` and `y`, one row per opening, before the change to
    log space) of all its openings' estimates, opening by opening: each opening's own
    block from `V`, the blocks between its canopies from the test's `pairs`; divided by
    the estimates where `log`.  None where a pair between two canopies is missing."""
    scale = np.where(np.array(log), y, 1.0)
    out = {}
    for test in dict.fromkeys(tests):
        rows = [i for i, u in enumerate(tests) if u == test]
        k = y.shape[1]
        block = np.zeros((len(rows) * k, len(rows) * k))
        for a, i in enumerate(rows):
            for b, j in enumerate(rows):
                if i == j:
                    cross = V[i]
                else:
                    found = pairs.get(test, {})
                    cross = np.array([[found.get((p, q), found.get((q, p), np.nan))
                                       for q in fulls[j]] for p in fulls[i]])
                    if not np.isfinite(cross).all():
                        return None
                block[a * k:(a + 1) * k, b * k:(b + 1) * k] = cross / np.outer(scale[i],
                                                                               scale[j])
        out[test] = block
    return out


def _with_position(frame: pd.DataFrame, covariates: Sequence[str]) -> tuple[list[str], str]:
    """`covariates` with the canopy's position added where the openings (a row each in
    `frame`) fly in two or more positions, each position held by two or more openings and
    the design still of full rank with two openings to spare; and a note saying so, or
    why not.  Canopies in fixed places of a cluster differ by fixed amounts (a position
    in the wake of another, a riser's length): left out of the mean, that difference
    would be read as between-test spread."""
    positions = frame["position"].fillna("").astype(str)
    levels = positions.value_counts()
    if len(levels) < 2 or (positions == "").any():
        return list(covariates), ""
    if levels.min() < 2:
        return list(covariates), (f"position not taken as a covariate: {levels.idxmin()} "
                                  f"has {levels.min()} opening")
    with_position = [*covariates, "position"]
    X, _ = _design(frame.assign(position=positions), with_position, "")
    if np.linalg.matrix_rank(X) < X.shape[1] or len(frame) < X.shape[1] + 2:
        return list(covariates), ("position not taken as a covariate: it does not vary "
                                  "apart from the other covariates")
    return with_position, ("position taken as a covariate: the openings fly in "
                           f"{len(levels)} positions ({', '.join(sorted(levels.index))})")


def population_groups(table: pd.DataFrame, covariances: pd.DataFrame | None, where: str,
                      parameters: Sequence[str] | None = None, covariates: Sequence[str] = (),
                      pool: Sequence[Sequence[tuple[str, str]]] = (), full_omega: bool = True,
                      alpha: float = 0.05, seed: int = 0, by_position: bool = True
                      ) -> tuple[list[PopulationGroup], list[str]]:
    """A fitted population per canopy type and stage (each set in `pool` fitted as one), with
    its grouping tests (their bootstrap drawn with `seed`) and the share of each
    parameter's between-test variance each covariate explains; and a note per type and
    stage left out.  With `by_position`, a type flown in two or more positions takes its
    position as a covariate (`_with_position`)."""
    tests = table.test.nunique()
    if tests < 2:
        raise InputError(where, "test", f"a campaign of two or more reconstructed tests; "
                         f"it holds {tests}")
    known = covariate_columns(table)
    unknown = [c for c in covariates if c not in known]
    if unknown:
        raise InputError(where, f"covariate {unknown[0]}", "a column of the campaign's "
                         f"table: {', '.join(known)}")
    rows = table[(table.parachute != "") & table.parameter.isin(parameters or DISPERSED)]
    members_of = {m: tuple(p) for p in pool for m in p}
    kinds = sorted({(str(t), str(s)) for t, s in zip(rows.type, rows.stage, strict=True)})
    missing = [m for p in pool for m in p if m not in kinds]
    if missing:
        raise InputError(where, "pool", f"canopy types and stages of the campaign; "
                         f"{missing[0][0]}/{missing[0][1]} has no parameters in it")
    sets = list(dict.fromkeys(members_of.get(u, (u,)) for u in kinds))
    groups, skipped = [], []
    for members in sets:
        label = " + ".join(f"{t} {s}" for t, s in members)
        part = rows[[(t, s) in members for t, s in zip(rows.type, rows.stage, strict=True)]]
        try:
            data, frame, notes, blocks = population_data(
                part, covariances, parameters, covariates, where,
                by_position and len({t for t, _ in members}) == 1)
        except TooFewOpenings as exc:
            skipped.append(f"{label}: {exc}")
            continue
        fit = fit_population(data, full_omega)
        coef, *_ = np.linalg.lstsq(data.X, data.y, rcond=None)
        spread = (data.y - data.X @ coef).std(axis=0, ddof=data.p)
        group = PopulationGroup(label, members, fit, spread, notes=notes,
                                units=dict(zip(part.parameter, part.unit, strict=True)),
                                covariates=frame, explained=explained_spread(fit))
        group.nested, note = _nested(data, frame, blocks)
        group.notes += [note] if note else []
        group.groupings, more = _groupings(frame, data, full_omega, alpha, len(members) > 1,
                                           seed, {covariate_of(c) for c in data.columns[1:]})
        group.notes += more
        groups.append(group)
    return groups, skipped


def _nested(data: PopulationData, frame: pd.DataFrame, blocks: dict[str, np.ndarray] | None
            ) -> tuple[NestedFit | None, str]:
    """The population with test-level and canopy-level spread (`nested_population`) where
    some test flies two or more of its canopies and every cross-covariance is known; and a
    note where such tests exist but it was not fitted."""
    tests = list(frame["test"])
    if max(tests.count(t) for t in tests) < 2:
        return None, ""
    if blocks is None:
        return None, ("test-level and canopy-level spread not separated: covariances.csv "
                      "lacks the covariances between a test's canopies")
    try:
        nested = NestedData.from_openings(data, tests, blocks)
    except PopulationInputError as exc:
        return None, f"test-level and canopy-level spread not separated: {exc}"
    return fit_nested(nested, full_omega=False), ""


def explained_spread(fit: PopulationFit) -> dict[str, np.ndarray]:
    """Per covariate of the fit's mean, per parameter: the share of the between-test
    variance the covariate explains, 1 - tau^2 / tau0^2 with tau0 the between-test
    standard deviation fitted without it (Raudenbush's R^2 of a meta-regression), held
    within [0, 1]; NaN where the fit without it finds no spread to explain (tau0's
    profile interval reaches 0: a share of a spread that may be nothing is noise)."""
    data = fit.data
    out = {}
    for covariate in dict.fromkeys(covariate_of(c) for c in data.columns[1:]):
        keep = [i for i, c in enumerate(data.columns) if covariate_of(c) != covariate]
        without = fit_population(data.subset(np.arange(data.n), keep), fit.full_omega,
                                 fit.reml)
        spread = np.array([without.tau[n].lower > 0.0 for n in data.names])
        tau2, tau2_without = np.diag(fit.omega), np.diag(without.omega)
        with np.errstate(divide="ignore", invalid="ignore"):
            out[covariate] = np.where(spread, np.clip(1.0 - tau2 / tau2_without, 0.0, 1.0),
                                      np.nan)
    return out


def _groupings(frame: pd.DataFrame, data: PopulationData, full_omega: bool, alpha: float,
               pooled: bool, seed: int, in_mean: set[str]
               ) -> tuple[list[GroupingTest], list[str]]:
    """The grouping test of every covariate column of `frame` (a row per opening) taking two
    or more values over the openings, each value held by at least k + 2 of them (k
    parameters); a column splitting the openings as one tested before is not tested
    again, nor one already in the mean (`in_mean`: its shift is there, with its
    interval)."""
    intercept = data.subset(np.arange(data.n), keep_columns=[0])
    tests, notes, seen = [], [], set()
    for column in [c for c in frame.columns if c not in ("test", *in_mean)]:
        if column == "type" and not pooled:
            continue
        values = frame[column]
        if values.isna().any() or values.nunique() < 2:
            continue
        partition = tuple(pd.factorize(values)[0])
        if partition in seen:  # the same split as a column tested already (L_s at one D_o)
            continue
        seen.add(partition)
        counts = values.value_counts()
        if counts.min() < data.k + 2:
            if column not in COVARIATE_COLUMNS:  # a manifest's covariate, a date say
                continue
            notes.append(f"{column}: not tested as a grouping; {counts.idxmin()} has "
                         f"{counts.min()} openings, fewer than {data.k + 2}")
            continue
        labels = [str(v) for v in values]
        tests.append(grouping_test(intercept, labels, column, full_omega, alpha, seed=seed))
    return tests, notes


# Candidates drawn per batch when drawing a population's cases inside the caps and hull.
DRAW_BATCH = 65_536


@dataclass
class PopulationDispersion(DispersionModel):
    """A canopy type and stage's Monte Carlo model drawn from its fitted population:
    (the population's parameters) ~ N(mu, Omega) in the model's space, mu at the
    covariates' reference, every case inside the point-estimate model's caps and its
    grown hull (redrawn until it is); parameters the population leaves out drawn from
    their point-estimate dispersions, as `DispersionModel` does."""

    population: PopulationGroup | None = None
    # The design row the cases are drawn at (`design_row`); None: the covariates'
    # reference, the intercept.
    at: np.ndarray | None = None

    @classmethod
    def of(cls, model: DispersionModel, group: PopulationGroup,
           at: np.ndarray | None = None) -> PopulationDispersion:
        fields = {f.name: getattr(model, f.name) for f in dataclasses.fields(DispersionModel)}
        return cls(**fields, population=group, at=at)

    def draw(self, n: int, seed: int) -> pd.DataFrame:
        """`n` cases, every parameter a column (SI), reproducible by `seed`."""
        group = self.population
        assert group is not None
        rng = generator(seed)
        data, fit = group.data, group.fit
        w, U = np.linalg.eigh(fit.omega)
        root = U * np.sqrt(np.clip(w, 0.0, None))
        names = [p for p in data.names if p in self.dispersions]
        idx = [data.names.index(p) for p in names]
        kept: list[np.ndarray] = []
        got, drawn = 0, 0
        while got < n:
            if drawn > 1000 * n + 100_000:
                raise RuntimeError(f"{self.label}: fewer than 1 in 1000 population draws fall "
                                   "inside the caps and the hull")
            mean = fit.beta[:, 0] if self.at is None else fit.beta @ self.at
            z = mean + rng.standard_normal((DRAW_BATCH, data.k)) @ root.T
            x = np.where(np.array(data.log), np.exp(z), z)[:, idx]
            ok = np.ones(DRAW_BATCH, dtype=bool)
            for j, p in enumerate(names):
                d = self.dispersions[p]
                ok &= (x[:, j] >= d.lower_cap) & (x[:, j] <= d.upper_cap)
            if self.hull is not None and set(self.hull_names) <= set(names):
                ok &= self.hull.contains(x[:, [names.index(h) for h in self.hull_names]])
            kept.append(x[ok])
            got += int(ok.sum())
            drawn += DRAW_BATCH
        out = dict(zip(names, np.concatenate(kept)[:n].T, strict=True))
        for name, dispersion in self.dispersions.items():
            if name not in out:
                out[name] = dispersion.sample(n, rng)
        return pd.DataFrame(out)[list(self.dispersions)]


def design_row(group: PopulationGroup, at: Mapping[str, str], where: str
               ) -> tuple[np.ndarray, list[str]]:
    """The design row of the configuration `at` (covariate -> value) in `group`'s mean: the
    intercept, each indicator 1 where `at` names its level, each number's value less its
    mean over the openings; a covariate `at` leaves out at its reference (the first level,
    or the mean).  The row and what it was drawn at, in words.  InputError where `at`
    names a level the population has not seen or a number that is not one."""
    x = np.zeros(group.data.p)
    x[0] = 1.0
    for a, column in enumerate(group.data.columns[1:], start=1):
        covariate = covariate_of(column)
        if covariate not in at:
            continue
        if "=" in column:
            levels = sorted(str(v) for v in group.covariates[covariate].unique())
            if str(at[covariate]) not in levels:
                raise InputError(where, f"--at {covariate}", f"a value the openings of "
                                 f"{group.label} hold: {', '.join(levels)}; got {at[covariate]}")
            x[a] = float(column == f"{covariate}={at[covariate]}")
        else:
            try:
                value = float(at[covariate])
            except ValueError:
                raise InputError(where, f"--at {covariate}", f"a number; got "
                                 f"{at[covariate]}") from None
            x[a] = value - float(group.covariates[covariate].astype(float).mean())
    used = [c for c in at if any(covariate_of(col) == c for col in group.data.columns[1:])]
    said = [f"{c}={at[c]}" for c in used]
    return x, said


def population_dispersions(models: Sequence[DispersionModel], groups: Sequence[PopulationGroup],
                           at: Mapping[str, str] | None = None, where: str = "(command line)"
                           ) -> tuple[list[DispersionModel], list[str]]:
    """Each model whose type and stage has a population of its own drawn from it, at the
    configuration `at` (covariate -> value, `design_row`; the reference where empty); a
    note per model left with its point-estimate dispersions or drawn at a configuration."""
    own = {g.members[0]: g for g in groups if len(g.members) == 1}
    out, notes = [], []
    for model in models:
        group = own.get((model.type, model.stage))
        if group is None:
            notes.append(f"{model.label}: no population of its own; point-estimate dispersions")
            out.append(model)
            continue
        x, said = design_row(group, at or {}, where)
        out.append(PopulationDispersion.of(model, group, x))
        notes += [f"{model.label}: drawn at {', '.join(said)}"] if said else []
    return out, notes
