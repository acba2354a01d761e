"""Whether a converged fit is a result: no free parameter pressed against a bound that was
only guessed, a chi-square some honest reading of the noise allows, every process within
its prior, and every drag area determined.

A fit that Ipopt calls converged is a claim about the test.  These things
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

*A drag area its descent contradicts.*  For an imported flight log, each opened
canopy's fitted drag area is set beside the drag area its own settled descent needs (the
import's forensics, 2 m g / (rho v^2) less the canopies open before it, its sigma
counting the vertical air's); beyond the two-sided family-wise 1 % level the data that set
the fit's value (an opening's shape pressed on a bound, a diameter's cap) and the descent
rate disagree, and the fit is no result for that canopy (`descent_disagreements`).

*A chi-square beyond the noise.*  P(chi^2_dof > chi^2) below ALPHA says the
model or the stated noise is wrong somewhere; the covariance's sigmas then
assume a noise the residuals do not show and are too small by about
sqrt(chi^2/dof).  Up to MAX_MISFIT this is a warning, not a refusal: real
flights misfit their noise (Prometheus in still air at chi^2/dof 5.3 and 4.0
on its two logs, 6-9 before its altimeter's sigma was taken per phase), and
the quasi-likelihood reading, every sigma scaled by sqrt(chi^2/dof)
(--rescale-sigmas), still holds where the model error is a modest, roughly
white addition to the noise.  Beyond it no honest reading of the noise is
left: chi^2/dof > 10 puts the residuals at more than sqrt(10) = 3.2 times the
stated sigma, i.e. the model's error is at least sqrt(10 - 1) = 3 times the
noise on every sample on average.  A sensor's sigma is at worst misjudged by
a factor of about 2 (a datasheet against the scatter about a local trend),
and a factor of 3.2 on every sample is a structure the model lacks (a canopy
that opened late, a process the air had), which the fit's parameters absorb:
their values, not only their sigmas, are then the model's compensation.  So
a fit beyond MAX_MISFIT is not a result (the sentence names the sensor that
misfits most).  The limit is not a tail probability: with thousands of
samples P(chi^2_dof > chi^2) is below any level at chi^2/dof 1.2, which
would refuse every real flight.

*A chi-square far below the noise.*  chi^2/dof well below 1 says the stated
sigmas are too large by about 1/sqrt(chi^2/dof), and every uncertainty with
them.  It is said (not refused) where both P(chi^2_dof < chi^2) < ALPHA (the
shortfall is not chance: with 100 dof that is chi^2/dof < 0.62, with 1000 <
0.87) and chi^2/dof < LOW_MISFIT = 0.5 (the sigmas overstated by more than
sqrt(2), so a stated 95 % interval holds at least 99.4 %): a well-fitted
process prior and a few hundred samples give chi^2/dof 0.90-0.97 on
simulated tests whose sigmas are right (`rocket_gusts`, `drogue` through
gusts), which the tail alone could flag.

*A process beyond its prior.*  An effect's stochastic process (`wind_process`:
the air's vertical motion, knots with a Gauss-Markov prior of stated sigma)
enters chi-square through its standardised innovations (`Effect.penalties`).
Where the data put a knot more than PROCESS_SIGMAS = 5 prior sigmas from zero
(`Effect.process_priors`), or an innovation beyond 5 sigma, the process is not
the stated one: it has absorbed something the model lacks (knots at -18 and
-21 m/s under a prior of 1 m/s, taking up a main canopy that opened 6 s late).
Five sigma: a Gaussian prior puts a knot there with probability 5.7e-7, so
among the hundred knots (and as many innovations) of a long descent a fit
whose prior is right is refused about once in 9,000.  The whole block departs
where its chi-square is beyond the tail a single 5-sigma deviate has
(two-sided, 5.7e-7) and also beyond MAX_MISFIT per innovation, the standard a
sensor's residuals are held to: the prior's sigma would have to be more than
3.2 times the stated one.  The tail alone is not enough: on the Prometheus
TeleMega log the card's 1 m/s prior gives 50 innovations of chi-square 118
(P = 2.0e-7, normalised RMS 1.54, no knot beyond 2.7 sigma), the air a little
livelier than stated, which the evidence puts at 2 m/s (`--wind-intensity`);
a sensor's sigma misjudged by that factor is a misfit to state, not a wrong
fit, and so is a prior's.  A block significant at ALPHA that does not depart
is said as such a misfit.  A departure is not a result: the sentence names the
process, the knot's time and its value in sigma.

*An undetermined drag area.*  A drag area (CdS) is the product a reconstruction
is for.  Where the covariance finds it undetermined (in a combination the data
do not fix), leaves it on a bound, or gives it a sigma (scaled by
sqrt(chi^2/dof) where that exceeds 1) larger than its value, the data have not
measured it, whatever its value: not a result (`check_drag_areas`).

A fit that is not a plain result (a guessed bound pressed, or a chi-square
beyond the noise) with start times at their windows' edges is retried
(`continuation.solve_checked`): each such window is centred on that edge
(the event that seeded it is taken to be off), and the phase fitted again
from the reduction; the refit is kept where it lowers chi-square.  A fit
still pressed after MAX_WINDOW_MOVES moves is not a result.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np
from scipy.stats import chi2 as chi2_law
from scipy.stats import norm

from cpas_ocp.estimation.estimator import Estimator, Fit
from cpas_ocp.estimation.uncertainty import Covariance
from cpas_ocp.inference.diagnostics import sensor_summary
from cpas_ocp.inference.hypothesis_tests import chi_bar_square_sf, cone_statistic
from cpas_ocp.inference.restarts import Restart
from cpas_ocp.io.import_reports import import_deployments, import_turned_over
from cpas_ocp.io.model_spec import ModelSpec
from cpas_ocp.physics.effects.canopy_inflation import CanopyInflation
from cpas_ocp.physics.parameters import param_name, split_name
from cpas_ocp.precision import with_sigma

# Two-sided family-wise level at which a fitted drag area and its settled descent's disagree
# (`descent_disagreements`), the level of the import's deployment forensics.
DESCENT_LEVEL = 0.01
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
# chi^2/dof beyond which no reading of the noise is honest: the fit is not a result.
MAX_MISFIT = 10.0
# chi^2/dof below which (where also significant at ALPHA) the sigmas are said overstated.
LOW_MISFIT = 0.5
# Prior sigmas beyond which a process parameter or innovation departs from its prior, and
# the tail probability of that (two-sided standard normal) for a whole prior block.
PROCESS_SIGMAS = 5.0
PROCESS_TAIL = float(2.0 * norm.sf(PROCESS_SIGMAS))
# The drag areas a reconstruction is for (the steady drag area of each canopy and stage).
DRAG_AREA = "CdS"


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

    def __str__(self) -> str:
        kind = "physical" if self.physical else "guessed"
        how = (f", the data would take it {abs(self.beyond):.4g} ({self.beyond_z:.1f} sigma) "
               f"beyond" if np.isfinite(self.beyond_z) else "")
        return f"{self.name} = {self.value:.6g} on its {kind} {self.side} bound{how}"


@dataclass(frozen=True)
class WindowMove(Restart):
    """A start time's window moved by `shift_s` (its start at the window's edge in a fit
    that was not a plain result), and the chi-square before and after the refit."""

    def __str__(self) -> str:
        return (f"{self.parameter}: window moved {self.shift_s:+.2f} s from its event "
                f"(chi-square {self.chi_square_before:.1f} -> {self.chi_square_after:.1f})")


# A process's departure this close (s) to where the body turned over is put to it: the
# rocket default's wind knots are 4 s apart, and a knot's B-spline reaches one spacing.
TURNED_REACH_S = 4.0


@dataclass(frozen=True)
class ProcessDeparture:
    """Where an effect's stochastic process departs from its stated prior: a knot whose
    value is `sigmas` prior sigmas from zero (`kind` "knot", at time `t` s), an
    innovation as large (`kind` "innovation"), or the prior block's chi-square
    (`kind` "block": `sigmas` is chi-square, `count` its terms)."""

    effect: str
    kind: str
    name: str
    t: float
    sigmas: float
    value: float = float("nan")
    unit: str = ""
    count: int = 0

    def __str__(self) -> str:
        if self.kind == "knot":
            return (f"{self.effect}: {self.name} at t = {self.t:.2f} s is "
                    f"{self.value:+.3g} {self.unit}, {self.sigmas:+.1f} sigma of its prior")
        if self.kind == "innovation":
            return (f"{self.effect}: the innovation of {self.name} at t = {self.t:.2f} s is "
                    f"{self.sigmas:+.1f} sigma of its prior")
        return (f"{self.effect}: the {self.count} innovations of {self.name} sum to "
                f"chi-square {self.sigmas:.1f} (P = {chi2_law.sf(self.sigmas, self.count):.2g},"
                f" beyond the {PROCESS_TAIL:.2g} of a {PROCESS_SIGMAS:g}-sigma deviate)")


@dataclass
class Claim:
    """What a converged fit may claim: its goodness of fit, the bounds it holds parameters on,
    the bound test, its processes against their priors, its drag areas against its
    covariance (`check_drag_areas`), and any start windows moved to reach it."""

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
    # The sensor whose normalised residual RMS is largest, and that RMS ('' without one).
    worst_sensor: str = ""
    worst_sensor_rms: float = float("nan")
    # P(chi^2_dof < chi^2): the lower tail, small where the stated sigmas are too large.
    low_p_value: float = 1.0
    # Where a process departs from its prior (`process_departures`).
    departures: list[ProcessDeparture] = field(default_factory=list)
    # Drag areas the covariance does not determine, each with why (`check_drag_areas`).
    undetermined_drag_areas: list[str] = field(default_factory=list)
    # Process prior blocks beyond their noise that do not depart (`process_misfits`).
    process_misfits: list[str] = field(default_factory=list)
    # What the log shows of the canopies (`deployment_findings`), each in a sentence: those
    # that make the fit no result (no canopy opened; one needed more drag area than its
    # diameter gives), and those said beside a result (a canopy that did not open, held
    # out of the fit, beside others that did; one that opened in part).
    failed_deployments: list[str] = field(default_factory=list)
    deployment_notes: list[str] = field(default_factory=list)
    # Where the import found the body turned over: (first, last) times (s).
    turned_over: list[tuple[float, float]] = field(default_factory=list)

    @property
    def pressed(self) -> list[HeldBound]:
        """Guessed bounds the data press against (empty where the joint test passes)."""
        if self.bound_p_value >= self.alpha:
            return []
        return [h for h in self.held if not h.physical and h.pressed] or \
            [h for h in self.held if not h.physical]

    @property
    def ratio(self) -> float:
        """chi^2/dof."""
        return self.chi_square / max(self.dof, 1)

    @property
    def beyond_noise(self) -> bool:
        """chi^2/dof beyond MAX_MISFIT: no honest reading of the noise allows the residuals."""
        return self.ratio > MAX_MISFIT

    @property
    def is_result(self) -> bool:
        """No guessed bound pressed, chi^2/dof within MAX_MISFIT, every process within its
        prior, every drag area determined and every canopy opened: the fit is a result (its
        sigmas may still need the misfit's scaling; see `fits_noise`)."""
        return not (self.failed_deployments or self.pressed or self.beyond_noise
                    or self.departures or self.undetermined_drag_areas)

    @property
    def fits_noise(self) -> bool:
        return self.fit_p_value >= self.alpha

    @property
    def overstates_noise(self) -> bool:
        """chi^2/dof significantly (at `alpha`) and materially (below LOW_MISFIT) under 1:
        the stated sigmas are too large."""
        return self.low_p_value < self.alpha and self.ratio < LOW_MISFIT

    @property
    def misfit_factor(self) -> float:
        """sqrt(chi^2/dof): how much larger the residuals are than their stated noise."""
        return float(np.sqrt(self.ratio))

    def _worst(self) -> str:
        return (f"; the worst sensor is {self.worst_sensor} (normalised RMS "
                f"{self.worst_sensor_rms:.2f})" if self.worst_sensor else "")

    def _lacks(self, departure: ProcessDeparture) -> str:
        """What a process's departure may stand for: a stretch where the body turned over
        (the import's) within TURNED_REACH_S of it, else a late opening or a wrong sigma."""
        near = [(a, b) for a, b in self.turned_over if departure.kind != "block"
                and a - TURNED_REACH_S <= departure.t <= b + TURNED_REACH_S]
        if not near:
            return " (a late opening, a wrong sigma): check the events and the model"
        a, b = min(near, key=lambda span: max(span[0] - departure.t, departure.t - span[1], 0.0))
        return (f": the body turned over from {a:.2f} to {b:.2f} s (the import's note), "
                "where the axial accelerometer reads the drag reversed and no canopy's drag "
                "follows it; the fit is about the canopies only without that stretch of "
                "accelerometer.csv")

    def problems(self) -> list[str]:
        """One line per reason the fit is less than a plain result (empty when none); those
        that make it no result first."""
        out = list(self.failed_deployments)
        if self.pressed:
            out.append(f"the data press {len(self.pressed)} parameter(s) against bounds that "
                       f"are guesses, not physical limits (p = {self.bound_p_value:.2g}): "
                       + "; ".join(str(h) for h in self.pressed)
                       + ". The optimum lies beyond them: check the events that seed the "
                         "start windows and the model")
        if self.beyond_noise:
            out.append(f"chi-square/dof = {self.ratio:.4g}, beyond the {MAX_MISFIT:g} any "
                       f"honest reading of the noise allows: the residuals are "
                       f"{self.misfit_factor:.1f} times their stated noise, so the model "
                       f"lacks an effect or the sigmas are wrong{self._worst()}")
        if self.departures:
            worst = max(self.departures, key=lambda d: (d.kind != "block", abs(d.sigmas)))
            more = len(self.departures) - 1
            out.append(f"a process departs from its prior beyond {PROCESS_SIGMAS:g} sigma: "
                       f"{worst}" + (f" (and {more} more)" if more else "")
                       + "; it has absorbed something the model lacks" + self._lacks(worst))
        for text in self.undetermined_drag_areas:
            out.append(f"the data do not determine the drag area {text}")
        if not self.fits_noise and not self.beyond_noise:
            out.append(f"chi-square/dof = {self.ratio:.2f} "
                       f"(p = {self.fit_p_value:.2g}): the residuals are "
                       f"{self.misfit_factor:.1f} times their stated noise, so the model or "
                       f"the noise is wrong somewhere and the sigmas are too small by about "
                       f"that factor (--rescale-sigmas scales them){self._worst()}")
        out += self.process_misfits
        out += self.deployment_notes
        if self.overstates_noise:
            out.append(overstated_text(self.ratio, self.low_p_value))
        return out

    def verdict(self) -> str:
        """"a result", "a result, with a misfit", "a result, with overstated sigmas" or
        "NOT A RESULT"."""
        if not self.is_result:
            return "NOT A RESULT"
        if not self.fits_noise:
            return "a result, with a misfit"
        return "a result, with overstated sigmas" if self.overstates_noise else "a result"

    def headline(self) -> str:
        """What a report says above all else, or '': the fit is not a result, a canopy did
        not open or opened in part, or its uncertainties are overstated."""
        if not self.is_result:
            return "Not a result. " + " ".join(f"{p}." for p in self.problems())
        said = [f"{n[0].upper()}{n[1:]}." for n in self.deployment_notes]
        if self.overstates_noise:
            said.append(f"Uncertainties overstated. "
                        f"{overstated_text(self.ratio, self.low_p_value)}.")
        return " ".join(said)

    def as_dict(self) -> dict:
        pressed = self.pressed
        return {"result": self.is_result, "verdict": self.verdict(),
                "fits_noise": self.fits_noise, "overstates_noise": self.overstates_noise,
                "beyond_noise": self.beyond_noise,
                "chi_square": self.chi_square, "dof": self.dof,
                "fit_p_value": self.fit_p_value, "low_p_value": self.low_p_value,
                "misfit_factor": self.misfit_factor,
                "worst_sensor": self.worst_sensor or None,
                "worst_sensor_normalised_rms": _number(self.worst_sensor_rms),
                "bound_statistic": self.bound_statistic, "bound_p_value": self.bound_p_value,
                "held_bounds": [{**vars(h), "physical": bool(h.physical),
                                 "beyond": _number(h.beyond), "beyond_z": _number(h.beyond_z),
                                 "pressed": h in pressed} for h in self.held],
                "process_departures": [{**vars(d), "t": _number(d.t),
                                        "value": _number(d.value), "text": str(d)}
                                       for d in self.departures],
                "undetermined_drag_areas": self.undetermined_drag_areas,
                "process_misfits": self.process_misfits,
                "failed_deployments": self.failed_deployments,
                "deployment_notes": self.deployment_notes,
                "window_moves": [vars(m) for m in self.moves], "notes": self.notes,
                "problems": self.problems(), "alpha": self.alpha}


def overstated_text(ratio: float, low_p_value: float) -> str:
    """The sentence for a chi^2/dof far below 1."""
    chance = f"= {low_p_value:.2g}" if low_p_value > 0.0 else "< 1e-300"
    return (f"chi-square/dof = {ratio:.3g} (P(chi-square this small) {chance}): "
            f"the stated sigmas are too large by about 1/sqrt(chi-square/dof) = "
            f"{1.0 / np.sqrt(max(ratio, 1e-300)):.1f}; the uncertainties are overstated "
            f"by that factor")


def worst_sensor(fit: Fit) -> tuple[str, float]:
    """The sensor (not events, priors or a process's innovations) whose normalised residual
    RMS is largest, and that RMS; ('', nan) where the fit has none."""
    rms = {s: e["normalised_rms"] for s, e in sensor_summary(fit).items()
           if s not in fit.pseudo_sensors}
    if not rms:
        return "", float("nan")
    name = max(rms, key=rms.__getitem__)
    return name, rms[name]


def process_departures(fit: Fit) -> list[ProcessDeparture]:
    """Where the fit's stochastic processes depart from their priors (module docstring):
    each free process parameter beyond PROCESS_SIGMAS of its prior's marginal sigma
    (`Effect.process_priors`), each standardised innovation (the effects' penalty
    residuals) beyond PROCESS_SIGMAS, and each prior block whose chi-square has a tail
    probability below PROCESS_TAIL."""
    out: list[ProcessDeparture] = []
    free = set(fit.free)
    for effect in fit.model.effects:
        for name, (t, sigma) in effect.process_priors(fit.test).items():
            if name not in free:
                continue
            value = fit.parameters[name]
            if abs(value) > PROCESS_SIGMAS * sigma:
                out.append(ProcessDeparture(effect.name, "knot", name, t, value / sigma, value,
                                            fit.model.parameter(name).unit))
    penalised = {e for e, *_ in fit.model.penalties}
    for r in fit.residuals:
        if r.sensor not in penalised or r.t.size == 0:
            continue
        innovation = -r.normalised  # the penalty is the model; its measurement is 0
        k = int(np.argmax(np.abs(innovation)))
        if abs(innovation[k]) > PROCESS_SIGMAS and not any(
                d.effect == r.sensor and d.kind == "knot" for d in out):
            out.append(ProcessDeparture(r.sensor, "innovation", r.channel, float(r.t[k]),
                                        float(innovation[k])))
        block = float(np.sum(innovation**2))
        if chi2_law.sf(block, innovation.size) < PROCESS_TAIL \
                and block > MAX_MISFIT * innovation.size:
            out.append(ProcessDeparture(r.sensor, "block", r.channel, float("nan"), block,
                                        count=int(innovation.size)))
    return out


def process_misfits(fit: Fit, alpha: float = ALPHA) -> list[str]:
    """One line per prior block of the fit's processes whose chi-square exceeds its noise at
    level `alpha` without departing from it (`process_departures`): the prior's sigma is
    smaller than the data would have it, by about the innovations' normalised RMS."""
    penalised = {e for e, *_ in fit.model.penalties}
    out = []
    for r in fit.residuals:
        if r.sensor not in penalised or r.t.size == 0:
            continue
        block = float(np.sum(r.normalised**2))
        p = float(chi2_law.sf(block, r.t.size))
        if p < alpha and block <= MAX_MISFIT * r.t.size:
            out.append(f"the {r.t.size} innovations of {r.sensor} {r.channel} have normalised "
                       f"RMS {np.sqrt(block / r.t.size):.2f} (p = {p:.2g}): the process is "
                       f"livelier than its prior's sigma says (for the air's motion, "
                       f"--wind-intensity lets the evidence choose it)")
    return out


def _number(x: float) -> float | None:
    """`x` as JSON can hold it: None for NaN (a bound the test did not reach)."""
    return float(x) if np.isfinite(x) else None


def deployment_findings(fit: Fit) -> tuple[list[str], list[str]]:
    """What the import of the flight log of `fit` found of its canopies
    (`io.deployment_forensics`, kept in the test folder's ``import.json``), in sentences:
    those that make the fit no result for its canopies, and those it states beside a
    result.  A canopy that did not open is held out of the fit by the import (its drag area
    at the model's least, the airframe's fitted where it was the first): where no canopy
    opened the fit is the airframe's, not a canopy's, and no result; where others opened
    it is theirs, and the sentence goes beside it.  A canopy whose descent needed more drag
    area than its diameter gives had another canopy out with it: the fit's drag area for it
    is not that canopy's.  A canopy that opened in part is said.  Empty for a folder not
    imported."""
    canopies = {c.name for c in fit.test.parachutes}
    found = {name: entry for name, entry in import_deployments(fit.test.path).items()
             if name in canopies}
    none_opened = bool(found) and all(e["verdict"] == "not_opened" for e in found.values()) \
        and len(found) == len(canopies)
    failed, notes = [], []
    for name, entry in found.items():
        if entry["verdict"] == "not_opened":
            (failed if none_opened else notes).append(
                f"{entry['sentence']}; the fit holds it closed"
                + (" and fits the airframe's drag area (CdS_V) instead"
                   if none_opened and "CdS_V" in fit.free else ""))
        elif entry.get("above_diameter") is True:
            failed.append(f"{entry['sentence']}; the fit's drag area for the {name} is more "
                          "than that canopy's")
        elif entry["verdict"] == "partial":
            notes.append(entry["sentence"])
    return failed, notes


def descent_disagreements(fit: Fit, std_of: Callable[[], dict[str, float]]) -> list[str]:
    """Each opened canopy of an imported flight log whose fitted drag area (its last
    stage's, its sigma from `std_of`, called only where a canopy can be compared) lies
    beyond the two-sided family-wise level `DESCENT_LEVEL` (Bonferroni over the canopies
    compared) from the drag area its own settled descent needs, 2 m g / (rho v^2) less
    the canopies open before it, as the import's forensics measured it (``import.json``
    ``deployments[...]["own"]``, its sigma counting the rate's and the vertical air's): a
    sentence each.  Such a fit is no result for that canopy: the data that set its drag
    area (an opening's shape, a bound, a diameter's cap) and the descent rate say
    different things."""
    found = import_deployments(fit.test.path)
    candidates = []
    for chute in fit.test.parachutes:
        entry = found.get(chute.name, {})
        name = param_name("CdS", chute.name, chute.stages[-1])
        if (entry.get("verdict") == "opened" and not entry.get("above_diameter")
                and entry.get("own") and name in fit.free):
            candidates.append((chute.name, name, entry["own"]))
    if not candidates:
        return []
    std = std_of()
    pairs = [(canopy, name, fit.parameters[name], std[name], float(own["value_m2"]),
              float(own["sigma_m2"])) for canopy, name, own in candidates
             if std.get(name, 0.0) > 0.0]
    if not pairs:
        return []
    limit = float(norm.isf(DESCENT_LEVEL / (2.0 * len(pairs))))
    out = []
    for canopy, name, value, sigma, needed, needed_sigma in pairs:
        z = (value - needed) / float(np.hypot(sigma, needed_sigma))
        if abs(z) > limit:
            out.append(f"the {canopy}'s fitted drag area {name} = {with_sigma(value, sigma)} "
                       f"m^2 lies {z:+.1f} sigma from the {with_sigma(needed, needed_sigma)} "
                       "m^2 its settled descent needs: the data that set it and the descent "
                       "rate disagree (the report's \"Drag areas from the steady descent\" "
                       "names the channel)")
    return out


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
                  alpha=alpha, low_p_value=float(chi2_law.cdf(fit.chi_square, fit.dof)),
                  departures=process_departures(fit), process_misfits=process_misfits(fit, alpha))
    claim.worst_sensor, claim.worst_sensor_rms = worst_sensor(fit)
    claim.failed_deployments, claim.deployment_notes = deployment_findings(fit)
    claim.turned_over = import_turned_over(fit.test.path)
    claim.failed_deployments += descent_disagreements(fit, lambda: est.covariance(fit).std)
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


