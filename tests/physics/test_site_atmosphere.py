"""The site atmosphere above its tropopause: isothermal, as the standard atmosphere's
lower stratosphere, so that heights a solver's iterate wanders to read finite air.

With the standard's own air (sea level, 288.15 K, 101325 Pa, 6.5 K/km) the site
atmosphere is the standard atmosphere at every height, the tropopause at 11 km included;
a hot, steep site's air stays finite and positive up to 100 km (its linear temperature
alone reaches zero 31 km up, beyond which pressure and density were NaN), and the
altitude of a pressure inverts the pressure there too.
"""

from __future__ import annotations

import casadi as ca
import numpy as np
import pytest

from cpas_ocp.physics.atmosphere import (
    ISA_P0_PA,
    ISA_T0_K,
    ISA_TROPOPAUSE_K,
    R_AIR,
    SiteAtmosphere,
    StandardAtmosphere,
    density_at,
)
from cpas_ocp.physics.units import G0

HEIGHTS = np.array([0.0, 5e3, 11e3, 15e3, 20e3, 44e3, 60e3, 100e3])


def test_the_standard_s_air_is_the_standard_atmosphere_above_11_km_too() -> None:
    site = SiteAtmosphere(0.0, ISA_P0_PA, ISA_T0_K)
    assert site.tropopause_m == pytest.approx(11000.0)
    np.testing.assert_allclose(density_at(site, HEIGHTS[:5]),
                               density_at(StandardAtmosphere(), HEIGHTS[:5]), rtol=1e-12)


def test_a_hot_steep_site_reads_finite_air_above_where_its_temperature_would_reach_zero(
        ) -> None:
    """A 310 K site at 1400 m with the dry adiabat's 9.8 K/km: its linear temperature reaches
    zero 31.6 km above the site; above its tropopause (216.65 K, 9.5 km up) the air is
    isothermal, its density falling by e every R T / g0 (6.3 km)."""
    site = SiteAtmosphere(1400.0, 86300.0, 310.0, 0.0098)
    h_t = site.tropopause_m
    assert h_t == pytest.approx(1400.0 + (310.0 - ISA_TROPOPAUSE_K) / 0.0098)
    rho = density_at(site, HEIGHTS)
    assert np.all(np.isfinite(rho)) and np.all(rho > 0.0) and np.all(np.diff(rho) < 0.0)
    scale = R_AIR * ISA_TROPOPAUSE_K / G0
    assert density_at(site, h_t + scale)[0] == pytest.approx(
        density_at(site, h_t)[0] / np.e, rel=1e-9)
    # Continuous at the tropopause; the temperature holds there above it.
    assert density_at(site, h_t + 1e-3)[0] == pytest.approx(density_at(site, h_t - 1e-3)[0],
                                                            rel=1e-6)
    assert float(site.temperature(h_t + 5e4)) == pytest.approx(ISA_TROPOPAUSE_K)
    # Symbolic and numeric heights agree, and the pressure inverts above and below.
    hs = ca.SX.sym("h")
    f = ca.Function("p", [hs], [site.pressure(hs)])
    p = np.array([float(f(h)) for h in HEIGHTS])
    np.testing.assert_allclose(p, site.pressure(HEIGHTS + 0.0), rtol=1e-12)
    np.testing.assert_allclose(site.altitude_at_pressure(p), HEIGHTS, atol=1e-6)
    # A gradient a solver reads there is finite too.
    grad = ca.Function("g", [hs], [ca.jacobian(site.density(hs), hs)])
    assert all(np.isfinite(float(grad(h))) for h in HEIGHTS)
