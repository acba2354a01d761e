"""The drag law by sparse regression selects nothing on data that hold none.

The recovery of a true term within its noise, on `drogue` flown with a drag
area falling as q^0.1, is a study (`benchmarks/studies/test_sparse_terms.py`).
"""

from __future__ import annotations

from cpas_ocp.discrepancy.diagnosis import ALPHA
from cpas_ocp.discrepancy.sparse_terms import select
from cpas_ocp.io.model_spec import baseline_spec


def test_data_without_a_drag_law_select_no_term(drogue_fit) -> None:
    """`drogue` as the baseline flies it: the gate (every term against none) does not pass."""
    fit, _, _ = drogue_fit(1)
    found = select(fit, baseline_spec(), 0, ALPHA)
    assert found.gate is not None, found.note
    assert not found.found and found.selected == {}, str(found)
    assert found.note == "no term is needed", str(found)
