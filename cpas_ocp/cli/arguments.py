"""The command line's arguments: each command's options, their types and their checks (a
value out of range is argparse's one-line error and exit code 2)."""

from __future__ import annotations

import argparse
from pathlib import Path

from cpas_ocp.cli import commands
from cpas_ocp.cli.argument_types import (
    COUNT,
    SEED,
    OneLineParser,
    pooled,
    ranged,
    scheduler,
    setting,
    shared,
    wind_factors,
)

DESCRIPTION = "The `cpas-ocp` command line."
# The test table's built-in columns a population's mean may depend on (population_study).
COVARIATES = ("type", "forebody", "cluster_size", "line_length", "line_length_ratio",
              "position")


def parser() -> argparse.ArgumentParser:
    """The command line's parser: each command's arguments, and its handler as `run`."""
    p = OneLineParser(prog="cpas-ocp", description=DESCRIPTION)
    sub = p.add_subparsers(required=True, metavar="COMMAND")

    s = sub.add_parser("problems", help="list the built-in test phases")
    s.set_defaults(run=commands.problems)

    s = sub.add_parser("effects", help="list the effects a model block may name, with options")
    _plugin_option(s, "also list the effects a plug-in file defines (repeatable)")
    s.set_defaults(run=commands.effects)

    s = sub.add_parser("simulate", help="simulate a built-in problem into a test folder")
    s.add_argument("name",
                   help="a built-in problem (cpas-ocp problems lists them)")
    s.add_argument("--out", required=True, type=Path,
                   help="the test folder to write (manifest, series, truth.json)")
    s.add_argument("--seed", required=True, type=SEED,
                   help="the seed of the sensor noise's draws")
    s.set_defaults(run=commands.simulate)

    s = sub.add_parser("reduce", help="offline drag-area reduction and the initial guess")
    s.add_argument("test_dir", type=Path,
                   help="a test folder (manifest.json and its series)")
    s.add_argument("--out", required=True, type=Path,
                   help="the folder to write the reduction's tables and figures to")
    _model_option(s)
    _units_option(s)
    s.set_defaults(run=commands.reduce)

    s = sub.add_parser("reconstruct", help="reconstruct a test folder")
    s.add_argument("test_dir", type=Path,
                   help="a test folder (manifest.json and its series)")
    s.add_argument("--out", required=True, type=Path,
                   help="the report folder to write (result.json, parameters.csv, report.md, "
                        "report.html, figures)")
    s.add_argument("--profile", action="append", default=[], metavar="NAME",
                   help="also profile the likelihood of this free parameter (repeatable)")
    s.add_argument("--profile-span", type=ranged(float, 0.0, low_open=True), default=3.0,
                   metavar="SIGMAS",
                   help="profile over the estimate -+ this many sigma (default 3)")
    s.add_argument("--profile-points", type=ranged(int, 2), default=13, metavar="N",
                   help="values per profile (default 13)")
    _model_option(s)
    _solver_options(s)
    _units_option(s)
    s.set_defaults(run=commands.reconstruct)

    s = sub.add_parser("whatif", help="re-solve under constraints and report what they cost")
    s.add_argument("test_dir", type=Path,
                   help="a test folder (manifest.json and its series)")
    s.add_argument("--constrain", action="append", required=True, metavar="EXPR",
                   help="NAME == VALUE [UNIT], NAME <= VALUE or NAME >= VALUE on a free "
                        "parameter, e.g. 'Ck[drogue1,stage1] == 1', or a peak limit, e.g. "
                        "'peak_load[drogue1] <= 30000 lbf' (repeatable)")
    _model_option(s)
    _solver_options(s)
    s.set_defaults(run=commands.whatif)

    s = sub.add_parser("diagnose", help="fit, then find where the model fails and which "
                                        "effect is missing")
    _diagnosis_options(s)
    _units_option(s)
    s.set_defaults(run=commands.diagnose)

    s = sub.add_parser("discover", help="diagnose, add the confirmed effect, refit, and "
                                        "again, until the residuals are noise or nothing "
                                        "left is significant")
    _diagnosis_options(s, resumable=True)
    s.add_argument("--max-steps", type=ranged(int, 1), default=4, metavar="K",
                   help="add at most K effects (default 4)")
    s.add_argument("--resume", type=Path, default=None, metavar="DIR",
                   help="go on from the finished steps of a discovery folder (one that was "
                        "interrupted or killed), with the test folder and options it was "
                        "started with; it is written again in place")
    _units_option(s)
    s.set_defaults(run=commands.discover)

    s = sub.add_parser("compare", help="fit two effect sets and test which the data prefer")
    s.add_argument("test_dir", type=Path,
                   help="a test folder (manifest.json and its series)")
    s.add_argument("--model", type=str, action="append", required=True, metavar="FILE",
                   help="a JSON model block, or 'manifest' for the test's own model; "
                        "give it twice")
    s.add_argument("--out", required=True, type=Path,
                   help="the folder to write the comparison to")
    _plugin_option(s, "a Python file whose effects the model files may name (repeatable)")
    _model_option(s, model=False)
    _solver_options(s)
    _units_option(s)
    s.set_defaults(run=commands.compare)

    s = sub.add_parser("campaign", help="reconstruct every test folder under a folder, in "
                                        "parallel, and write the parameter table")
    s.add_argument("tests_dir", type=Path,
                   help="a folder whose subfolders are test folders")
    s.add_argument("--out", required=True, type=Path,
                   help="the campaign folder to write (its tables and report)")
    _parallel_options(s)
    s.set_defaults(run=commands.campaign)

    s = sub.add_parser("population", help="each canopy type and stage's population from a "
                                          "campaign: mu, the between-test Omega, each "
                                          "test's shrunken estimate, grouping tests")
    s.add_argument("campaign", type=Path, help="a campaign folder (cpas-ocp campaign)")
    s.add_argument("--out", required=True, type=Path,
                   help="the folder to write the populations to")
    s.add_argument("--parameter", action="append", dest="parameters", default=None,
                   help="a canopy parameter to include (repeatable; default: CdS, Ck, n_p, "
                        "n, expopen, t_k where determined)")
    s.add_argument("--covariate", action="append", dest="covariates", default=[],
                   help="a column of the campaign's table the mean depends on: "
                        f"{', '.join(COVARIATES)} or a covariate the manifests name "
                        "(repeatable)")
    s.add_argument("--no-position", action="store_true",
                   help="no position covariate by default for a type flown in two or more "
                        "positions of its cluster")
    s.add_argument("--pool", action="append", default=[], type=pooled,
                   help="canopy types and stages fitted as one population, e.g. "
                        "fbcp/stage1+drogue/stage1 (repeatable)")
    s.add_argument("--diagonal", action="store_true",
                   help="no between-test correlations (a diagonal Omega)")
    s.add_argument("--alpha", type=float, default=0.05,
                   help="the grouping tests' level (0.05)")
    s.add_argument("--seed", type=SEED, default=0,
                   help="the seed of the grouping tests' bootstrap (0)")
    s.set_defaults(run=commands.population)

    s = sub.add_parser("joint", help="several tests that share hardware reconstructed in one "
                                     "NLP, the shared parameters held equal across them")
    s.add_argument("tests", nargs="+", type=Path, help="two or more test folders")
    s.add_argument("--share", action="append", required=True, type=shared,
                   help="a parameter shared across the tests: its base name, one per canopy "
                        "type and stage (CdS), or BASE:vehicle, one per test vehicle "
                        "(prf:vehicle) (repeatable)")
    s.add_argument("--out", required=True, type=Path,
                   help="the folder to write the joint fit to (joint.md, joint.csv, "
                        "parameters.csv, joint.json)")
    s.set_defaults(run=commands.joint)

    s = sub.add_parser("hierarchical", help="several tests and their parameters' populations "
                                            "in one NLP: each test's copy drawn from a "
                                            "population whose median and spread are fitted "
                                            "with it")
    s.add_argument("tests", nargs="+", type=Path, help="two or more test folders")
    s.add_argument("--population", action="append", required=True, type=shared,
                   help="a parameter drawn per test from a log-normal population: its base "
                        "name, one population per canopy type and stage (CdS), or "
                        "BASE:vehicle, one per test vehicle (repeatable)")
    s.add_argument("--share", action="append", default=[], type=shared,
                   help="a parameter held equal across the tests instead, as joint holds it "
                        "(repeatable)")
    s.add_argument("--out", required=True, type=Path,
                   help="the folder to write the fit to (hierarchical.md, hierarchical.csv, "
                        "copies.csv, hierarchical.json)")
    s.set_defaults(run=commands.hierarchical)

    s = sub.add_parser("dispersions", help="Monte Carlo cases per canopy type and stage from "
                                           "a campaign's parameter table")
    s.add_argument("campaign", type=Path, help="a campaign folder or its parameters table")
    s.add_argument("--out", required=True, type=Path,
                   help="the folder to write the cases and their dispersions to")
    s.add_argument("--cases", type=COUNT, default=200_000, help="cases per canopy (200,000)")
    s.add_argument("--seed", type=SEED, required=True,
                   help="the seed of the cases' draws")
    s.add_argument("--population", action="store_true",
                   help="draw each canopy type and stage from its fitted population (mu, "
                        "Omega: each test's uncertainty taken out of the spread) instead of "
                        "from its point estimates; still within the caps and the grown hull")
    s.add_argument("--at", action="append", default=[], type=setting, metavar="COVARIATE=VALUE",
                   help="with --population, draw at this configuration of a covariate of "
                        "the population's mean, e.g. position=drogue2 (repeatable; the "
                        "covariates' reference where not given)")
    s.set_defaults(run=commands.dispersions)

    s = sub.add_parser("montecarlo", help="reconstruct a test folder and fly the dispersed "
                                          "cases of its canopy stages: peak-load distributions")
    s.add_argument("test_dir", type=Path,
                   help="a test folder (manifest.json and its series)")
    s.add_argument("--cases", required=True, type=Path, metavar="DISPERSIONS_DIR",
                   help="a cpas-ocp dispersions folder (cases_<type>_<stage>.parquet)")
    s.add_argument("--out", required=True, type=Path,
                   help="the folder to write the dispersed cases' peak loads to")
    s.add_argument("--limit", type=COUNT, default=None, metavar="N",
                   help="fly the first N cases of each file (default: all)")
    _parallel_options(s)
    s.set_defaults(run=commands.montecarlo)

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
    s.set_defaults(run=commands.import_log)

    s = sub.add_parser("import-altus", help="an Altus Metrum (TeleMega, TeleMetrum) CSV log "
                                            "into a test folder (import --format altus)")
    s.add_argument("log", type=Path,
                   help="the AltOS CSV export")
    _card_options(s)
    s.set_defaults(run=commands.import_log, format="altus", columns=None)

    s = sub.add_parser("flight", help="import a real flight's logs, reconstruct each, and "
                                      "compare with the nominal drag areas and the descent")
    s.add_argument("card", metavar="CARD", help="a built-in flight card (prometheus) or a file")
    s.add_argument("--out", required=True, type=Path,
                   help="the folder to write each log's test folder and report to")
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
    s.set_defaults(run=commands.flight)

    s = sub.add_parser("rocketpy", help="a reconstruction's fitted canopies as RocketPy "
                                        "parachutes: a script building them, and the numbers")
    s.add_argument("report_dir", type=Path, metavar="REPORT_DIR",
                   help="a report folder of cpas-ocp reconstruct (its result.json), one that "
                        "is a result")
    s.add_argument("--test", required=True, type=Path, metavar="TEST_DIR",
                   help="the test folder it reconstructs (its canopies, deployments, "
                        "altimeter and site)")
    s.add_argument("--out", required=True, type=Path, metavar="DIR",
                   help="folder to write parachutes.py (builds rocketpy.Parachute and "
                        "StochasticParachute objects) and parachutes.json (the numbers)")
    s.set_defaults(run=commands.rocketpy)

    s = sub.add_parser("design", help="predict the sigma of every parameter under planned "
                       "instrumentations and rank single sensor changes (a plan file)")
    s.add_argument("plan", type=Path,
                   help="a test plan (JSON, data_schemas/test_plan.schema.json)")
    s.add_argument("--out", required=True, type=Path,
                   help="the folder to write the design's tables and figures to")
    s.set_defaults(run=commands.design)

    s = sub.add_parser("demo", help="simulate the built-in Drogue test and reconstruct it")
    s.add_argument("--out", type=Path, default=Path("cpas-demo"),
                   help="the folder to write the demo's test folder and report to (cpas-demo)")
    s.add_argument("--seed", type=SEED, default=1,
                   help="the seed of the demo's sensor noise (1)")
    _solver_options(s)
    _units_option(s)
    s.set_defaults(run=commands.demo)
    return p


