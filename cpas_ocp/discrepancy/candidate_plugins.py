"""Plug-in effects written from a residual's signature, where no library effect explains it.

When the diagnosis confirms nothing but the residuals keep significant
structure (`Diagnosis.structure`), the structure's signature points to the
kind of physics that is missing.  Three signatures have a parametric answer
that can be written down without knowing more:

* **a periodic line** at f Hz in some windows: the canopies' drag area
  modulated at f, for each canopy from the first of its own windows the line
  is seen in to the last one's end (canopy breathing, a coning or swinging
  canopy): CdS (1 + g_P(t) (a_P cos 2 pi f (t - t_P) + b_P sin 2 pi f
  (t - t_P))), with g_P a smooth gate and the in-phase and quadrature
  amplitudes a_P, b_P linear (null 0); f starts at the found value and is
  estimated;
* **a load-cell residual that follows the load's level** (correlated with the
  tension or the drag area of its own canopy, or the dynamic pressure): a load-cell gain that
  varies with the tension, reading = T (1 + k_P T / T_ref), k_P the change of
  gain at the phase's peak tension T_ref (null 0);
* **a residual that follows altitude** (a GPS or an altimeter): a horizontal
  wind that changes with height on top of the atmosphere's, a cubic Legendre
  series over the phase's altitude span (offset, shear, curvature and an
  S-shaped layer term), east and north (null 0).  A straight line in
  altitude leaves most of a shear layer's S for other effects: on `fbcp`
  flown through one, a GPS lag stayed in the final model to take it up.

Each proposal is Python source: a plug-in file with its physics in its
docstring and its constants at the top, for the user to read, edit and pass
to `--plugin`.  `discovery.discover` writes each to a file, loads it as a
plug-in and tests it the way the diagnosis tests a library effect (a score
test at the fit and a confirming refit from it), so the file is tested
exactly as written.
"""

from __future__ import annotations

from dataclasses import dataclass
from string import Template

import numpy as np

from cpas_ocp.discrepancy.diagnosis import Diagnosis
from cpas_ocp.discrepancy.residual_diagnosis import PERIODICITY, Finding
from cpas_ocp.discrepancy.signatures import Correlation
from cpas_ocp.estimation.estimator import Fit
from cpas_ocp.io.model_spec import ModelSpec

# Findings at frequencies within this share of the strongest line, or within one
# frequency bin of its window, are the same line seen in another channel or window.
SAME_LINE_SHARE = 0.1
# Fewest cycles of a line in its window for it to be an oscillation: a "line" with a
# period near the window's length is a drift, which any slow signature fits as well.
MIN_CYCLES = 3.0
# A periodic window that ends within this time of the phase's end leaves the gate open.
OPEN_END_S = 0.5
# Signatures of the load's level: a load-cell residual correlated with one of them asks
# for a gain that varies with the load.
LOAD_LEVEL = ("tension", "cds", "dynamic_pressure")


@dataclass(frozen=True)
class Proposal:
    """A plug-in proposed from a signature: its effect name, the finding that asked for it
    (one line), and the plug-in file's text."""

    name: str
    reason: str
    source: str

    @property
    def file_name(self) -> str:
        return f"{self.name}.py"


def propose(diagnosis: Diagnosis, spec: ModelSpec) -> list[Proposal]:
    """The plug-ins the diagnosis's unexplained structure asks for (none where it has none):
    a drag-area modulation, a tension-dependent load-cell gain, a wind profile, in that
    order; effects the fitted model (`spec`) already has are not proposed."""
    structure = diagnosis.structure
    fit = diagnosis.fit
    canopy_of = {w.name: w.parachute for w in diagnosis.windows}
    out = [p for p in (_periodic(structure, fit, canopy_of), _load_gain(structure, fit),
                       _wind_profile(structure, fit)) if p is not None]
    return [p for p in out if p.name not in spec.effect_names]


def _base(name: str) -> str:
    """The signature kind of a signature name: ``tension[drogue1]`` -> ``tension``."""
    return name.split("[")[0]


