"""Whether a converged fit is a result: no free parameter pressed against a bound that was
only guessed, and a chi-square the stated noise allows.

A fit that Ipopt calls converged is a claim about the test.  Two things
make it less than one.

*A guessed bound the data press against.*  Some bounds are physical (an
added-mass factor is not negative, a start time lies within the phase;
`Parameter.physical_lower`/`physical_upper`); the others are guesses of where
a value plausibly lies: a fill constant's range, and above all the window a
start time may take about its observed event (`CanopyInflation.start_window`).
When a bag-strip time is 1.5 s off and the window is 1 s, the fit ends on the
window's edge with the shape parameters stretched to their own bounds, at
chi-square/dof 50, and called converged (`drogue`, seeds 1-10).  Whether the
data press against the bounds is a score test: the bounds of the free
parameters the fit holds on a guessed bound are released, one Gauss-Newton
step from the fit gives their linearised estimates theta and covariance C,
and the chi-square decrease on offer beyond the bounds,

    T = max over the cone {t beyond the bounds} of [theta' W theta - (t - theta)' W (t - theta)],

W = C^-1 (`hypothesis_tests.cone_statistic`), is chi-bar-squared with k
one-sided restrictions under the null that the optimum lies on them.  A
bound is "active" in this sense only where the KKT multiplier, measured in
the covariance's metric, is significant; a parameter that merely sits on a
bound the data do not push against is not flagged.  Where the residuals
exceed their noise (chi-square/dof = s^2 > 1), every score statistic is
inflated by s^2, so T is divided by s^2 (quasi-likelihood): a real flight
that misfits its noise by 3x is not flagged for the misfit alone.

*A chi-square beyond the noise.*  P(chi^2_dof > chi^2) below ALPHA says the
model or the stated noise is wrong somewhere; the covariance's sigmas then
assume a noise the residuals do not show and are too small by about
sqrt(chi^2/dof).  This is reported with every fit (real flights misfit
their noise: Prometheus at chi^2/dof 6-9); it is a warning, not a refusal.

A fit that is not a plain result (a guessed bound pressed, or a chi-square
beyond the noise) with start times at their windows' edges is retried
(`continuation.solve_checked`): each such window is centred on that edge
(the event that seeded it is taken to be off), and the phase fitted again
from the reduction; the refit is kept where it lowers chi-square.  A fit
still pressed after MAX_WINDOW_MOVES moves is not a result.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field

import numpy as np
from scipy.stats import chi2 as chi2_law

from cpas_ocp.estimation.estimator import Estimator, Fit
from cpas_ocp.inference.hypothesis_tests import chi_bar_square_sf, cone_statistic
from cpas_ocp.inference.restarts import Restart
from cpas_ocp.io.model_spec import ModelSpec
from cpas_ocp.physics.effects.canopy_inflation import CanopyInflation
from cpas_ocp.physics.parameters import split_name

# Level of both tests.  A fit with a parameter on a guessed bound the data do not press
# against is flagged with at most this probability; so is a fit whose model and noise are
# right, for its chi-square.
ALPHA = 0.001
# A held parameter is listed as pressing when its own outward estimate lies this many
# sigma beyond its bound (the joint test decides; the list says where).
PRESSED_Z = 2.0
# Start-window moves tried before a fit pressed against its windows is given up.
MAX_WINDOW_MOVES = 3
# A start time within this fraction of its window's half-width from a guessed edge is at
# that edge, for a fit that is not a plain result (`moved_windows`).
EDGE_FRACTION = 0.1


@dataclass(frozen=True)
class HeldBound:
    """A free parameter the fit left on a bound: which side, whether the bound is physical,
    and how far beyond it the data would take the value (linearised, SI and in sigma,
    positive outward)."""

    name: str
    side: str
    value: float
    physical: bool
    beyond: float = float("nan")
    beyond_z: float = float("nan")

    @property
    def pressed(self) -> bool:
        return bool(self.beyond_z > PRESSED_Z)

    def text(self) -> str:
        kind = "physical" if self.physical else "guessed"
        how = (f", the data would take it {abs(self.beyond):.4g} ({self.beyond_z:.1f} sigma) "
               f"beyond" if np.isfinite(self.beyond_z) else "")
        return f"{self.name} = {self.value:.6g} on its {kind} {self.side} bound{how}"


@dataclass(frozen=True)
class WindowMove(Restart):
    """A start time's window moved by `shift_s` (its start at the window's edge in a fit
    that was not a plain result), and the chi-square before and after the refit."""

    def text(self) -> str:
        return (f"{self.parameter}: window moved {self.shift_s:+.2f} s from its event "
                f"(chi-square {self.chi_square_before:.1f} -> {self.chi_square_after:.1f})")


@dataclass
class Claim:
    """What a converged fit may claim: its goodness of fit, the bounds it holds parameters on,
    the bound test, and any start windows moved to reach it."""

    chi_square: float
    dof: int
    fit_p_value: float
    held: list[HeldBound]
    bound_statistic: float = 0.0
    bound_p_value: float = 1.0
    moves: list[WindowMove] = field(default_factory=list)
    alpha: float = ALPHA
    # How the fit was reached beyond one solve (a process intensity chosen by evidence).
    notes: list[str] = field(default_factory=list)

    @property
    def pressed(self) -> list[HeldBound]:
        """Guessed bounds the data press against (empty where the joint test passes)."""
        if self.bound_p_value >= self.alpha:
            return []
        return [h for h in self.held if not h.physical and h.pressed] or \
            [h for h in self.held if not h.physical]

    @property
    def is_result(self) -> bool:
        """No guessed bound pressed: the fit is a result (its sigmas may still need the
        misfit's scaling; see `fits_noise`)."""
        return not self.pressed

    @property
    def fits_noise(self) -> bool:
        return self.fit_p_value >= self.alpha

    @property
    def misfit_factor(self) -> float:
        """sqrt(chi^2/dof): how much larger the residuals are than their stated noise."""
        return float(np.sqrt(self.chi_square / max(self.dof, 1)))

    def problems(self) -> list[str]:
        """One line per reason the fit is less than a plain result (empty when none)."""
        out = []
        if self.pressed:
            out.append(f"the data press {len(self.pressed)} parameter(s) against bounds that "
                       f"are guesses, not physical limits (p = {self.bound_p_value:.2g}): "
                       + "; ".join(h.text() for h in self.pressed)
                       + ". The optimum lies beyond them: check the events that seed the "
                         "start windows and the model")
        if not self.fits_noise:
            out.append(f"chi-square/dof = {self.chi_square / max(self.dof, 1):.2f} "
                       f"(p = {self.fit_p_value:.2g}): the residuals are "
                       f"{self.misfit_factor:.1f} times their stated noise, so the model or "
                       f"the noise is wrong somewhere and the sigmas are too small by about "
                       f"that factor (--rescale-sigmas scales them)")
        return out

    def text(self) -> str:
        verdict = ("a result" if self.is_result and self.fits_noise else
                   "a result, with a misfit" if self.is_result else "NOT A RESULT")
        lines = [f"claim: {verdict}"]
        lines += [f"  - {p}" for p in self.problems()]
        lines += [f"  - moved {m.text()}" for m in self.moves]
        lines += [f"  - {note}" for note in self.notes]
        return "\n".join(lines)

    def as_dict(self) -> dict:
        pressed = self.pressed
        return {"result": self.is_result, "fits_noise": self.fits_noise,
                "chi_square": self.chi_square, "dof": self.dof,
                "fit_p_value": self.fit_p_value, "misfit_factor": self.misfit_factor,
                "bound_statistic": self.bound_statistic, "bound_p_value": self.bound_p_value,
                "held_bounds": [{**vars(h), "physical": bool(h.physical),
                                 "beyond": _number(h.beyond), "beyond_z": _number(h.beyond_z),
                                 "pressed": h in pressed} for h in self.held],
                "window_moves": [vars(m) for m in self.moves], "notes": self.notes,
                "problems": self.problems(), "alpha": self.alpha}


def _number(x: float) -> float | None:
    """`x` as JSON can hold it: None for NaN (a bound the test did not reach)."""
    return float(x) if np.isfinite(x) else None


def check_claim(est: Estimator, fit: Fit, alpha: float = ALPHA) -> Claim:
    """The claim `fit` (of `est`) may make (see the module docstring)."""
    model = fit.model
    held = []
    for name in fit.free:
        prm = model.parameter(name)
        side = prm.held_side(fit.parameters[name])
        if side is not None:
            held.append(HeldBound(name, side, fit.parameters[name], prm.is_physical(side)))
    claim = Claim(fit.chi_square, fit.dof, float(chi2_law.sf(fit.chi_square, fit.dof)), held,
                  alpha=alpha)
    guessed = [h for h in held if not h.physical]
    if not guessed:
        return claim
    values, cov = est.gauss_newton_estimate(fit.z, release=[h.name for h in guessed])
    std = cov.std
    tested = [h for h in guessed if h.name in std and std[h.name] > 0.0]
    if not tested:
        return claim
    outward = np.array([1.0 if h.side == "upper" else -1.0 for h in tested])
    theta = np.array([values[h.name] - h.value for h in tested]) * outward
    index = [cov.names.index(h.name) for h in tested]
    C = cov.matrix[np.ix_(index, index)] * np.outer(outward, outward)
    inflation = max(1.0, fit.chi_square / fit.dof)
    statistic = cone_statistic(theta, C, np.zeros(len(tested)),
                               np.full(len(tested), np.inf)) / inflation
    sigma = np.sqrt(np.diag(C) * inflation)
    by_name = {h.name: (t, t / s) for h, t, s in zip(tested, theta, sigma, strict=True)}
    claim.held = [HeldBound(h.name, h.side, h.value, h.physical, *by_name[h.name])
                  if h.name in by_name else h for h in held]
    claim.bound_statistic = statistic
    claim.bound_p_value = chi_bar_square_sf(statistic, 0, len(tested))
    return claim


def start_shifts(spec: ModelSpec) -> dict[str, float]:
    """The start-window shifts of `spec`'s `canopy_inflation` (s, by start-time name)."""
    return next((dict(e.start_shifts) for e in spec.effects
                 if isinstance(e, CanopyInflation)), {})


def with_start_shifts(spec: ModelSpec, shifts: dict[str, float]) -> ModelSpec:
    """`spec` with its `canopy_inflation` windows shifted by `shifts` (unchanged without
    one, or without shifts)."""
    if not shifts:
        return spec
    effects = tuple(dataclasses.replace(e, start_shifts=dict(shifts))
                    if isinstance(e, CanopyInflation) else e for e in spec.effects)
    return dataclasses.replace(spec, effects=effects)


def moved_windows(claim: Claim, est: Estimator, fit: Fit) -> ModelSpec | None:
    """`est`'s model with the windows of the start times at their edges moved by the
    window's width past that edge, on top of any shift the model already has, where
    `fit` (of `est`) is not a plain result; None when it is, when no start time is at an
    edge, or when the model has no `canopy_inflation` to move.

    A start time is at an edge within EDGE_FRACTION of the window's half-width of a
    guessed bound.  Not only those on the bound: an interior-point solver leaves a
    start time 0.01-0.05 s off its window's edge, at a local minimum or at the last
    iterate of a failed run, when the event that seeded it is 1.5 s off (`drogue`,
    seeds 1, 2 and 5).  And all of them, whichever way the bound test's one step
    would take them: that far from the optimum the linearisation can point the wrong
    way (seed 9: two start times pulled 0.7-1.0 s inward with the truth 0.56 s
    outward; moved without them, the refit failed).  A move that does not lower
    chi-square is not kept."""
    inflation = next((e for e in est.spec.effects if isinstance(e, CanopyInflation)), None)
    if inflation is None or (claim.is_result and claim.fits_noise):
        return None
    edge = EDGE_FRACTION * inflation.start_window
    shifts = start_shifts(est.spec)
    moved = False
    for name in fit.free:
        if split_name(name)[0] != "t_start":
            continue
        prm, value = est.model.parameter(name), fit.parameters[name]
        if value - prm.lower < edge and not prm.physical_lower:
            bound = prm.lower
        elif prm.upper - value < edge and not prm.physical_upper:
            bound = prm.upper
        else:
            continue
        shifts[name] = shifts.get(name, 0.0) + (bound - prm.default)
        moved = True
    return with_start_shifts(est.spec, shifts) if moved else None
