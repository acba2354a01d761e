"""Drag-area growth laws of a canopy stage (paper Eqs. 5 and 6).

A stage starts at the inflation start time t_i (bag strip or disreef) from the
previous stage's drag area CdS_{i-1} and grows to its own CdS_i.

* Finite mass (Pilots, Mains), Eq. 5:
  CdS(t) = CdS_{i-1} + (CdS_i - CdS_{i-1}) ((t - t_i)/t_f)^expopen, for
  t_i <= t <= t_i + t_f, then CdS_i.
* Infinite mass (FBCPs, Drogues), Eq. 5 then Eq. 6: the same curve rises to
  the peak Ck CdS_i at t_fp after t_i, then decays as
  CdS_peak Ck^((t_fp + t_i - t)/t_k), reaching CdS_i exactly t_k after the
  peak, and holds CdS_i.

Fill time is the fill constant times a fill length over the stage's start
airspeed V_i: t_f = n L / V_i.  Two fill lengths are supported (name them in
the problem):

* ``"diameter"``: L = D_o, the paper's normalisation to reference diameters;
* ``"growth_scaled"``: L = D_o sqrt((CdS_i - CdS_{i-1}) / CdS_o), the CPAS
  Model Memo form that scales by the growth fraction of the stage.

Infinite-mass stages are parameterised by the peak fill constant n_p
(t_fp = n_p L / V_i), which is what dispersions are drawn in; the standard
fill constant follows from `fill_constant_from_peak`.

Every corner of the curves is rounded over +-`CORNER_S` (5 ms), shorter
than any sensor's sampling interval: the start (the elapsed time t - t_i is a
C2 smooth ramp, `smooth_ramp`, so a stage begins CORNER_S before t_i with
zero growth), the over-inflation peak and the end of settling (infinite
mass), and the end of the fill (finite mass), each with a C2 smoothstep.  No
measurable prediction changes, but the estimation problem becomes twice
differentiable in every parameter (at the start, for expopen above 0.5,
since the ramp grows as the fourth power; a floor of 1e-12 under tau leaves a
step of (CdS_i - CdS_{i-1}) 1e-12^expopen where the stage switches on: a
millionth of the stage's growth at expopen 0.5, far below the noise).
Unrounded, the RK4 integral of a kinked drag area is itself kinked wherever
a corner crosses an integration point,
and Ipopt cycled: the `main2` fit, with its finite-mass fill ends sharp,
oscillated between two points 0.2 apart in chi-square for 500 iterations.

All functions accept CasADi symbols or floats and return CasADi expressions.
Times in s, drag areas in m^2, lengths in m, speeds in m/s.
"""

from __future__ import annotations

from typing import Literal

import casadi as ca

FillLength = Literal["diameter", "growth_scaled"]
FILL_LENGTHS: tuple[str, ...] = ("diameter", "growth_scaled")

_TINY = 1e-12  # keeps pow() and log() differentiable at the very start of a stage
CORNER_S = 0.005  # half-width of the rounding of the curve's corners (s)

Expr = ca.SX | ca.MX | float


def fill_length(form: FillLength, diameter: Expr, cds_prev: Expr, cds: Expr,
                cds_full_open: Expr) -> Expr:
    """Fill length L (m) such that t_f = n L / V_i."""
    if form == "diameter":
        return diameter
    if form == "growth_scaled":
        return diameter * ca.sqrt(ca.fmax(cds - cds_prev, _TINY) / cds_full_open)
    raise ValueError(f"unknown fill-length form {form!r}; expected one of {FILL_LENGTHS}")


def fill_time(fill_constant: Expr, length: Expr, v_start: Expr) -> Expr:
    """Time (s) for a fill constant over a fill length at the start airspeed: n L / V_i."""
    return fill_constant * length / v_start


def peak_ratio(cds_prev: Expr, cds: Expr, ck: Expr) -> Expr:
    """x = (Ck CdS_i - CdS_{i-1}) / (CdS_i - CdS_{i-1}), the Eq. 5 level reached at the peak."""
    return (ck * cds - cds_prev) / ca.fmax(cds - cds_prev, _TINY)


