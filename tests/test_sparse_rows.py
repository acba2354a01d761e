"""Stacked sparse Jacobians: one gather of nonzeros equals CasADi's vertcat and row indexing."""

from __future__ import annotations

import casadi as ca
import numpy as np
import pytest

from cpas_ocp.estimation.sparse_rows import stacked_rows


def _random_sparse(rng: np.random.Generator, rows: int, cols: int, density: float) -> ca.DM:
    dense = rng.normal(size=(rows, cols)) * (rng.random((rows, cols)) < density)
    return ca.DM(ca.sparsify(ca.DM(dense)))


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_stacked_rows_equal_vertcat_then_row_indexing(seed: int) -> None:
    rng = np.random.default_rng(seed)
    z = ca.MX.sym("z", 7)
    shapes = [(5, 0.4), (1, 0.9), (8, 0.2), (3, 0.0)]  # one block with no nonzeros
    mats = [ca.mtimes(ca.MX(_random_sparse(rng, r, 7, d)), ca.diag(z)) for r, d in shapes]
    total = sum(r for r, _ in shapes)
    rows = rng.permutation(total)[: total - 4]  # reordered, four rows left out
    for chosen in (None, rows):
        ours = stacked_rows(mats, chosen)
        expected = ca.vertcat(*mats) if chosen is None else ca.vertcat(*mats)[chosen.tolist(), :]
        zv = rng.normal(size=7)
        got = ca.Function("ours", [z], [ours])(zv)
        want = ca.Function("theirs", [z], [expected])(zv)
        assert got.shape == want.shape
        np.testing.assert_array_equal(np.asarray(ca.densify(got)), np.asarray(ca.densify(want)))
        # The pattern is the stacked matrices' own, nothing more.
        assert ours.sparsity() == expected.sparsity()


def test_blocks_of_different_widths_are_refused() -> None:
    with pytest.raises(ValueError, match="stacking 3 columns under 2"):
        stacked_rows([ca.MX.sym("a", 1, 2), ca.MX.sym("b", 1, 3)])
