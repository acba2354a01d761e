"""A CasADi function evaluated straight into NumPy arrays, through its function buffer."""

from __future__ import annotations

import casadi as ca
import numpy as np
import scipy.sparse as sp


class FunctionBuffer:
    """Evaluates a CasADi function of dense vector inputs straight into NumPy arrays.

    Through CasADi's function buffer the outputs land in preallocated arrays
    (the nonzeros of each output in CasADi's column-major order); through DM
    objects, copying the values out of Python lists took as long as
    evaluating them (the `drogue` constraint Jacobian: 68 ms of 150).
    """

    def __init__(self, fn: ca.Function) -> None:
        self.fn = fn
        self.buffer, self.run = fn.buffer()
        self.args = [np.zeros(fn.nnz_in(i)) for i in range(fn.n_in())]
        for i, arg in enumerate(self.args):
            self.buffer.set_arg(i, memoryview(arg))
        self.out = [np.zeros(fn.nnz_out(i)) for i in range(fn.n_out())]
        for i, out in enumerate(self.out):
            self.buffer.set_res(i, memoryview(out))
        self._patterns = [(np.asarray(fn.sparsity_out(i).row(), dtype=np.int32),
                           np.asarray(fn.sparsity_out(i).colind(), dtype=np.int32),
                           fn.sparsity_out(i).shape) for i in range(fn.n_out())]

    def nonzeros(self, *args: np.ndarray | float) -> list[np.ndarray]:
        """The nonzeros of every output at `args` (fresh copies)."""
        for target, value in zip(self.args, args, strict=True):
            target[:] = np.ravel(value)
        self.run()
        return [out.copy() for out in self.out]

    def __call__(self, *args: np.ndarray | float) -> list[np.ndarray | sp.csc_matrix]:
        """Every output at `args`: a column as a dense vector whatever its pattern, a
        matrix as a SciPy CSC matrix on its fixed pattern."""
        return [self.shaped(i, values) for i, values in enumerate(self.nonzeros(*args))]

    def pattern(self, i: int) -> sp.csc_matrix:
        """Output `i`'s fixed pattern, every stored entry 1."""
        row, colind, shape = self._patterns[i]
        return sp.csc_matrix((np.ones(row.size), row, colind), shape=shape)

    def shaped(self, i: int, values: np.ndarray) -> np.ndarray | sp.csc_matrix:
        """Output `i` from its nonzeros."""
        row, colind, shape = self._patterns[i]
        if shape[1] == 1:
            vector = np.zeros(shape[0])
            vector[row] = values
            return vector
        return sp.csc_matrix((values, row, colind), shape=shape)
