"""The population model of a campaign: recovery of a known population from estimates drawn
with known noise, the calibration of its intervals and grouping test, and the command
line on a campaign's tables (good and bad).

The estimates here are drawn from the two-stage model itself (each opening's true
parameters from the population, its estimate from its own covariance), so these tests
check the statistics; `benchmarks/population_coverage.py` checks the same through
simulated and reconstructed tests.
"""

from __future__ import annotations

import json

import numpy as np
import pandas as pd
import pytest
from scipy import stats

from cpas_ocp.campaign.campaign import COLUMNS, COVARIANCE_COLUMNS
from cpas_ocp.campaign.population_model import PopulationData, fit_population, grouping_test
from cpas_ocp.cli import main

TAU = np.array([0.05, 0.08, 0.03])
RHO = np.array([[1.0, -0.5, 0.2], [-0.5, 1.0, 0.0], [0.2, 0.0, 1.0]])
MEAN = np.array([np.log(2.0), np.log(9.0), np.log(1.5)])
EFFECT = np.array([0.06, 0.0, -0.03])  # per unit of the covariate (0 or 1)


def draw(seed: int, n: int, k: int = 3, shift: float = 0.0, noise: float = 0.03,
         effect: bool = True) -> PopulationData:
    """`n` openings of a k-parameter population with one 0/1 covariate (of no effect
    without `effect`); each estimate's standard deviations `noise` times a factor in
    [0.5, 2], correlated 0.4 within a test.  The second half of the openings shifted by
    `shift` between-test sigmas."""
    rng = np.random.default_rng(seed)
    omega = RHO[:k, :k] * np.outer(TAU[:k], TAU[:k])
    x = (np.arange(n) % 2).astype(float)
    X = np.column_stack([np.ones(n), x])
    sd = noise * rng.uniform(0.5, 2.0, (n, 1)) * np.ones(k)
    within = 0.6 * np.eye(k) + 0.4
    V = within[None] * sd[:, :, None] * sd[:, None, :]
    theta = (MEAN[:k] + x[:, None] * EFFECT[:k] * effect
             + rng.multivariate_normal(np.zeros(k), omega, n))
    theta[n // 2:] += shift * TAU[:k]
    y = theta + np.array([rng.multivariate_normal(np.zeros(k), v) for v in V])
    return PopulationData(tuple("abc"[:k]), tuple(f"t{i} c1" for i in range(n)), y, V, X,
                          ("intercept", "x"), (True,) * k)


def test_a_large_population_is_recovered_within_its_intervals() -> None:
    """400 openings: each coefficient within its interval at the 99.9 % level, and each tau
    and correlation within four of their standard errors."""
    data = draw(seed=3, n=400)
    fit = fit_population(data, level=0.999)
    truth = np.column_stack([MEAN, EFFECT])
    for j, name in enumerate(data.names):
        for a, column in enumerate(data.columns):
            assert fit.coefficients[(name, column)].covers(truth[j, a]), (name, column)
        assert fit.tau[name].covers(TAU[j]), name
    # Large-sample standard error of a correlation: (1 - rho^2) / sqrt(n).
    se = (1.0 - RHO**2) / np.sqrt(data.n) + 1e-12
    off = ~np.eye(3, dtype=bool)
    assert (np.abs(fit.correlation() - RHO)[off] < 4.0 * se[off] + 0.05).all()


def test_shrinkage_runs_from_the_estimate_to_the_population_mean() -> None:
    """An opening measured far better than the spread keeps its estimate; one measured far
    worse is drawn to the population mean."""
    data = draw(seed=5, n=30, k=2)
    V = data.V.copy()
    V[0] = np.eye(2) * 1e-10  # measured perfectly
    V[1] = np.eye(2) * 1e2  # not measured at all
    sharp = PopulationData(data.names, data.openings, data.y, V, data.X, data.columns, data.log)
    fit = fit_population(sharp, tau_intervals=False)
    theta, cov = fit.shrunken()
    mean = sharp.X @ fit.beta.T
    assert np.allclose(theta[0], sharp.y[0], atol=1e-6)
    assert np.allclose(theta[1], mean[1], atol=1e-3 * TAU[:2].min())
    assert np.allclose(cov[1], fit.omega, rtol=1e-3)


def test_i_squared_is_the_real_share_of_the_spread() -> None:
    """With every opening measured alike (variance v), I^2 = tau^2 / (tau^2 + v)."""
    data = draw(seed=7, n=40, k=2)
    v = 0.04**2
    same = PopulationData(data.names, data.openings, data.y, np.tile(np.eye(2) * v, (40, 1, 1)),
                          data.X, data.columns, data.log)
    fit = fit_population(same, tau_intervals=False)
    tau2 = np.diag(fit.omega)
    assert np.allclose(fit.i_squared(), tau2 / (tau2 + v), rtol=1e-9)


def _binomial_range(n: int, level: float, checks: int) -> tuple[float, float]:
    """The range of the covered fraction of `n` independent intervals at `level`, at a
    family-wise 99 % over `checks` such fractions."""
    lo, hi = stats.binom.ppf([0.005 / checks, 1 - 0.005 / checks], n, level)
    return lo / n, hi / n


def write_campaign_tables(folder, seed: int, tests: int = 12, v_scale: float = 1.0) -> None:
    """A campaign's parameters.csv and covariances.csv drawn from the population above: the
    tests fbcp and drogue in turn, each type's tests with 14 ft and 10.5 ft lines in turn;
    two canopies each."""
    rng = np.random.default_rng(seed)
    names, units = ("CdS", "n_p", "Ck"), ("m^2", "1", "1")
    rows, cov = [], []
    omega = RHO * np.outer(TAU, TAU)
    for t in range(tests):
        test, kind = f"test{t:02d}", ("fbcp", "drogue")[t % 2]
        for chute in ("c1", "c2"):
            sd = 0.03 * rng.uniform(0.5, 2.0, 3)
            value = np.exp(MEAN + rng.multivariate_normal(np.zeros(3), omega)
                           + rng.normal(0.0, sd))
            full = [f"{n}[{chute},stage1]" for n in names]
            for n, f, v, s, u in zip(names, full, value, sd * value, units, strict=True):
                rows.append({"test": test, "parameter": n, "name": f, "parachute": chute,
                             "type": kind, "stage": "stage1", "forebody": "capsule",
                             "cluster_size": 2, "line_length": (4.2672, 3.2004)[t // 2 % 2],
                             "value": v, "std": s, "unit": u})
            S = np.diag(sd * value) ** 2 * v_scale
            for a in range(3):
                for b in range(a + 1):
                    cov.append({"test": test, "name_a": full[a], "name_b": full[b],
                                "covariance": S[a, b]})
    folder.mkdir(parents=True, exist_ok=True)
    pd.DataFrame(rows, columns=COLUMNS).to_csv(folder / "parameters.csv", index=False)
    pd.DataFrame(cov, columns=COVARIANCE_COLUMNS).to_csv(folder / "covariances.csv", index=False)


def test_population_command_writes_its_folder(tmp_path, capsys) -> None:
    campaign = tmp_path / "campaign"
    write_campaign_tables(campaign, seed=1)
    out = tmp_path / "population"
    assert main(["population", str(campaign), "--out", str(out),
                 "--pool", "fbcp/stage1+drogue/stage1"]) == 0
    printed = capsys.readouterr().out
    assert "fbcp stage1 + drogue stage1: 24 openings of 12 tests" in printed
    assert "grouping type (drogue vs fbcp)" in printed
    table = pd.read_csv(out / "population.csv")
    assert list(table.parameter) == ["CdS", "Ck", "n_p"]
    assert (table.median_lower < table["median"]).all()
    assert (table["median"] < table.median_upper).all()
    openings = pd.read_csv(out / "openings.csv")
    assert len(openings) == 24 * 3 and openings.opening_p.between(0, 1).all()
    summary = json.loads((out / "population.json").read_text())
    assert summary["populations"][0]["members"] == [["fbcp", "stage1"], ["drogue", "stage1"]]
    groupings = pd.read_csv(out / "groupings.csv")
    assert set(groupings.covariate) == {"type", "line_length"}
    assert "plotly" in (out / "report.html").read_text()


@pytest.mark.parametrize("args, field", [
    (["--covariate", "forebody"], "forebody"),
    (["--pool", "fbcp/stage1+main/stage1"], "pool"),
])
def test_bad_population_requests_are_one_line_exit_2(tmp_path, capsys, args, field) -> None:
    campaign = tmp_path / "campaign"
    write_campaign_tables(campaign, seed=2)
    assert main(["population", str(campaign), "--out", str(tmp_path / "o"), *args]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and str(campaign) in err and field in err
    assert not (tmp_path / "o").exists()


def test_a_campaign_of_one_test_is_exit_2(tmp_path, capsys) -> None:
    campaign = tmp_path / "campaign"
    write_campaign_tables(campaign, seed=3)
    table = pd.read_csv(campaign / "parameters.csv")
    table[table.test == "test00"].to_csv(campaign / "parameters.csv", index=False)
    assert main(["population", str(campaign), "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "two or more reconstructed tests" in err


def test_a_covariance_not_positive_definite_is_exit_2(tmp_path, capsys) -> None:
    campaign = tmp_path / "campaign"
    write_campaign_tables(campaign, seed=4)
    cov = pd.read_csv(campaign / "covariances.csv")
    first = cov.index[(cov.test == "test03") & (cov.name_a != cov.name_b)][0]
    a, b = cov.loc[first, ["name_a", "name_b"]]
    va = cov[(cov.test == "test03") & (cov.name_a == a) & (cov.name_b == a)].covariance.iloc[0]
    vb = cov[(cov.test == "test03") & (cov.name_a == b) & (cov.name_b == b)].covariance.iloc[0]
    cov.loc[first, "covariance"] = 2.0 * np.sqrt(va * vb)  # a correlation of 2
    cov.to_csv(campaign / "covariances.csv", index=False)
    assert main(["population", str(campaign), "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "test03" in err and "positive definite" in err


def test_a_malformed_pool_is_exit_2(tmp_path, capsys) -> None:
    campaign = tmp_path / "campaign"
    write_campaign_tables(campaign, seed=5)
    assert main(["population", str(campaign), "--out", str(tmp_path / "o"),
                 "--pool", "fbcp"]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "--pool" in err and "TYPE/STAGE" in err


def test_the_python_interface_gives_the_command_s_table(tmp_path) -> None:
    import cpas_ocp as co
    campaign = tmp_path / "campaign"
    write_campaign_tables(campaign, seed=6)
    pop = co.population(campaign, covariates=["line_length"])
    assert [g.label for g in pop.groups] == ["drogue stage1", "fbcp stage1"]
    assert "<table" in pop._repr_html_() and "fbcp stage1" in repr(pop)
    assert pop.summary().startswith("drogue stage1: 12 openings of 6 tests")
    out = pop.report(tmp_path / "out")
    written = pd.read_csv(out / "population.csv")
    assert np.allclose(written["tau"], pop.table["tau"]) and len(written) == 6


def test_dispersions_drawn_from_the_population_stay_in_the_caps(tmp_path, capsys) -> None:
    campaign = tmp_path / "campaign"
    write_campaign_tables(campaign, seed=7)
    runs = []
    for k in (1, 2):
        out = tmp_path / f"cases{k}"
        assert main(["dispersions", str(campaign), "--out", str(out), "--cases", "3000",
                     "--seed", "4", "--population"]) == 0
        runs.append(out)
    assert "cases drawn from the population" in capsys.readouterr().out
    summary = json.loads((runs[0] / "dispersions.json").read_text())
    for model in summary["models"]:
        assert model["drawn_from"] == f"population of {model['type']} {model['stage']}"
        cases = pd.read_parquet(runs[0] / f"cases_{model['type']}_{model['stage']}.parquet")
        assert len(cases) == 3000
        for name, d in model["dispersions"].items():
            assert cases[name].between(d["lower_cap"], d["upper_cap"]).all()
        again = pd.read_parquet(runs[1] / f"cases_{model['type']}_{model['stage']}.parquet")
        pd.testing.assert_frame_equal(cases, again)


def test_the_line_length_ratio_is_a_covariate_where_the_stages_give_d_o(tmp_path) -> None:
    """L_s / D_o from the stages table: at one D_o its effect is the line length's times D_o,
    and the grouping by it is not tested twice."""
    import cpas_ocp as co
    from cpas_ocp.campaign.campaign import STAGE_COLUMNS
    campaign = tmp_path / "campaign"
    write_campaign_tables(campaign, seed=8)
    table = pd.read_csv(campaign / "parameters.csv")
    d_o = 2.1336
    stages = table.groupby(["test", "parachute"]).first().reset_index().assign(
        stage_index=0, inflation="infinite_mass", fill_length="diameter", diameter=d_o,
        v_start=60.0)[STAGE_COLUMNS]
    stages.to_csv(campaign / "stages.csv", index=False)
    by_length = co.population(campaign, covariates=["line_length"])
    by_ratio = co.population(campaign, covariates=["line_length_ratio"])
    for a, b in zip(by_length.groups, by_ratio.groups, strict=True):
        length = next(c for c in a.data.columns if c.startswith("line_length"))
        ratio = next(c for c in b.data.columns if c.startswith("line_length_ratio"))
        for name in a.data.names:
            assert np.isclose(b.fit.coefficients[(name, ratio)].value,
                              a.fit.coefficients[(name, length)].value * d_o, rtol=1e-4)
        assert [t.covariate for t in b.groupings] == ["line_length"]


@pytest.mark.parametrize("reml", [True, False])
def test_the_likelihood_s_gradient_is_its_derivative(reml: bool) -> None:
    """The analytic d(log L)/d(Omega), through Omega's parametrisation, against central
    differences of the log-likelihood itself."""
    from cpas_ocp.campaign.population_model import OmegaForm, evaluate, omega_gradient
    data = draw(seed=9, n=25)
    form = OmegaForm(3, full=True)
    theta = np.array([np.log(0.04), np.log(0.07), np.log(0.02), 0.3, -0.2, 0.5])
    ev = evaluate(data, form.omega(theta), reml)
    analytic = np.einsum("jl,jlm->m", omega_gradient(data, ev, reml), form.jacobian(theta))
    h = 1e-5
    numeric = [(evaluate(data, form.omega(theta + h * e), reml).log_likelihood
                - evaluate(data, form.omega(theta - h * e), reml).log_likelihood) / (2 * h)
               for e in np.eye(6)]
    assert np.allclose(analytic, numeric, rtol=1e-5, atol=1e-6 * np.abs(numeric).max())


@pytest.mark.slow
def test_the_bartlett_factor_is_the_statistic_s_mean_under_pooling() -> None:
    """Three parameters, a full Omega, 12 openings a level: the bootstrap's Bartlett factor
    of one campaign against the statistic's mean over 40 campaigns drawn from the truth
    (per dof), within three standard errors of their difference (the statistic is about b
    times a chi-square on dof, so each mean over 40 has a standard error b sqrt(2 / (40
    dof))); the mean itself above 1, the chi-square law's."""
    from cpas_ocp.campaign.population_model import OmegaForm
    labels = np.array(["A"] * 12 + ["B"] * 12)
    dof = 1 * 3 + OmegaForm(3, full=True).size
    statistics = []
    for seed in range(40):
        data = draw(seed=900 + seed, n=24, k=3, effect=False).subset(np.arange(24),
                                                                      keep_columns=[0])
        statistics.append(grouping_test(data, list(labels), "type", bootstrap=0).statistic)
    mean = float(np.mean(statistics)) / dof
    one = draw(seed=899, n=24, k=3, effect=False).subset(np.arange(24), keep_columns=[0])
    factor = grouping_test(one, list(labels), "type", bootstrap=40, seed=3).bartlett
    se = mean * np.sqrt(2.0 / (dof * 40)) * np.sqrt(2.0)  # of the difference of two means
    assert mean > 1.0
    assert abs(factor - mean) < 3.0 * se


def test_omega_s_jacobian_is_its_derivative() -> None:
    """d(Omega)/d(theta) in closed form against central differences of Omega(theta), for a
    full Omega of four parameters."""
    from cpas_ocp.campaign.population_model import OmegaForm
    form = OmegaForm(4, full=True)
    theta = np.array([-3.0, -2.5, -3.2, -2.8, 0.3, -0.4, 0.5, 0.1, -0.7, 0.2])
    h = 1e-6
    numeric = np.stack([(form.omega(theta + h * e) - form.omega(theta - h * e)) / (2 * h)
                        for e in np.eye(form.size)], axis=2)
    assert np.allclose(form.jacobian(theta), numeric, rtol=1e-6, atol=1e-9 * abs(numeric).max())


def test_a_maximisation_that_did_not_converge_is_a_failure_not_a_result():
    from scipy.optimize import OptimizeResult

    from cpas_ocp.campaign.population_model import STATIONARY, _check_converged
    from cpas_ocp.errors import SolverFailure
    bounds = [(-5.0, 1.0), (-3.0, 3.0)]
    stuck = OptimizeResult(success=False, message="ABNORMAL_TERMINATION_IN_LNSRCH", nit=7,
                           x=np.array([0.0, 0.5]), jac=np.array([0.3, 0.0]))
    with pytest.raises(SolverFailure, match=r"ABNORMAL.*after 7 iterations"):
        _check_converged(stuck, bounds)
    # stationary where free, pushing outwards where on a bound: the maximum itself
    at_optimum = OptimizeResult(success=False, message="ABNORMAL_TERMINATION_IN_LNSRCH",
                                nit=7, x=np.array([-5.0, 0.5]),
                                jac=np.array([4.0, 0.1 * STATIONARY]))
    _check_converged(at_optimum, bounds)
