"""The command line's commands: each reads its arguments, calls the workflow of the Python
interface (`cpas_ocp.api`) and prints what it returns.  Imports are made inside each
command, so that a command loads only the part of the package it runs."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import TYPE_CHECKING, Any

from cpas_ocp.errors import InputError, NotAResult

if TYPE_CHECKING:
    from cpas_ocp.api import FitOptions
    from cpas_ocp.progress import Narration


def one_line(message: str) -> None:
    """Print `message` on stderr as the one line the exit codes promise: a message that
    spans lines (a library's, a solver's) keeps them all, joined by "; "."""
    print("; ".join(line.strip() for line in message.splitlines() if line.strip()),
          file=sys.stderr)


def _options(args: argparse.Namespace) -> FitOptions:
    """The fit's options of the solver arguments (`arguments._solver_options`)."""
    from cpas_ocp import api
    from cpas_ocp.estimation.fit import Settings
    return api.FitOptions(Settings(grid_step=args.grid_step, verbose=args.verbose,
                               max_iter=args.max_iter),
                      args.hessian, args.rescale_sigmas, tuple(args.wind_intensity or ()))


def _tell(args: argparse.Namespace) -> Narration:
    """Narration on the terminal; progress lines unless Ipopt's own log is shown."""
    from cpas_ocp.progress import terminal
    return terminal(progress=not getattr(args, "verbose", False))


def _model(args: argparse.Namespace) -> dict[str, Any]:
    """The model arguments of the workflows: --model, --plugin, --allow-external-plugins."""
    return {"model": getattr(args, "model", None), "plugins": getattr(args, "plugin", []),
            "allow_external_plugins": getattr(args, "allow_external_plugins", False)}


def _written(text: str, kind: str, out: Path) -> None:
    """Print a diagnosis's or a comparison's text (`kind`) and the folder it was written to
    (KIND.md, KIND.json, windows.csv, figures, KIND.html)."""
    print()
    print(text)
    print(f"\n{kind} written to {out} ({kind}.md, {kind}.json, windows.csv, figures)")
    print(f"interactive report: {out / f'{kind}.html'}")


def problems(args: argparse.Namespace) -> int:
    from cpas_ocp.reports.listings import problems_text
    print(problems_text())
    return 0


def effects(args: argparse.Namespace) -> int:
    from cpas_ocp.physics.effects.registry import load_plugins
    from cpas_ocp.reports.listings import effects_text
    print(effects_text(load_plugins(args.plugin)))
    return 0


def simulate(args: argparse.Namespace) -> int:
    from cpas_ocp import api
    test = api.simulate(args.name, args.out, args.seed)
    print(f"wrote test folder {args.out} ({test.name}) with truth.json")
    return 0


def design(args: argparse.Namespace) -> int:
    from cpas_ocp import api
    from cpas_ocp.reports.design_report import design_text
    found = api.design(args.plan, args.out, progress=_tell(args).say)
    print(design_text(found))
    extra = ", population_sigma.csv" if found.spread is not None else ""
    print(f"\ndesign written to {args.out} (design.html, sigma.csv, changes.csv, failures.csv"
          f"{extra}, design.json)")
    return 0


def reduce(args: argparse.Namespace) -> int:
    from cpas_ocp import api
    found = api.reduce(args.test_dir, args.out, units=args.units, **_model(args))
    print(found.summary())
    print(f"\nreduction written to {found.out} (reduction.csv, initial_guess.json, "
          "reduction.png)")
    return 0


def reconstruct(args: argparse.Namespace) -> int:
    from cpas_ocp import api
    from cpas_ocp.api.reconstruction import require_result, say_written
    tell = _tell(args)
    rec = api.reconstruct(args.test_dir, options=_options(args), out=args.out,
                          profiles=args.profile, profile_span=args.profile_span,
                          profile_points=args.profile_points, units=args.units, tell=tell,
                          **_model(args))
    say_written(rec, tell)
    require_result(rec)
    return 0


def demo(args: argparse.Namespace) -> int:
    from cpas_ocp import api
    from cpas_ocp.api.reconstruction import require_result, say_written
    tell = _tell(args)
    rec = api.demo(args.out, args.seed, _options(args), args.units, tell)
    say_written(rec, tell)
    require_result(rec)
    return 0


def whatif(args: argparse.Namespace) -> int:
    from cpas_ocp import api
    from cpas_ocp.reports.fit_text import whatif_text
    print(whatif_text(api.what_if(args.test_dir, args.constrain, options=_options(args),
                                  tell=_tell(args), **_model(args))))
    return 0


def diagnose(args: argparse.Namespace) -> int:
    from cpas_ocp import api
    diag = api.diagnose(args.test_dir, args.out, confirm=args.confirm, alpha=args.alpha,
                        options=_options(args), units=args.units, tell=_tell(args),
                        **_model(args))
    _written(api.summary(diag), "diagnosis", args.out)
    return 0


