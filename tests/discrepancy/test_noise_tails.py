"""The noise test is two-sided: a chi-square below the noise is the stated sigma too large
(or fewer independent samples than counted), never a misfit.

A real rocket log's `discover` ended at chi-square/dof 0.669 (upper tail p = 0.96) as "a
misfit nothing tested explains ... the stated sigma about -18 % too small", because its
residual kept a 0.13 Hz line.  A chi-square that low is within the noise on a few dozen
degrees of freedom and below it on thousands; the residual's shape within the noise's
size is described, not called a misfit.  The end-to-end case (`drogue` flown, its sigmas
then stated 25 % large) is the study `benchmarks/studies/test_stated_sigmas.py`.
"""

from __future__ import annotations

import json
from types import SimpleNamespace

import pytest
from scipy.stats import chi2

from cpas_ocp.discrepancy.diagnosis import ALPHA, Diagnosis
from cpas_ocp.discrepancy.discovery import Discovery, DiscoveryStep, _ending_state, next_step
from cpas_ocp.discrepancy.residual_diagnosis import PERIODICITY, Finding
from cpas_ocp.inference.noise_test import NoiseTest
from cpas_ocp.io.model_spec import baseline_spec


def _noise(chi2_per_dof: float, dof: int) -> NoiseTest:
    chi = chi2_per_dof * dof
    return NoiseTest(chi, dof, float(chi2.sf(chi, dof)), ALPHA, 3)


def _line() -> Finding:
    """A significant 0.13 Hz line in the altimeter's residual under the drogue."""
    return Finding("baro", "altitude", "steady drogue open", 40.0, 100.0, 300, 0.82, 0.3, 0.13,
                   1e-6, None, None, None, [], True, 1e-5, (PERIODICITY,))


def _ended(noise: NoiseTest, findings: list[Finding]) -> tuple[Diagnosis, Discovery]:
    """A diagnosis with nothing confirmed, and the chain that stops at it."""
    fit = SimpleNamespace()
    diag = Diagnosis(fit, [], [], [], findings, _noise=noise)  # type: ignore[arg-type]
    step = DiscoveryStep(None, baseline_spec(), fit, diagnosis=diag)  # type: ignore[arg-type]
    found = next_step(diag)
    assert isinstance(found, str)
    return diag, Discovery([step], stopped=found, state=_ending_state(diag))


def test_a_low_chi_square_with_a_line_in_the_residual_is_no_misfit() -> None:
    """0.669 on 47 degrees of freedom (p = 0.96) with a 0.13 Hz line: consistent with the noise
    in size, the line described; no "misfit", no sigma "too small"."""
    noise = _noise(0.669, 47)
    assert noise.p_value == pytest.approx(0.96, abs=0.01) and noise.passes
    diag, chain = _ended(noise, [_line()])
    assert diag.state == "consistent" and chain.state == "consistent"
    for text in (diag.verdict(), chain.ending()):
        assert "misfit" not in text and "too small" not in text, text
    assert diag.verdict().startswith("the residuals are consistent with the sensor noise")
    assert "0.13 Hz" in diag.verdict()
    assert chain.ending().startswith("consistent with the noise: chi-square 31.4 on 47")


def test_a_chi_square_in_its_lower_tail_is_below_the_noise() -> None:
    """0.669 on 3,000 degrees of freedom: below the noise, the stated sigma about
    1 / sqrt(0.669) - 1 = 22 % too large."""
    noise = _noise(0.669, 3000)
    assert noise.below and not noise.above and not noise.passes
    for findings in ([], [_line()]):
        diag, chain = _ended(noise, findings)
        assert diag.state == "below the noise" and chain.state == "below the noise"
        assert diag.consistent_with_noise
        assert "22 % too large" in diag.verdict() and "22 % too large" in chain.ending()
        assert chain.ending().startswith("below the noise")
        for text in (diag.verdict(), chain.ending()):
            assert "misfit" not in text and "too small" not in text, text
    assert json.loads(json.dumps(noise.as_dict()))["below"] is True


def test_the_two_tails_share_the_level() -> None:
    """Under the noise the test rejects with probability alpha: alpha / 2 in each tail."""
    dof = 400

    def at(tail: float, upper: bool) -> NoiseTest:
        chi = chi2.isf(tail, dof) if upper else chi2.ppf(tail, dof)
        return NoiseTest(chi, dof, float(chi2.sf(chi, dof)), ALPHA, 3)

    outside, inside = 0.99 * ALPHA / 2, 1.01 * ALPHA / 2
    assert at(outside, True).above and not at(outside, True).passes
    assert at(inside, True).passes
    assert at(outside, False).below and not at(outside, False).above
    assert not at(outside, False).passes and at(inside, False).passes
