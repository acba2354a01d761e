"""Forward Monte Carlo of a Drogue stage through the fitted model: peak riser loads."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from cpas_ocp.campaign.peak_loads import stage_peak_loads
from cpas_ocp.physics.parameters import param_name

SHAPE = ("CdS", "Ck", "n_p", "expopen", "t_k")


def test_fitted_values_reproduce_the_fit_and_more_drag_pulls_harder(drogue_fit) -> None:
    fit, _, _ = drogue_fit(1)
    fitted = {b: fit.parameters[param_name(b, "drogue1", "stage2")] for b in SHAPE}
    rng = np.random.default_rng(5)
    n = 200
    cases = pd.DataFrame({b: [v, *(v * (1 + 0.05 * rng.standard_normal(n - 1)))]
                          for b, v in fitted.items()})
    result = stage_peak_loads(fit, "drogue1", "stage2", cases)
    # Case 0 is the fit itself: its peak is the fit's own, which the shooting nodes (10 ms)
    # sample from below, within 1 % of the peak (the load changes ~2 % per 10 ms near it).
    q = fit.quantities()["tension[drogue1]"]
    window = (fit.t >= result.t0) & (fit.t <= result.t1)
    assert q[window].max() <= result.tension[0] * (1 + 1e-3)
    assert result.tension[0] < q[window].max() * 1.01
    # Over the cases the peak grows with the drag area and the over-inflation (the load
    # is about CdS Ck q at the peak): both correlations clearly positive.
    for base in ("CdS", "Ck"):
        r = np.corrcoef(cases[base], result.tension)[0, 1]
        assert r > 0.3, (base, r)
    assert np.all(result.load_factor > 0.0)
    assert result.table().shape == (n, 2)


def test_unknown_stage_or_parameter_is_refused(drogue_fit) -> None:
    fit, _, _ = drogue_fit(1)
    with pytest.raises(ValueError, match="no stage"):
        stage_peak_loads(fit, "drogue1", "stage9", pd.DataFrame({"CdS": [1.0]}))
    with pytest.raises(ValueError, match="no parameter"):
        stage_peak_loads(fit, "drogue1", "stage2", pd.DataFrame({"Cx": [1.0]}))