def check_drag_areas(claim: Claim, fit: Fit, cov: Covariance) -> Claim:
    """`claim` with the drag areas (CdS) of `fit` that `cov` does not determine listed
    (module docstring): undetermined, on a bound, or with a sigma larger than the value
    (the sigma scaled by sqrt(chi^2/dof) where that exceeds 1 and `cov` is not scaled
    already).  Returns `claim` itself, changed."""
    inflation = 1.0 if cov.scaled else float(np.sqrt(max(1.0, fit.chi_square / fit.dof)))
    std = cov.std
    found = []
    for name in fit.free:
        if split_name(name)[0] != DRAG_AREA:
            continue
        prm, value = fit.model.parameter(name), fit.parameters[name]
        side = prm.held_side(value)
        if name in cov.undetermined:
            found.append(f"{name} = {value:.4g} {prm.unit}: it lies in a combination of "
                         "parameters the data do not fix (the identifiability lines)")
        elif side is not None or name in cov.at_bound:
            side = side or prm.nearer_bound(value)
            kind = "physical" if prm.is_physical(side) else "guessed"
            found.append(f"{name} = {value:.4g} {prm.unit}: it is on its {kind} {side} "
                         "bound, where the data leave it no sigma")
        elif name in std and std[name] * inflation > abs(value):
            found.append(f"{name} = {value:.4g} {prm.unit}: its sigma "
                         f"{std[name] * inflation:.3g} {prm.unit} is larger than its value")
    claim.undetermined_drag_areas = found
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
