"""A flight log's import, and a flight's recorders compared, in the terminal and in
markdown."""

from __future__ import annotations

import numpy as np

from cpas_ocp.io.import_reports import ImportSummary
from cpas_ocp.io.recorder_clocks import RecorderEstimates, clock_offset
from cpas_ocp.precision import with_sigma


def import_text(summary: ImportSummary) -> str:
    """A few lines for the terminal: the phase and events, the launch site's air, the
    sensors' sigmas, each opening's snatch, the flight events, the notes and the samples
    kept and dropped."""
    events = ", ".join(f"{k} {v:.2f} s" for k, v in summary.events.items())
    site = summary.site
    lines = [f"{summary.recorder} log: phase {summary.phase[0]:.2f}-{summary.phase[1]:.2f} s; "
             f"{events}",
             f"site: {site.elevation_m:.0f} m, {site.pressure_pa:.0f} Pa, "
             f"{site.temperature_k:.1f} K, lapse rate {1e3 * site.lapse_rate_k_m:.2f} K/km"]
    if summary.lapse_fit is not None:
        lines.append(f"  (lapse rate fitted to the GPS fixes: GPS offset "
                     f"{summary.lapse_fit[1]:+.1f} m, residual sigma "
                     f"{summary.lapse_fit[2]:.1f} m)")
    if summary.baro_sigma_m:
        lines.append("altimeter sigma per canopy phase: "
                     + ", ".join(f"{s:.2f} m" for s in summary.baro_sigma_m))
    if summary.descent_channel == "gps_altitude":
        lines.append(f"the descent is read in the GNSS altitude (the altimeter stops in the "
                     f"air), sigma {summary.gnss_sigma_m:.2f} m from its scatter")
    if summary.accel_sigma:
        lines.append("accelerometer sigma per steady descent and opening (the swing "
                     "counted): " + ", ".join(f"{s:.2f} m/s²" for s in summary.accel_sigma))
    for name, snatch in summary.snatches.items():
        lines.append(f"{name}'s opening: {snatch}")
    if summary.flight_events:
        lines.append("flight events: " + ", ".join(
            f"{k} {with_sigma(e.time, e.sigma)} s ({e.source})"
            for k, e in summary.flight_events.items()))
    lines.extend(f"deployment: {entry['sentence']}" for entry in summary.deployments.values())
    lines.extend(f"note: {n}" for n in summary.notes)
    lines.append("samples: " + ", ".join(f"{k} {v}" for k, v in summary.samples.items())
                 + "; dropped: " + ", ".join(f"{k} {v}" for k, v in summary.dropped.items()))
    return "\n".join(lines)


def recorders_text(recorders: list[RecorderEstimates]) -> str:
    """Markdown comparing the recorders of one flight: the clock offset of each to the
    first, and each shared drag area and start time with its sigma, start times in the
    first recorder's clock, and every difference from the first in units of the
    combined sigma (independent fits)."""
    first = recorders[0]
    offsets = [0.0] + [clock_offset(first.log, r.log) for r in recorders[1:]]
    lines = ["## The recorders compared", "",
             f"Start times are in the clock of {first.log.path.name}: each later recorder's "
             "clock offset is measured on the motor's burn (`recorder_clocks`). "
             "Differences are from the first recorder, in combined σ.", ""]
    for r, offset in zip(recorders[1:], offsets[1:], strict=True):
        lines.append(f"- {r.log.path.name} reads {offset:+.3f} s against {first.log.path.name}.")
    lines += ["", "| parameter | " + " | ".join(r.log.path.name for r in recorders) +
              " | difference / σ |", "|---" * (len(recorders) + 2) + "|"]
    for name, (value0, std0) in first.estimates.items():
        cells, z = [with_sigma(value0, std0)], []
        for r, offset in zip(recorders[1:], offsets[1:], strict=True):
            if name not in r.estimates:
                cells.append("—")
                continue
            value, std = r.estimates[name]
            value -= offset if name.startswith("t_start") else 0.0
            cells.append(with_sigma(value, std))
            z.append(f"{(value - value0) / np.hypot(std, std0):+.1f}")
        lines.append(f"| {name} | " + " | ".join(cells) + f" | {', '.join(z)} |")
    return "\n".join(lines) + "\n"
