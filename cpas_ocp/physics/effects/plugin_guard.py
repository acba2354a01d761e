"""A plug-in's own failure reported as the plug-in's: its file, the hook, what it raised.

A plug-in file is the user's Python code, run inside the model's composition,
the simulator and the diagnosis.  Whatever it raises from its own code (a
ZeroDivisionError, a KeyError, even KeyboardInterrupt or SystemExit) or
returns as NaN is a mistake in that file, not a defect of the tool and not a
request to stop: `guard_hooks` wraps each hook a plug-in class defines so that
such a failure becomes a `PluginError` naming the file and the hook, which the
command line reports as bad input (one line, exit 2).  The library's own
refusals, raised from its code that a hook calls (an effect listed where its
model cannot compose), stay what they are.

A real signal is not the plug-in's: the command line's handler raises
`interrupts.Interrupted`, which passes through.  Without that handler (a
notebook) Python's own SIGINT handler raises KeyboardInterrupt, and a
KeyboardInterrupt then passes through too, since it may be the user's Ctrl-C.
"""

from __future__ import annotations

import dataclasses
import functools
import signal
from collections.abc import Callable
from pathlib import Path
from typing import Any

import casadi as ca
import numpy as np

from cpas_ocp import interrupts
from cpas_ocp.errors import PluginError
from cpas_ocp.physics.effects.base import Effect

# The methods of `Effect` the library calls: the hooks of a model's composition, and
# `plausible`, which the result's claim reads.
HOOKS = ("parameters", "states", "captures", "event_timings", "state_guess", "forces",
         "observations", "constraints", "penalties", "process_priors", "null_values")
CALLED = (*HOOKS, "plausible")


def plugin_failure(exc: BaseException) -> bool:
    """Whether `exc`, raised out of a plug-in's code, is the plug-in's own failure (any
    exception, SystemExit, a KeyboardInterrupt no signal can have caused) rather than a
    signal to stop (`interrupts.Interrupted`, or a KeyboardInterrupt under Python's own
    SIGINT handler)."""
    if isinstance(exc, interrupts.Interrupted):
        return False
    if isinstance(exc, KeyboardInterrupt):
        return signal.getsignal(signal.SIGINT) is not signal.default_int_handler
    return True


def guard_hooks(cls: type[Effect], path: Path) -> None:
    """Wrap the hooks the plug-in class `cls` (from the file `path`) defines itself: see the
    module docstring.  Hooks it inherits from the library stay as they are."""
    for name in CALLED:
        hook = vars(cls).get(name)
        if callable(hook) and not hasattr(hook, "__plugin_file__"):
            setattr(cls, name, _guarded(hook, path, name))


def _guarded(hook: Callable[..., Any], path: Path, name: str) -> Callable[..., Any]:
    @functools.wraps(hook)
    def call(*args: Any, **kwargs: Any) -> Any:
        try:
            value = hook(*args, **kwargs)
        except PluginError:  # a plug-in's hook calling another's, already named
            raise
        except BaseException as exc:
            if not plugin_failure(exc) or _library_refusal(exc):
                raise
            raise PluginError(str(path), name, f"raised {type(exc).__name__}: {exc}") from None
        where = nan_in(value)
        if where is not None:
            raise PluginError(str(path), name, f"returned NaN{where}")
        return value

    call.__plugin_file__ = str(path)  # type: ignore[attr-defined]
    return call


_LIBRARY = Path(__file__).resolve().parents[2]  # the cpas_ocp package


def _library_refusal(exc: BaseException) -> bool:
    """Whether `exc` is the library refusing what a hook asked of it: a ValueError or
    KeyError raised in the library's own code (`ModelContext.scale_drag` when the effects
    are listed in an order that cannot compose).  Composing a model relies on them: the
    model file's order is named as wrong, and the diagnosis tries the candidate effect at
    another place in the list."""
    if not isinstance(exc, ValueError | KeyError):
        return False
    tb = exc.__traceback__
    while tb is not None and tb.tb_next is not None:
        tb = tb.tb_next
    return tb is not None and Path(tb.tb_frame.f_code.co_filename).resolve().is_relative_to(
        _LIBRARY)


def nan_in(value: Any, where: str = "", depth: int = 0) -> str | None:
    """Where in `value` (a hook's return: numbers, arrays, constant CasADi expressions, and
    lists, dicts and dataclasses of them) a NaN lies ("" for the value itself, " in
    [2].default" deeper), or None.  Infinities are fine: they are open bounds."""
    if depth > 6:
        return None
    if isinstance(value, bool | str | type(None)):
        return None
    if isinstance(value, float | np.floating | np.ndarray):
        nan = bool(np.isnan(value).any()) if np.asarray(value).dtype.kind in "fc" else False
        return (f" in {where}" if where else "") if nan else None
    if isinstance(value, ca.SX | ca.DM):
        if isinstance(value, ca.SX) and not value.is_constant():
            return None
        return nan_in(np.array(ca.DM(value), dtype=float), where, depth + 1)
    if isinstance(value, dict):
        items: Any = value.items()
    elif isinstance(value, list | tuple):
        items = enumerate(value)
    elif dataclasses.is_dataclass(value) and not isinstance(value, type):
        items = ((f.name, getattr(value, f.name)) for f in dataclasses.fields(value))
    else:
        return None
    for key, item in items:
        part = f".{key}" if isinstance(key, str) and not isinstance(value, dict) else f"[{key!r}]"
        found = nan_in(item, where + part, depth + 1)
        if found is not None:
            return found
    return None
