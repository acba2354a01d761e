"""The classical fourth-order Runge-Kutta step, shared by the simulator, the
shooting transcription and the time-shifted sensor models."""

from __future__ import annotations

from typing import TypeVar

import casadi as ca

S = TypeVar("S", ca.SX, ca.MX)


def rk4(f: ca.Function, x: S, t: S, h: S | float, p: S, c: S) -> S:
    """x(t + h) from x(t) by one RK4 step of x' = f(x, t, p, c); h may be negative."""
    k1 = f(x, t, p, c)
    k2 = f(x + h / 2 * k1, t + h / 2, p, c)
    k3 = f(x + h / 2 * k2, t + h / 2, p, c)
    k4 = f(x + h * k3, t + h, p, c)
    return x + h / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
