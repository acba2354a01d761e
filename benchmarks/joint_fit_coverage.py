"""Benchmark: a PRF shared by five tests, jointly fitted against the two-stage estimate.

Each seed simulates eight `fbcp`-problem tests flown with the same hardware:
both canopies' drag area CdS = 2.0 m^2 in every test (one canopy type, one
stage), the other inflation parameters, load-cell scales and start times as
the problem has them.  Three tests fly behind a small vehicle (no wake, PRF 1);
five behind the capsule, in whose wake both canopies see a fraction PRF = 0.85
of the dynamic pressure (`wake_deficit`).  The manifests are the user's: the
capsule tests' models hold the wake's PRF at 1 (within one test it cannot be
told from CdS), so each test alone reports the product PRF*CdS there; the
small vehicle's have no wake.

Per seed, three estimates of the PRF and its 95 % interval:

* **joint**: `co.joint_fit` with ``CdS`` shared over the canopy type and
  ``prf`` over the vehicle: one NLP of the eight tests, the covariance from
  its KKT system (normal interval, +-1.96 sigma);
* **two-stage population**: what `cpas-ocp population` does with the
  vehicle as covariate: each canopy's log CdS from its own test's fit (its
  variance from that fit), a random-effects model (REML) with the vehicle's
  effect, whose Knapp-Hartung t interval gives log PRF;
* **two-stage fixed effect**: each test's pair of log drag areas with their
  2x2 covariance, one drag area per type and no between-test spread (GLS):
  the best a two-stage estimate can do when the tests share hardware.

Scored against the truth, which no fit sees: coverage of each interval, the
mean sigma, and the spread of the estimates over seeds.

    python benchmarks/joint_fit_coverage.py [--seeds 30] [--first 1] [--workers 2]
"""

from __future__ import annotations

import dataclasses
import json
import sys
import tempfile
from pathlib import Path

import harness
import numpy as np
from scipy import stats

from cpas_ocp.campaign.population_model import PopulationData, fit_population
from cpas_ocp.estimation.simulate import simulate_problem
from cpas_ocp.inference.joint_fit import joint_fit
from cpas_ocp.io.flight_test import load_test
from cpas_ocp.io.problems import Problem, load_problem

CDS = 2.0  # m^2, every canopy
PRF = 0.85  # behind the capsule
SMALL, CAPSULE = 3, 5  # tests behind each vehicle
CANOPIES = ("fbcp1", "fbcp2")
EFFECTS = ["canopy_inflation", "forebody_drag", "wake_deficit", "rigid_riser", "drag_scale",
           "loadcell_scale", "gps", "imu", "load_cell"]
Z95 = stats.norm.ppf(0.975)


def variant(base: Problem, capsule: bool) -> Problem:
    """The `fbcp` problem with one drag area for both canopies, behind the small vehicle or
    the capsule (whose wake the truth model has; the manifest's model holds PRF at 1)."""
    manifest = json.loads(json.dumps(base.manifest))
    truth = dict(base.truth)
    manifest["vehicle"]["name"] = "capsule" if capsule else "small vehicle"
    if capsule:
        manifest["model"] = {"effects": EFFECTS}
    for chute in CANOPIES:
        truth[f"CdS[{chute},stage1]"] = CDS
        if capsule:
            truth[f"prf[{chute}]"] = PRF
    return dataclasses.replace(base, manifest=manifest, truth=truth)


def two_stage(fits: list, covs: list, capsule: np.ndarray) -> dict[str, tuple[float, float, bool]]:
    """The two two-stage estimates of log PRF: (estimate, sigma, interval covers)."""
    y, V, per_test = [], [], []
    for fit, cov in zip(fits, covs, strict=True):
        names = [f"CdS[{c},stage1]" for c in CANOPIES]
        value = np.array([fit.parameters[n] for n in names])
        idx = [cov.names.index(n) for n in names]
        C = cov.matrix[np.ix_(idx, idx)] / np.outer(value, value)  # of log CdS
        y.extend(np.log(value))
        V.extend(np.diag(C))
        per_test.append((np.log(value), C))
    truth = np.log(PRF)
    x = np.repeat(capsule.astype(float), len(CANOPIES))
    data = PopulationData(("CdS",), tuple(f"o{i}" for i in range(len(y))),
                          np.array(y)[:, None], np.array(V)[:, None, None],
                          np.column_stack([np.ones_like(x), x]), ("intercept", "capsule"),
                          (True,))
    pop = fit_population(data, full_omega=False, tau_intervals=False)
    b = pop.coefficients[("CdS", "capsule")]
    se = float(np.sqrt(pop.beta_cov[1, 1]))
    out = {"population": (b.value, se, bool(b.covers(truth)))}
    # GLS: y_i = [1, 1]' (mu + beta capsule_i) + e_i, e_i ~ N(0, C_i).
    info, score = np.zeros((2, 2)), np.zeros(2)
    for (yi, Ci), cap in zip(per_test, capsule, strict=True):
        Xi = np.array([[1.0, float(cap)]] * len(CANOPIES))
        W = np.linalg.inv(Ci)
        info += Xi.T @ W @ Xi
        score += Xi.T @ W @ yi
    cov = np.linalg.inv(info)
    beta = cov @ score
    se = float(np.sqrt(cov[1, 1]))
    out["fixed"] = (float(beta[1]), se, bool(abs(beta[1] - truth) <= Z95 * se))
    return out


