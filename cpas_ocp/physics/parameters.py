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

    A bound is *physical* (`physical_lower`, `physical_upper`) where nature or
    the data set it: an added-mass factor or a lag cannot be negative, an
    over-inflation factor is at least 1, a start time lies within the phase.
    The others are guesses of where a value can plausibly lie (a fill
    constant's range, a start time's window around its observed event): a fit
    that the data press against such a bound is not yet a result
    (`result_claim`).
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
    physical_lower: bool = False
    physical_upper: bool = False
    # A knot of a stochastic process (`wind_process`): one of many, each acting over a
    # knot interval.  The Hessian leaves out the curvature of captured quantities in it.
    process_knot: bool = False

    def on_bound(self, value: float) -> bool:
        """Whether `value` is one of the bounds: a hypothesis holding the parameter there
        admits alternatives on one side only (chi-bar-squared tests)."""
        return value <= self.lower or value >= self.upper

    def held_side(self, value: float, tolerance: float = 1e-6) -> str | None:
        """"lower" or "upper" where `value` lies on that bound (within `tolerance` of the
        range, as a solver leaves it), else None."""
        span = (self.upper - self.lower) * tolerance
        if value <= self.lower + span:
            return "lower"
        if value >= self.upper - span:
            return "upper"
        return None

    def is_physical(self, side: str) -> bool:
        """Whether the `side` ("lower"/"upper") bound is a physical limit, not a guess."""
        return self.physical_lower if side == "lower" else self.physical_upper

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
