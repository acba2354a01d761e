"""Sparse Jacobians stacked and their rows reordered through one gather of their nonzeros.

The NLP's residual and constraint Jacobians are stacked from the Jacobians of
many blocks (each a mapped chain of the model's pieces), and their rows are
then put in node order.  CasADi's MX `vertcat` and row indexing of sparse
matrices go through transposes of the whole matrix: on `drogue` (398,313
nonzeros) they took a sixth of each Jacobian evaluation.  Here the pattern of
the result is worked out once, in NumPy, and each evaluation is one gather of
the blocks' nonzeros into it.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import casadi as ca
import numpy as np

# False: stack through vertcat and row indexing, as before (`benchmarks/jacobian_assembly.py`).
ONE_GATHER = True


def nonzeros(mat: ca.MX) -> ca.MX:
    """The nonzeros of `mat` as a column, in its column-major order (no copy is planned:
    the pattern is only reinterpreted)."""
    return ca.sparsity_cast(mat, ca.Sparsity.dense(mat.nnz(), 1))


@dataclass(frozen=True)
class Rows:
    """Rows `rows` of the stacked matrices `mats` (`vertcat(*mats)[rows, :]`), not yet
    gathered: a stretch of a larger stack that `stacked_parts` gathers in one go."""

    mats: tuple[ca.MX, ...]
    rows: np.ndarray


def stacked_parts(parts: Sequence[ca.MX | Rows]) -> ca.MX:
    """The parts stacked (a matrix as it is, `Rows` as their rows), through one gather of
    the nonzeros of every matrix they come from (each set of `Rows.mats` taken once)."""
    mats: list[ca.MX] = []
    rows: list[np.ndarray] = []
    first = 0
    placed: dict[int, int] = {}  # id of a Rows' matrices -> their first row in the stack
    for part in parts:
        if isinstance(part, Rows):
            if id(part.mats) not in placed:
                placed[id(part.mats)] = first
                mats.extend(part.mats)
                first += sum(mat.size1() for mat in part.mats)
            rows.append(placed[id(part.mats)] + np.asarray(part.rows, dtype=np.int64))
        else:
            mats.append(part)
            rows.append(first + np.arange(part.size1()))
            first += part.size1()
    return stacked_rows(mats, np.concatenate(rows) if rows else np.zeros(0, dtype=np.int64))


def stacked_rows(mats: Sequence[ca.MX], rows: np.ndarray | None = None) -> ca.MX:
    """`vertcat(*mats)[rows, :]` (every row where `rows` is None), on the exact pattern of
    the stacked matrices, as one gather of their nonzeros."""
    first = sum(mat.size1() for mat in mats)
    chosen = np.arange(first) if rows is None else np.asarray(rows, dtype=np.int64)
    if not mats:
        return ca.MX(chosen.size, 0)
    if not ONE_GATHER:
        return ca.vertcat(*mats)[chosen.tolist(), :]
    ncol = mats[0].size2()
    row_parts, col_parts, values = [], [], []
    first = 0
    for mat in mats:
        if mat.size2() != ncol:
            raise ValueError(f"stacking {mat.size2()} columns under {ncol}")
        if mat.nnz():
            sp = mat.sparsity()
            row_parts.append(np.asarray(sp.row(), dtype=np.int64) + first)
            col_parts.append(np.asarray(sp.get_col(), dtype=np.int64))
            values.append(nonzeros(mat))
        first += mat.size1()
    if not values:
        return ca.MX(chosen.size, ncol)
    position = np.full(first, -1, dtype=np.int64)  # result row of each stacked row
    position[chosen] = np.arange(chosen.size)
    row = position[np.concatenate(row_parts)]
    col = np.concatenate(col_parts)
    kept = np.flatnonzero(row >= 0)  # rows not chosen are left out
    # Column-major, CasADi's nonzero order: one sort of one key.
    order = kept[np.argsort(col[kept] * max(chosen.size, 1) + row[kept], kind="stable")]
    colind = np.concatenate([[0], np.cumsum(np.bincount(col[order], minlength=ncol))])
    sp = ca.Sparsity(int(chosen.size), ncol, colind.tolist(), row[order].tolist())
    gathered = ca.vertcat(*values)[order.tolist()] if order.size else ca.MX(0, 1)
    return ca.sparsity_cast(gathered, sp)
