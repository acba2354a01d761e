"""Shape restarts solve every start but the one the first fit was solved from.

`restart_shapes` only orchestrates: which starts it solves, and which fit it keeps.  The
estimator here is a stand-in with one stage's drag area and fill constant, whose solves
record their starts; the fits it returns sit where each start's fill constant leads.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from types import SimpleNamespace

import numpy as np
import pytest

from cpas_ocp.errors import SolverFailure
from cpas_ocp.estimation.fit import FROM_REDUCTION
from cpas_ocp.estimation.stage_curve_fit import inside_bounds
from cpas_ocp.inference.shape_restarts import SHAPE_START_FACTORS, restart_shapes

N = "n[main,open]"
DEFAULT_N, LOWER_N, UPPER_N = 8.0, 1.0, 60.0


@dataclass
class StandIn:
    """Two free parameters, drag area and fill constant (a guessed range); the reduction's
    point holds `reduced_n`.  A solve from a start with fill constant n ends at chi-square
    `chi2(n)`, on the upper bound where n started above the default."""

    reduced_n: float
    chi2: dict[float, float] = field(default_factory=dict)
    starts: list[float] = field(default_factory=list)
    free: tuple[str, ...] = ("CdS[main,open]", N)

    def __post_init__(self) -> None:
        self.settings = SimpleNamespace(max_iter=500)
        self.model = SimpleNamespace(parameter=lambda name: SimpleNamespace(
            default=DEFAULT_N, lower=LOWER_N, upper=UPPER_N, physical_lower=False,
            physical_upper=False))

    def initial_point(self) -> np.ndarray:
        return np.array([13.0, self.reduced_n])

    def with_value(self, z: np.ndarray, name: str, value: float) -> np.ndarray:
        out = z.copy()
        out[self.free.index(name)] = value
        return out

    def solve(self, progress: bool = False, start: np.ndarray | None = None
              ) -> SimpleNamespace:
        n = float(self.initial_point()[1] if start is None else start[1])
        self.starts.append(n)
        return fitted(UPPER_N if n >= DEFAULT_N else 20.0, self.chi2.get(n, 100.0),
                      FROM_REDUCTION if start is None else "a given point")


def fitted(n: float, chi2: float, start: str) -> SimpleNamespace:
    return SimpleNamespace(parameters={"CdS[main,open]": 13.0, N: n}, chi_square=chi2,
                           solver=SimpleNamespace(start=start))


def factor_starts(factors: tuple[float, ...]) -> list[float]:
    return [inside_bounds(f * DEFAULT_N, LOWER_N, UPPER_N) for f in factors]


def test_the_reduction_s_own_start_is_not_solved_again() -> None:
    """The reduction left the fill constant at its default and the first fit, solved from
    there, ended on its guessed upper bound: the restart at 1 times the default is that same
    start, so only the other factors are solved."""
    est = StandIn(reduced_n=DEFAULT_N)
    first = est.solve()
    est.starts.clear()
    fit = restart_shapes(est, lambda: first)
    assert est.starts == factor_starts(tuple(f for f in SHAPE_START_FACTORS if f != 1.0))
    assert fit is first


@pytest.mark.parametrize("reduced_n, start", [(10.0, FROM_REDUCTION),
                                              (DEFAULT_N, "a fit with no added_mass")])
def test_every_factor_is_solved_where_the_first_fit_came_from_elsewhere(
        reduced_n: float, start: str) -> None:
    """Where the reduction gave the fill constant a value of its own, or the first fit was
    not solved from the reduction's point (through a relaxed model, say), the start at 1
    times the default is a new one."""
    est = StandIn(reduced_n=reduced_n)
    fit = restart_shapes(est, lambda: fitted(UPPER_N, 100.0, start))
    assert est.starts == factor_starts(SHAPE_START_FACTORS)
    assert fit.solver.start == start


def test_a_restart_that_lowers_chi_square_is_kept_and_says_so() -> None:
    """The start at half the default leads to chi-square 50 against the first fit's 100:
    that fit is kept, and where it started says which restart made it."""
    half = inside_bounds(0.5 * DEFAULT_N, LOWER_N, UPPER_N)
    est = StandIn(reduced_n=DEFAULT_N, chi2={half: 50.0})
    first = est.solve()
    fit = restart_shapes(est, lambda: first)
    assert fit.chi_square == 50.0 and fit.parameters[N] == 20.0
    assert "at 0.5 x their defaults" in fit.solver.start and N in fit.solver.start


def test_each_restart_says_what_it_refits_when_progress_is_shown(capsys) -> None:
    est = StandIn(reduced_n=DEFAULT_N)
    first = est.solve()
    restart_shapes(est, lambda: first, progress=True)
    lines = capsys.readouterr().err.splitlines()
    assert lines == [f"{N} on a guessed bound: fitting again from the reduction with {N} at "
                     f"{f:g} x their defaults ..." for f in SHAPE_START_FACTORS if f != 1.0]


@pytest.mark.parametrize("status, iterations, repeated", [
    ("Stalled_Without_Progress", 91, False), ("Maximum_Iterations_Exceeded", 500, False),
    ("Maximum_Iterations_Exceeded", 100, True)])
def test_a_first_attempt_that_failed_from_the_reduction_is_not_solved_again(
        status: str, iterations: int, repeated: bool) -> None:
    """The first attempt failed from the reduction's own point, which left the fill
    constant at its default: solved again from there with the same limit it would fail
    again (it had repeated 500 iterations on the NDRT 2020 log), so only the other
    factors are solved.  A failure stopped short of the limit (a direct start of a model
    with continuation effects, capped at 100) is solved again with the whole limit."""
    est = StandIn(reduced_n=DEFAULT_N)
    failure = SolverFailure(status, iterations, "",
                            100.0, fitted(UPPER_N, 100.0, FROM_REDUCTION))

    def first() -> SimpleNamespace:
        raise failure

    restart_shapes(est, first)
    factors = tuple(f for f in SHAPE_START_FACTORS if repeated or f != 1.0)
    assert est.starts == factor_starts(factors)