def _periodic(structure: list[Finding], fit: Fit, canopy_of: dict[str, str]
              ) -> Proposal | None:
    """A drag-area modulation at the strongest line, gated for each canopy from the first
    to the last of that canopy's own windows the line is seen in (the union of all
    where a canopy has none: its amplitudes may still be small but not zero).  Two
    canopies of a cluster open at different times and breathe from their own openings:
    one gate for both, opened at the earlier, asks the later canopy to breathe while
    it is still filling."""
    lines = [f for f in structure if PERIODICITY in f.rejected
             and f.frequency_hz * (f.t1 - f.t0) >= MIN_CYCLES]
    if not lines:
        return None
    top = min(lines, key=lambda f: f.periodicity_p)
    f0 = top.frequency_hz
    same = [f for f in lines if abs(f.frequency_hz - f0)
            <= max(SAME_LINE_SHARE * f0, 1.0 / max(f.t1 - f.t0, 1e-9))]
    t_end = float(fit.t[-1]) - OPEN_END_S

    def span(findings: list[Finding]) -> str:
        t0, t1 = min(f.t0 for f in findings), max(f.t1 for f in findings)
        return f"({t0:.3f}, {'math.inf' if t1 >= t_end else f'{t1:.3f}'})"

    gates = {c.name: span([f for f in same if canopy_of.get(f.window) == c.name] or same)
             for c in fit.test.parachutes}
    where = ", ".join(sorted({f"{f.sensor} {f.window}" for f in same}))
    reason = (f"a {f0:.2f} Hz line in {where} (strongest: {top})")
    windows = "".join(f"\n    {name!r}: {gate}," for name, gate in gates.items())
    return Proposal("drag_area_modulation", reason, _PERIODIC.substitute(
        frequency=f"{f0:.4f}", windows=windows, reason=_wrap(reason)))


def _strongest(structure: list[Finding], sensors: dict[str, str | None] | None,
               signatures: tuple[str, ...]) -> tuple[Finding, Correlation] | None:
    """The finding (of `sensors`, or of any sensor) and its significant correlation with a
    signature of one of the kinds `signatures` that has the smallest p-value; None where
    there is none.  `sensors` maps each sensor to its own canopy (None for a vehicle
    sensor): a signature of another canopy (``cds[drogue2]`` for the load cell of
    drogue1) is no signature of that sensor, only its own canopy's or a shared
    quantity's (``dynamic_pressure``).  Two canopies' drag areas and loads rise
    together, so one canopy's residual correlates with the other's too; a gain
    proposed from that correlation was fitted with opposite signs on two identical
    cells."""
    def own(f: Finding, c: Correlation) -> bool:
        canopy = None if sensors is None else sensors.get(f.sensor)
        index = c.signature.partition("[")[2].rstrip("]")
        return canopy is None or not index or index == canopy

    hits = [(f, c) for f in structure if sensors is None or f.sensor in sensors
            for c in f.correlations
            if c.signature in f.rejected and _base(c.signature) in signatures and own(f, c)]
    return min(hits, key=lambda h: h[1].p_value) if hits else None


def _load_gain(structure: list[Finding], fit: Fit) -> Proposal | None:
    cells = {s.name: s.parachute for s in fit.test.sensors_of("load_cell")}
    hit = _strongest(structure, cells, LOAD_LEVEL)
    if hit is None:
        return None
    f, c = hit
    q = fit.quantities()
    peaks = [float(np.max(np.abs(q[k]))) for k in q if _base(k) == "tension"]
    t_ref = _round_up(max(peaks, default=10_000.0))
    reason = (f"{f.sensor} in {f.window} correlates with {c.signature} (r = {c.r:+.2f}, "
              f"p {c.p_value:.2g})")
    return Proposal("tension_gain", reason, _LOAD_GAIN.substitute(
        t_ref=f"{t_ref:.0f}", reason=_wrap(reason)))


def _wind_profile(structure: list[Finding], fit: Fit) -> Proposal | None:
    hit = _strongest(structure, None, ("altitude",))
    if hit is None:
        return None
    f, c = hit
    h = fit.quantities()["altitude"]
    top, bottom = float(np.max(h)), float(np.min(h))
    reason = (f"{f.sensor} {f.channel} in {f.window} correlates with altitude "
              f"(r = {c.r:+.2f}, p {c.p_value:.2g})")
    return Proposal("wind_profile", reason, _WIND_PROFILE.substitute(
        middle=f"{0.5 * (top + bottom):.1f}", half_span=f"{max(0.5 * (top - bottom), 1.0):.1f}",
        reason=_wrap(reason)))


def _round_up(value: float) -> float:
    """`value` rounded up to two significant figures (a reference load that reads well)."""
    magnitude = 10.0 ** (np.floor(np.log10(value)) - 1)
    return float(np.ceil(value / magnitude) * magnitude)


def _wrap(text: str, width: int = 76) -> str:
    """`text` broken into lines of at most `width` characters, for a docstring."""
    lines, line = [], ""
    for word in text.split():
        if line and len(line) + 1 + len(word) > width:
            lines.append(line)
            line = word
        else:
            line = f"{line} {word}" if line else word
    return "\n".join([*lines, line])




