"""The launch site's air from a flight log: the pad's pressure and, where the card asks for
it, the lapse rate fitted to the GNSS altitudes of the descent.

The site atmosphere (`atmosphere.SiteAtmosphere`) of an imported log is the pad pressure
(`pad_pressure`: the card's, or the median of the barometer before launch), the pad
temperature (`flight_card.pad_temperature`) and a lapse rate, the card's or, with
``"gps"``, `fit_lapse_rate`'s: in boost the receiver lags the vehicle by tens of metres,
so only the descent's fixes are fitted.
"""

from __future__ import annotations

import numpy as np
import pandas as pd
from scipy.optimize import minimize_scalar

from cpas_ocp.io.flight_card import FlightCard, card_quantity
from cpas_ocp.io.flight_events import FlightEvent
from cpas_ocp.physics.atmosphere import SiteAtmosphere

LAPSE_BOUNDS_K_M = (0.002, 0.0098)  # search range of a fitted lapse rate (to the dry adiabat)


LAUNCH_RISE_M = 10.0  # launch: the altitude has risen this far above its lowest so far (m) ...


LAUNCH_LEAD_S = 1.0  # ... and the pad's samples end this long before that (s)


MIN_PAD_SAMPLES = 10  # the pad's level is their median where the log has this many


def fit_lapse_rate(fixes: pd.DataFrame, pressure: pd.Series, times: pd.Series,
                   elevation: float, p0: float, t0: float) -> tuple[float, float, float]:
    """The lapse rate (K/m) that makes the site atmosphere's altitude of the measured
    pressure match the GPS altitudes, with a constant GPS offset.

    Returns (lapse rate, GPS offset (m), residual standard deviation (m)).
    Least squares over every fix; the offset is profiled out (its estimate is
    the mean difference).
    """
    p_at = np.interp(fixes["time"], times, pressure)
    h_gps = fixes["gps_altitude"].to_numpy()

    def residual(lapse: float) -> np.ndarray:
        site = SiteAtmosphere(elevation, p0, t0, lapse)
        d = h_gps - site.altitude_at_pressure(p_at)
        return d - d.mean()

    best = minimize_scalar(lambda lapse: float(np.sum(residual(lapse) ** 2)),
                           bounds=LAPSE_BOUNDS_K_M, method="bounded",
                           options={"xatol": 1e-6})
    lapse = float(best.x)
    site = SiteAtmosphere(elevation, p0, t0, lapse)
    offset = float(np.mean(h_gps - site.altitude_at_pressure(p_at)))
    return lapse, offset, float(np.std(residual(lapse), ddof=2))


def pad_pressure(baro: pd.DataFrame, events: dict[str, FlightEvent], card: FlightCard
                 ) -> tuple[float, str]:
    """The air pressure on the pad (Pa) and a sentence saying where it came from.

    The card's ``site.pressure`` where it gives one; else the median of the barometer's
    samples before launch, launch being the boost the accelerometer saw or, without one,
    `LAUNCH_LEAD_S` before the altitude first stands `LAUNCH_RISE_M` above its lowest
    reading so far (a log that starts on the pad); where fewer than `MIN_PAD_SAMPLES`
    precede it (the log starts at launch), the lowest reading before the rise: the
    recorder's first samples, taken as the rocket left the pad."""
    if "pressure" in card.site:
        p0 = card_quantity(card.site["pressure"], "pressure", card.source, "site.pressure")
        return p0, f"pad pressure {p0:.0f} Pa from the card's site.pressure"
    t, h = baro["time"].to_numpy(), baro["altitude"].to_numpy()
    rise = np.flatnonzero(h - np.minimum.accumulate(h) > LAUNCH_RISE_M)
    k_rise = int(rise[0]) if rise.size else len(h) - 1
    t_launch = events["boost"].time if "boost" in events else float(t[k_rise]) - LAUNCH_LEAD_S
    pad = baro[baro["time"] < t_launch]
    if len(pad) >= MIN_PAD_SAMPLES:
        p0 = float(pad["pressure"].median())
        return p0, (f"pad pressure {p0:.0f} Pa: the median of the {len(pad)} barometer "
                    f"samples before launch ({t_launch:.2f} s)")
    k = int(np.argmin(h[:k_rise + 1]))
    p0 = float(baro["pressure"].iloc[k])
    return p0, (f"pad pressure {p0:.0f} Pa: the log starts at launch (only {len(pad)} "
                f"samples before it), so the pad is its lowest reading before the climb, "
                f"at {t[k]:.2f} s; give site.pressure in the card where that is not the pad")
