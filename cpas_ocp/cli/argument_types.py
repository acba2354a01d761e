"""How the command line reads and checks its values: argparse types, each a one-line
error and exit code 2 for a value it refuses."""

from __future__ import annotations

import argparse
import math
from collections.abc import Callable


class OneLineParser(argparse.ArgumentParser):
    """argparse with its errors as one line (no usage block) and exit code 2."""

    def error(self, message: str) -> None:  # type: ignore[override]
        self.exit(2, "; ".join(f"error: {self.prog}: {message}".splitlines()) + "\n")


def ranged(kind: type, low: float, high: float = math.inf, low_open: bool = False,
            high_open: bool = False) -> Callable[[str], float]:
    """An argparse type: a finite number of `kind` within [low, high] (ends open as asked)."""
    what = (f"a{'n integer' if kind is int else ' number'} "
            f"{'>' if low_open else '>='} {low:g}"
            + (f" and {'<' if high_open else '<='} {high:g}" if high < math.inf else ""))

    def parse(text: str) -> float:
        try:
            value = kind(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"{what}; got {text!r}") from None
        if not (math.isfinite(value) and (value > low if low_open else value >= low)
                and (value < high if high_open else value <= high)):
            raise argparse.ArgumentTypeError(f"{what}; got {text!r}")
        return value

    return parse


SEED = ranged(int, 0)
COUNT = ranged(int, 1)


# The multiples of the wind process's sigmas (m/s, about 1) --wind-intensity may try: six
# decades about them, from still air to winds beyond any a parachute flies in, so that
# no multiple reaches the solver as a sigma of 1e-300 or 1e300 m/s.
WIND_FACTORS = (1e-3, 1e3)


def wind_factors(text: str) -> tuple[float, ...]:
    """An argparse type: comma-separated distinct multiples within WIND_FACTORS."""
    parse = ranged(float, *WIND_FACTORS)
    try:
        values = tuple(parse(part) for part in text.split(","))
    except argparse.ArgumentTypeError as exc:
        raise argparse.ArgumentTypeError(f"multiples of the wind process's sigmas, each {exc}"
                                         ) from None
    if len(set(values)) != len(values):
        raise argparse.ArgumentTypeError(f"distinct multiples; got {text!r}")
    return values


def pooled(text: str) -> list[tuple[str, str]]:
    """`type/stage+type/stage...` as (type, stage) pairs; argparse's error (exit 2) where
    malformed."""
    members = [tuple(m.split("/")) for m in text.split("+")]
    if len(members) < 2 or any(len(m) != 2 or not all(m) for m in members):
        raise argparse.ArgumentTypeError(f"two or more TYPE/STAGE joined by '+'; got {text!r}")
    return [(str(t), str(s)) for t, s in members]


def setting(text: str) -> tuple[str, str]:
    """`NAME=VALUE` as (name, value); argparse's error (exit 2) where malformed."""
    name, sep, value = text.partition("=")
    if not sep or not name or not value:
        raise argparse.ArgumentTypeError(f"a covariate and its value as NAME=VALUE; got "
                                         f"{text!r}")
    return name, value


def shared(text: str) -> tuple[str, str]:
    """`BASE` or `BASE:type|vehicle` as (base, over); argparse's error (exit 2) where
    malformed."""
    base, _, over = text.partition(":")
    over = over or "type"
    if not base or over not in ("type", "vehicle"):
        raise argparse.ArgumentTypeError(f"a parameter's base name, optionally followed by "
                                         f":type or :vehicle; got {text!r}")
    return base, over


def scheduler(text: str) -> str:
    """An argparse type: a Dask scheduler address (`scheduler_address`)."""
    from cpas_ocp.campaign.parallel import scheduler_address
    try:
        return scheduler_address(text)
    except ValueError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None
