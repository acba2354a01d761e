"""A descent logged only by the GNSS: its altitude as the descent's altitude channel where the
barometer's file stops in the air.

A log may be several files: an altimeter's that ends at apogee (or just after the drogue's
charge) beside a GNSS file whose 1-10 Hz fixes, each with an altitude above mean sea level,
go on to the ground.  Where the barometer does not cover the descent and the GNSS does
(`flight_events.gnss_reads_on`), the import reads the descent in the GNSS altitude:

* its datum (`gnss_offset`): a receiver's altitude differs from the site atmosphere's
  geometric altitude by a constant of metres to tens of metres (the geoid, the receiver,
  the card's elevation).  It is the median of the differences between each fix and the
  site atmosphere's altitude of the barometer's pressure at that time, over the fixes
  where both read and the vehicle moves slower than `DATUM_SPEED_M_S` (on the pad, near
  apogee: a receiver lags a climbing rocket by tens of metres, which a slow vehicle does
  not move);
* its heights as the altimeter would have read them (`gnss_channel`): the site
  atmosphere's pressure at the fix's geometric altitude (less the offset) and its
  pressure altitude, so that the steps that read an altimeter (the descent's drag areas,
  the card's events at a height, the deployment forensics) read the GNSS alike;
* its noise (`gnss_sigma`): the scatter about the local trend (`log_noise.scatter_sigma`,
  1.4826 MAD about a quadratic over `log_noise.SCATTER_WINDOW_S`), whose trend takes
  three of the window's n fixes' degrees of freedom: the scatter times sqrt(n / (n - 3))
  (3 m of white noise on a steady descent reads, over 40 seeds, 3.15 ± 0.55 m at 1 Hz,
  3.05 ± 0.32 m at 2 Hz, 2.99 ± 0.20 m at 5 Hz).  It is taken over the later half of each
  canopy's descent (`descent_sigma`, `log_noise.settled`): an opening's deceleration,
  which a local quadratic does not follow, reads as noise (over a whole 14 s drogue
  descent from apogee, 3.35 m at 5 Hz and 3.6 m at 1 Hz for 3 m; over the later halves,
  2.98 and 2.87 m over 30 seeds).

Times are on the log's own clock (s), altitudes in m, pressures in Pa.
"""

from __future__ import annotations

from itertools import pairwise

import numpy as np
import pandas as pd

from cpas_ocp.io.flight_events import sample_interval
from cpas_ocp.io.log_noise import SCATTER_WINDOW_S, scatter_sigma, settled
from cpas_ocp.physics.atmosphere import SiteAtmosphere, pressure_altitude

DATUM_SPEED_M_S = 10.0  # the GNSS's datum is read where the vehicle is slower than this (m/s)


DATUM_SPEED_WINDOW_S = 2.0  # ... its vertical speed the slope of the barometer over this (s)


TREND_PARAMETERS = 3  # the local trend the scatter is taken about is a quadratic


MIN_SIGMA_FIXES = 7  # least fixes of a later half of a descent the sigma is taken over


def gnss_sigma(t: np.ndarray, altitude: np.ndarray) -> float:
    """The GNSS altitude's noise sigma (m) from its fixes at times `t` (s): the robust scatter
    about the local quadratic trend (`log_noise.scatter_sigma`), corrected for the trend's
    three degrees of freedom among the n = `SCATTER_WINDOW_S` / dt fixes it is fitted to
    (module docstring)."""
    n = min(SCATTER_WINDOW_S, float(t[-1] - t[0])) / sample_interval(t)
    share = n / (n - TREND_PARAMETERS) if n > 2 * TREND_PARAMETERS else 1.0
    return scatter_sigma(t, altitude) * float(np.sqrt(share))


def descent_sigma(t: np.ndarray, altitude: np.ndarray, starts: list[float], t_end: float
                  ) -> float:
    """The GNSS altitude's noise sigma (m, `gnss_sigma`) over the later half of each
    canopy's descent (`log_noise.settled`: from the deployments `starts`, s, in order, to
    the next or `t_end`), pooled by fix count; over the whole phase where no half holds
    `MIN_SIGMA_FIXES` fixes."""
    counts, variances = [], []
    for a, b in pairwise([*starts, t_end]):
        sel = (t >= a) & (t <= b)
        if sel.sum() < 2:
            continue
        half = settled(t[sel], b)
        if half.sum() >= MIN_SIGMA_FIXES:
            counts.append(int(half.sum()))
            variances.append(gnss_sigma(t[sel][half], altitude[sel][half]) ** 2)
    if not counts:
        sel = (t >= starts[0]) & (t <= t_end)
        return gnss_sigma(t[sel], altitude[sel])
    return float(np.sqrt(np.dot(counts, variances) / sum(counts)))


def gnss_offset(fixes: pd.DataFrame, baro: pd.DataFrame, site: SiteAtmosphere
                ) -> tuple[float, int]:
    """The GNSS altitude's offset (m) from the site atmosphere's geometric altitude, and the
    fixes it was read from: the median of each fix's ``gps_altitude`` less the site's
    altitude of the barometer's ``pressure`` (Pa) at its time, over the fixes within the
    barometer's span where its vertical speed (the slope over `DATUM_SPEED_WINDOW_S`) is
    below `DATUM_SPEED_M_S`.  (0, 0) where there are none."""
    tb, hb = baro["time"].to_numpy(float), baro["altitude"].to_numpy(float)
    tg = fixes["time"].to_numpy(float)
    inside = (tg >= tb[0]) & (tg <= tb[-1])
    half = 0.5 * DATUM_SPEED_WINDOW_S
    lo, hi = np.searchsorted(tb, tg - half), np.searchsorted(tb, tg + half, side="right")
    slow = np.zeros(tg.size, dtype=bool)
    for k in np.flatnonzero(inside):
        if hi[k] - lo[k] >= 3:
            ts, hs = tb[lo[k]:hi[k]], hb[lo[k]:hi[k]]
            slow[k] = abs(float(np.polyfit(ts - ts[0], hs, 1)[0])) < DATUM_SPEED_M_S
    if not slow.any():
        return 0.0, 0
    p = np.interp(tg[slow], tb, baro["pressure"].to_numpy(float))
    diff = fixes["gps_altitude"].to_numpy(float)[slow] - np.asarray(
        site.altitude_at_pressure(p), dtype=float).ravel()
    return float(np.median(diff)), int(slow.sum())


def gnss_channel(fixes: pd.DataFrame, site: SiteAtmosphere, offset: float) -> pd.DataFrame:
    """The GNSS fixes as an altimeter's samples: ``time`` (s), ``altitude`` (m, the pressure
    altitude of the site atmosphere's pressure at the fix's altitude less `offset`) and
    ``pressure`` (Pa)."""
    geometric = fixes["gps_altitude"].to_numpy(float) - offset
    pressure = np.asarray(site.pressure(geometric), dtype=float).ravel()
    return pd.DataFrame({"time": fixes["time"].to_numpy(float),
                         "altitude": np.asarray(pressure_altitude(pressure), float).ravel(),
                         "pressure": pressure})
