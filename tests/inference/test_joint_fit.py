"""Several tests in one NLP with shared parameters (`inference.joint_fit`, `cpas-ocp joint`).

The campaign: four `fbcp`-problem tests flown with the same canopies (one drag
area, 2.0 m^2, for both canopies of every test), two behind a small vehicle
and two behind the capsule, whose wake leaves the canopies a fraction
PRF = 0.85 of the dynamic pressure.  Alone, a capsule test sees only PRF*CdS;
jointly, the small vehicle's tests fix CdS and the capsule's then fix PRF.
"""

from __future__ import annotations

import dataclasses
import json

import numpy as np
import pytest
import scipy.sparse as sp

from cpas_ocp.cli import main
from cpas_ocp.estimation.estimator import Estimator
from cpas_ocp.estimation.joint_nlp import JointNlp, Link, _Gather
from cpas_ocp.estimation.simulate import simulate_problem
from cpas_ocp.inference.joint_fit import joint_fit, shared_key
from cpas_ocp.io.flight_test import load_test
from cpas_ocp.io.problems import load_problem

CDS, PRF = 2.0, 0.85
CANOPIES = ("fbcp1", "fbcp2")
WAKE_MODEL = {"effects": ["canopy_inflation", "forebody_drag", "wake_deficit", "rigid_riser",
                          "drag_scale", "loadcell_scale", "gps", "imu", "load_cell"]}


def _variant(capsule: bool, cds: float = CDS):
    base = load_problem("fbcp")
    manifest = json.loads(json.dumps(base.manifest))
    truth = dict(base.truth)
    manifest["vehicle"]["name"] = "capsule" if capsule else "small vehicle"
    if capsule:
        manifest["model"] = WAKE_MODEL
    for chute in CANOPIES:
        truth[f"CdS[{chute},stage1]"] = cds
        if capsule:
            truth[f"prf[{chute}]"] = PRF
    return dataclasses.replace(base, manifest=manifest, truth=truth)


@pytest.fixture(scope="module")
def folders(tmp_path_factory):
    root = tmp_path_factory.mktemp("joint")
    out = []
    for i, capsule in enumerate((False, False, True, True)):
        folder = root / f"t{i}"
        simulate_problem(_variant(capsule), folder, 500 + i)
        (folder / "truth.json").unlink()
        out.append(folder)
    return out


@pytest.fixture(scope="module")
def fitted(folders):
    return joint_fit([load_test(f) for f in folders], {"CdS": "type", "prf": "vehicle"})


def test_gather_places_blocks_and_orders_rows():
    rng = np.random.default_rng(3)
    blocks = [sp.random(5, 4, 0.5, format="csc", random_state=1),
              sp.random(3, 6, 0.5, format="csc", random_state=2)]
    rows = rng.permutation(8)
    gather = _Gather([(blocks[0], 0, 0), (blocks[1], 5, 4)], (8, 10), rows)
    got = gather([b.data for b in blocks])
    want = sp.block_diag(blocks).tocsr()[rows].toarray()
    assert np.array_equal(got.toarray(), want)
    assert np.all(np.diff(got.indptr) >= 0) and got.has_sorted_indices


def test_joint_jacobians_match_differences_of_the_joint_functions(folders):
    tests = [load_test(f) for f in folders[:2]]
    ests = [Estimator(t) for t in tests]
    link = Link("CdS[fbcp,stage1]", ((0, "CdS[fbcp1,stage1]"), (1, "CdS[fbcp1,stage1]")))
    nlp = JointNlp(ests, [link])
    z = np.concatenate([e.initial_point() for e in ests])
    rng = np.random.default_rng(0)
    d = rng.standard_normal(z.size) * 1e-6
    for value, with_jacobian in ((nlp.residual_value, nlp.residual_jacobian),
                                 (nlp.constraint_value, nlp.constraints)):
        _, M = with_jacobian(z)
        difference = (value(z + d) - value(z - d)) / 2.0
        np.testing.assert_allclose(M @ d, difference, rtol=1e-4, atol=1e-9)
    # the link's row: the two copies' difference over the first copy's scale
    g = nlp.constraint_value(z)
    c0, c1 = nlp.column(0, "CdS[fbcp1,stage1]"), nlp.column(1, "CdS[fbcp1,stage1]")
    assert g[-1] == pytest.approx(z[c0] - z[c1] * nlp.scale(1, "CdS[fbcp1,stage1]")
                                  / nlp.scale(0, "CdS[fbcp1,stage1]"))
    # every test's shooting gaps first, as the linearisation's elimination needs them
    assert nlp.chain_rows == sum(e.transcription.sizes[0] - e.model.nx for e in ests)


def test_shared_keys_replace_canopies_by_type_and_add_the_vehicle(folders):
    test = load_test(folders[2])
    assert shared_key("CdS[fbcp2,stage1]", test, "type") == "CdS[fbcp,stage1]"
    assert shared_key("prf[fbcp1]", test, "vehicle") == "prf[fbcp]@capsule"
    assert shared_key("loadcell_scale[fbcp1]", test, "type") == "loadcell_scale[fbcp]"


