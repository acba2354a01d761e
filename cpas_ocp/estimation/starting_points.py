"""Points of one test phase's NLP (`Estimator`'s starting points): where a solve starts
from the reduction or from another model's fit, and the feasible points that state
integrations give (every shooting gap closed).

The transcription (`transcription.Transcription`) holds the NLP; these build decision
vectors for it: the initial point from the kinematic track and the reduction, a point
from a fit of the same or a simpler model, the sweeps that integrate chosen states
through the grid, and the feasible point near a given one.
"""

from __future__ import annotations

from collections.abc import Sequence

import casadi as ca
import numpy as np

from cpas_ocp.estimation.fit import STOP_CONSTRAINT_TOL, Fit
from cpas_ocp.estimation.kinematic_track import effect_state_guesses, guessed_states
from cpas_ocp.estimation.linearisation import Linearisations
from cpas_ocp.estimation.shooting_grid import fitted_steps
from cpas_ocp.estimation.simulate import rk4_step, simulate
from cpas_ocp.estimation.transcription import Transcription

# Alternations of integrating the trajectory and meeting the other constraints that
# `StartingPoints.feasible_point` makes (each correction moves the trajectory only slightly).
FEASIBILITY_SWEEPS = 5


class StartingPoints:
    """Decision vectors of one transcribed NLP: its starts and its feasible points."""

    def __init__(self, nlp: Transcription, linearisations: Linearisations) -> None:
        """`nlp` is the transcription the points belong to; `linearisations` evaluates
        chi-square and the constraints' violation at a point (`Linearisations.evaluate`)."""
        self.nlp = nlp
        self._linearisations = linearisations
        self._sweeps: dict[tuple[int, ...], ca.Function] = {}  # `_sweep`'s, by rows

    def initial_point(self) -> np.ndarray:
        """Shooting nodes from the kinematic track (GPS, or the altimeter's vertical track) and
        the effects' own state guesses, parameters from the reduction, captures from the
        track's speed."""
        nlp = self.nlp
        m = nlp.model
        x0, guessed = guessed_states(nlp.test, m, nlp.values, nlp.t)
        vel = x0[m.state_slice("velocity")].T
        unguessed = [st for st in m.states if st.name not in guessed]
        if unguessed:
            # States no effect guesses from the data (a Pilot's separation): a forward
            # simulation from the first node with the initial parameter values.
            traj = simulate(m, nlp.values, x0[:, 0], nlp.t[0], nlp.t[-1],
                            step=nlp.fine_step)
            for st in unguessed:
                rows = m.state_slice(st.name)
                x0[rows] = np.array([np.interp(nlp.t, traj.t, col) for col in traj.x[:, rows].T])
        p0 = np.array([nlp.values[f] for f in nlp.free]) / nlp.pscale
        # Captured values: each capture's quantity at the guessed state nearest its time
        # (the start airspeeds the captures themselves feed in at the GPS speed).
        speed = np.linalg.norm(vel, axis=1)
        times = [c.at_time if c.at_time is not None else nlp.values[c.time_parameter]
                 for c in m.captures]
        c_speed = np.interp(times, nlp.t, speed)
        pvec = m.parameter_vector(nlp.values)
        c0 = np.empty(len(m.captures))
        for i, (cap, tc) in enumerate(zip(m.captures, times, strict=True)):
            k = int(np.argmin(np.abs(nlp.t - tc)))
            c0[i] = float(m.capture_function(cap.name)(x0[:, k], nlp.t[k], pvec, c_speed))
        c0 = np.maximum(c0, [c.lower for c in m.captures]) / nlp.cscale
        return np.concatenate([(x0 / nlp.xscale[:, None]).ravel(order="F"), p0, c0])

    def point_from(self, fit: Fit, values: dict[str, float] | None = None) -> np.ndarray:
        """This NLP's decision vector at `fit`, a fit of another model of the same test on
        this grid or a coarser one within it (`_fit_states`): states, parameters and
        captured values by name.

        States the fit's model lacks come from this model's effects' guesses
        (`Effect.state_guess`), else zero; parameters it lacks take this
        estimator's values; `values` (SI) override both.
        """
        nlp = self.nlp
        fit_x = self._fit_states(fit)
        m = nlp.model
        known = {**nlp.values, **{k: v for k, v in fit.parameters.items()
                                  if k in m.parameter_names}, **(values or {})}
        x0 = np.zeros((m.nx, len(nlp.t)))
        theirs = {st.name for st in fit.model.states}
        for name, guess in effect_state_guesses(nlp.test, m, known, nlp.t).items():
            if name not in theirs:
                x0[m.state_slice(name)] = guess
        for st in m.states:
            if st.name in theirs:
                x0[m.state_slice(st.name)] = fit_x[:, fit.model.state_slice(st.name)].T
            elif st.pinned:
                x0[m.state_slice(st.name), 0] = st.initial
        return self.decision_vector(x0, known, fit.captures)

    def decision_vector(self, states: np.ndarray, values: dict[str, float],
                        captures: dict[str, float]) -> np.ndarray:
        """The scaled decision vector of the node `states` (nx x nodes, SI), the free
        parameters' `values` (SI) and the captured values by name (SI)."""
        nlp = self.nlp
        p0 = np.array([values[f] for f in nlp.free]) / nlp.pscale
        c0 = np.array([captures[c.name] for c in nlp.model.captures]) / nlp.cscale
        return np.concatenate([(states / nlp.xscale[:, None]).ravel(order="F"), p0, c0])

    def extension_start(self, fit: Fit, values: dict[str, float] | None = None
                        ) -> tuple[np.ndarray, tuple[float, float]]:
        """This NLP's start at `fit`, a fit of a model this one extends, with its chi-square
        and largest scaled gap (`evaluate`): `point_from(fit, values)`, with the states
        the fit's model lacks guessed from the data or, where that is nearer feasible,
        integrated through the fitted motion (`swept`).

        On `drogue` flown with added mass and fitted without it, an elastic
        riser's stretch guessed from the measured tension left shooting gaps of
        0.45 (scaled) and chi-square 87,477; integrated, 1.3e-5 and 8,553
        against the fit's 8,518.
        """
        z = self.point_from(fit, values)
        theirs = {st.name for st in fit.model.states}
        new = [st.name for st in self.nlp.model.states if st.name not in theirs]
        guessed = self._linearisations.evaluate(z)
        if not new:
            return z, guessed
        swept = self.swept(z, new)
        integrated = self._linearisations.evaluate(swept)
        return (swept, integrated) if integrated[1] < guessed[1] else (z, guessed)

    def _fit_states(self, fit: Fit) -> np.ndarray:
        """The fit's states at this grid's nodes (len(t) x the fit's nx): its own nodes, and
        between them (this grid refined, `_stable_grid`) RK4 steps of the fit's model
        from the node before (one, or as many as the fit's longest interval there has
        sub-steps), as its shooting intervals predict."""
        nlp = self.nlp
        if fit.t.shape == nlp.t.shape and np.allclose(fit.t, nlp.t):
            return fit.x
        k = np.clip(np.searchsorted(fit.t, nlp.t + 1e-9, side="right") - 1, 0, len(fit.t) - 1)
        dt = nlp.t - fit.t[k]
        inside = np.isin(np.round(fit.t, 6), np.round(nlp.t, 6))
        if not (np.all(inside) and abs(fit.t[-1] - nlp.t[-1]) < 1e-6):
            raise ValueError("the fit was made on a shooting grid this one does not refine")
        between = dt > 1e-9
        x = fit.x[k].copy()
        if np.any(between):
            step = rk4_step(fit.model).map(int(between.sum()))
            # Within a long interval of the fit, in its sub-steps' length at the most.
            count = int(np.max(fitted_steps(fit)[k[between]]))
            xb, tb = fit.x[k[between]].T, fit.t[k[between]]
            for j in range(count):
                xb = step(xb, tb + j * dt[between] / count, dt[between] / count,
                          fit.model.parameter_vector(fit.parameters),
                          fit.model.capture_vector(fit.captures))
            x[between] = np.asarray(xb).T
        return x

    def swept(self, z: np.ndarray, states: Sequence[str]) -> np.ndarray:
        """`z` with the named states integrated forward along the grid from their first node,
        every other state held at its node values: the named states' shooting gaps close.

        A fit extended by an effect with states of its own starts those states
        from the effect's guesses from the data (`Effect.state_guess`), which
        the fitted trajectory does not carry: with a riser's stretch guessed
        from the measured tension, the null point of the elastic riser on a
        misspecified `drogue` fit opened gaps no solve closed in 500
        iterations.  Integrated through the fitted motion, the states follow it.
        """
        nlp = self.nlp
        m = nlp.model
        nx, n = m.nx, len(nlp.t) - 1
        X = z[:nx * (n + 1)].reshape(n + 1, nx).T * nlp.xscale[:, None]
        _, pfull, Cp = nlp.unpack(z)
        rows = np.concatenate([np.arange(nx)[m.state_slice(name)] for name in states])
        ends = np.asarray(self._sweep(tuple(int(r) for r in rows))(
            X[:, 0], X[:, :n], nlp.t[:n], np.diff(nlp.t), nlp.steps, pfull, Cp))
        X[rows, 1:] = ends[rows]
        out = z.copy()
        out[:nx * (n + 1)] = (X / nlp.xscale[:, None]).ravel(order="F")
        return out

    def _sweep(self, rows: tuple[int, ...]) -> ca.Function:
        """(x0, node states, interval starts, lengths, sub-steps, p, c) -> the state at every
        interval's end, integrated over the grid from x0 in `rows` and restarted at each
        interval's node values in the other states (its sub-steps times
        `settings.substeps` RK4 steps, as its gap; steps past an interval's count have
        zero length): `swept`'s loop as one CasADi call (`mapaccum`), made once per set
        of rows.

        Called from Python interval by interval, the RK4 steps took 26 s of a 350 s
        discovery on `drogue` (130 ms a sweep over 1,000 intervals)."""
        nlp = self.nlp
        cached = self._sweeps.get(rows)
        if cached is not None:
            return cached
        m, sub = nlp.model, nlp.settings.substeps
        carried, node = ca.SX.sym("carried", m.nx), ca.SX.sym("node", m.nx)
        t, h, count = ca.SX.sym("t"), ca.SX.sym("h"), ca.SX.sym("count")
        p, c = ca.SX.sym("p", len(m.parameters)), ca.SX.sym("c", len(m.captures))
        kept = set(rows)
        x = ca.vertcat(*[carried[i] if i in kept else node[i] for i in range(m.nx)])
        steps = sub * count
        for j in range(sub * int(np.max(nlp.steps, initial=1))):
            x = nlp.step(x, t + j * h / steps, ca.if_else(j < steps, h / steps, 0.0), p, c)
        interval = ca.Function("sweep_interval", [carried, node, t, h, count, p, c], [x])
        self._sweeps[rows] = interval.mapaccum("sweep", len(nlp.t) - 1)
        return self._sweeps[rows]

    def feasible_point(self, z: np.ndarray) -> tuple[np.ndarray, float] | None:
        """A feasible point near `z` and its chi-square; None where none is found.

        Every state is integrated forward from the first node with the
        parameters at `z` (`swept`), which closes the shooting gaps.  The other
        constraints are then met by alternating with that integration: each
        captured value is set to what the trajectory gives at its event, and
        the parameters take the least-norm (scaled) step that meets the
        effects' own constraints to first order.  None where, after
        FEASIBILITY_SWEEPS, a constraint is still violated by more than
        STOP_CONSTRAINT_TOL: a what-if limit, a trajectory that left the
        model's domain, or a constraint on a captured state (a Pilot's riser
        gap at its start time), which only a change of the trajectory would meet.

        Any feasible point bounds the optimum from above: an unconverged solve's
        last iterate, made feasible this way, gives a lower bound on the
        chi-square a richer model removes (`score_test.confirm`).
        """
        nlp = self.nlp
        all_states = [st.name for st in nlp.model.states]
        n_gaps = nlp.model.nx * (len(nlp.t) - 1)
        n_states, n_free, ncap = nlp.sizes
        captures = slice(n_states + n_free, n_states + n_free + ncap)
        effect_rows = slice(n_gaps + ncap, n_gaps + ncap + len(nlp.model.constraints))
        params = nlp.param_index
        point = self.swept(z, all_states)
        for _ in range(FEASIBILITY_SWEEPS):
            # The values only: the Jacobian serves the effects' constraints, where there are
            # any, and a trial point that is not kept never needs it.
            g = nlp.points.constraint_value(point)
            excess = g - np.clip(g, nlp.lbg, nlp.ubg)
            if not np.all(np.isfinite(excess)) \
                    or np.max(np.abs(excess[n_gaps:]), initial=0.0) <= STOP_CONSTRAINT_TOL:
                break
            point = point.copy()
            # Capture rows read C_i - (the trajectory's value at the event) / cscale.
            point[captures] -= excess[n_gaps:n_gaps + ncap]
            if effect_rows.stop > effect_rows.start:
                rows = nlp.points.constraints(point)[1][effect_rows][:, params].toarray()
                point[params] -= np.linalg.lstsq(rows, excess[effect_rows], rcond=None)[0]
            point[params] = np.clip(point[params], nlp.lbz[params], nlp.ubz[params])
            point = self.swept(point, all_states)
        chi2, violation = self._linearisations.evaluate(point)
        if not (np.isfinite(chi2) and violation <= STOP_CONSTRAINT_TOL):
            return None
        return point, chi2
