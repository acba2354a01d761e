"""Real flights: a flight card's logs imported (`log_import`), reconstructed, diagnosed and
compared with the card's nominal drag areas (the command line's `flight`)."""

from __future__ import annotations

import dataclasses
import shutil
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from cpas_ocp.api.reconstruction import (
    FitOptions,
    build,
    fit_estimator,
    reconstruct,
    require_result,
    say_written,
)
from cpas_ocp.errors import InputError, SolverFailure
from cpas_ocp.estimation.estimator import Fit
from cpas_ocp.estimation.uncertainty import Covariance
from cpas_ocp.inference.process_intensity import without_wind
from cpas_ocp.io.flight_card import FlightCard, card_folder, card_reading, is_card_file, load_card
from cpas_ocp.io.flight_log import import_flight
from cpas_ocp.io.flight_record import FlightRecord
from cpas_ocp.io.flight_test import load_test
from cpas_ocp.io.log_formats import read_flight_log
from cpas_ocp.io.model_spec import ModelSpec
from cpas_ocp.io.recorder_clocks import RecorderEstimates
from cpas_ocp.physics.flight_test import FlightTest
from cpas_ocp.progress import SILENT, Narration
from cpas_ocp.reports.flight_report import air_motion_text, flight_text, held_opening_profiles
from cpas_ocp.reports.import_text import import_text, recorders_text


@dataclass
class Flight:
    """A flight card's logs reconstructed (`flight`): each log's drag areas and start times
    with their sigmas, and the recorders compared where there are several (markdown, also
    written to recorders.md)."""

    recorders: list[RecorderEstimates]
    comparison: str | None
    out: Path


def flight(card: str | FlightCard, out: str | Path, data: str | Path | None = None,
           logs: Sequence[str] = (), log_format: str | None = None,
           columns: str | Path | None = None, options: FitOptions | None = None,
           tell: Narration = SILENT) -> Flight:
    """Import each log of the flight `card` (or only `logs`) from the folder `data` (default:
    the card's data folder beside a card file, or under ../shared/data for a built-in
    card) into out/<log>/test, then reconstruct it (out/<log>/report, with flight.md
    comparing the drag areas with the card's nominal ones), diagnose its residuals, profile
    the opening's held parameters and, where the model has a wind process, fit it again
    in still air (`cpas-ocp flight`).  The logs are read as `log_format` or through the
    column map `columns`, else as the card says, else as Altus Metrum exports.

    Every log is imported before any is reconstructed, so a log the import refuses is
    said at once; a refused input leaves no output it created.  A log whose fit is not a
    result ends the run (NotAResult) after its report is written."""
    card = card if isinstance(card, FlightCard) else load_card(str(card))
    out = Path(out)
    folder = Path(data) if data is not None else (
        card_folder(card) if is_card_file(card) else Path("../shared/data")) / card.data_folder
    names = list(logs) or list(card.logs)
    if not names:
        raise InputError(card.source, "data.logs", "the flight logs to reconstruct (or give "
                         "--log FILE)")
    for name in names:
        if not (folder / name).exists():
            raise InputError(card.source, "data.logs", f"flight logs that exist; "
                             f"{folder / name} does not (give the folder holding it with "
                             "--data)")
    if log_format is None and columns is None:
        log_format, columns = card_reading(card)
        if log_format is None and columns is None:
            log_format = "altus"
    new_out = not out.exists() or not any(out.iterdir())
    try:
        records = [_flight_import(card, folder / name, log_format, columns, out, tell)
                   for name in names]
        recorders = [_flight_log(card, out / log.stem, record, options, tell)
                     for log, record in records]
    except InputError:
        if new_out:  # a refused input leaves no half-written output
            shutil.rmtree(out, ignore_errors=True)
        raise
    comparison = None
    if len(recorders) > 1:
        comparison = recorders_text(recorders)
        (out / "recorders.md").write_text(f"# {card.title}\n\n{comparison}")
        tell.say(f"\n{comparison}\nrecorders compared in {out / 'recorders.md'}")
    return Flight(recorders, comparison, out)


def _flight_import(card: FlightCard, log: Path, log_format: str | None,
                   columns: str | Path | dict[str, Any] | None, out: Path, tell: Narration
                   ) -> tuple[Path, FlightRecord]:
    """Read one log of a `flight` and import it into out/<log stem>/test (the import's
    summary said): the log and its record."""
    tell.say(f"== {log.name}: import")
    record = read_flight_log(log, log_format, columns, f"{card.source}: data.columns")
    tell.say(import_text(import_flight(record, card, out / log.stem / "test")))
    return log, record


def _flight_log(card: FlightCard, folder: Path, record: FlightRecord,
                options: FitOptions | None, tell: Narration) -> RecorderEstimates:
    """Reconstruct, diagnose and compare one log of a `flight`, imported into folder/test by
    `_flight_import` (a function of its own so that one log's fits and refits are freed
    before the next log's): its drag areas and start times, for the recorders'
    comparison."""
    tell.say(f"== {folder.name}: reconstruct")
    test = load_test(folder / "test")
    rec = reconstruct(test, options=options, out=folder / "report", tell=tell)
    say_written(rec, tell)
    require_result(rec)
    fit, cov = rec.fit, rec.covariance
    still = without_wind(rec.spec, test)
    air = None if still is None else _still_air(test, still, folder, options, tell)
    tell.say("diagnosing the residuals ...")
    diag = rec.diagnose(folder / "diagnosis", progress=tell.progress)
    tell.say("profiling the opening's held parameters ...")
    held = held_opening_profiles(fit, rec.spec, progress=tell.progress)
    text = flight_text(fit, cov, card.nominal, diag, held)
    if still is not None:
        text += "\n" + (air if isinstance(air, str) else
                        air_motion_text(air[0], air[1], fit, cov, "wind.png") + air[2])
    written = folder / "report" / "flight.md"
    written.write_text(f"# {card.title}\n\n{card.label}\n\n{text}")
    tell.say(f"\n{text}\nflight comparison written to {written}")
    return RecorderEstimates(record, {n: (fit.parameters[n], cov.std.get(n, float("nan")))
                                     for n in fit.free if n.startswith(("CdS", "t_start"))})


def _still_air(test: FlightTest, spec: ModelSpec, folder: Path, options: FitOptions | None,
               tell: Narration) -> tuple[Fit, Covariance, str] | str:
    """A `flight` log fitted again without the card's wind process (report in
    ``report_still``): the fit, its covariance and a markdown line where it is not a
    result, or the markdown that says it failed."""
    tell.say("reconstructing in still air (the card's model without its wind_process) ...")
    still_options = dataclasses.replace(options or FitOptions(), wind_intensities=())
    est = build(test, spec, still_options.settings, tell)
    try:
        still = fit_estimator(est, still_options, tell=tell)
    except SolverFailure as exc:
        tell.warn(f"the fit in still air did not converge: {exc}")
        return (f"## Air motion\n\nThe fit in still air (the card's model without its "
                f"`wind_process`) did not converge ({exc.status} after {exc.iterations} "
                "iterations): no comparison.\n")
    out = still.report(folder / "report_still")
    tell.say(f"in still air: chi-square/dof {still.chi_square_per_dof:.2f}; report written "
             f"to {out}")
    # Said where the comparison is read, not only in its report.
    note = ("" if still.is_result else "\n**The fit in still air is not a result.** "
            + " ".join(f"{p}." for p in still.problems) + "\n")
    return still.fit, still.covariance, note
