"""Stacked sparse Jacobians: one gather of nonzeros equals CasADi's vertcat and row indexing."""

from __future__ import annotations

import itertools

import casadi as ca
import numpy as np
import pytest

from cpas_ocp.estimation.sparse_rows import Rows, stacked_parts, stacked_rows


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


def test_stretches_of_reordered_rows_equal_their_slices_of_the_stack() -> None:
    rng = np.random.default_rng(3)
    z = ca.MX.sym("z", 6)
    mats = [ca.mtimes(ca.MX(_random_sparse(rng, r, 6, 0.5)), ca.diag(z)) for r in (4, 7, 2)]
    rows = rng.permutation(13)
    bounds = [2, 5, 5, 13]  # the first two rows in no range, one range empty
    stack = ca.vertcat(*mats)
    zv = rng.normal(size=6)
    for a, b in itertools.pairwise(bounds):
        ours = stacked_rows(mats, rows[a:b])
        theirs = stack[rows[a:b].tolist(), :]
        assert ours.sparsity() == theirs.sparsity()
        got, want = (ca.Function("f", [z], [m])(zv) for m in (ours, theirs))
        np.testing.assert_array_equal(np.asarray(ca.densify(got)), np.asarray(ca.densify(want)))


def test_parts_gather_their_rows_from_the_matrices_they_come_from() -> None:
    rng = np.random.default_rng(4)
    z = ca.MX.sym("z", 5)
    source = tuple(ca.mtimes(ca.MX(_random_sparse(rng, r, 5, 0.5)), ca.diag(z)) for r in (3, 4))
    own = ca.mtimes(ca.MX(_random_sparse(rng, 2, 5, 0.6)), ca.diag(z))
    order = rng.permutation(7)
    parts = [Rows(source, order[:4]), own, Rows(source, order[4:])]
    stack = ca.vertcat(*source)
    theirs = ca.vertcat(stack[order[:4].tolist(), :], own, stack[order[4:].tolist(), :])
    ours = stacked_parts(parts)
    assert ours.sparsity() == theirs.sparsity()
    zv = rng.normal(size=5)
    got, want = (ca.Function("f", [z], [m])(zv) for m in (ours, theirs))
    np.testing.assert_array_equal(np.asarray(ca.densify(got)), np.asarray(ca.densify(want)))
