"""Errors the product reports to its users.

`InputError` is a user's mistake in a test folder or on the command line: it
carries the file, the field and what was expected, and the CLI prints it as one
line and exits with code 2; so is `PluginError`, a plug-in file whose own code
failed.  `SolverFailure` is an estimation that did not
converge: it carries Ipopt's status and iteration count, and is never shown as
a result.  `NotAResult` is a converged fit that may not claim to be one.
"""

from __future__ import annotations

from typing import Any


class InputError(ValueError):
    """A user's input does not meet the test-folder contract."""

    def __init__(self, file: str, field: str, expectation: str) -> None:
        self.file = file
        self.field = field
        # One line, whatever a library's message carried along (pandas ends some with \n).
        self.expectation = " ".join(expectation.split())
        super().__init__(f"{_printable(file)}: {_printable(field)}: {self.expectation}")


def _printable(text: str) -> str:
    """`text` with its line breaks and other control characters escaped (a file name or a
    JSON key may hold them): one line that still says exactly what was named."""
    return "".join(c if c.isprintable() else repr(c)[1:-1] for c in text)


class PluginError(Exception):
    """A plug-in file's own code failed: a hook raised, or returned NaN.  Bad input like an
    `InputError` (the CLI prints it as one line and exits with 2), but no ValueError, so
    that no code that catches those as a numerical failure takes it for one."""

    def __init__(self, file: str, hook: str, problem: str) -> None:
        self.file = file
        self.hook = hook
        self.problem = " ".join(problem.split())
        super().__init__(f"{_printable(file)}: hook {hook} {self.problem}")


class NotAResult(RuntimeError):
    """A converged fit the data press against bounds that were only guessed
    (`result_claim`): its report is written and says why, and the CLI exits with 4."""


class SolverFailure(RuntimeError):
    """Ipopt ended without a converged, feasible solution."""

    def __init__(self, status: str, iterations: int, worst_constraint: str = "",
                 chi_square: float | None = None, last_iterate: Any = None) -> None:
        self.status = status
        self.iterations = iterations
        self.worst_constraint = worst_constraint
        self.chi_square = chi_square  # at the last iterate: a diagnostic, not a result
        # The estimator's Fit at the last iterate, for a failure report (never a result).
        self.last_iterate = last_iterate
        detail = f"; worst constraint {worst_constraint}" if worst_constraint else ""
        if chi_square is not None:
            detail += f"; chi-square {chi_square:.6g} at the last iterate"
        super().__init__(
            f"solver failed: status {status} after {iterations} iterations{detail}"
        )

    def __reduce__(self) -> tuple[Any, ...]:
        """Rebuilt from its fields where it crosses to another process (a worker's
        failure reported by the process that waits for it); the last iterate stays
        behind."""
        return (type(self), (self.status, self.iterations, self.worst_constraint,
                             self.chi_square))
