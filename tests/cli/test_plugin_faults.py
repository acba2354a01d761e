"""A plug-in that fails in its own code is the plug-in's error: one line naming its file and
the hook, exit 2, nothing written, whatever it raises (KeyboardInterrupt and SystemExit
included) or if it returns NaN; a real signal while its code runs stays an interrupt.

- every hook the library calls, each kind of failure, called directly;
- drawn by Hypothesis: a model file naming the ``gust`` effect of a plug-in that fails at
  import or in a hook, the plug-in listed by the model file or given with --plugin
  (`reduce`, which composes the model);
- the hooks only a fit reaches, in `reconstruct`, `diagnose` and `discover`.
"""

from __future__ import annotations

import json
import shutil
import signal
import subprocess
import sys
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from cpas_ocp import interrupts
from cpas_ocp.cli import main
from cpas_ocp.errors import PluginError
from cpas_ocp.io.model_spec import BASELINE
from cpas_ocp.physics.effects.plugin_guard import CALLED
from cpas_ocp.physics.effects.registry import load_plugin
from tests.corruption import EXAMPLES, SEEDED, assert_contract
from tests.plugin_faults import FAULTS, PLACES, faulty_plugin

SETTINGS = settings(max_examples=EXAMPLES, deadline=None, derandomize=not SEEDED,
                    suppress_health_check=[HealthCheck.function_scoped_fixture])
# The hooks composing a model calls (what `reduce` reaches).
COMPOSING = ("parameters", "states", "captures", "event_timings", "forces", "observations",
             "constraints", "penalties")
EFFECTS = [BASELINE[0], "gust", *BASELINE[1:]]  # a change of drag: after canopy_inflation


@pytest.fixture
def handlers() -> Iterator[None]:
    """The command line's signal handlers, as `main` installs them."""
    previous = {s: signal.getsignal(s) for s in interrupts.SIGNALS}
    interrupts.handle_signals()
    yield
    for s, handler in previous.items():
        signal.signal(s, handler)


@pytest.fixture
def python_sigint() -> Iterator[None]:
    """Python's own SIGINT handler, as a notebook has it.  A process started in the
    background by a shell inherits SIGINT ignored, and Python then installs no handler."""
    previous = signal.signal(signal.SIGINT, signal.default_int_handler)
    yield
    signal.signal(signal.SIGINT, previous)


@pytest.fixture(scope="module")
def fbcp(problem_folder) -> Path:
    return problem_folder("fbcp", 1)


def _call(effect: object, hook: str, test: object) -> object:
    """Call `hook` of `effect` with arguments of the kinds the library passes (the failing
    hook fails before it reads them)."""
    if hook == "state_guess":
        return effect.state_guess(test, np.zeros(3), {})  # type: ignore[attr-defined]
    return getattr(effect, hook)(test)


@pytest.mark.parametrize("fault", FAULTS)
@pytest.mark.parametrize("hook", CALLED)
def test_every_hook_failing_is_a_plugin_error_naming_it(hook, fault, tmp_path,
                                                        handlers) -> None:
    path = faulty_plugin(tmp_path / "gust.py", hook, fault)
    effect = load_plugin(path)["gust"].build({}, str(path), "test")
    with pytest.raises(PluginError) as raised:
        _call(effect, hook, None)
    assert raised.value.file == str(path) and raised.value.hook == hook
    said = "returned NaN" if fault == "NaN" else f"raised {fault}"
    assert str(raised.value).startswith(f"{path}: hook {hook} {said}")


@pytest.mark.parametrize("fault", [f for f in FAULTS if f != "NaN"])
def test_a_plugin_failing_at_import_names_its_file(fault, tmp_path, handlers) -> None:
    from cpas_ocp.errors import InputError

    path = faulty_plugin(tmp_path / "gust.py", "import", fault)
    with pytest.raises(InputError, match=f"gust.py: \\(python\\): .* raised {fault}"):
        load_plugin(path)


def test_a_signal_is_not_the_plugins(tmp_path, python_sigint) -> None:
    """`Interrupted` (the handlers' signal) always passes through a hook; KeyboardInterrupt
    too where Python's own SIGINT handler may have raised it (a notebook's Ctrl-C)."""
    path = faulty_plugin(tmp_path / "gust.py", "parameters", "KeyboardInterrupt")
    effect = load_plugin(path)["gust"].build({}, str(path), "test")
    assert signal.getsignal(signal.SIGINT) is signal.default_int_handler
    with pytest.raises(KeyboardInterrupt):
        effect.parameters(None)
    (tmp_path / "stop.py").write_text(
        path.read_text().replace('__builtins__[FAULT]("planted fault")',
                                 "__import__('cpas_ocp.interrupts').interrupts"
                                 ".Interrupted(2)"))
    stop = load_plugin(tmp_path / "stop.py")["gust"].build({}, "stop.py", "test")
    with pytest.raises(interrupts.Interrupted):
        stop.parameters(None)