@pytest.mark.slow  # joint fits of four tests
def test_joint_fit_recovers_the_shared_prf_and_drag_area(fitted):
    jf = fitted
    assert jf.stats.success
    prf, cds = jf.estimate("prf[fbcp]@capsule"), jf.estimate("CdS[fbcp,stage1]")
    assert len(prf.members) == 4 and len(cds.members) == 8
    # Alone, the capsule tests held PRF at 1 and so reported PRF*CdS.
    assert all(jf.individual[t].parameters[n] == 1.0 for t, n in prf.members)
    for est, truth in ((prf, PRF), (cds, CDS)):
        assert est.determined
        assert abs(est.value - truth) < 3.0 * est.std, (est.name, est.value, est.std)
    # chi-square of the joint fit: the tests' noise, no more
    assert abs(jf.chi2 - jf.dof) < 4.0 * np.sqrt(2.0 * jf.dof)
    assert jf.is_result and jf.problems == []
    # each copy of a shared parameter sits at the shared value in its test's fit
    for t, name in prf.members:
        assert jf.fits[t].parameters[name] == pytest.approx(prf.value, rel=1e-9)


@pytest.mark.slow  # joint fits of four tests
def test_joint_covariance_is_the_two_stage_fixed_effect_one(fitted):
    """Linearised, the joint fit's information on (log CdS, log PRF) is the sum of what each
    test alone gives on its two drag areas (the canopies' 2x2 covariance kept): the
    generalised least-squares combination of the tests' own fits.  Agreement checks the
    joint NLP's assembly, links and KKT covariance against the single-test machinery."""
    jf = fitted
    info = np.zeros((2, 2))
    for t, (fit, cov) in enumerate(zip(jf.individual, jf.individual_covariances, strict=True)):
        names = [f"CdS[{c},stage1]" for c in CANOPIES]
        value = np.array([fit.parameters[n] for n in names])
        idx = [cov.names.index(n) for n in names]
        C = cov.matrix[np.ix_(idx, idx)] / np.outer(value, value)
        X = np.array([[1.0, float(t >= 2)]] * 2)
        info += X.T @ np.linalg.inv(C) @ X
    sd_log_prf = float(np.sqrt(np.linalg.inv(info)[1, 1]))
    prf = jf.estimate("prf[fbcp]@capsule")
    assert prf.std / prf.value == pytest.approx(sd_log_prf, rel=0.02)


@pytest.mark.slow  # joint fits of four tests
def test_a_shared_parameter_no_test_determines_is_reported_so(folders):
    """Behind the small vehicle with the wake in the model and PRF shared too, drag area and
    PRF enter every test only as their product: neither is determined."""
    tests = [load_test(f) for f in folders[2:]]
    jf = joint_fit(tests, {"CdS": "type", "prf": "type"})
    assert not jf.estimate("prf[fbcp]").determined
    assert not jf.estimate("CdS[fbcp,stage1]").determined
    assert not jf.is_result and any("do not determine" in p for p in jf.problems)


@pytest.mark.slow  # a joint fit of two tests
def test_hardware_that_differs_is_not_a_result_and_the_command_exits_4(folders, tmp_path,
                                                                       capsys):
    """Two tests whose canopies' drag areas differ by 15 % fitted as one hardware: the joint
    chi-square is beyond the noise, said in the report, and the command exits 4."""
    other = tmp_path / "larger"
    simulate_problem(_variant(False, cds=1.15 * CDS), other, 777)
    (other / "truth.json").unlink()
    out = tmp_path / "joint"
    code = main(["joint", str(folders[0]), str(other), "--share", "CdS", "--out", str(out)])
    err = capsys.readouterr().err
    assert code == 4 and "beyond the tests' noise" in err
    saved = json.loads((out / "joint.json").read_text())
    assert saved["result"] is False and saved["fit_p_value"] < 1e-3
    assert "**Not a result.**" in (out / "joint.md").read_text()


@pytest.mark.slow  # a joint fit of two tests
def test_cli_writes_the_joint_fit(folders, tmp_path, capsys):
    """The command on one test behind the small vehicle and one behind the capsule: the
    first holds the shared drag area, which frees the capsule's PRF (the fit of all four is
    `fitted`'s)."""
    out = tmp_path / "joint"
    code = main(["joint", *map(str, folders[1:3]), "--share", "CdS", "--share",
                 "prf:vehicle", "--out", str(out)])
    printed = capsys.readouterr().out
    assert code == 0
    assert "prf[fbcp]@capsule" in printed and "CdS[fbcp,stage1]" in printed
    saved = json.loads((out / "joint.json").read_text())
    assert {s["name"] for s in saved["shared"]} == {"CdS[fbcp,stage1]", "prf[fbcp]@capsule"}
    assert (out / "parameters.csv").exists() and (out / "joint.csv").exists()


@pytest.mark.parametrize("argv, field", [
    (["--share", "prf:wing"], "--share"),
    pytest.param(["--share", "nothing_like_this"], "share",
                 marks=pytest.mark.slow),  # the tests' estimators are built first
])
def test_cli_refuses_a_bad_declaration_in_one_line(folders, tmp_path, capsys, argv, field):
    code = main(["joint", *map(str, folders[:2]), *argv, "--out", str(tmp_path / "o")])
    err = capsys.readouterr().err.strip()
    assert code == 2
    assert len(err.splitlines()) == 1 and field in err
    assert not (tmp_path / "o").exists()


def test_cli_refuses_a_single_test(folders, tmp_path, capsys):
    code = main(["joint", str(folders[0]), "--share", "CdS", "--out", str(tmp_path / "o")])
    err = capsys.readouterr().err.strip()
    assert code == 2 and "at least two" in err and len(err.splitlines()) == 1
