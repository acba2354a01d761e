"""Property-based: the rocketry inputs and the campaign's tables, corrupted, are valid input
or one line with exit 2 naming the file, with nothing written; where one is accepted, what
was written holds physics a flight has.

- a column map (`import LOG --columns MAP`): a node of a map that uses every block (time
  in ms, pressure in hPa, three accelerometer axes, GNSS) deleted or replaced;
- a CATS Configurator export (`import EXPORT --format cats`): one of its CSVs with a cell
  replaced, rows dropped or repeated, the header damaged or the last line cut;
- a rocket's flight card (`import LOG --card CARD`, the log read through the card's
  inline column map): a node of the card deleted or replaced;
- a flight card for `cpas-ocp flight`: a node of a card whose data block names the log
  beside it; the reconstruction is replaced by a stand-in that ends the command with exit
  4 once the import is done (the fits are `test_rocket_log_import`'s business; here every
  way the command's inputs can be wrong is);
- a campaign's tables (`dispersions CAMPAIGN`): parameters.csv or stages.csv corrupted as
  a log is.  Where one is accepted, every drag area and dispersed parameter it held was a
  finite number above zero;
- the cases `montecarlo` flies (cases_<type>_<stage>.parquet, written by `dispersions`):
  the table corrupted as a log is and written back as Parquet (or, where the text no
  longer parses, as the damaged file itself); the fit is replaced by a stand-in that ends
  the command with exit 4 once the cases are read and matched to the test's model.
  Where they are accepted, every case was finite and positive.

An import accepted must have written a folder that loads, whose pad air is a launch
pad's (30-110 kPa, 180-340 K).  `benchmarks/fuzz_inputs.py` runs the long profile of the
other files' tests.
"""

from __future__ import annotations

import io
import json
import shutil
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from hypothesis import event, given
from hypothesis import strategies as st
from pyarrow import ArrowException

from cpas_ocp.campaign.campaign import COLUMNS
from cpas_ocp.campaign.dispersion_study import DISPERSED
from cpas_ocp.cli import main
from cpas_ocp.errors import NotAResult
from cpas_ocp.io.example_flight import Flight, fly
from cpas_ocp.io.flight_test import load_test
from cpas_ocp.io.plausibility import PAD_PRESSURE_PA, PAD_TEMPERATURE_K
from tests.campaign.test_dispersion_study import _table
from tests.campaign.test_drag_area_envelope import stage_table
from tests.corruption import assert_contract, corrupted_document, corrupted_lines
from tests.io.test_fuzz_files import SETTINGS, _case
from tests.io.test_rocket_log_import import CARD, COLUMN_MAP, write_cats, write_mapped

RATE_HZ = 50.0  # the logs' sample rate: events resolved, a few thousand rows to rewrite
NOMINAL = {"CdS[drogue,stage1]": {"value": 0.467, "unit": "m^2", "source": "card"},
           "CdS[main,stage2]": {"value": 5.78, "unit": "m^2", "source": "card"}}
# A card that reads its log through its own column map and names it, for `import` and
# `flight` alike.
FULL_CARD = {**CARD, "data": {"folder": "", "logs": ["log.csv"], "columns": COLUMN_MAP},
             "nominal": NOMINAL}
CATS_FILES = ("imu.csv", "baro.csv", "flightStates.csv", "gnssInfo.csv")


@pytest.fixture(scope="module")
def flight() -> Flight:
    return fly(rate_hz=RATE_HZ)