def discover(args: argparse.Namespace) -> int:
    from cpas_ocp import api
    from cpas_ocp.discrepancy.discovery import Discovery, DiscoveryStep, InterruptedDiscovery

    def said(step: DiscoveryStep) -> None:
        print(f"step {step.label} ({step.found_s + step.diagnosed_s:.0f} s): chi-square "
              f"{step.fit.chi_square:.1f} (chi2/dof {step.fit.chi_square / step.fit.dof:.3f}); "
              f"{step.diagnosis.verdict().splitlines()[0] if step.diagnosis else ''}",
              flush=True)

    def read(chain: Discovery) -> None:
        print(f"  {len(chain.steps)} step(s) read; going on from step {len(chain.steps) - 1}"
              "\ndiagnosing, step by step ...", flush=True)

    out = args.resume if args.resume is not None else args.out
    try:
        if args.resume is not None:
            print(f"reading the finished steps in {args.resume} ...", flush=True)
            found = api.resume_discovery(out, progress=not args.verbose, on_step=said,
                                         on_read=read)
        elif args.test_dir is None or args.out is None:
            raise InputError("(command line)", "test_dir, --out",
                             "a test folder and --out DIR, or --resume DIR")
        else:
            found = api.discover(args.test_dir, out, max_steps=args.max_steps, alpha=args.alpha,
                                 confirm=args.confirm, options=_options(args), units=args.units,
                                 tell=_tell(args), on_step=said, **_model(args))
    except InterruptedDiscovery as exc:
        one_line(f"interrupted ({exc}); the {len(exc.partial.steps)} finished step(s) written "
                 f"to {out} (discovery.md, discovery.json, step_K.json); go on with "
                 f"cpas-ocp discover --resume {out}")
        return exc.exit_code
    print()
    print(api.summary(found))
    print(f"\ndiscovery written to {out} (discovery.md, discovery.html, discovery.json, "
          "discovery.png, step_K.json)")
    return 0


def compare(args: argparse.Namespace) -> int:
    from cpas_ocp import api
    comparison = api.compare(args.test_dir, args.model, args.out, args.plugin,
                             _options(args), args.units, args.allow_external_plugins,
                             _tell(args))
    _written(api.summary(comparison), "comparison", args.out)
    return 0


def campaign(args: argparse.Namespace) -> int:
    from cpas_ocp import api
    done = api.reconstruct_campaign(args.tests_dir, args.out, args.workers, args.scheduler,
                                    progress=True)
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


def joint(args: argparse.Namespace) -> int:
    from cpas_ocp import api
    done = api.joint(args.tests, dict(args.share), progress=sys.stderr.isatty())
    out = done.report(args.out)
    print(done.summary())
    print(f"\njoint fit written to {out} (joint.md, joint.csv, parameters.csv, joint.json)")
    if not done.fit.is_result:
        raise NotAResult(f"the joint fit is not a result: {done.fit.problems[0]}")
    return 0


def hierarchical(args: argparse.Namespace) -> int:
    from cpas_ocp import api
    done = api.hierarchical(args.tests, dict(args.population), dict(args.share),
                            progress=sys.stderr.isatty())
    out = done.report(args.out)
    print(done.summary())
    print(f"\nhierarchical fit written to {out} (hierarchical.md, hierarchical.csv, "
          "copies.csv, hierarchical.json)")
    if not done.fit.is_result:
        raise NotAResult(f"the hierarchical fit is not a result: {done.fit.problems[0]}")
    return 0


def population(args: argparse.Namespace) -> int:
    from cpas_ocp import api
    if not 0.0 < args.alpha < 1.0:
        raise InputError("(command line)", "--alpha", f"a level in (0, 1); got {args.alpha:g}")
    pop = api.population(args.campaign, args.parameters, args.covariates, args.pool,
                         not args.diagonal, args.alpha, args.seed, not args.no_position)
    out = pop.report(args.out)
    print(pop.summary())
    print(f"\npopulations written to {out} (population.md, population.csv, openings.csv, "
          "explained.csv, groupings.csv, population.json, report.html)")
    return 0


def dispersions(args: argparse.Namespace) -> int:
    from cpas_ocp import api
    done = api.dispersions(args.campaign, args.out, args.cases, args.seed, args.population,
                           dict(args.at))
    for model in done.models:
        print(api.summary(model))
    for note in done.skipped:
        print(f"not dispersed: {note}")
    for note in done.notes:
        print(note)
    if not done.envelopes:
        print("no stages.csv beside the campaign's table: drag-area envelopes not drawn")
    print(f"\ndispersions written to {done.out} (cases_*.parquet, dispersions.json, "
          "dispersions.md, figures)")
    return 0


def montecarlo(args: argparse.Namespace) -> int:
    from cpas_ocp import api
    done = api.monte_carlo(args.test_dir, args.cases, args.out, args.limit, args.workers,
                           args.scheduler, progress=True)
    print(done.summary())
    print(f"\nMonte Carlo written to {args.out} (quantiles_*.csv, peak_loads_*.parquet, "
          "peak_loads_*.png, montecarlo.md)")
    return 0


def import_log(args: argparse.Namespace) -> int:
    from cpas_ocp import api
    from cpas_ocp.reports.import_text import import_text  # `api.summary` loads every report
    imported = api.import_log(args.log, args.card, args.out, args.format, args.columns,
                              args.still_air)
    print(import_text(imported))
    print(f"test folder written to {args.out}")
    return 0


def rocketpy(args: argparse.Namespace) -> int:
    from cpas_ocp.api.rocketpy_export import EXPORT_FILES, rocketpy_export, write_export
    export = rocketpy_export(args.report_dir, args.test)
    out = write_export(export, args.out)
    print(export.summary())
    print(f"\nwritten to {out} ({', '.join(EXPORT_FILES)}); python {out / EXPORT_FILES[1]} "
          "builds the parachutes where RocketPy is installed")
    return 0


def flight(args: argparse.Namespace) -> int:
    from cpas_ocp import api
    api.flight(args.card, args.out, args.data, args.log, args.format, args.columns,
                   _options(args), _tell(args))
    return 0