def run_seed(seed: int) -> dict:
    """Simulate and fit one seed's eight tests; the three estimates of PRF."""
    base = load_problem("fbcp")
    capsule = np.array([False] * SMALL + [True] * CAPSULE)
    with tempfile.TemporaryDirectory() as tmp:
        tests = []
        for i, cap in enumerate(capsule):
            folder = Path(tmp) / f"t{i}"
            simulate_problem(variant(base, bool(cap)), folder, 1000 * seed + i)
            (folder / "truth.json").unlink()
            tests.append(load_test(folder))
        timer = harness.Timer()
        with timer("joint fit"):
            jf = joint_fit(tests, {"CdS": "type", "prf": "vehicle"})
        wall = timer["joint fit"]
    prf = jf.estimate("prf[fbcp]@capsule")
    cds = jf.estimate("CdS[fbcp,stage1]")
    out = {"seed": seed, "wall_s": wall, "iterations": jf.stats.iterations,
           "chi2_dof": jf.chi2 / jf.dof,
           "joint": (float(np.log(prf.value)), prf.std / prf.value,
                     bool(abs(prf.value - PRF) <= Z95 * prf.std)),
           "joint_cds": (cds.value, cds.std, bool(abs(cds.value - CDS) <= Z95 * cds.std))}
    out.update(two_stage(jf.individual, jf.individual_covariances, capsule))
    return out


def summarise(rows: list[dict]) -> dict:
    """Print the three estimates' scores over the seeds; return them."""
    n = len(rows)
    out: dict = {"seeds": n}
    print(f"\n{n} seeds; truth PRF {PRF}, CdS {CDS} m^2")
    print("| estimate | coverage of the 95 % interval | mean sigma (log PRF) | "
          "SD of the estimates over seeds | mean error |")
    print("|---|---|---|---|---|")
    for key, label in (("joint", "joint fit"), ("population", "two-stage population (REML, KH)"),
                       ("fixed", "two-stage fixed effect (GLS)")):
        est = np.array([r[key][0] for r in rows])
        sig = np.array([r[key][1] for r in rows])
        cov = np.mean([r[key][2] for r in rows])
        print(f"| {label} | {100 * cov:.0f} % | {sig.mean():.5f} | {est.std(ddof=1):.5f} | "
              f"{(est - np.log(PRF)).mean():+.5f} |")
        out[key] = {"coverage": cov, "mean_sigma": sig.mean(), "sd": est.std(ddof=1),
                    "mean_error": (est - np.log(PRF)).mean()}
    cds = np.array([r["joint_cds"][0] for r in rows])
    print(f"joint CdS: coverage {100 * np.mean([r['joint_cds'][2] for r in rows]):.0f} %, "
          f"mean sigma {np.mean([r['joint_cds'][1] for r in rows]):.5f}, SD over seeds "
          f"{cds.std(ddof=1):.5f}")
    ratio = np.array([r["population"][1] / r["joint"][1] for r in rows])
    print(f"sigma ratio two-stage population / joint: median {np.median(ratio):.2f} "
          f"(range {ratio.min():.2f}-{ratio.max():.2f}); fixed effect / joint: median "
          f"{np.median([r['fixed'][1] / r['joint'][1] for r in rows]):.2f}")
    print(f"joint fit: {np.mean([r['wall_s'] for r in rows]):.1f} s and "
          f"{np.mean([r['iterations'] for r in rows]):.0f} iterations on average; chi2/dof "
          f"{min(r['chi2_dof'] for r in rows):.3f}-{max(r['chi2_dof'] for r in rows):.3f}")
    return {**out, "joint_cds": {"coverage": np.mean([r["joint_cds"][2] for r in rows]),
                                 "mean_sigma": np.mean([r["joint_cds"][1] for r in rows]),
                                 "sd": cds.std(ddof=1)},
            "sigma_ratio_population_over_joint": np.median(ratio),
            "sigma_ratio_fixed_over_joint": np.median([r["fixed"][1] / r["joint"][1]
                                                       for r in rows]),
            "joint_wall_s": np.mean([r["wall_s"] for r in rows]),
            "joint_iterations": np.mean([r["iterations"] for r in rows])}


def main() -> None:
    ap = harness.seeds_parser(__doc__, seeds=30)
    ap.add_argument("--out", type=Path, help="a JSON-lines file of each seed's scores")
    args = ap.parse_args()
    rows = harness.run_seeds(run_seed, args, args.out)
    harness.report("joint_fit_coverage", first=args.first, **summarise(rows))
    return None


if __name__ == "__main__":
    sys.exit(main())
