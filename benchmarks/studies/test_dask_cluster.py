"""A dask cluster gives what the local processes give: a campaign's parameter table, and a
Monte Carlo study's peak loads, run on a two-process `distributed.LocalCluster` through
``--scheduler`` and compared with the local run (relative 1e-9 and 1e-12).  The suite's
smaller cases: `tests/campaign/test_campaign.py` and `test_monte_carlo_cli.py` (the same
commands on local processes) and `tests/cli/test_scheduler_backend.py`."""

from __future__ import annotations

import pandas as pd
import pytest

from cpas_ocp.campaign.campaign import find_tests, parameter_table, run_campaign
from cpas_ocp.cli import main
from tests.campaign.test_monte_carlo_cli import LIMIT


def test_dask_cluster_gives_the_same_table(tests_root) -> None:
    distributed = pytest.importorskip("distributed")
    folders = find_tests(tests_root)
    local = parameter_table(run_campaign(folders, workers=1))
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True,
                                  dashboard_address=None) as cluster:
        outcomes = run_campaign(folders, scheduler=cluster.scheduler_address)
    assert [o.kind for o in outcomes] == ["input", "ok", "ok", "ok"]
    remote = parameter_table(outcomes)
    pd.testing.assert_frame_equal(local, remote, check_exact=False, rtol=1e-9)


def test_dask_cluster_gives_the_same_peaks(study) -> None:
    distributed = pytest.importorskip("distributed")
    folder, root = study
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True,
                                  dashboard_address=None) as cluster:
        assert main(["montecarlo", str(folder), "--cases", str(root / "dispersions"), "--out",
                     str(root / "dask"), "--limit", str(LIMIT),
                     "--scheduler", cluster.scheduler_address]) == 0
    for chute in ("fbcp1", "fbcp2"):
        local = pd.read_parquet(root / "local" / f"peak_loads_{chute}_stage1.parquet")
        remote = pd.read_parquet(root / "dask" / f"peak_loads_{chute}_stage1.parquet")
        pd.testing.assert_frame_equal(local, remote, check_exact=False, rtol=1e-12)
