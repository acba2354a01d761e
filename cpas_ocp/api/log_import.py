"""A recorder's log, as it came off the recorder, into a test folder under a flight card
(the command line's `import`).  Reading a log needs pandas and scipy (and CasADi's small
Python module, for the atmosphere): this module imports nothing of the estimator, so the
command starts without it or matplotlib."""

from __future__ import annotations

from pathlib import Path

from cpas_ocp.errors import InputError
from cpas_ocp.io.flight_card import FlightCard, card_reading, load_card
from cpas_ocp.io.flight_log import import_flight
from cpas_ocp.io.import_reports import ImportSummary
from cpas_ocp.io.log_formats import read_flight_log


def import_log(log: str | Path, card: str | FlightCard, out: str | Path,
               log_format: str | None = None, columns: str | Path | None = None,
               still_air: bool = False) -> ImportSummary:
    """A flight log, as it came off the recorder, into a test folder at `out` under the
    flight `card` (a built-in name, a card file or a loaded card): read as `log_format` (a
    built-in format: altus, cats) or through the column map `columns`, else as the card's
    ``data`` block says (`cpas-ocp import`)."""
    card = card if isinstance(card, FlightCard) else load_card(str(card))
    if log_format is None and columns is None:  # the card says how its logs are read
        if card.data_format is None and card.data_columns is None:
            raise InputError(card.source, "data.format/data.columns", "one of the two, "
                             "saying how the card's logs are read (a built-in format, or a "
                             "column map), or --format/--columns on the command line")
        log_format, columns = card_reading(card)
    record = read_flight_log(log, log_format, columns, f"{card.source}: data.columns")
    return import_flight(record, card, out, still_air)
