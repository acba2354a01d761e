"""Every argument of every command says what it is: `cpas-ocp COMMAND --help` leaves none
without a help text."""

from __future__ import annotations

import argparse

from cpas_ocp.cli import arguments


def test_every_argument_has_a_help_text() -> None:
    parser = arguments.parser()
    commands = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
    missing = [f"{name} {action.dest}" for name, sub in commands.choices.items()
               for action in sub._actions
               if not isinstance(action, argparse._HelpAction) and not action.help]
    assert not missing, missing
    assert len(commands.choices) > 10  # the commands are there to be checked