def _header(dataclass_names: str = "dataclass", effect_names: str = "Effect") -> str:
    """A plug-in file's imports, with the names it takes from dataclasses and effects."""
    return (f"from __future__ import annotations\n\nimport math\nfrom dataclasses import "
            f"{dataclass_names}\n\nimport casadi as ca\n\nfrom cpas_ocp.physics.effects "
            f"import {effect_names}\nfrom cpas_ocp.physics.parameters import Parameter, "
            "param_name\n")


_PERIODIC = Template('''"""Drag-area modulation at the residual's frequency (proposed by cpas-ocp).

Proposed from the residual's signature:
$reason

Every canopy P's drag area is CdS (1 + g_P(t) (a cos 2 pi f (t - t_P)
+ b sin 2 pi f (t - t_P))): canopy breathing, or a coning or swinging
canopy seen through its drag.  g_P is a smooth gate, 0 before the start t_P
of P's window in WINDOWS_S and 1 RAMP_S after it (and back to 0 over RAMP_S
before the window's end where that is finite): each canopy's window is where
the line was seen in its own phases.  The in-phase and quadrature amplitudes
``modulation_cos[P]`` and
``modulation_sin[P]`` (fractions of CdS) enter linearly and vanish at the null;
``modulation_frequency`` (Hz) starts at FREQUENCY_HZ and is estimated.  With
the option ``free_start`` each canopy's gate start is estimated too
(``modulation_start[P]``, s, from its window's start; the phase keeps its
reference there): where the oscillation begins is known only to within the
windows the residual was tested in, and the data may say otherwise.  Edit
the window or the gate to fit what you know; list the effect after
canopy_inflation, before the riser effects.
"""
''' + _header("dataclass, replace", "Effect, Refinement") + '''
FREQUENCY_HZ = $frequency  # the residual's line (Hz)
# Each canopy's window (s): where the line was first and last seen in its own phases
# (math.inf: to the phase's end).
WINDOWS_S = {$windows
}
RAMP_S = 0.1  # the gate's opening time (s)


def gate(t, start, end):
    """0 before `start`, 1 from start + RAMP_S (to end - RAMP_S), smooth."""
    opened = 0.5 * (1.0 + ca.tanh(4.0 * (t - start - 0.5 * RAMP_S) / RAMP_S))
    if math.isinf(end):
        return opened
    return opened * 0.5 * (1.0 + ca.tanh(4.0 * (end - 0.5 * RAMP_S - t) / RAMP_S))


@dataclass(frozen=True)
class DragAreaModulation(Effect):
    """Drag-area oscillation at ``modulation_frequency`` (Hz), amplitudes per canopy;
    `free_start`: each canopy's gate start estimated (``modulation_start[P]``, s)."""

    free_start: bool = False
    name: str = "drag_area_modulation"

    def parameters(self, test):
        out = [Parameter("modulation_frequency", "Hz", FREQUENCY_HZ, 0.5 * FREQUENCY_HZ,
                         1.5 * FREQUENCY_HZ, scale=FREQUENCY_HZ,
                         description="drag-area modulation frequency"),
               *(Parameter(param_name(base, c.name), "1", 0.0, -0.3, 0.3, scale=0.05,
                           description=f"{part} drag-area modulation amplitude")
                 for c in test.parachutes
                 for base, part in (("modulation_cos", "in-phase"),
                                    ("modulation_sin", "quadrature")))]
        if self.free_start:
            out += [Parameter(param_name("modulation_start", c.name), "s",
                              WINDOWS_S[c.name][0], float(test.t_start),
                              min(WINDOWS_S[c.name][1], float(test.t_end)) - RAMP_S,
                              scale=1.0, description="drag-area modulation's start")
                    for c in test.parachutes]
        return out

    def null_values(self, test):
        return {p.name: 0.0 for p in self.parameters(test)[1:]
                if p.name.startswith("modulation_cos") or p.name.startswith("modulation_sin")}

    def refinements(self, test):
        """Each canopy's gate start estimated, null at its window's start, refitted from
        there and from a quarter and half of the way through the window (where the
        oscillation begins within it is not known)."""
        if self.free_start:
            return []

        def at(share):
            starts = {}
            for c in test.parachutes:
                start, end = WINDOWS_S[c.name]
                last = min(end, float(test.t_end)) - RAMP_S
                starts[param_name("modulation_start", c.name)] = start + share * (last - start)
            return starts

        return [Refinement(replace(self, free_start=True), "each canopy's start estimated",
                           at(0.0), (at(0.25), at(0.5)))]

    def forces(self, ctx):
        for chute in ctx.test.parachutes:
            start, end = WINDOWS_S[chute.name]
            phase = 2.0 * math.pi * ctx.p["modulation_frequency"] * (ctx.t - start)
            if self.free_start:
                start = ctx.p[param_name("modulation_start", chute.name)]
            g = gate(ctx.t, start, end)
            a = ctx.p[param_name("modulation_cos", chute.name)]
            b = ctx.p[param_name("modulation_sin", chute.name)]
            factor = 1.0 + g * (a * ca.cos(phase) + b * ca.sin(phase))
            ctx.scale_drag(chute.name, factor, self.name, ("axial_fraction", "riser_force"))
''')

