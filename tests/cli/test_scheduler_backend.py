"""A scheduler address Dask reads but cannot connect with here (``ucx://`` without the UCX
back end) is the user's choice of cluster: one line on --scheduler, exit 2."""

from __future__ import annotations

import pytest

from cpas_ocp.cli import main


def test_a_ucx_scheduler_without_its_back_end_is_one_line(tmp_path, capsys,
                                                           drogue_folder) -> None:
    from distributed.comm.registry import get_backend

    try:
        get_backend("ucx").get_connector()
    except Exception:  # whatever Dask's stub raises: the case to test
        pass
    else:
        pytest.skip("this installation has a working UCX back end")
    code = main(["campaign", str(drogue_folder(1)), "--out", str(tmp_path / "c"),
                 "--scheduler", "ucx://127.0.0.1:13337"])
    err = capsys.readouterr().err.strip()
    assert code == 2, err
    assert len(err.splitlines()) == 1 and "--scheduler" in err and "ucx://127.0.0.1:13337" in err
    assert "distributed-ucxx" in err and "Traceback" not in err
    assert not (tmp_path / "c").exists()