def _model(work: Path, through_model: bool) -> list[str]:
    """A model file naming ``gust`` (listing gust.py among its plug-ins, or not), and the
    options that give it: --model, and --plugin where the file does not list it."""
    block: dict = {"effects": EFFECTS}
    if through_model:
        block["plugins"] = ["gust.py"]
    (work / "model.json").write_text(json.dumps(block))
    return ["--model", str(work / "model.json"),
            *([] if through_model else ["--plugin", str(work / "gust.py")])]


def _case(tmp_path: Path, key: object) -> Path:
    work = tmp_path / f"case{abs(hash(key))}"
    shutil.rmtree(work, ignore_errors=True)
    work.mkdir()
    return work


@SETTINGS
@given(place=st.sampled_from([*PLACES, "nowhere"]), fault=st.sampled_from(FAULTS),
       through_model=st.booleans())
def test_a_model_naming_a_failing_plugin_is_valid_or_one_line_exit_2(
        place, fault, through_model, fbcp, tmp_path, capsys) -> None:
    """Where composing the model reaches the failure, it is exit 2 naming the plug-in file
    and the hook (at import: the file, and the model file that lists it)."""
    work = _case(tmp_path, (place, fault, through_model))
    faulty_plugin(work / "gust.py", place, fault)
    code = main(["reduce", str(fbcp), *_model(work, through_model), "--out",
                 str(work / "out")])
    err = capsys.readouterr().err.strip()
    assert_contract(code, err, "gust.py", work / "out")
    if place in COMPOSING:
        assert code == 2 and f"hook {place} " in err, err
    elif place == "import" and fault != "NaN":
        assert code == 2 and f"raised {fault}" in err, err
        assert ("model.json" in err) == through_model, err


@pytest.mark.parametrize("command, place, fault", [
    ("reconstruct", "state_guess", "KeyboardInterrupt"),
    ("reconstruct", "process_priors", "SystemExit"),
    ("diagnose", "forces", "ZeroDivisionError"),
    ("diagnose", "null_values", "NaN"),
    ("discover", "penalties", "NaN"),
])
@pytest.mark.slow
def test_a_fit_reaching_a_failing_hook_is_exit_2_naming_it(command, place, fault, fbcp,
                                                            tmp_path, capsys) -> None:
    """The hooks a fit or a score test calls: `reconstruct` with the plug-in in its model,
    `diagnose` and `discover` with it as a candidate (tried at every place in the list)."""
    faulty_plugin(tmp_path / "gust.py", place, fault)
    options = _model(tmp_path, True) if command == "reconstruct" else \
        ["--plugin", str(tmp_path / "gust.py")]
    code = main([command, str(fbcp), *options, "--out", str(tmp_path / "out")])
    err = capsys.readouterr().err.strip()
    assert code == 2, err
    said = "returned NaN" if fault == "NaN" else f"raised {fault}"
    assert len(err.splitlines()) == 1, err
    assert err.startswith(f"error: {tmp_path / 'gust.py'}: hook {place} {said}"), err
    assert not (tmp_path / "out").exists()


# A plug-in whose hook announces itself and then takes its time, so that the signal
# surely arrives while the plug-in's code runs.
SLOW_HOOK = '''
import sys, time
sys.stdout.write("in the hook\\n")
sys.stdout.flush()
time.sleep(30)
'''


@pytest.mark.parametrize("place", ["import", "parameters"])
def test_a_real_ctrl_c_inside_a_plugin_is_an_interrupt(place, fbcp, tmp_path) -> None:
    """A signal that arrives while a plug-in's code runs (at import, or in a hook) is the
    user's Ctrl-C, not the plug-in's failure: exit 130, not 2."""
    source = faulty_plugin(tmp_path / "gust.py", "nowhere", "NaN").read_text()
    slow = "\n".join("    " + line for line in SLOW_HOOK.strip().splitlines())
    if place == "import":
        source = source.replace('if PLACE == "import":\n', f"if True:\n{slow}\n")
    else:
        source = source.replace("    def parameters(self, test):\n",
                                "    def parameters(self, test):\n"
                                + "\n".join("    " + line for line in slow.splitlines())
                                + "\n")
    (tmp_path / "gust.py").write_text(source)
    proc = subprocess.Popen([sys.executable, "-m", "cpas_ocp.cli", "reduce", str(fbcp),
                             *_model(tmp_path, True), "--out", str(tmp_path / "out")],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    assert proc.stdout is not None
    assert proc.stdout.readline().startswith("in the hook")
    proc.send_signal(signal.SIGINT)
    _, err = proc.communicate(timeout=60)
    assert proc.returncode == 130, err
    assert err.strip() == "interrupted (SIGINT); nothing written", err
    assert not (tmp_path / "out").exists()
