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
    cpas-ocp dispersions CAMPAIGN --out DIR   Monte Carlo cases within the grown hulls
    cpas-ocp montecarlo TEST_DIR --cases DIR --out DIR
                                              fly the cases through a test's fit: peak loads
    cpas-ocp import LOG (--format NAME | --columns MAP.json) --card CARD --out DIR
                                              a rocketry flight log (altus, cats, or any CSV
                                              through a column map) into a test folder;
                                              import-altus LOG ... is import --format altus
    cpas-ocp flight NAME --out DIR            import a real flight's logs, reconstruct, compare
                                              with the nominal drag areas and the measured descent
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

import argparse
import math
import os
import shutil
import signal
import sys
import time
import traceback
from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING, Any

from cpas_ocp import interrupts
from cpas_ocp.errors import InputError, NotAResult, PluginError, SolverFailure
from cpas_ocp.io.output_folder import check_output

if TYPE_CHECKING:
    from cpas_ocp.api import Reconstruction
    from cpas_ocp.estimation.estimator import Estimator, Fit
    from cpas_ocp.estimation.uncertainty import Covariance
    from cpas_ocp.io.flight_card import FlightCard
    from cpas_ocp.io.flight_record import FlightRecord
    from cpas_ocp.io.model_spec import ModelSpec
    from cpas_ocp.io.recorder_clocks import RecorderEstimates
    from cpas_ocp.physics.effects.registry import EffectType
    from cpas_ocp.physics.flight_test import FlightTest
    from cpas_ocp.reports.display_units import DisplayUnits


def main(argv: list[str] | None = None) -> int:
    """Run one command; every way it can end is an exit code and at most one line on stderr
    (the module's docstring lists them)."""
    # The handlers first: building the parser imports CasADi (seconds), and a signal in
    # that time is an interrupt like any other, not a traceback or a silent death.
    previous = {sig: signal.getsignal(sig) for sig in interrupts.SIGNALS}
    interrupts.handle_signals()
    try:
        try:
            args = _parser().parse_args(argv)
        except SystemExit as exc:  # --help (0), or a usage error already printed as one line
            return int(exc.code or 0)
        if isinstance(getattr(args, "out", None), Path):
            check_output(args.out)  # before the work, not after it
        return int(args.run(args) or 0)
    except (InputError, PluginError) as exc:
        _say(f"error: {exc}")
        return 2
    except SolverFailure as exc:
        _say(f"error: {exc}; no result written")
        return 3
    except NotAResult as exc:
        _say(f"error: {exc}")
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
        _say(f"error: code run by the command called sys.exit({exc.code!r}) before it "
             f"finished (a plug-in?)")
        return 1
    except Exception as exc:  # the one boundary for errors
        return _internal_error(exc)
    finally:
        for sig, handler in previous.items():
            signal.signal(sig, handler)


def _say(message: str) -> None:
    """Print `message` on stderr as the one line the exit codes promise: a message that
    spans lines (a library's, a solver's) keeps them all, joined by "; "."""
    print("; ".join(line.strip() for line in message.splitlines() if line.strip()),
          file=sys.stderr)


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


class _Parser(argparse.ArgumentParser):
    """argparse with its errors as one line (no usage block) and exit code 2."""

    def error(self, message: str) -> None:  # type: ignore[override]
        self.exit(2, "; ".join(f"error: {self.prog}: {message}".splitlines()) + "\n")


