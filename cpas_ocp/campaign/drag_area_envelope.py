"""The Monte Carlo drag-area envelope of a parachute type and stage against its flight curves
and the extreme corner curves (the paper's Figs. 18 and 27).

A stage's drag area CdS(t) follows the inflation law of `inflation.py`
(Eqs. 5-6): infinite mass from (CdS, Ck, n_p, expopen, t_k), finite mass
from (CdS, n, expopen), with the fill time n L / V_i.  The law also needs
the stage's conditions: the previous stage's steady drag area (0 for the
first stage), the fill length L (D_o, or D_o sqrt(growth / full-open CdS))
and the start airspeed V_i.  These are not dispersed, so every curve here
is drawn at one set of them, the campaign's medians for the type and stage
(`StageConditions`, from the campaign's stages.csv and parameter table).
The curves then differ only in the parameters that are dispersed:

* the flight curves: each test canopy's fitted parameters;
* the Monte Carlo envelope: the first `ENVELOPE_CASES` cases, summarised at
  every time by their minimum, maximum and percentiles;
* the corner curves: every combination of the lower and upper caps of the
  inflation-shape parameters (those the hull bounds, or the dispersed shape
  parameters where there is no hull), the others at the tests' medians.
  Corners outside the grown hull are the combinations the rejection sampling
  excludes (paper: low n_p, low expopen, high Ck give a load above flight
  experience);
* the Monte Carlo cases with the largest and smallest peak drag area and
  the fastest and slowest rise (time to 90 % of their own steady CdS).

Time is measured from the stage's start t_i (s); drag areas are m^2.
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass, field

import casadi as ca
import numpy as np
import pandas as pd

from cpas_ocp.campaign.dispersion_study import DispersionModel
from cpas_ocp.physics.inflation import fill_length, fill_time, finite_mass_cds, infinite_mass_cds

ENVELOPE_CASES = 4000
PERCENTILES = (0, 5, 25, 50, 75, 95, 100)
TIME_POINTS = 301
# The time axis runs to this multiple of the slowest flight or corner curve's settling time.
TIME_MARGIN = 1.15
LAW_PARAMETERS = {"infinite_mass": ("CdS", "Ck", "n_p", "expopen", "t_k"),
                  "finite_mass": ("CdS", "n", "expopen")}
SHAPE = ("Ck", "n_p", "n", "expopen")


@dataclass(frozen=True)
class StageConditions:
    """What the inflation law of a stage needs besides its dispersed parameters: the law
    (`inflation`), the fill-length form, D_o (m), the start airspeed V_i (m/s), the previous
    stage's steady CdS (m^2; 0 for a first stage), the full-open CdS (m^2) that a
    growth-scaled fill length divides by, and whether the stage is the canopy's last (its
    own CdS is then the full-open one)."""

    inflation: str
    fill_length: str
    diameter: float
    v_start: float
    cds_prev: float
    cds_full_open: float
    last_stage: bool

    @property
    def names(self) -> tuple[str, ...]:
        return LAW_PARAMETERS[self.inflation]


def stage_conditions(stages: pd.DataFrame, table: pd.DataFrame, kind: str, stage: str
                     ) -> StageConditions | None:
    """The campaign's median conditions of a type and stage from its stages table
    (`campaign.STAGE_COLUMNS`) and parameter table; None where the stages table has no
    canopy of it with a start airspeed, or no previous stage's drag area is known."""
    rows = stages[(stages.type == kind) & (stages.stage == stage)].dropna(subset=["v_start"])
    if rows.empty:
        return None
    cds = table[table.parameter == "CdS"].set_index(["test", "parachute", "stage"])["value"]
    order = stages.set_index(["test", "parachute", "stage_index"])["stage"]
    last = stages.groupby(["test", "parachute"])["stage_index"].max()
    prev, full_open, is_last = [], [], []
    for r in rows.itertuples():
        k, final = int(r.stage_index), int(last[(r.test, r.parachute)])
        before = order.get((r.test, r.parachute, k - 1))
        prev.append(0.0 if k == 0 else cds.get((r.test, r.parachute, before), np.nan))
        full_open.append(cds.get((r.test, r.parachute, order[(r.test, r.parachute, final)]),
                                 np.nan))
        is_last.append(k == final)
    prev_known = [v for v in prev if np.isfinite(v)]
    if not prev_known:
        return None
    return StageConditions(
        inflation=str(rows.inflation.mode().iloc[0]),
        fill_length=str(rows.fill_length.mode().iloc[0]),
        diameter=float(rows.diameter.median()), v_start=float(rows.v_start.median()),
        cds_prev=float(np.median(prev_known)),
        cds_full_open=float(np.nanmedian(full_open)), last_stage=all(is_last))