@pytest.fixture(scope="module")
def logs(flight: Flight, tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A column-mapped log (log.csv), a CATS export (export/) and a campaign folder
    (campaign/: parameters.csv and stages.csv of the synthetic 25-test table)."""
    root = tmp_path_factory.mktemp("fuzz_logs")
    write_mapped(flight, root / "log.csv", seed=21)
    write_cats(flight, root / "export", seed=22)
    (root / "campaign").mkdir()
    table = _table()
    table.to_csv(root / "campaign" / "parameters.csv", index=False)
    stage_table(table).to_csv(root / "campaign" / "stages.csv", index=False)
    return root


@pytest.fixture
def no_reconstruction(monkeypatch: pytest.MonkeyPatch) -> None:
    """`flight` ends with exit 4 where its first log's reconstruction would begin."""
    def stand_in(*_args: object) -> None:
        raise NotAResult("reconstruction left out by the test")
    monkeypatch.setattr("cpas_ocp.api.flights._flight_log", stand_in)


@pytest.fixture(scope="module")
def dispersed(problem_folder, tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Path]:
    """The fbcp seed-1 test folder and a dispersions folder drawn from 12 tests scattered
    5 % about its truth (as `test_monte_carlo_cli` draws them)."""
    folder = problem_folder("fbcp", 1)
    truth = json.loads((folder / "truth.json").read_text())["parameters"]
    root = tmp_path_factory.mktemp("dispersed")
    rng = np.random.default_rng(5)
    rows = [{"test": f"t{k}", "parameter": b, "name": f"{b}[fbcp1,stage1]",
             "parachute": "fbcp1", "type": "fbcp", "stage": "stage1", "forebody": "capsule",
             "cluster_size": 2, "line_length": np.nan,
             "value": truth[f"{b}[fbcp1,stage1]"] * (1 + 0.05 * rng.standard_normal()),
             "std": 0.01, "unit": "1"} for k in range(12) for b in ("CdS", "Ck", "n_p",
                                                                   "expopen", "t_k")]
    (root / "campaign").mkdir()
    pd.DataFrame(rows, columns=COLUMNS).to_csv(root / "campaign" / "parameters.csv",
                                               index=False)
    assert main(["dispersions", str(root / "campaign"), "--out", str(root / "cases"),
                 "--cases", "20", "--seed", "5"]) == 0
    return folder, root / "cases"


@pytest.fixture
def no_fit(monkeypatch: pytest.MonkeyPatch) -> None:
    """`montecarlo` ends with exit 4 where its fit would begin: at the building of the
    NLP, which comes after the cases are read, matched and their columns checked."""
    def stand_in(*_args: object, **_kwargs: object) -> None:
        raise NotAResult("fit left out by the test")
    monkeypatch.setattr("cpas_ocp.api.campaigns.Estimator", stand_in)


def _write(path: Path, obj: object) -> str:
    path.write_text(json.dumps(obj))
    return str(path)


def assert_imported(code: int, out: Path) -> None:
    """An import that exited 0 wrote a folder that loads, with a launch pad's air."""
    if code != 0:
        return
    test = load_test(out)
    atmosphere = json.loads((out / "manifest.json").read_text())["atmosphere"]
    assert PAD_PRESSURE_PA[0] <= atmosphere["pressure"]["value"] <= PAD_PRESSURE_PA[1]
    assert PAD_TEMPERATURE_K[0] <= atmosphere["temperature"]["value"] <= PAD_TEMPERATURE_K[1]
    assert test.t_end > test.t_start


def imported_or_refused(code: int, capsys: pytest.CaptureFixture[str],
                        named: tuple[str, ...], out: Path) -> None:
    """An import's exit: refused in one line naming one of `named` with nothing at `out`
    (`assert_contract`), or a folder written that holds a flight (`assert_imported`)."""
    event(f"exit {code}")
    assert_contract(code, capsys.readouterr().err.strip(), named, out)
    assert_imported(code, out)


def test_the_uncorrupted_inputs_are_valid(logs: Path, tmp_path: Path, no_reconstruction,
                                          capsys: pytest.CaptureFixture[str]) -> None:
    """Every base input is valid, so that every exit 2 below comes from a corruption."""
    card = _write(tmp_path / "card.json", FULL_CARD)
    assert main(["import", str(logs / "log.csv"), "--columns",
                 _write(tmp_path / "map.json", COLUMN_MAP), "--card", card,
                 "--out", str(tmp_path / "mapped")]) == 0
    assert main(["import", str(logs / "export"), "--format", "cats", "--card", card,
                 "--out", str(tmp_path / "cats")]) == 0
    assert main(["import", str(logs / "log.csv"), "--card", card,
                 "--out", str(tmp_path / "carded")]) == 0
    for out in ("mapped", "cats", "carded"):
        assert_imported(0, tmp_path / out)
    shutil.copy(logs / "log.csv", tmp_path / "log.csv")
    assert main(["flight", card, "--out", str(tmp_path / "flight")]) == 4
    assert "left out by the test" in capsys.readouterr().err
    assert load_test(tmp_path / "flight" / "log" / "test").name == CARD["name"]
    assert main(["dispersions", str(logs / "campaign"), "--out", str(tmp_path / "disp"),
                 "--cases", "100", "--seed", "1"]) == 0


@SETTINGS
@given(data=st.data())
def test_a_corrupted_column_map_is_valid_or_one_line_exit_2(data, logs, tmp_path, capsys):
    document = corrupted_document(data, COLUMN_MAP)
    work = _case(tmp_path, json.dumps(document, sort_keys=True))
    code = main(["import", str(logs / "log.csv"), "--columns",
                 _write(work / "map.json", document), "--card",
                 _write(work / "card.json", CARD), "--out", str(work / "test")])
    # A map naming the wrong column or unit is named in the map, or in the log's column
    # whose readings no flight makes.
    imported_or_refused(code, capsys, ("map.json", "log.csv"), work / "test")


@SETTINGS
@given(data=st.data())
def test_a_corrupted_cats_export_is_valid_or_one_line_exit_2(data, logs, tmp_path, capsys):
    name = data.draw(st.sampled_from(CATS_FILES), label="file")
    lines = corrupted_lines(data, (logs / "export" / name).read_text().splitlines())
    work = _case(tmp_path, (name, *lines))
    shutil.copytree(logs / "export", work / "export")
    (work / "export" / name).write_text("\n".join(lines) + "\n")
    code = main(["import", str(work / "export"), "--format", "cats", "--card",
                 _write(work / "card.json", CARD), "--out", str(work / "test")])
    # Rows dropped may take a flight state the card deploys at: then the card's field is
    # named, with the states the log has.
    imported_or_refused(code, capsys, (str(work / "export"), "card.json"), work / "test")


@SETTINGS
@given(data=st.data())
def test_a_corrupted_rocket_card_is_valid_or_one_line_exit_2(data, logs, tmp_path, capsys):
    document = corrupted_document(data, FULL_CARD)
    work = _case(tmp_path, json.dumps(document, sort_keys=True))
    code = main(["import", str(logs / "log.csv"), "--card", _write(work / "card.json", document),
                 "--out", str(work / "test")])
    # A unit the card's inline map gets wrong is named at the log's column it misreads.
    imported_or_refused(code, capsys, ("card.json", "log.csv"), work / "test")


@SETTINGS
@given(data=st.data())
def test_a_corrupted_flight_card_is_valid_or_one_line_exit_2(data, logs, tmp_path,
                                                             no_reconstruction, capsys):
    document = corrupted_document(data, FULL_CARD)
    work = _case(tmp_path, json.dumps(document, sort_keys=True))
    shutil.copy(logs / "log.csv", work / "log.csv")
    code = main(["flight", _write(work / "card.json", document), "--out", str(work / "out")])
    event(f"exit {code}")
    err = capsys.readouterr().err.strip()
    if code == 4:  # imported; the stand-in ended it where the fits begin
        assert "left out by the test" in err, err
        assert_imported(0, work / "out" / "log" / "test")
        return
    assert_contract(code, err, ("card.json", "log.csv"), work / "out")


@pytest.mark.slow  # each table accepted draws its figures: about 3 s
@SETTINGS
@given(data=st.data())
def test_a_corrupted_campaign_table_is_valid_or_one_line_exit_2(data, logs, tmp_path, capsys):
    name = data.draw(st.sampled_from(["parameters.csv", "stages.csv"]), label="file")
    lines = corrupted_lines(data, (logs / "campaign" / name).read_text().splitlines())
    work = _case(tmp_path, (name, *lines))
    shutil.copytree(logs / "campaign", work / "campaign")
    (work / "campaign" / name).write_text("\n".join(lines) + "\n")
    code = main(["dispersions", str(work / "campaign"), "--out", str(work / "out"),
                 "--cases", "100", "--seed", "1"])
    event(f"exit {code}")
    assert_contract(code, capsys.readouterr().err.strip(), str(work / "campaign"),
                    work / "out")
    if code == 0:  # every dispersed value it read was a positive number
        table = pd.read_csv(work / "campaign" / "parameters.csv", keep_default_na=False,
                            na_values=[""])
        values = pd.to_numeric(table.loc[table["parameter"].isin(DISPERSED), "value"],
                               errors="coerce")
        assert (np.isfinite(values) & (values > 0.0)).all()


@pytest.mark.slow
@SETTINGS
@given(data=st.data())
def test_corrupted_monte_carlo_cases_are_valid_or_one_line_exit_2(data, dispersed, tmp_path,
                                                                  no_fit, capsys):
    folder, cases = dispersed
    name = "cases_fbcp_stage1.parquet"
    lines = corrupted_lines(data, pd.read_parquet(cases / name).to_csv(index=False)
                            .splitlines())
    work = _case(tmp_path, tuple(lines))
    shutil.copytree(cases, work / "cases")
    text = "\n".join(lines) + "\n"
    try:
        pd.read_csv(io.StringIO(text)).to_parquet(work / "cases" / name)
    except (ValueError, TypeError, ArrowException):  # no table: the damaged file itself
        (work / "cases" / name).write_text(text)
    code = main(["montecarlo", str(folder), "--cases", str(work / "cases"), "--out",
                 str(work / "out")])
    event(f"exit {code}")
    err = capsys.readouterr().err.strip()
    if code == 4:  # read and matched; the stand-in ended it where the fit begins
        assert "fit left out by the test" in err, err
        values = pd.read_parquet(work / "cases" / name).to_numpy(float)
        assert np.isfinite(values).all() and (values > 0.0).all()
        assert not (work / "out").exists()
        return
    assert_contract(code, err, name, work / "out")
