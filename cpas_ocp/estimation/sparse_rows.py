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

import casadi as ca
import numpy as np

# False: stack through vertcat and row indexing, as before (`benchmarks/jacobian_assembly.py`).
ONE_GATHER = True


def nonzeros(mat: ca.MX) -> ca.MX:
    """The nonzeros of `mat` as a column, in its column-major order (no copy is planned:
    the pattern is only reinterpreted)."""
    return ca.sparsity_cast(mat, ca.Sparsity.dense(mat.nnz(), 1))


def stacked_rows(mats: Sequence[ca.MX], rows: np.ndarray | None = None) -> ca.MX:
    """`vertcat(*mats)[rows, :]` (every row where `rows` is None), on the exact pattern of
    the stacked matrices, as one gather of their nonzeros."""
    if not mats:
        return ca.MX(0, 1)
    if not ONE_GATHER:
        stacked_mx = ca.vertcat(*mats)
        return stacked_mx if rows is None else stacked_mx[np.asarray(rows).tolist(), :]
    ncol = mats[0].size2()
    row_parts, col_parts, values = [], [], []
    first = 0
    for mat in mats:
        if mat.size2() != ncol:
            raise ValueError(f"stacking {mat.size2()} columns under {ncol}")
        sp = mat.sparsity()
        if mat.nnz():
            row_parts.append(np.asarray(sp.row(), dtype=np.int64) + first)
            col_parts.append(np.asarray(sp.get_col(), dtype=np.int64))
            values.append(nonzeros(mat))
        first += mat.size1()
    stacked = np.arange(first) if rows is None else np.asarray(rows, dtype=np.int64)
    position = np.full(first, -1, dtype=np.int64)  # result row of each stacked row
    position[stacked] = np.arange(stacked.size)
    if not values:
        return ca.MX(stacked.size, ncol)
    row = position[np.concatenate(row_parts)]
    col = np.concatenate(col_parts)
    kept = np.flatnonzero(row >= 0)
    order = kept[np.lexsort((row[kept], col[kept]))]  # column-major: CasADi's nonzero order
    sp = ca.Sparsity.triplet(stacked.size, ncol, row[order].tolist(), col[order].tolist())
    gathered = ca.vertcat(*values)[order.tolist()]
    return ca.sparsity_cast(gathered, sp)
