"""JSON files of every kind `io` reads: reading them strictly (no NaN or Infinity), and
validating them against the package's JSON Schemas (`data_schemas/`), each violation an
`InputError` naming the file, the field and the expectation.
"""

from __future__ import annotations

import json
import math
from functools import cache
from importlib import resources
from pathlib import Path
from typing import Any

import jsonschema
import referencing

from cpas_ocp.errors import InputError

SCHEMAS = ("manifest.schema.json", "series.schema.json", "model.schema.json",
           "flight_card.schema.json", "column_map.schema.json", "test_plan.schema.json",
           "problem.schema.json")


@cache


def _schema_registry() -> tuple[dict[str, dict[str, Any]], referencing.Registry]:
    folder = resources.files("cpas_ocp.schemas")
    schemas = {name: json.loads(folder.joinpath(name).read_text()) for name in SCHEMAS}
    registry = referencing.Registry().with_resources(
        (s["$id"], referencing.Resource.from_contents(s)) for s in schemas.values()
    )
    return schemas, registry


def _json_path(parts: Any, prefix: str = "") -> str:
    out = prefix
    for p in parts:
        out += f"[{p}]" if isinstance(p, int) else (f".{p}" if out else str(p))
    return out or "(top level)"


def validate_block(obj: Any, schema: str, file: str, prefix: str = "") -> None:
    """Validate `obj` against one of the shipped JSON Schemas; InputError on the first problem.

    `prefix` is the field path of `obj` inside its file (empty at top level).
    """
    schemas, registry = _schema_registry()
    validator = jsonschema.Draft202012Validator(schemas[schema], registry=registry)
    errors = list(validator.iter_errors(obj))
    # A field a subschema rejects is also "unevaluated" to the block that refuses unknown
    # fields: name the subschema's reason, and an unknown field only where it is the only one.
    error = jsonschema.exceptions.best_match(
        [e for e in errors if e.validator != "unevaluatedProperties"] or errors)
    if error is not None:
        # Descend to the most specific cause so the message names the leaf field.
        while error.context:
            error = jsonschema.exceptions.best_match(error.context)
        path = list(error.absolute_path)
        if error.validator == "required" and isinstance(error.instance, dict):
            # A missing field is named itself, not its parent.
            path.append(next(k for k in error.validator_value if k not in error.instance))
            raise InputError(file, _json_path(path, prefix), "a required field, missing")
        raise InputError(file, _json_path(path, prefix), error.message)


# Largest magnitude a number in a manifest may have.  No quantity of a parachute test comes


# near it in any accepted unit (a 20,000 lb vehicle is 9e3 kg, sea-level pressure 1e5 Pa),


# and squares of larger ones overflow: a vehicle mass of 1e300 passed the schema and ended


# as an internal error in the covariance.


MAX_MAGNITUDE = 1e9


def check_magnitudes(node: Any, file: str, path: str = "") -> None:
    """InputError naming the first number in `node` (a manifest or part of one) that is not
    finite or exceeds MAX_MAGNITUDE."""
    if isinstance(node, bool):
        return
    if isinstance(node, int | float):
        if not (math.isfinite(node) and abs(node) <= MAX_MAGNITUDE):
            raise InputError(file, path or "(value)", f"a finite number of magnitude at most "
                             f"{MAX_MAGNITUDE:g}; got {node!r}")
        return
    items = node.items() if isinstance(node, dict) else \
        enumerate(node) if isinstance(node, list) else ()
    for key, child in items:
        where = f"{path}[{key}]" if isinstance(key, int) else f"{path}.{key}" if path else key
        check_magnitudes(child, file, where)


def read_text(path: Path, missing: str) -> str:
    """The text of `path` as UTF-8 (a leading byte-order mark dropped); InputError with
    `missing` if absent, and naming the byte where it is not UTF-8 text."""
    if not path.is_file():
        raise InputError(str(path), "(file)", missing)
    try:
        return path.read_text(encoding="utf-8-sig")
    except UnicodeDecodeError as exc:
        raise InputError(str(path), f"byte {exc.start}",
                         "UTF-8 text (this file is binary or in another encoding)") from None


def _no_constant(name: str) -> float:
    raise ValueError(f"{name} is not a JSON number; write a finite number")


def read_json(path: Path, missing: str) -> Any:
    """The JSON content of `path`; InputError with `missing` if absent, the line if invalid.

    JSON has no NaN or Infinity: Python's reader accepts those literals, and a
    NaN that reached the model would surface as a solver failure minutes
    later, so they are refused here."""
    text = read_text(path, missing)
    try:
        return json.loads(text, parse_constant=_no_constant)
    except json.JSONDecodeError as exc:
        raise InputError(str(path), f"line {exc.lineno}", f"valid JSON ({exc.msg})") from None
    except ValueError as exc:  # a NaN or Infinity literal
        raise InputError(str(path), "(value)", str(exc)) from None