def _ranged(kind: type, low: float, high: float = math.inf, low_open: bool = False,
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


SEED = _ranged(int, 0)
COUNT = _ranged(int, 1)
# The test table's columns a population's mean may depend on (population_study).
COVARIATES = ("type", "forebody", "cluster_size", "line_length", "line_length_ratio")


def _parser() -> argparse.ArgumentParser:
    p = _Parser(prog="cpas-ocp", description=__doc__.split("\n\n")[0])
    sub = p.add_subparsers(required=True, metavar="COMMAND")

    s = sub.add_parser("problems", help="list the built-in test phases")
    s.set_defaults(run=_problems)

    s = sub.add_parser("effects", help="list the effects a model block may name, with options")
    _plugin_option(s, "also list the effects a plug-in file defines (repeatable)")
    s.set_defaults(run=_effects)

    s = sub.add_parser("simulate", help="simulate a built-in problem into a test folder")
    s.add_argument("name")
    s.add_argument("--out", required=True, type=Path)
    s.add_argument("--seed", required=True, type=SEED)
    s.set_defaults(run=_simulate)

    s = sub.add_parser("reduce", help="offline drag-area reduction and the initial guess")
    s.add_argument("test_dir", type=Path)
    s.add_argument("--out", required=True, type=Path)
    _model_option(s)
    _units_option(s)
    s.set_defaults(run=_reduce)

    s = sub.add_parser("reconstruct", help="reconstruct a test folder")
    s.add_argument("test_dir", type=Path)
    s.add_argument("--out", required=True, type=Path)
    s.add_argument("--profile", action="append", default=[], metavar="NAME",
                   help="also profile the likelihood of this free parameter (repeatable)")
    s.add_argument("--profile-span", type=_ranged(float, 0.0, low_open=True), default=3.0,
                   metavar="SIGMAS",
                   help="profile over the estimate -+ this many sigma (default 3)")
    s.add_argument("--profile-points", type=_ranged(int, 2), default=13, metavar="N",
                   help="values per profile (default 13)")
    _model_option(s)
    _solver_options(s)
    _units_option(s)
    s.set_defaults(run=_reconstruct)

    s = sub.add_parser("whatif", help="re-solve under constraints and report what they cost")
    s.add_argument("test_dir", type=Path)
    s.add_argument("--constrain", action="append", required=True, metavar="EXPR",
                   help="NAME == VALUE [UNIT], NAME <= VALUE or NAME >= VALUE on a free "
                        "parameter, e.g. 'Ck[drogue1,stage1] == 1', or a peak limit, e.g. "
                        "'peak_load[drogue1] <= 30000 lbf' (repeatable)")
    _model_option(s)
    _solver_options(s)
    s.set_defaults(run=_whatif)

    s = sub.add_parser("diagnose", help="fit, then find where the model fails and which "
                                        "effect is missing")
    _diagnosis_options(s)
    _units_option(s)
    s.set_defaults(run=_diagnose)

    s = sub.add_parser("discover", help="diagnose, add the confirmed effect, refit, and "
                                        "again, until the residuals are noise or nothing "
                                        "left is significant")
    _diagnosis_options(s, resumable=True)
    s.add_argument("--max-steps", type=_ranged(int, 1), default=4, metavar="K",
                   help="add at most K effects (default 4)")
    s.add_argument("--resume", type=Path, default=None, metavar="DIR",
                   help="go on from the finished steps of a discovery folder (one that was "
                        "interrupted or killed), with the test folder and options it was "
                        "started with; it is written again in place")
    _units_option(s)
    s.set_defaults(run=_discover)

    s = sub.add_parser("compare", help="fit two effect sets and test which the data prefer")
    s.add_argument("test_dir", type=Path)
    s.add_argument("--model", type=str, action="append", required=True, metavar="FILE",
                   help="a JSON model block, or 'manifest' for the test's own model; "
                        "give it twice")
    s.add_argument("--out", required=True, type=Path)
    _plugin_option(s, "a Python file whose effects the model files may name (repeatable)")
    _model_option(s, model=False)
    _solver_options(s)
    _units_option(s)
    s.set_defaults(run=_compare)

    s = sub.add_parser("campaign", help="reconstruct every test folder under a folder, in "
                                        "parallel, and write the parameter table")
    s.add_argument("tests_dir", type=Path)
    s.add_argument("--out", required=True, type=Path)
    _parallel_options(s)
    s.set_defaults(run=_campaign)

    s = sub.add_parser("population", help="each canopy type and stage's population from a "
                                          "campaign: mu, the between-test Omega, each "
                                          "test's shrunken estimate, grouping tests")
    s.add_argument("campaign", type=Path, help="a campaign folder (cpas-ocp campaign)")
    s.add_argument("--out", required=True, type=Path)
    s.add_argument("--parameter", action="append", dest="parameters", default=None,
                   help="a canopy parameter to include (repeatable; default: CdS, Ck, n_p, "
                        "n, expopen, t_k where determined)")
    s.add_argument("--covariate", action="append", dest="covariates", default=[],
                   choices=COVARIATES, help="a column of the test table the mean depends on "
                                            "(repeatable)")
    s.add_argument("--pool", action="append", default=[], type=_pooled,
                   help="canopy types and stages fitted as one population, e.g. "
                        "fbcp/stage1+drogue/stage1 (repeatable)")
    s.add_argument("--diagonal", action="store_true",
                   help="no between-test correlations (a diagonal Omega)")
    s.add_argument("--alpha", type=float, default=0.05,
                   help="the grouping tests' level (0.05)")
    s.add_argument("--seed", type=SEED, default=0,
                   help="the seed of the grouping tests' bootstrap (0)")
    s.set_defaults(run=_population)

    s = sub.add_parser("joint", help="several tests that share hardware reconstructed in one "
                                     "NLP, the shared parameters held equal across them")
    s.add_argument("tests", nargs="+", type=Path, help="two or more test folders")
    s.add_argument("--share", action="append", required=True, type=_shared,
                   help="a parameter shared across the tests: its base name, one per canopy "
                        "type and stage (CdS), or BASE:vehicle, one per test vehicle "
                        "(prf:vehicle) (repeatable)")
    s.add_argument("--out", required=True, type=Path)
    s.set_defaults(run=_joint)

    s = sub.add_parser("dispersions", help="Monte Carlo cases per canopy type and stage from "
                                           "a campaign's parameter table")
    s.add_argument("campaign", type=Path, help="a campaign folder or its parameters table")
    s.add_argument("--out", required=True, type=Path)
    s.add_argument("--cases", type=COUNT, default=200_000, help="cases per canopy (200,000)")
    s.add_argument("--seed", type=SEED, required=True)
    s.add_argument("--population", action="store_true",
                   help="draw each canopy type and stage from its fitted population (mu, "
                        "Omega: each test's uncertainty taken out of the spread) instead of "
                        "from its point estimates; still within the caps and the grown hull")
    s.set_defaults(run=_dispersions)

    s = sub.add_parser("montecarlo", help="reconstruct a test folder and fly the dispersed "
                                          "cases of its canopy stages: peak-load distributions")
    s.add_argument("test_dir", type=Path)
    s.add_argument("--cases", required=True, type=Path, metavar="DISPERSIONS_DIR",
                   help="a cpas-ocp dispersions folder (cases_<type>_<stage>.parquet)")
    s.add_argument("--out", required=True, type=Path)
    s.add_argument("--limit", type=COUNT, default=None, metavar="N",
                   help="fly the first N cases of each file (default: all)")
    _parallel_options(s)
    s.set_defaults(run=_montecarlo)

    s = sub.add_parser("import", help="a rocketry flight log into a test folder: Altus "
                                      "Metrum, CATS, or any CSV through a column map")
    s.add_argument("log", type=Path, help="the log file (for cats: the export folder)")
    source = s.add_mutually_exclusive_group()
    source.add_argument("--format", metavar="NAME", help="a built-in format: altus, cats "
                                                          "(default: the card's data.format)")
    source.add_argument("--columns", type=Path, metavar="MAP.json",
                        help="a column map: which column holds what, in which unit (default: "
                             "the card's data.columns)")
    _card_options(s)
    s.set_defaults(run=_import)

    s = sub.add_parser("import-altus", help="an Altus Metrum (TeleMega, TeleMetrum) CSV log "
                                            "into a test folder (import --format altus)")
    s.add_argument("log", type=Path)
    _card_options(s)
    s.set_defaults(run=_import, format="altus", columns=None)

    s = sub.add_parser("flight", help="import a real flight's logs, reconstruct each, and "
                                      "compare with the nominal drag areas and the descent")
    s.add_argument("card", metavar="CARD", help="a built-in flight card (prometheus) or a file")
    s.add_argument("--out", required=True, type=Path)
    s.add_argument("--data", type=Path, default=None,
                   help="folder holding the card's logs (default: the card's data.folder, "
                        "beside a card file, or under ../shared/data for a built-in card)")
    s.add_argument("--log", action="append", default=[], metavar="FILE",
                   help="reconstruct only this log of the card (repeatable)")
    s.add_argument("--format", default=None, metavar="NAME",
                   help="the logs' built-in format: altus, cats (default: the card's "
                        "data.format, else altus)")
    s.add_argument("--columns", type=Path, default=None, metavar="MAP.json",
                   help="a column map for the logs (default: the card's data.columns)")
    _solver_options(s)
    s.set_defaults(run=_flight)

    s = sub.add_parser("design", help="predict the sigma of every parameter under planned "
                       "instrumentations and rank single sensor changes (a plan file)")
    s.add_argument("plan", type=Path)
    s.add_argument("--out", required=True, type=Path)
    s.set_defaults(run=_design)

    s = sub.add_parser("demo", help="simulate the built-in Drogue test and reconstruct it")
    s.add_argument("--out", type=Path, default=Path("cpas-demo"))
    s.add_argument("--seed", type=SEED, default=1)
    _solver_options(s)
    _units_option(s)
    s.set_defaults(run=_demo)
    return p


def _units_option(s: argparse.ArgumentParser) -> None:
    s.add_argument("--units", choices=("si", "us"), default=None,
                   help="draw figures and tables in SI or US customary units (default: "
                        "the manifest's; result.json is always SI)")


def _units(test: FlightTest, args: argparse.Namespace) -> DisplayUnits:
    """The display units of --units, else those the test's manifest is written in."""
    from cpas_ocp.reports.display_units import display_units
    return display_units(test, getattr(args, "units", None))


def _plugin_option(s: argparse.ArgumentParser, text: str) -> None:
    s.add_argument("--plugin", type=Path, action="append", default=[], metavar="FILE",
                   help=text)


def _plugins(args: argparse.Namespace) -> dict[str, EffectType]:
    """The effects of the plug-in files given with --plugin, by name."""
    from cpas_ocp.physics.effects.registry import load_plugins
    return load_plugins(args.plugin)


def _parallel_options(s: argparse.ArgumentParser) -> None:
    s.add_argument("--workers", type=COUNT, default=2, help="local processes (default 2)")
    s.add_argument("--scheduler", type=_scheduler, default=None, metavar="ADDRESS",
                   help="run on this Dask scheduler (e.g. tcp://host:8786) instead")


def _scheduler(text: str) -> str:
    """An argparse type: a Dask scheduler address (`scheduler_address`)."""
    from cpas_ocp.campaign.parallel import scheduler_address
    try:
        return scheduler_address(text)
    except ValueError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None


def _model_option(s: argparse.ArgumentParser, model: bool = True, plugin: bool = True
                  ) -> None:
    """--model FILE (where `model`), with --plugin FILE for the effects it names (where
    `plugin`: a command that tests plug-ins has its own), and --allow-external-plugins."""
    if model:
        s.add_argument("--model", type=Path, default=None, metavar="FILE",
                       help="a JSON model block (effects, plugins, fix, free) used instead "
                            "of the manifest's")
        if plugin:
            _plugin_option(s, "a Python file whose effects the --model file may name "
                              "(repeatable)")
    s.add_argument("--allow-external-plugins", action="store_true",
                   help="run plug-ins a manifest or model file names from outside its own "
                        "folder (plug-ins are Python code run with your rights)")


def _spec(test: FlightTest, args: argparse.Namespace,
          plugins: dict[str, EffectType] | None = None) -> ModelSpec:
    """The model of --model, else the manifest's, plug-ins contained as asked; `plugins`:
    the effects of --plugin already loaded (else they are loaded here)."""
    from cpas_ocp.io.model_spec import load_model_file, spec_of_test
    allow = getattr(args, "allow_external_plugins", False)
    model = getattr(args, "model", None)
    if plugins is None and getattr(args, "plugin", None):
        plugins = _plugins(args)
    return load_model_file(model, plugins, allow) if model is not None else \
        spec_of_test(test, allow)


def _solver_options(s: argparse.ArgumentParser) -> None:
    from cpas_ocp.estimation.estimator import MIN_GRID_STEP_S
    from cpas_ocp.estimation.uncertainty import HESSIANS
    s.add_argument("--grid-step", type=_ranged(float, MIN_GRID_STEP_S), default=None,
                   help="force a uniform shooting interval [s] (default: chosen from the "
                        "dynamics, the fastest sensor's sampling interval where the motion "
                        "changes fast)")
    s.add_argument("--verbose", action="store_true", help="show Ipopt's iteration log")
    s.add_argument("--max-iter", type=COUNT, default=500, metavar="N",
                   help="stop the solver after N iterations (default 500); a run stopped "
                        "there writes a NOT CONVERGED failure report, not a result")
    s.add_argument("--hessian", choices=HESSIANS, default="gauss-newton",
                   help="curvature the covariance inverts (exact: the Lagrangian's, slower)")
    s.add_argument("--rescale-sigmas", action="store_true",
                   help="the sensor sigmas are not trusted: scale the covariance and the "
                        "what-if test by chi^2/dof")
    s.add_argument("--wind-intensity", type=_factors, default=None, metavar="F,F,...",
                   help="choose the model's wind_process intensity by the marginal "
                        "likelihood among these multiples of its sigmas (e.g. "
                        "0.25,0.5,1,2,4): one fit each")


# The multiples of the wind process's sigmas (m/s, about 1) --wind-intensity may try: six
# decades about them, from still air to winds beyond any a parachute flies in, so that
# no multiple reaches the solver as a sigma of 1e-300 or 1e300 m/s.
WIND_FACTORS = (1e-3, 1e3)


def _factors(text: str) -> tuple[float, ...]:
    """An argparse type: comma-separated distinct multiples within WIND_FACTORS."""
    parse = _ranged(float, *WIND_FACTORS)
    try:
        values = tuple(parse(part) for part in text.split(","))
    except argparse.ArgumentTypeError as exc:
        raise argparse.ArgumentTypeError(f"multiples of the wind process's sigmas, each {exc}"
                                         ) from None
    if len(set(values)) != len(values):
        raise argparse.ArgumentTypeError(f"distinct multiples; got {text!r}")
    return values


def _problems(args: argparse.Namespace) -> int:
    from cpas_ocp.io.problems import load_problem, problem_names
    for name in problem_names():
        prob = load_problem(name)
        print(f"{name:12s} {prob.title}\n{'':12s} {prob.label}")
    return 0


def _effects(args: argparse.Namespace) -> int:
    from cpas_ocp.physics.effects.registry import BASELINE, BUILTIN
    entries = {**BUILTIN, **_plugins(args)}
    for name, entry in entries.items():
        mark = "*" if name in BASELINE else " "
        options = ", ".join(entry.options()) or "-"
        print(f"{mark} {name:17s} {entry.summary}\n  {'':17s} options: {options}"
              + (f"; from {entry.source}" if entry.source != "cpas_ocp" else ""))
    print("\n* in the baseline set (used when a manifest has no model block)")
    return 0


def _simulate(args: argparse.Namespace) -> int:
    from cpas_ocp.estimation.simulate import simulate_problem
    from cpas_ocp.io.problems import load_problem
    test = simulate_problem(load_problem(args.name), args.out, args.seed)
    print(f"wrote test folder {args.out} ({test.name}) with truth.json")
    return 0


def _design(args: argparse.Namespace) -> int:
    from cpas_ocp.api import design
    from cpas_ocp.reports.design_report import design_text
    found = design(args.plan, args.out)
    print(design_text(found))
    print(f"\ndesign written to {args.out} (design.html, sigma.csv, changes.csv, failures.csv,"
          f" design.json)")
    return 0


def _reduce(args: argparse.Namespace) -> int:
    from cpas_ocp.io.flight_test import load_test
    from cpas_ocp.reports.reduction_report import guess_table, write_reduction
    test = load_test(args.test_dir)
    units = _units(test, args)
    out, model, guess = write_reduction(test, args.out, _spec(test, args), units)
    print(guess_table(model, guess, units))
    print(f"\nreduction written to {out} (reduction.csv, initial_guess.json, reduction.png)")
    return 0


def _reconstruct(args: argparse.Namespace) -> int:
    from cpas_ocp.io.flight_test import load_test
    test = load_test(args.test_dir)
    _run_reconstruction(test, args, _spec(test, args))
    return 0


def _whatif(args: argparse.Namespace) -> int:
    from cpas_ocp.inference.whatif import parameter_bounds, parse_constraint, whatif_text
    from cpas_ocp.io.flight_test import load_test
    test = load_test(args.test_dir)
    est = _estimator(test, args, _spec(test, args))
    constraints = [parse_constraint(text, est) for text in args.constrain]
    parameter_bounds(constraints, est)  # contradictions are refused before the fits
    print(f"solving without the constraints: {est.size_text()} ...", flush=True)
    rec = _reconstruction(est, args)
    if not rec.is_result:
        raise NotAResult("the fit without the constraints is not a result, so a what-if from "
                         "it means nothing: " + "; ".join(rec.problems))
    print("solving with them ...", flush=True)
    print(whatif_text(rec.what_if(*args.constrain, progress=not args.verbose)))
    return 0


def _diagnose(args: argparse.Namespace) -> int:
    from cpas_ocp.io.flight_test import load_test
    test = load_test(args.test_dir)
    plugins = _plugins(args)
    est = _estimator(test, args, _spec(test, args, plugins))
    print(f"solving: {est.size_text()} ...", flush=True)
    rec = _reconstruction(est, args, plugins)
    print("testing the effects the model does not use ...", flush=True)
    out = Path(args.out)
    diag = rec.diagnose(out, args.confirm, args.alpha, not args.verbose, _units(test, args))
    print()
    print(diag.text())
    print(f"\ndiagnosis written to {out} (diagnosis.md, diagnosis.json, windows.csv, figures)")
    print(f"interactive report: {out / 'diagnosis.html'}")
    return 0


def _diagnosis_options(s: argparse.ArgumentParser, resumable: bool = False) -> None:
    """The test folder, output folder, plug-ins, confirmation, level, model and solver
    options of a command that diagnoses (`diagnose`, `discover`; with `resumable`, the
    test and output folders may come from --resume instead)."""
    s.add_argument("test_dir", type=Path, nargs="?" if resumable else None)
    s.add_argument("--out", required=not resumable, type=Path)
    _plugin_option(s, "also test the effects this Python file defines (repeatable)")
    s.add_argument("--confirm", type=_ranged(int, 0), default=3, metavar="N",
                   help="refit the N leading significant effects to confirm them, and more "
                        "where the best confirmed is implausible (default 3)")
    s.add_argument("--alpha", type=_ranged(float, 0.0, 1.0, low_open=True, high_open=True),
                   default=0.01,
                   help="family-wise significance level (default 0.01)")
    _model_option(s, plugin=False)
    _solver_options(s)


def _discover(args: argparse.Namespace) -> int:
    from cpas_ocp.api import discover_kept, discovery_context, resume_discovery
    from cpas_ocp.discrepancy.discovery import Discovery, DiscoveryStep, InterruptedDiscovery
    from cpas_ocp.io.flight_test import load_test

    def said(step: DiscoveryStep) -> None:
        print(f"step {step.label} ({step.found_s + step.diagnosed_s:.0f} s): chi-square "
              f"{step.fit.chi_square:.1f} (chi2/dof {step.fit.chi_square / step.fit.dof:.3f}); "
              f"{step.diagnosis.verdict().splitlines()[0] if step.diagnosis else ''}",
              flush=True)

    def read(chain: Discovery) -> None:
        print(f"  {len(chain.steps)} step(s) read; going on from step {len(chain.steps) - 1}"
              "\ndiagnosing, step by step ...", flush=True)

    try:
        if args.resume is not None:
            print(f"reading the finished steps in {args.resume} ...", flush=True)
            out = args.resume
            found = resume_discovery(out, progress=not args.verbose, on_step=said,
                                     on_read=read)
        else:
            if args.test_dir is None or args.out is None:
                raise InputError("(command line)", "test_dir, --out",
                                 "a test folder and --out DIR, or --resume DIR")
            out = args.out
            test = load_test(args.test_dir)
            plugins = _plugins(args)
            est = _estimator(test, args, _spec(test, args, plugins))
            print(f"solving: {est.size_text()} ...", flush=True)
            rec = _reconstruction(est, args, plugins)
            context = discovery_context(args.test_dir, args.plugin, args.max_steps,
                                        args.alpha, args.confirm, args.units)
            # A first fit the data press against guessed bounds is said in the report too,
            # and kept with the steps so that a resumed run says it as well.
            if not rec.is_result:
                context["first_fit"] = f"the first fit is not a result: {rec.problems[0]}"
            print("diagnosing, step by step ...", flush=True)
            found = discover_kept(out, rec.fit, rec.spec, plugins, context, _units(test, args),
                                  estimator=rec.estimator, progress=not args.verbose,
                                  on_step=said)
    except InterruptedDiscovery as exc:
        _say(f"interrupted ({exc}); the {len(exc.partial.steps)} finished step(s) written "
             f"to {out} (discovery.md, discovery.json, step_K.json); go on with "
             f"cpas-ocp discover --resume {out}")
        return exc.exit_code
    print()
    print(found.text())
    print(f"\ndiscovery written to {out} (discovery.md, discovery.html, discovery.json, "
          "discovery.png, step_K.json)")
    return 0


def _compare(args: argparse.Namespace) -> int:
    from cpas_ocp.io.flight_test import load_test
    from cpas_ocp.io.model_spec import load_model_file, spec_of_test
    if len(args.model) != 2:
        raise InputError("(command line)", "--model",
                         f"exactly two models (--model A --model B); got {len(args.model)}")
    test = load_test(args.test_dir)
    plugins = _plugins(args)
    allow = args.allow_external_plugins
    specs = [spec_of_test(test, allow) if m == "manifest"
             else load_model_file(m, plugins, allow) for m in args.model]
    labels = tuple(Path(m).stem if m != "manifest" else "manifest" for m in args.model)
    if labels[0] == labels[1]:
        labels = (f"A: {labels[0]}", f"B: {labels[1]}")
    est = _estimator(test, args, specs[0])
    print(f"solving {labels[0]}: {est.size_text()} ...", flush=True)
    rec = _reconstruction(est, args, plugins)
    print(f"solving {labels[1]} from it ...", flush=True)
    out = Path(args.out)
    comparison = rec.compare(specs[1], out, labels, not args.verbose, _units(test, args))
    print()
    print(comparison.text())
    print(f"\ncomparison written to {out} (comparison.md, comparison.json, windows.csv, "
          "figures)")
    print(f"interactive report: {out / 'comparison.html'}")
    return 0


def _campaign(args: argparse.Namespace) -> int:
    from cpas_ocp.api import campaign
    done = campaign(args.tests_dir, args.out, args.workers, args.scheduler, progress=True)
    print(done.summary())
    print(f"\ncampaign written to {done.out} (parameters.csv, parameters.parquet, stages.csv, "
          "failures.csv, ratios_*.csv, campaign.md)")
    if done.failed == len(done.outcomes):  # no result at all: its reasons in failures.csv
        print(f"error: every one of the {done.failed} tests failed; why is in "
              f"{done.out / 'failures.csv'}", file=sys.stderr)
        return 3
    if done.failed:
        print(f"warning: {done.failed} of {len(done.outcomes)} tests failed (failures.csv)",
              file=sys.stderr)
    return 0


def _pooled(text: str) -> list[tuple[str, str]]:
    """`type/stage+type/stage...` as (type, stage) pairs; argparse's error (exit 2) where
    malformed."""
    members = [tuple(m.split("/")) for m in text.split("+")]
    if len(members) < 2 or any(len(m) != 2 or not all(m) for m in members):
        raise argparse.ArgumentTypeError(f"two or more TYPE/STAGE joined by '+'; got {text!r}")
    return [(str(t), str(s)) for t, s in members]


def _shared(text: str) -> tuple[str, str]:
    """`BASE` or `BASE:type|vehicle` as (base, over); argparse's error (exit 2) where
    malformed."""
    base, _, over = text.partition(":")
    over = over or "type"
    if not base or over not in ("type", "vehicle"):
        raise argparse.ArgumentTypeError(f"a parameter's base name, optionally followed by "
                                         f":type or :vehicle; got {text!r}")
    return base, over


def _joint(args: argparse.Namespace) -> int:
    from cpas_ocp.api import joint
    done = joint(args.tests, dict(args.share), progress=sys.stderr.isatty())
    out = done.report(args.out)
    print(done.summary())
    print(f"\njoint fit written to {out} (joint.md, joint.csv, parameters.csv, joint.json)")
    if not done.fit.is_result:
        raise NotAResult(f"the joint fit is not a result: {done.fit.problems[0]}")
    return 0


def _population(args: argparse.Namespace) -> int:
    from cpas_ocp.api import population
    if not 0.0 < args.alpha < 1.0:
        raise InputError("(command line)", "--alpha", f"a level in (0, 1); got {args.alpha:g}")
    pop = population(args.campaign, args.parameters, args.covariates, args.pool,
                     not args.diagonal, args.alpha, args.seed)
    out = pop.report(args.out)
    print(pop.summary())
    print(f"\npopulations written to {out} (population.md, population.csv, openings.csv, "
          "groupings.csv, population.json, report.html)")
    return 0


def _dispersions(args: argparse.Namespace) -> int:
    from cpas_ocp.api import dispersions
    done = dispersions(args.campaign, args.out, args.cases, args.seed, args.population)
    for model in done.models:
        print(model.text())
    for note in done.skipped:
        print(f"not dispersed: {note}")
    for note in done.notes:
        print(note)
    if not done.envelopes:
        print("no stages.csv beside the campaign's table: drag-area envelopes not drawn")
    print(f"\ndispersions written to {done.out} (cases_*.parquet, dispersions.json, "
          "dispersions.md, figures)")
    return 0


def _montecarlo(args: argparse.Namespace) -> int:
    from cpas_ocp.api import monte_carlo
    done = monte_carlo(args.test_dir, args.cases, args.out, args.limit, args.workers,
                       args.scheduler, progress=True)
    print(done.summary())
    print(f"\nMonte Carlo written to {args.out} (quantiles_*.csv, peak_loads_*.parquet, "
          "peak_loads_*.png, montecarlo.md)")
    return 0


def _card_options(s: argparse.ArgumentParser) -> None:
    s.add_argument("--card", required=True, metavar="CARD",
                   help="a flight card: a built-in name (prometheus) or a JSON file")
    s.add_argument("--out", required=True, type=Path)
    s.add_argument("--still-air", action="store_true",
                   help="where the card gives no model: the rocket default without the air's "
                        "vertical motion (wind_process)")


def _import(args: argparse.Namespace) -> int:
    from cpas_ocp.api import import_log
    summary = import_log(args.log, args.card, args.out, args.format, args.columns,
                         args.still_air)
    print(summary.text())
    print(f"test folder written to {args.out}")
    return 0


def _flight(args: argparse.Namespace) -> int:
    from cpas_ocp.io.flight_card import card_folder, card_reading, is_card_file, load_card
    card = load_card(args.card)
    data = args.data if args.data is not None else (
        card_folder(card) if is_card_file(card) else Path("../shared/data")) / card.data_folder
    logs = args.log or list(card.logs)
    if not logs:
        raise InputError(card.source, "data.logs", "the flight logs to reconstruct (or give "
                         "--log FILE)")
    for name in logs:
        if not (data / name).exists():
            raise InputError(card.source, "data.logs", f"flight logs that exist; {data / name} "
                             "does not (give the folder holding it with --data)")
    # The command line's format or map, else the card's, else an Altus Metrum export.
    log_format, columns = args.format, args.columns
    if log_format is None and columns is None:
        log_format, columns = card_reading(card)
        if log_format is None and columns is None:
            log_format = "altus"
    new_out = not args.out.exists() or not any(args.out.iterdir())
    try:
        # Every log is imported before any is reconstructed: a log the import refuses is
        # said in a second, not after the fits of the others.
        records = [_flight_import(card, data / name, log_format, columns, args.out)
                   for name in logs]
        recorders = [_flight_log(args, card, log, record) for log, record in records]
    except InputError:
        if new_out:  # a refused input leaves no half-written output
            shutil.rmtree(args.out, ignore_errors=True)
        raise
    if len(recorders) > 1:
        from cpas_ocp.io.recorder_clocks import recorders_text
        text = recorders_text(recorders)
        (args.out / "recorders.md").write_text(f"# {card.title}\n\n{text}")
        print()
        print(text)
        print(f"recorders compared in {args.out / 'recorders.md'}")
    return 0


def _flight_import(card: FlightCard, log: Path, log_format: str | None,
                   columns: Path | dict[str, Any] | None, out: Path
                   ) -> tuple[Path, FlightRecord]:
    """Read one log of the `flight` command and import it into out/<log stem>/test (the
    import's summary printed): the log and its record."""
    from cpas_ocp.io.flight_log import import_flight
    from cpas_ocp.io.log_formats import read_flight_log
    print(f"== {log.name}: import", flush=True)
    record = read_flight_log(log, log_format, columns, f"{card.source}: data.columns")
    summary = import_flight(record, card, out / log.stem / "test")
    print(summary.text())
    return log, record


def _flight_log(args: argparse.Namespace, card: FlightCard, log: Path, record: FlightRecord
                ) -> RecorderEstimates:
    """Reconstruct, diagnose and compare one log of the `flight` command, imported by
    `_flight_import` (a function of its own so that one log's fits and refits are freed
    before the next log's): its drag areas and start times, for the recorders'
    comparison."""
    from cpas_ocp.inference.process_intensity import without_wind
    from cpas_ocp.io.flight_test import load_test
    from cpas_ocp.io.recorder_clocks import RecorderEstimates
    from cpas_ocp.reports.flight_report import air_motion_text, flight_text, held_opening_profiles
    folder = args.out / log.stem
    print(f"== {log.name}: reconstruct", flush=True)
    test = load_test(folder / "test")
    rec, out = _run_reconstruction(test, args, _spec(test, args), folder / "report")
    est, fit, cov = rec.estimator, rec.fit, rec.covariance
    still = without_wind(est.spec, test)
    air = None if still is None else _flight_still_air(test, args, still, folder)
    print("diagnosing the residuals ...", flush=True)
    diag = rec.diagnose(folder / "diagnosis", progress=not args.verbose)
    print("profiling the opening's held parameters ...", flush=True)
    held = held_opening_profiles(fit, est.spec, progress=not args.verbose)
    text = flight_text(fit, cov, card.nominal, diag, held)
    if still is not None:
        text += "\n" + (air if isinstance(air, str) else
                        air_motion_text(air[0], air[1], fit, cov, "wind.png") + air[2])
    (out / "flight.md").write_text(f"# {card.title}\n\n{card.label}\n\n{text}")
    print()
    print(text)
    print(f"flight comparison written to {out / 'flight.md'}")
    return RecorderEstimates(record, {n: (fit.parameters[n], cov.std.get(n, float("nan")))
                                     for n in fit.free if n.startswith(("CdS", "t_start"))})


def _flight_still_air(test: FlightTest, args: argparse.Namespace, spec: ModelSpec,
                      folder: Path) -> tuple[Fit, Covariance, str] | str:
    """The `flight` log fitted again without the card's wind process (report in
    ``report_still``): the fit, its covariance and a markdown line where it is not a
    result, or the markdown that says it failed."""
    from cpas_ocp.reports.report import write_report
    print("reconstructing in still air (the card's model without its wind_process) ...",
          flush=True)
    still_args = argparse.Namespace(**{**vars(args), "wind_intensity": None})
    est = _estimator(test, still_args, spec)
    try:
        still = _reconstruction(est, still_args)
        est, fit, cov, claim = still.estimator, still.fit, still.covariance, still.claim
    except SolverFailure as exc:
        print(f"the fit in still air did not converge: {exc}", file=sys.stderr)
        return (f"## Air motion\n\nThe fit in still air (the card's model without its "
                f"`wind_process`) did not converge ({exc.status} after {exc.iterations} "
                "iterations): no comparison.\n")
    out = write_report(fit, cov, folder / "report_still", claim=claim)
    print(f"in still air: chi-square/dof {fit.chi_square / fit.dof:.2f}; report written to "
          f"{out}")
    # Said where the comparison is read, not only in its report.
    note = ("" if claim.is_result else "\n**The fit in still air is not a result.** "
            + " ".join(f"{p}." for p in claim.problems()) + "\n")
    return fit, cov, note


def _demo(args: argparse.Namespace) -> int:
    from cpas_ocp.estimation.simulate import simulate_problem
    from cpas_ocp.io.problems import load_problem
    test_dir = args.out / "test"
    if test_dir.is_symlink() or (test_dir.exists() and not (test_dir / "truth.json").is_file()):
        raise InputError(str(test_dir), "(folder)", "no such folder, or a test simulated by an "
                         "earlier demo (holding truth.json) to replace")
    if test_dir.exists():
        shutil.rmtree(test_dir)
    print(f"simulating the built-in 'drogue' problem (seed {args.seed}) into {test_dir}")
    test = simulate_problem(load_problem("drogue"), test_dir, args.seed)
    args.out = args.out / "report"
    try:
        _run_reconstruction(test, args, _spec(test, args))
    except (interrupts.Interrupted, KeyboardInterrupt):
        shutil.rmtree(test_dir, ignore_errors=True)  # an interrupted demo leaves nothing
        raise
    return 0


def _run_reconstruction(test: FlightTest, args: argparse.Namespace, spec: ModelSpec,
                        out: Path | None = None) -> tuple[Reconstruction, Path]:
    """Solve, write the report folder (`out`, default --out) and print the tables and the
    fit's claim; NotAResult, after the report is written, where the fit is not a result."""
    from cpas_ocp.inference.profile_likelihood import require_free
    est = _estimator(test, args, spec)
    names = getattr(args, "profile", [])
    for name in names:
        require_free(est, name)
    print(f"solving: {est.size_text()} ...", flush=True)
    target = out if out is not None else args.out
    try:
        rec = _reconstruction(est, args)
    except SolverFailure as exc:
        from cpas_ocp.reports.failure_report import write_failure_report
        folder = write_failure_report(exc, target)
        print(f"NOT CONVERGED: why is in {folder / 'failure.md'}", file=sys.stderr)
        raise
    profiles = [rec.profile(n, args.profile_span, args.profile_points,
                            progress=not args.verbose) for n in names]
    units = _units(test, args)
    out = rec.report(target, profiles, units)
    print()
    print(rec.summary(units))
    for prof in profiles:
        print(f"profile likelihood, {prof.text()}")
    print(f"\nreport written to {out} (result.json, parameters.csv, report.md, figures)")
    print(f"interactive report: {out / 'report.html'}")
    if not rec.is_result:
        raise NotAResult(f"the fit converged but is not a result (see the claim in "
                         f"{out / 'report.md'}): {rec.problems[0]}")
    return rec, out


def _estimator(test: FlightTest, args: argparse.Namespace, spec: ModelSpec) -> Estimator:
    """The NLP of a test phase with the command line's solver options (built and announced)."""
    from cpas_ocp.estimation.estimator import Estimator, Settings
    from cpas_ocp.estimation.shooting_grid import grid_text
    if args.grid_step is not None and not 0.0 < args.grid_step < test.t_end - test.t_start:
        raise InputError("(command line)", "--grid-step",
                         f"a step in seconds, positive and shorter than the phase; "
                         f"got {args.grid_step}")
    print(f"building the multiple-shooting NLP of {test.name} "
          f"({test.t_end - test.t_start:.1f} s) ...", flush=True)
    est = Estimator(test, spec, settings=Settings(grid_step=args.grid_step,
                                                  verbose=args.verbose, max_iter=args.max_iter))
    print(f"  {grid_text(est.t)}", flush=True)
    if est.unfitted:
        print(f"warning: no effect of the model predicts sensor(s) {', '.join(est.unfitted)}: "
              "their data are not fitted", file=sys.stderr)
    return est


def _reconstruction(est: Estimator, args: argparse.Namespace,
                    plugins: dict[str, EffectType] | None = None) -> Reconstruction:
    """`api.fit_estimator` with the command line's options (and the plug-in effects its
    diagnosis may test), announced, and a warning for every parameter combination the
    data leave undetermined and every reason the fit is not yet a result."""
    from cpas_ocp.api import fit_estimator
    intensities = getattr(args, "wind_intensity", None) or ()
    if intensities:
        print(f"choosing the wind process's intensity ({len(intensities)} fits) ...",
              flush=True)
    if args.hessian == "exact":
        print("the fit, then its exact-Hessian covariance ...", flush=True)
    rec = fit_estimator(est, args.rescale_sigmas, args.hessian, intensities,
                        progress=not args.verbose, plugins=plugins)
    if rec.intensity_choice is not None:
        print(rec.intensity_choice.text(), flush=True)
    if rec.covariance.undetermined:
        print(f"warning: the data do not determine {', '.join(rec.covariance.undetermined)} "
              f"(see the identifiability lines)", file=sys.stderr)
    for problem in rec.problems:
        print(f"warning: {problem}", file=sys.stderr)
    return rec


if __name__ == "__main__":  # python -m cpas_ocp.cli, as the cpas-ocp script
    sys.exit(main())
