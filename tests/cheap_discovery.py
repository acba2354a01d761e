"""A discovery chain that costs one fit and a diagnosis of one score test per step.

`cheap(patch)` (pytest's monkeypatch in process) or `python -m
tests.cheap_discovery ARGS` (the command line in a process of its own, for a
signal) makes `discover` diagnose with one score test and no confirming refits,
and take, in place of the effect a refit would confirm, the step's own fit again
under the name "gps_lag": a chain of `--max-steps` steps whose every fit is a
real one, so what is written, read back and resumed is real.
"""

from __future__ import annotations

import sys
from typing import Any

from cpas_ocp.discrepancy import discovery
from cpas_ocp.discrepancy.score_test import candidate_effects

REAL_DIAGNOSE = discovery.diagnose
_SPECS: list[Any] = []  # the spec of each fit diagnosed


def _diagnose(fit: Any, spec: Any, candidates: Any, confirm_top: int, alpha: float,
              progress: bool, exclude: frozenset[str], at_misfit: bool = True) -> Any:
    """The diagnosis with one score test (an IMU bias) and no refits."""
    _SPECS.append(spec)
    others = frozenset(candidate_effects(candidates)) - {"imu_bias"}
    return REAL_DIAGNOSE(fit, spec, candidates, 0, alpha, progress, exclude | others,
                         at_misfit=False)


def _next_step(diag: Any, progress: bool = False) -> discovery.DiscoveryStep:
    return discovery.DiscoveryStep("gps_lag", _SPECS[-1], diag.fit, "in place of a refit")


def cheap(patch: Any) -> None:
    """Make `discover` cheap, through `patch.setattr`."""
    patch.setattr(discovery, "diagnose", _diagnose)
    patch.setattr(discovery, "next_step", _next_step)


class _Setter:
    @staticmethod
    def setattr(target: Any, name: str, value: Any) -> None:
        setattr(target, name, value)


if __name__ == "__main__":
    from cpas_ocp.cli import main
    cheap(_Setter())
    sys.exit(main(sys.argv[1:]))
