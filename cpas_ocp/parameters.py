"""Named model parameters: what they mean, their unit, bounds and default.

Names follow the issue tracker and the reports: ``CdS[drogue1,stage1]``,
``t_start[drogue2,stage3]``, ``drag_scale[stage2]``, ``loadcell_scale[drogue1]``.
Values are SI.
"""

from __future__ import annotations

import re
from dataclasses import dataclass

_NAME = re.compile(r"^(?P<base>[A-Za-z_][A-Za-z0-9_]*)(\[(?P<index>[A-Za-z0-9_,]+)\])?$")


@dataclass(frozen=True)
class Parameter:
    """A scalar model parameter.

    `default` is the value used when the parameter is not estimated and no
    better value is known; `lower`/`upper` bound it when it is estimated.
    `scale` is its typical magnitude, used to scale the NLP.  A parameter that
    is `estimable` but not `free_by_default` (the forebody drag area, which
    comes from the aerodynamic database; fly-out angles, which the drag scale
    factors absorb) is estimated only when a model names it in ``free``.
    """

    name: str
    unit: str
    default: float
    lower: float
    upper: float
    estimable: bool = True
    description: str = ""
    scale: float = 1.0
    free_by_default: bool = True

    def on_bound(self, value: float) -> bool:
        """Whether `value` is one of the bounds: a hypothesis holding the parameter there
        admits alternatives on one side only (chi-bar-squared tests)."""
        return value <= self.lower or value >= self.upper

    def nearer_bound(self, value: float) -> str:
        """"lower" or "upper": the bound `value` lies nearer to (for a parameter a fit left on
        a bound)."""
        return "lower" if abs(value - self.lower) <= abs(value - self.upper) else "upper"


def param_name(base: str, *index: str) -> str:
    """`param_name("CdS", "drogue1", "stage1")` -> ``"CdS[drogue1,stage1]"``."""
    return f"{base}[{','.join(index)}]" if index else base


def split_name(name: str) -> tuple[str, tuple[str, ...]]:
    """Inverse of `param_name`: ``"CdS[drogue1,stage1]"`` -> ``("CdS", ("drogue1", "stage1"))``."""
    m = _NAME.match(name)
    if m is None:
        raise ValueError(f"not a parameter name: {name!r}")
    index = m.group("index")
    return m.group("base"), tuple(index.split(",")) if index else ()
