"""Real flight logs into test folders: a flight card plus a flight-computer log.

A *flight card* (JSON; the built-in ones are problems with ``"kind":
"flight_log"``) holds what the log does not: the vehicle's descent mass and
forebody drag area, the parachutes and the flight state that deploys each,
the launch site (elevation, surface air density, lapse rate or ``"gps"``),
the model block to reconstruct with, and the published nominal drag areas
to compare against.

`import_flight` turns a cleaned log (`flight_record.FlightRecord`, from any
reader: `altus_metrum`, `cats_vega`, `column_map`) and a card into a test
folder:

* the card's deployments name flight states (``drogue``, ``main``): the
  log's own where it logged states, else the events `flight_events`
  detects in the accelerometer and the altimeter (the charge near apogee,
  or apogee itself, is ``drogue``, the next ``main``);
* phase: from the first deployment to touchdown (`flight_events.touchdown`:
  the altitude has stopped falling and the accelerometer is at rest), less
  `TOUCHDOWN_MARGIN_S` (or three of touchdown's sigmas); a log that ends
  before touchdown ends the phase at its end, and the import says so;
* the descent's altitude channel: the barometer's or, where the altimeter's
  file stops in the air and a GNSS altitude reads on to the ground, the
  GNSS's (`gnss_descent`): touchdown, the descent's drag areas and forensics
  read it, and a note says so; each file is read over its own span, and a
  channel that stops inside the phase is left out of what it does not read;
* events: each deployment as a ``mortar_fire`` of its canopy, with the state
  machine's timing sigma `EVENT_SIGMA_S` or the detector's sigma;
* every series runs `SERIES_MARGIN_S` beyond the phase, so that each
  covers it;
* ``baro.csv``: pressure altitude (m); samples from `EVENT_SIGMA_S` before to
  `EJECTION_EXCLUDE_S` after a deployment are left out (the ejection charge's pressure pulse reads
  as a 150 m jump in one sample);
* ``gps_altitude.csv``: GPS altitude (m MSL) at each new fix with at least
  four satellites, where the lapse rate is fitted to it or it carries the
  descent (then less its datum offset, at a sigma from its scatter);
* ``accelerometer.csv`` (where the log has an accelerometer): axial
  acceleration (m/s^2, 1 g subtracted), fitted by the `axial_accelerometer`
  effect, less the charge samples and, in each
  later canopy's opening, the samples above the drag ceiling
  (`drag_ceiling`: the shock cord's snatch, which no drag model makes; the
  largest is the full-open event below);
* a ``full_open`` event for each later canopy whose opening the
  accelerometer shows (`opening_peak`) where the accelerometer's series is
  not written (it stops inside the phase): the time of the largest axial
  specific force in the `OPENING_WINDOW_S` after the charge, with one
  accelerometer sample interval as its sigma.  On a hobby rocket that peak
  is often the snatch of the elastic shock cord, when the canopy has stopped
  ahead of the vehicle; it needs no attitude (the axis swinging against the
  riser scales the reading, not its timing).  Where the series is written,
  the fit reads the opening from the samples themselves, and the peak's time
  is reported (``events_s``) but not fitted: a snatch before the fill ends
  would otherwise be forced onto the fill's end at a sample's sigma.  The
  first canopy's is not taken: it opens near apogee, where the load barely
  rises;
* the site atmosphere (`atmosphere.SiteAtmosphere`): the pad pressure (median
  before launch), the temperature from the card's surface density
  (T = p / (R rho)), and the lapse rate from the card or, with ``"gps"``,
  fitted to the GPS fixes of the descent (`fit_lapse_rate`; in boost the
  receiver lags the vehicle by tens of metres);
* noise sigmas from the data: the altimeter's per canopy phase, from its
  scatter about the local trend (`log_noise.scatter_sigma`; under a 30 m/s drogue the
  static pressure swings by metres over seconds), the GPS altitude's from the
  lapse-rate fit's residuals.  A later canopy's altimeter sigma applies from
  the time its descent has settled (`log_noise.settled_time`), not from its deployment:
  until then the vehicle still falls fast and is jerked about by the opening,
  and the static port errs as it did under the canopy before.  The
  accelerometer's sigma is the RMS of its scatter about the local trend
  (`log_noise.scatter_rms`: the swing's jolts are part of the swing), under each
  canopy's steady descent and apart over each later canopy's opening (from
  the charge until the descent has settled, at least `OPENING_WINDOW_S`),
  where the shock cord bounces the body by g's within a sample.

The import is a sequence of named steps (`import_steps.STEPS`: read, events,
deployments, phase, site air, descent drag areas, each sensor's series, model), each
a function of its own.  The folder is written to a temporary sibling and moved into
place only once it loads, so a failed import leaves nothing behind.
"""

