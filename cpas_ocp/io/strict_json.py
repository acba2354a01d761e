"""JSON that every parser reads: a number that is not finite is written as null.

Python's `json` writes NaN and Infinity as bare words, which RFC 8259 does not
allow: a strict parser (JavaScript's `JSON.parse`, jq, Go, Rust's serde) fails
on the whole file.  A NaN in a result means "not defined here" (the excess a fit
at the noise cannot explain, a window's share with no excess), and null says
that in JSON.  NumPy scalars and arrays are written as numbers and lists.
"""

from __future__ import annotations

import json
import math
from collections.abc import Mapping
from typing import Any

import numpy as np


def plain(value: Any) -> Any:
    """`value` with NumPy scalars and arrays as Python numbers and lists, tuples as lists,
    mapping keys as strings, and every non-finite float as None."""
    if isinstance(value, Mapping):
        return {str(k): plain(v) for k, v in value.items()}
    if isinstance(value, list | tuple | set | frozenset | np.ndarray):
        return [plain(v) for v in value]
    if isinstance(value, bool | np.bool_):
        return bool(value)
    if isinstance(value, int | np.integer):
        return int(value)
    if isinstance(value, float | np.floating):
        return float(value) if math.isfinite(value) else None
    return value


def json_text(value: Any, indent: int | None = 2) -> str:
    """`value` as strict JSON text (see the module docstring), ending in a newline."""
    return json.dumps(plain(value), indent=indent, allow_nan=False) + "\n"