def _law(cond: StageConditions) -> ca.Function:
    """(t, *parameters) -> (CdS(t) in m^2, time from t_i to the steady drag area in s)."""
    t = ca.SX.sym("t")
    p = {n: ca.SX.sym(n) for n in cond.names}
    cds_o = p["CdS"] if cond.last_stage else cond.cds_full_open
    length = fill_length(cond.fill_length, cond.diameter, cond.cds_prev, p["CdS"], cds_o)
    if cond.inflation == "infinite_mass":
        curve = infinite_mass_cds(t, 0.0, cond.cds_prev, p["CdS"], p["Ck"], p["n_p"],
                                  p["expopen"], p["t_k"], length, cond.v_start)
        settled = fill_time(p["n_p"], length, cond.v_start) + p["t_k"]
    else:
        curve = finite_mass_cds(t, 0.0, cond.cds_prev, p["CdS"], p["n"], p["expopen"], length,
                                cond.v_start)
        settled = fill_time(p["n"], length, cond.v_start)
    return ca.Function("stage_cds", [t, *p.values()], [curve, settled])


def cds_curves(cond: StageConditions, params: pd.DataFrame, t: np.ndarray
               ) -> tuple[np.ndarray, np.ndarray]:
    """CdS(t) (m^2) of every row of `params` (columns `cond.names`, SI) at the times `t` (s
    from the stage start), shape (rows, times), and each row's settling time (s)."""
    law = _law(cond)
    n, m = len(params), len(t)
    values = [params[c].to_numpy(dtype=float) for c in cond.names]
    curves, _ = law.map(n * m)(np.tile(t, n)[None, :], *(np.repeat(v, m)[None, :]
                                                         for v in values))
    _, settled = law.map(n)(np.zeros((1, n)), *(v[None, :] for v in values))
    return np.asarray(curves).reshape(n, m), np.asarray(settled).ravel()


@dataclass
class DragAreaEnvelope:
    """Curves of one type and stage at common conditions; every curve row-aligned with `t`."""

    label: str
    conditions: StageConditions
    t: np.ndarray
    cases: int
    bands: pd.DataFrame
    flight: np.ndarray
    flight_names: list[str]
    corners: np.ndarray
    corner_labels: list[str]
    corner_inside: list[bool | None]  # None where no hull bounds the draws
    extremes: dict[str, np.ndarray] = field(default_factory=dict)

    def flight_inside(self, tolerance: float = 0.0) -> float:
        """Fraction of the flight curves' (curve, time) points inside the Monte Carlo
        min-max band widened by `tolerance` (m^2)."""
        lo = self.bands["min"].to_numpy() - tolerance
        hi = self.bands["max"].to_numpy() + tolerance
        return float(np.mean((self.flight >= lo) & (self.flight <= hi)))


def drag_area_envelope(model: DispersionModel, cases: pd.DataFrame, cond: StageConditions,
                       n_cases: int = ENVELOPE_CASES) -> DragAreaEnvelope | None:
    """The envelope of the first `n_cases` of `cases` against the model's test points and the
    corners of its caps box; None where the tests lack a parameter of the law."""
    names = cond.names
    points = model.test_points
    if not set(names) <= set(points.columns):
        return None
    median = points[list(names)].median()
    draws = cases.iloc[:n_cases].reset_index(drop=True)
    mc = pd.DataFrame({n: draws[n] if n in draws else np.full(len(draws), median[n])
                       for n in names})
    shape = list(model.hull_names) or [n for n in SHAPE if n in model.dispersions]
    corner_rows, labels, inside = [], [], []
    for signs in itertools.product((0, 1), repeat=len(shape)):
        row = median.copy()
        for name, s in zip(shape, signs, strict=True):
            d = model.dispersions[name]
            row[name] = d.upper_cap if s else d.lower_cap
        corner_rows.append(row)
        labels.append(" ".join(f"{n}{'+' if s else '-'}" for n, s in zip(shape, signs,
                                                                          strict=True)))
        inside.append(None if model.hull is None else
                      bool(model.hull.contains(row[list(model.hull_names)].to_numpy()[None])[0]))
    corner_frame = pd.DataFrame(corner_rows)[list(names)]
    flight_frame = points[list(names)]
    zero = np.zeros(1)
    settled = np.concatenate([cds_curves(cond, f, zero)[1] for f in (flight_frame, corner_frame)])
    t = np.linspace(0.0, TIME_MARGIN * float(settled.max()), TIME_POINTS)
    flight, _ = cds_curves(cond, flight_frame, t)
    corners, _ = cds_curves(cond, corner_frame, t)
    curves, _ = cds_curves(cond, mc, t)
    bands = pd.DataFrame({"t": t})
    for q in PERCENTILES:
        column = {0: "min", 100: "max"}.get(q, f"p{q:02d}")
        bands[column] = np.percentile(curves, q, axis=0)
    peak = curves.max(axis=1)
    rise = np.argmax(curves >= 0.9 * mc["CdS"].to_numpy()[:, None], axis=1)
    extremes = {"largest peak": curves[np.argmax(peak)], "smallest peak": curves[np.argmin(peak)],
                "fastest rise": curves[np.argmin(rise)], "slowest rise": curves[np.argmax(rise)]}
    return DragAreaEnvelope(model.label, cond, t, len(mc), bands, flight,
                            [f"{a} {b}" for a, b in flight_frame.index], corners, labels,
                            inside, extremes)
