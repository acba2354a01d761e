"""The errors a command reports cross process boundaries intact: a worker's solver failure
reaches the process that waits for it with its status and iterations."""

from __future__ import annotations

import pickle

from cpas_ocp.errors import SolverFailure


def test_a_solver_failure_survives_pickling() -> None:
    failure = SolverFailure("Maximum_Iterations_Exceeded", 500, "index 3, violation 0.1",
                            2.5e4, last_iterate=object())
    again = pickle.loads(pickle.dumps(failure))
    assert isinstance(again, SolverFailure)
    assert (again.status, again.iterations, again.worst_constraint, again.chi_square) == (
        "Maximum_Iterations_Exceeded", 500, "index 3, violation 0.1", 2.5e4)
    assert str(again) == str(failure) and again.last_iterate is None