_LOAD_GAIN = Template('''"""A load-cell gain that varies with the load (proposed by cpas-ocp).

Proposed from the residual's signature:
$reason

Each load cell reads T (1 + k T / T_REF_N): a cell (or its fairlead) whose
gain changes with the load it carries.  ``tension_gain[P]`` = k is the
change of gain at T_REF_N, the phase's peak tension (k = -0.1: the peak reads
10 % low); it vanishes at the null.  Edit the law (a square, a saturation) to
fit what you know; list the effect after the load-cell sensor.
"""
''' + _header() + '''
T_REF_N = $t_ref  # the phase's peak tension, rounded up (N)


@dataclass(frozen=True)
class TensionGain(Effect):
    """Load-cell gain 1 + k T / T_REF_N, ``tension_gain[P]`` = k per load cell."""

    name: str = "tension_gain"

    def parameters(self, test):
        return [Parameter(param_name("tension_gain", s.parachute), "1", 0.0, -0.5, 0.5,
                          scale=0.05, description="load-cell gain change at the peak tension")
                for s in test.sensors_of("load_cell")]

    def null_values(self, test):
        return {p.name: 0.0 for p in self.parameters(test)}

    def observations(self, ctx):
        for s in ctx.test.sensors_of("load_cell"):
            reading = ctx.y[s.name]["tension"]
            k = ctx.p[param_name("tension_gain", s.parachute)]
            ctx.y[s.name]["tension"] = reading * (1.0 + k * reading / T_REF_N)
''')

_WIND_PROFILE = Template('''"""A horizontal wind that changes with altitude (proposed by cpas-ocp).

Proposed from the residual's signature:
$reason

On top of the atmosphere's wind, the air moves at
u(h) = offset + shear P1(s) + curvature P2(s) + layer P3(s)  (m/s, east and
north), s = (h - H_MID_M) / HALF_SPAN_M running from -1 at the phase's lowest
altitude to +1 at its highest, P1..P3 the Legendre polynomials (s,
(3 s^2 - 1) / 2, (5 s^3 - 3 s) / 2: orthogonal over the span, so each
coefficient is what the others leave).  ``wind_offset_*`` is the mean change
across the span, ``wind_shear_*`` half the straight-line change from its bottom
to its top, ``wind_curvature_*`` a bend, ``wind_layer_*`` an S-shaped change
such as a shear layer inside the span; all vanish at the null.  A wind that
changes through a layer (tanh-like) is not a straight line, and a straight
line leaves the rest for other effects to take up.  Edit the profile (layers,
a power law) to fit what you know; list the effect first, before any drag.
"""
''' + _header() + '''
H_MID_M = $middle  # the middle of the phase's altitude span (m)
HALF_SPAN_M = $half_span  # half the phase's altitude span (m)
LIMIT_MS = 30.0  # bound on each coefficient (m/s)
TERMS = ("offset", "shear", "curvature", "layer")  # Legendre P0..P3


def legendre(s):
    """P0..P3 at s."""
    return (1.0, s, 0.5 * (3.0 * s**2 - 1.0), 0.5 * (5.0 * s**3 - 3.0 * s))


@dataclass(frozen=True)
class WindProfile(Effect):
    """Horizontal wind, a cubic Legendre series in altitude, east and north (m/s)."""

    name: str = "wind_profile"

    def parameters(self, test):
        return [Parameter(f"wind_{kind}_{axis}", "m/s", 0.0, -LIMIT_MS, LIMIT_MS, scale=1.0,
                          description=f"{axis} wind {kind} against the atmosphere's")
                for kind in TERMS for axis in ("east", "north")]

    def null_values(self, test):
        return {p.name: 0.0 for p in self.parameters(test)}

    def forces(self, ctx):
        s = (ctx.x["position"][2] - H_MID_M) / HALF_SPAN_M
        basis = legendre(s)
        u = [sum(ctx.p[f"wind_{kind}_{axis}"] * b for kind, b in zip(TERMS, basis))
             for axis in ("east", "north")]
        ctx.add_air_velocity(ca.vertcat(u[0], u[1], 0.0), self.name)
''')
