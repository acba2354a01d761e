"""The `cpas-ocp` command line.

    cpas-ocp problems                         list the built-in test phases
    cpas-ocp effects [--plugin FILE]          list the effects a model block may name
    cpas-ocp simulate NAME --out DIR --seed N write a synthetic test folder (+ truth.json)
    cpas-ocp reduce TEST_DIR --out DIR        offline reduction (Eqs. 2-3) and initial guess
    cpas-ocp reconstruct TEST_DIR --out DIR   reconstruct a test folder, write the report
    cpas-ocp whatif TEST_DIR --constrain EXPR re-solve under constraints: cost, test, push
    cpas-ocp diagnose TEST_DIR --out DIR      fit, find where it fails, rank the missing effects
    cpas-ocp discover TEST_DIR --out DIR      diagnose, add the confirmed effect, refit, again
    cpas-ocp compare TEST_DIR --model A --model B --out DIR
                                              fit two effect sets, test which the data prefer
    cpas-ocp campaign TESTS_DIR --out DIR     reconstruct many test folders, tabulate parameters
    cpas-ocp population CAMPAIGN --out DIR    each canopy type's population: mu, Omega, groupings
    cpas-ocp hierarchical TEST_DIR TEST_DIR ... --population CdS --out DIR
                                              tests and their populations in one NLP
    cpas-ocp dispersions CAMPAIGN --out DIR   Monte Carlo cases within the grown hulls
    cpas-ocp montecarlo TEST_DIR --cases DIR --out DIR
                                              fly the cases through a test's fit: peak loads
    cpas-ocp import LOG (--format NAME | --columns MAP.json) --card CARD --out DIR
                                              a rocketry flight log (altus, cats, or any CSV
                                              through a column map) into a test folder;
                                              import-altus LOG ... is import --format altus
    cpas-ocp flight NAME --out DIR            import a real flight's logs, reconstruct, compare
                                              with the nominal drag areas and the measured descent
    cpas-ocp rocketpy REPORT_DIR --test TEST_DIR --out DIR
                                              a reconstruction's canopies as RocketPy
                                              parachutes (a script and the numbers)
    cpas-ocp design PLAN --out DIR            predict each parameter's sigma under planned
                                              instrumentations, rank single sensor changes
    cpas-ocp demo [--out DIR]                 simulate the built-in Drogue test and reconstruct it

Exit codes: 0 success; 1 an internal error (one line, the traceback in a log
file); 2 bad input (one line naming file, field and expectation); 3 the solver
did not converge (status and iteration count; also a campaign none of whose
tests gave a result); 4 the fit converged but is not a result: the data press
parameters against bounds that are guesses, not physical limits, even after
the start windows were moved; or chi-square/dof beyond 10; or a process (the
air's motion) beyond 5 sigma of its prior; or a drag area the data do not
determine (the report is written and says why, see `result_claim`); 130 and
143 interrupted by SIGINT (Ctrl-C) or SIGTERM, with nothing written; 141 the
output's reader went away (`| head`).
"""

from __future__ import annotations

import os
import signal
import sys
import time
import traceback
from pathlib import Path

from cpas_ocp import interrupts
from cpas_ocp.errors import InputError, NotAResult, PluginError, SolverFailure


def main(argv: list[str] | None = None) -> int:
    """Run one command; every way it can end is an exit code and at most one line on stderr
    (the module's docstring lists them)."""
    # The handlers first: a command's imports take seconds (CasADi, matplotlib, scipy),
    # and a signal in that time is an interrupt like any other, not a traceback or a
    # silent death.  So this module imports nothing heavier than the handlers before
    # they are in place (`python -m cpas_ocp.cli` runs it before `main`), and the
    # command line's own modules are imported here, after them.
    previous = {sig: signal.getsignal(sig) for sig in interrupts.SIGNALS}
    interrupts.handle_signals()
    try:
        from cpas_ocp.cli import arguments
        from cpas_ocp.cli.commands import one_line
        from cpas_ocp.io.output_folder import check_output
        try:
            args = arguments.parser().parse_args(argv)
        except SystemExit as exc:  # --help (0), or a usage error already printed as one line
            return int(exc.code or 0)
        if isinstance(getattr(args, "out", None), Path):
            check_output(args.out)  # before the work, not after it
        return int(args.run(args) or 0)
    except (InputError, PluginError) as exc:
        one_line(f"error: {exc}")
        return 2
    except SolverFailure as exc:
        one_line(f"error: {exc}; no result written")
        return 3
    except NotAResult as exc:
        one_line(f"error: {exc}")
        return 4
    except interrupts.Interrupted as exc:
        print(f"interrupted ({exc}); nothing written", file=sys.stderr)
        return exc.exit_code
    except KeyboardInterrupt:
        print("interrupted (SIGINT); nothing written", file=sys.stderr)
        return 128 + signal.SIGINT
    except BrokenPipeError:  # the reader of the output went away (`| head`): stop quietly,
        # as a Unix tool does, and keep the interpreter's last flush from failing again
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return 128 + signal.SIGPIPE
    except SystemExit as exc:  # a plug-in or library code ending the process mid-command
        one_line(f"error: code run by the command called sys.exit({exc.code!r}) before it "
             f"finished (a plug-in?)")
        return 1
    except Exception as exc:  # the one boundary for errors
        return _internal_error(exc)
    finally:
        for sig, handler in previous.items():
            signal.signal(sig, handler)


def _internal_error(exc: Exception) -> int:
    """Report an error that is the tool's own, not the user's: one line on stderr, the
    traceback in a log file beside the compile cache; exit code 1."""
    from cpas_ocp.estimation.compiled import cache_folder
    line = f"{type(exc).__name__}: {exc}".splitlines()[0][:300]
    log = cache_folder() / "crash" / f"{time.strftime('%Y%m%d-%H%M%S')}-{os.getpid()}.log"
    try:
        log.parent.mkdir(parents=True, exist_ok=True)
        log.write_text("".join(traceback.format_exception(exc)))
        where = f"; the traceback is in {log}"
    except OSError:
        where = ""
    print(f"internal error: {line}{where}", file=sys.stderr)
    return 1