from __future__ import annotations

import json
import shutil
import tempfile
from pathlib import Path
from typing import Any

import pandas as pd

from cpas_ocp.errors import InputError
from cpas_ocp.io.altus_metrum import AltusLog
from cpas_ocp.io.flight_card import FlightCard
from cpas_ocp.io.flight_record import FlightRecord
from cpas_ocp.io.flight_test import MANIFEST, load_test, validate_manifest
from cpas_ocp.io.import_reports import ImportSummary
from cpas_ocp.io.import_steps import STEPS, LogImport
from cpas_ocp.io.strict_json import json_text


def import_flight(log: FlightRecord | AltusLog, card: FlightCard, out: str | Path,
                  still_air: bool = False) -> ImportSummary:
    """Write the test folder of `log` under `card` to `out` (see the module docstring);
    `still_air`: the default model (`rocket_model`) without the air's motion."""
    record = log if isinstance(log, FlightRecord) else log.record()
    d = LogImport(record, card, still_air)
    for step in STEPS:
        step(d)
    try:
        validate_manifest(d.manifest, card.source)
    except InputError as exc:
        raise blamed(exc, card.source, d.source, MANIFEST) from None
    assert d.site is not None
    summary = ImportSummary(
        record.recorder, (d.t_begin, d.t_end),
        {**d.deploy, **{f"{name} full open": t for name, (t, _) in d.full_open.items()},
         "touchdown": d.t_down}, d.site, d.lapse_fit,
        d.baro_sigmas, {name: len(frame) for name, frame in d.files.items()},
        {**record.dropped, **d.dropped},
        d.accel_sigmas, d.snatches, d.events, [*record.notes, *d.notes], card.nominal,
        {} if d.forensics is None else {c.name: c.as_dict() for c in d.forensics.canopies},
        d.carrier, d.gnss_sigma if d.carrier == "gps_altitude" else None, d.turned_over)
    _write_folder(Path(out), d.manifest, d.files, summary, card.source, d.source)
    return summary


# Manifest fields the import copies from the card; the others it derives from the log.
CARD_FIELDS = ("name", "label", "vehicle", "parachutes", "model")


def blamed(exc: InputError, card_source: str, log_source: str, written: str) -> InputError:
    """What the test folder's loading refused in the file `written` of an import, named
    against where it came from: the card (the manifest's vehicle, canopies and model) or
    the log (the phase, events, sensors, atmosphere)."""
    if written == MANIFEST and exc.field.startswith(CARD_FIELDS):
        return InputError(card_source, exc.field, f"{exc.expectation} (in the manifest the "
                          "card makes)")
    return InputError(log_source, f"(imported as {written}: {exc.field})", exc.expectation)


def _write_folder(out: Path, manifest: dict[str, Any], files: dict[str, pd.DataFrame],
                  summary: ImportSummary, card_source: str, log_source: str) -> None:
    """Write into a temporary sibling, check that it loads, then move it to `out`.  What the
    loading refuses in the manifest is named against where it came from: the card (its
    vehicle, canopies and model) or the log (the phase, events, sensors, atmosphere)."""
    if out.exists() and any(out.iterdir()):
        raise InputError(str(out), "(folder)", "a new or empty folder for the test")
    out.parent.mkdir(parents=True, exist_ok=True)
    tmp = Path(tempfile.mkdtemp(prefix=f".{out.name}-", dir=out.parent))
    try:
        for name, frame in files.items():
            frame.to_csv(tmp / name, index=False)
        (tmp / MANIFEST).write_text(json.dumps(manifest, indent=2) + "\n")
        (tmp / "import.json").write_text(json_text(summary.to_dict()))
        try:
            load_test(tmp)
        except InputError as exc:
            written = Path(exc.file)
            if written.parent != tmp:
                raise
            raise blamed(exc, card_source, log_source, written.name) from None
        if out.exists():
            out.rmdir()
        tmp.rename(out)
    finally:
        if tmp.exists():
            shutil.rmtree(tmp)
