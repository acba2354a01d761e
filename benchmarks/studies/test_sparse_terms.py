"""The drag law by sparse regression on data that hold one: the true term selected within its
noise and the others dropped.

The truth is `drogue` flown with every drag area times (q / 1 kPa)^-0.1 (the
regression's own log-pressure feature, about another reference: a constant
factor the drag areas take up), fitted with the baseline from observed events
0.3 s off; the regression never sees the truth.  The suite's smaller case:
`tests/discrepancy/test_sparse_terms.py` (no term selected on data without one).
"""

from __future__ import annotations

import dataclasses

import pytest

from cpas_ocp.discrepancy.diagnosis import ALPHA
from cpas_ocp.discrepancy.sparse_terms import select
from cpas_ocp.estimation.estimator import Estimator
from cpas_ocp.estimation.simulate import simulate_problem
from cpas_ocp.io.flight_test import load_test
from cpas_ocp.io.model_spec import baseline_spec
from cpas_ocp.io.problems import load_problem
from cpas_ocp.physics.effects import DragLawTerms, baseline_effects
from cpas_ocp.physics.effects.drag_law_terms import term_name
from tests.conftest import START_GUESS_OFFSET_S, offset_events

EXPONENT = -0.1
TRUE_TERM = "log_dynamic_pressure"


@pytest.fixture(scope="module")
def flattening_fit(tmp_path_factory):
    """`drogue` seed 1 flown with the drag area falling as q^0.1, fitted with the baseline."""
    problem = load_problem("drogue")
    root = tmp_path_factory.mktemp("drogue-flattening")
    base = baseline_effects()
    simulate_problem(dataclasses.replace(problem, truth={**problem.truth,
                                                         term_name(TRUE_TERM): EXPONENT}),
                     root / "sim", 1, effects=[base[0], DragLawTerms(terms=(TRUE_TERM,)),
                                               *base[1:]])
    test = load_test(offset_events(root / "sim", root / "test", START_GUESS_OFFSET_S))
    return Estimator(test).solve()


@pytest.mark.slow  # a phase fitted, then refitted with three terms and fewer
def test_the_true_term_is_selected_within_its_noise_and_the_others_dropped(flattening_fit
                                                                           ) -> None:
    found = select(flattening_fit, baseline_spec(), 0, ALPHA)
    assert found.found, str(found)
    assert list(found.selected) == [term_name(TRUE_TERM)], str(found)
    value, sigma = found.selected[term_name(TRUE_TERM)]
    assert abs(value - EXPONENT) < 4.0 * sigma, str(found)
    assert found.lr is not None and found.lr.p_value < ALPHA
