"""Property-based: model files, flight cards and AltOS logs, corrupted, are valid input or one
line with exit 2, naming the file, with nothing written.

- a model file (`reduce --model FILE`): a node of a model block that uses every
  part of the block (options, fixed values, freed parameters, priors) deleted or
  replaced;
- a flight card (`import-altus LOG --card CARD`): a node of a rocket's card;
- an Altus Metrum log (`import-altus LOG`): a cell replaced, rows dropped or
  repeated, the header damaged, the last line cut;
- a `--scheduler` address (`campaign`), assembled from schemes, hosts and ports valid
  and not, or any text: refused in one line naming the option, or one Dask reads.

Plug-in files that fail are drawn in `test_plugin_faults.py`.

`benchmarks/fuzz_inputs.py` runs the long profile.
"""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from cpas_ocp.cli import main
from tests.corruption import EXAMPLES, SEEDED, assert_contract, corrupted_document, corrupted_lines
from tests.io.test_altus_import import CARD, _write_log

MODEL = {
    "effects": [
        {"effect": "canopy_inflation", "start_window": 1.0,
         "start_shifts": {"t_start[fbcp1,stage1]": 0.1}},
        "forebody_drag", "rigid_riser", "drag_scale", "loadcell_scale", "gps", "imu",
        "load_cell", {"effect": "added_mass"}],
    "fix": {"added_mass_factor[fbcp1]": {"value": 1.0, "unit": "1"}},
    "free": ["CdS_V"],
    "priors": {"CdS[fbcp1,stage1]": {"value": 2.1, "sigma": 0.06}},
}

SETTINGS = settings(max_examples=EXAMPLES, deadline=None, derandomize=not SEEDED,
                    suppress_health_check=[HealthCheck.function_scoped_fixture])


@pytest.fixture(scope="module")
def fbcp(problem_folder) -> Path:
    return problem_folder("fbcp", 1)


@pytest.fixture(scope="module")
def altus_log(tmp_path_factory) -> Path:
    path = tmp_path_factory.mktemp("altus") / "log.csv"
    _write_log(path, seed=3)
    return path


def _case(tmp_path: Path, key: object) -> Path:
    work = tmp_path / f"case{abs(hash(key))}"
    shutil.rmtree(work, ignore_errors=True)
    work.mkdir()
    return work


def test_the_uncorrupted_files_are_valid(fbcp, altus_log, tmp_path) -> None:
    """The base documents are valid, so that every exit 2 below comes from a corruption."""
    (tmp_path / "model.json").write_text(json.dumps(MODEL))
    assert main(["reduce", str(fbcp), "--model", str(tmp_path / "model.json"),
                 "--out", str(tmp_path / "reduced")]) == 0
    (tmp_path / "card.json").write_text(json.dumps(CARD))
    assert main(["import-altus", str(altus_log), "--card", str(tmp_path / "card.json"),
                 "--out", str(tmp_path / "test")]) == 0


@SETTINGS
@given(data=st.data())
def test_a_corrupted_model_file_is_valid_or_one_line_exit_2(data, fbcp, tmp_path, capsys):
    document = corrupted_document(data, MODEL)
    work = _case(tmp_path, json.dumps(document, sort_keys=True))
    (work / "model.json").write_text(json.dumps(document))
    code = main(["reduce", str(fbcp), "--model", str(work / "model.json"),
                 "--out", str(work / "out")])
    assert_contract(code, capsys.readouterr().err.strip(), str(work / "model.json"),
                    work / "out")


@SETTINGS
@given(data=st.data())
def test_a_corrupted_flight_card_is_valid_or_one_line_exit_2(data, altus_log, tmp_path,
                                                              capsys):
    document = corrupted_document(data, CARD)
    work = _case(tmp_path, json.dumps(document, sort_keys=True))
    (work / "card.json").write_text(json.dumps(document))
    code = main(["import-altus", str(altus_log), "--card", str(work / "card.json"),
                 "--out", str(work / "test")])
    assert_contract(code, capsys.readouterr().err.strip(), "card.json", work / "test")


@SETTINGS
@given(data=st.data())
def test_a_corrupted_altus_log_is_valid_or_one_line_exit_2(data, altus_log, tmp_path, capsys):
    lines = corrupted_lines(data, altus_log.read_text().splitlines())
    work = _case(tmp_path, tuple(lines))
    (work / "log.csv").write_text("\n".join(lines) + "\n")
    (work / "card.json").write_text(json.dumps(CARD))
    code = main(["import-altus", str(work / "log.csv"), "--card", str(work / "card.json"),
                 "--out", str(work / "test")])
    assert_contract(code, capsys.readouterr().err.strip(), "log.csv", work / "test")


SCHEMES = st.sampled_from(["tcp://", "tls://", "ws://", "wss://", "ucx://", "inproc://", "",
                           "foo://", "TCP://", "tcp:/", "://"])
HOSTS = st.sampled_from(["host", "10.0.0.2", "[::1]", "sched.example.org", "node_7", "",
                         "[::1", "::1]", "[zz]", "-x", "a b", "1.2.3.4.5", "h@h", "h/x",
                         "\x00", "é"])
PORTS = st.sampled_from(["", ":8786", ":1", ":65535", ":0", ":65536", ":99999", ":x", ":",
                         ":-1", ":+1", ": 1", "/", "/x?y"])
ADDRESSES = st.one_of(st.builds(lambda a, b, c: a + b + c, SCHEMES, HOSTS, PORTS),
                      st.text(max_size=30))


@SETTINGS
@given(address=ADDRESSES)
def test_a_scheduler_address_is_one_dask_reads_or_one_line_exit_2(address, tmp_path, capsys):
    """Refused before any work, in one line naming --scheduler; or accepted, and then Dask's
    own parser reads it (the command goes on, to refuse the missing tests folder)."""
    from distributed.comm.addressing import parse_address, parse_host_port

    code = main(["campaign", str(tmp_path / "nowhere"), "--out", str(tmp_path / "c"),
                 "--scheduler", address])
    err = capsys.readouterr().err.strip()
    assert_contract(code, err, "", tmp_path / "c")
    assert code == 2
    if "--scheduler" not in err:
        assert "nowhere" in err, err
        scheme, location = parse_address(address)
        if scheme != "inproc":
            parse_host_port(location, 8786)