def _units_option(s: argparse.ArgumentParser) -> None:
    s.add_argument("--units", choices=("si", "us"), default=None,
                   help="draw figures and tables in SI or US customary units (default: "
                        "the manifest's; result.json is always SI)")


def _plugin_option(s: argparse.ArgumentParser, text: str) -> None:
    s.add_argument("--plugin", type=Path, action="append", default=[], metavar="FILE",
                   help=text)


def _parallel_options(s: argparse.ArgumentParser) -> None:
    s.add_argument("--workers", type=COUNT, default=2, help="local processes (default 2)")
    s.add_argument("--scheduler", type=scheduler, default=None, metavar="ADDRESS",
                   help="run on this Dask scheduler (e.g. tcp://host:8786) instead")


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


def _solver_options(s: argparse.ArgumentParser) -> None:
    from cpas_ocp.estimation.fit import HESSIANS, MIN_GRID_STEP_S
    s.add_argument("--grid-step", type=ranged(float, MIN_GRID_STEP_S), default=None,
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
    s.add_argument("--wind-intensity", type=wind_factors, default=None, metavar="F,F,...",
                   help="choose the model's wind_process intensity by the marginal "
                        "likelihood among these multiples of its sigmas (e.g. "
                        "0.25,0.5,1,2,4): one fit each")


def _diagnosis_options(s: argparse.ArgumentParser, resumable: bool = False) -> None:
    """The test folder, output folder, plug-ins, confirmation, level, model and solver
    options of a command that diagnoses (`diagnose`, `discover`; with `resumable`, the
    test and output folders may come from --resume instead)."""
    s.add_argument("test_dir", type=Path, nargs="?" if resumable else None,
                   help="a test folder (manifest.json and its series)")
    s.add_argument("--out", required=not resumable, type=Path,
                   help="the folder to write the diagnosis or the discovery to")
    _plugin_option(s, "also test the effects this Python file defines (repeatable)")
    s.add_argument("--confirm", type=ranged(int, 0), default=3, metavar="N",
                   help="refit the N leading significant effects to confirm them, and more "
                        "where the best confirmed is implausible (default 3)")
    s.add_argument("--alpha", type=ranged(float, 0.0, 1.0, low_open=True, high_open=True),
                   default=0.01,
                   help="family-wise significance level (default 0.01)")
    _model_option(s, plugin=False)
    _solver_options(s)


def _card_options(s: argparse.ArgumentParser) -> None:
    s.add_argument("--card", required=True, metavar="CARD",
                   help="a flight card: a built-in name (prometheus) or a JSON file")
    s.add_argument("--out", required=True, type=Path,
                   help="the test folder to write")
    s.add_argument("--still-air", action="store_true",
                   help="where the card gives no model: the rocket default without the air's "
                        "vertical motion (wind_process)")