def fill_constant_from_peak(n_p: Expr, cds_prev: Expr, cds: Expr, ck: Expr,
                            expopen: Expr) -> Expr:
    """Standard fill constant n from the peak fill constant: n = n_p x^(-1/expopen)."""
    return n_p * peak_ratio(cds_prev, cds, ck) ** (-1.0 / expopen)


def peak_fill_constant(n: Expr, cds_prev: Expr, cds: Expr, ck: Expr, expopen: Expr) -> Expr:
    """Peak fill constant n_p from the standard one: n_p = n x^(1/expopen)."""
    return n * peak_ratio(cds_prev, cds, ck) ** (1.0 / expopen)


def smoothstep(x: Expr) -> Expr:
    """C2 step from 0 (x <= -1) to 1 (x >= 1): 1/2 + (15x - 10x^3 + 3x^5)/16 in between."""
    s = ca.fmin(ca.fmax(x, -1.0), 1.0)
    return 0.5 + s * (15.0 - 10.0 * s**2 + 3.0 * s**4) / 16.0


def smooth_ramp(u: Expr) -> Expr:
    """C2 ramp (s): 0 for u <= -CORNER_S, u for u >= CORNER_S, the integral of the
    smoothstep in between, so that a curve in powers of it starts without a kink."""
    x = ca.fmin(ca.fmax(u / CORNER_S, -1.0), 1.0)
    inner = (x + 1.0) / 2.0 + (7.5 * x**2 - 2.5 * x**4 + 0.5 * x**6 - 5.5) / 16.0
    return ca.if_else(u >= CORNER_S, u, CORNER_S * inner)


def stage_started(t: Expr, t_start: Expr) -> Expr:
    """Whether a stage's curve applies at t: from CORNER_S before its start time."""
    return t >= t_start - CORNER_S


def infinite_mass_cds(t: Expr, t_start: Expr, cds_prev: Expr, cds: Expr, ck: Expr,
                      n_p: Expr, expopen: Expr, t_k: Expr, length: Expr,
                      v_start: Expr) -> Expr:
    """Drag area (m^2) of an infinite-mass stage with over-inflation, for t >= t_start.

    Rises per Eq. 5 to Ck*CdS_i at t_fp = n_p L / V_i, decays per Eq. 6 over
    t_k to CdS_i, then holds; corners rounded over +-CORNER_S.  The caller
    selects this branch where `stage_started`.
    """
    t_fp = fill_time(n_p, length, v_start)
    tau = ca.fmax(smooth_ramp(t - t_start) / t_fp, _TINY)
    after_peak = t - t_start - t_fp
    # Each branch is evaluated a little beyond its own range so the blend is smooth;
    # the clamps keep the unused far ends finite.  Eq. 5 to the peak reads
    # CdS_{i-1} + (CdS_i - CdS_{i-1}) x tau^expopen with x = `peak_ratio`, i.e.
    # (Ck CdS_i - CdS_{i-1}) tau^expopen: written without the division, the curve
    # stays finite where a guess puts CdS_i at or below CdS_{i-1} (the ratio's
    # denominator would be clamped to 1e-12 there and the drag area reach 1e13 m^2).
    rising = cds_prev + (ck * cds - cds_prev) * ca.fmin(tau, 2.0) ** expopen
    decaying = ck * cds * ck ** (-ca.fmax(after_peak, -CORNER_S) / t_k)
    to_decay = smoothstep(after_peak / CORNER_S)
    to_steady = smoothstep((after_peak - t_k) / CORNER_S)
    return (1.0 - to_decay) * rising + to_decay * ((1.0 - to_steady) * decaying
                                                   + to_steady * cds)


def finite_mass_cds(t: Expr, t_start: Expr, cds_prev: Expr, cds: Expr, n: Expr,
                    expopen: Expr, length: Expr, v_start: Expr) -> Expr:
    """Drag area (m^2) of a finite-mass stage (Eq. 5) where `stage_started`; the end of
    the fill rounded over +-CORNER_S."""
    t_f = fill_time(n, length, v_start)
    tau = ca.fmax(smooth_ramp(t - t_start) / t_f, _TINY)
    rising = cds_prev + (cds - cds_prev) * ca.fmin(tau, 2.0) ** expopen
    filled = smoothstep((t - t_start - t_f) / CORNER_S)
    return (1.0 - filled) * rising + filled * cds
