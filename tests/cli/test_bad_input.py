"""A user's mistake gets one line naming file and field, exit code 2, and nothing written."""

from __future__ import annotations

import json
import shutil
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from cpas_ocp.cli import main


def _csv(folder: Path, name: str, change: Callable[[pd.DataFrame], pd.DataFrame]) -> None:
    path = folder / name
    change(pd.read_csv(path)).to_csv(path, index=False)


def _manifest(folder: Path, change: Callable[[dict], None]) -> None:
    path = folder / "manifest.json"
    m = json.loads(path.read_text())
    change(m)
    path.write_text(json.dumps(m))


def _nan_run(d: pd.DataFrame) -> pd.DataFrame:
    d.loc[100:119, "load_factor"] = np.nan
    return d


def _swap_times(d: pd.DataFrame) -> pd.DataFrame:
    d.loc[[10, 11], "time"] = d.loc[[11, 10], "time"].to_numpy()
    return d


def _huge_reading(d: pd.DataFrame) -> pd.DataFrame:
    d.iloc[5:7, 1] = 1e300
    return d


def _disreef_first(m: dict) -> None:
    """Move the first disreef to 0.5 s before its canopy's mortar fire."""
    disreef = next(e for e in m["events"] if e["name"] == "disreef")
    fire = next(e for e in m["events"] if e["name"] == "mortar_fire"
                and e["parachute"] == disreef["parachute"])
    disreef["time"] = {**disreef["time"], "value": fire["time"]["value"] - 0.5}


def _set(path: list, value) -> Callable[[dict], None]:
    def change(m: dict) -> None:
        node = m
        for key in path[:-1]:
            node = node[key]
        node[path[-1]] = value
    return change


CASES = {
    "missing column": (lambda f: _csv(f, "riser_drogue1.csv", lambda d: d.drop(columns="tension")),
                       "riser_drogue1.csv", "tension"),
    "NaN run": (lambda f: _csv(f, "imu.csv", _nan_run), "imu.csv", "load_factor"),
    "non-monotonic time": (lambda f: _csv(f, "gps.csv", _swap_times), "gps.csv", "time"),
    "unknown unit": (lambda f: _manifest(f, _set(["sensors", 0, "columns", "up"], "furlong")),
                     "manifest.json", "sensors[0].columns.up"),
    "negative mass": (lambda f: _manifest(f, _set(["vehicle", "mass", "value"], -5.0)),
                      "manifest.json", "vehicle.mass"),
    "event outside the data": (lambda f: _manifest(f, _set(["events", 0, "time", "value"], 99.0)),
                               "manifest.json", "events[0].time"),
    "event given twice": (lambda f: _manifest(f, lambda m: m["events"].append(m["events"][0])),
                          "manifest.json", "is the same event"),
    "disreef before its mortar fire": (lambda f: _manifest(f, _disreef_first), "manifest.json",
                                       "out of order"),
    "truncated series": (lambda f: _csv(f, "imu.csv", lambda d: d.iloc[: len(d) // 2]),
                         "imu.csv", "truncated"),
    "huge mass": (lambda f: _manifest(f, _set(["vehicle", "mass", "value"], 1e300)),
                  "manifest.json", "vehicle.mass.value"),
    "huge reading": (lambda f: _csv(f, "gps.csv", _huge_reading), "gps.csv", "rows 6-7"),
    "binary manifest": (lambda f: (f / "manifest.json").write_bytes(b"\x89PNG\r\n\x1a\n\xff\x00"),
                        "manifest.json", "byte 0"),
    "UTF-16 manifest": (lambda f: (f / "manifest.json").write_bytes(
        (f / "manifest.json").read_text().encode("utf-16")), "manifest.json", "byte 0"),
    "NaN literal": (lambda f: _manifest(f, _set(["vehicle", "mass", "value"], float("nan"))),
                    "manifest.json", "NaN"),
    "Infinity literal": (lambda f: _manifest(f, _set(["vehicle", "mass", "value"], float("inf"))),
                         "manifest.json", "Infinity"),
}


@pytest.mark.parametrize("case", list(CASES))
def test_bad_input_is_one_line_exit_2_nothing_written(case, drogue_folder, tmp_path, capsys):
    mutate, file, field = CASES[case]
    folder = tmp_path / "test"
    shutil.copytree(drogue_folder(1), folder)
    mutate(folder)
    out = tmp_path / "report"
    code = main(["reconstruct", str(folder), "--out", str(out)])
    err = capsys.readouterr().err.strip()
    assert code == 2
    assert len(err.splitlines()) == 1, err
    assert file in err and field in err, err
    assert "Traceback" not in err
    assert not out.exists()


def test_nan_run_names_the_rows(drogue_folder, tmp_path, capsys):
    folder = tmp_path / "test"
    shutil.copytree(drogue_folder(1), folder)
    _csv(folder, "imu.csv", _nan_run)
    assert main(["reconstruct", str(folder), "--out", str(tmp_path / "r")]) == 2
    assert "rows 101-120" in capsys.readouterr().err


def test_missing_folder(tmp_path, capsys):
    assert main(["reconstruct", str(tmp_path / "nowhere"), "--out", str(tmp_path / "r")]) == 2
    assert "manifest.json" in capsys.readouterr().err


def test_a_byte_order_mark_is_valid_input(drogue_folder, tmp_path):
    """Spreadsheet programs write UTF-8 with a byte-order mark: the manifest and the CSV
    files load as they do without one."""
    from cpas_ocp.io.flight_test import load_test

    folder = tmp_path / "test"
    shutil.copytree(drogue_folder(1), folder)
    plain = load_test(folder)
    for name in ("manifest.json", "gps.csv"):
        path = folder / name
        path.write_bytes(b"\xef\xbb\xbf" + path.read_bytes())
    marked = load_test(folder)
    assert [s.name for s in marked.sensors] == [s.name for s in plain.sensors]
    for a, b in zip(marked.sensors, plain.sensors, strict=True):
        assert a.data.equals(b.data), a.name
    assert marked.vehicle == plain.vehicle


@pytest.mark.parametrize("option, value", [
    ("--grid-step", "0"), ("--grid-step", "-0.01"), ("--grid-step", "nan"),
    ("--max-iter", "0"), ("--seed", "-1"), ("--profile-points", "1"),
    ("--wind-intensity", "1e-300"), ("--wind-intensity", "1e300"),
])
def test_an_option_out_of_range_is_one_line_exit_2(option, value, tmp_path, capsys):
    command = ["demo", "--out", str(tmp_path / "d")]
    code = main([*command, option, value] if option != "--profile-points" else
                ["reconstruct", str(tmp_path), "--out", str(tmp_path / "r"), option, value])
    err = capsys.readouterr().err.strip()
    assert code == 2
    assert len(err.splitlines()) == 1 and option in err and repr(value) in err, err
    assert not (tmp_path / "d").exists()


def _link(tmp_path: Path) -> Path:
    link = tmp_path / "link"
    link.symlink_to(tmp_path / "earlier")  # dangling
    return link


def _under_file(tmp_path: Path) -> Path:
    (tmp_path / "a_file").write_text("x")
    return tmp_path / "a_file" / "report"


@pytest.mark.parametrize("make", [_link, _under_file], ids=["dangling symlink", "under a file"])
def test_a_bad_out_path_is_refused_before_the_work(make, drogue_folder, tmp_path, capsys):
    out = make(tmp_path)
    code = main(["reconstruct", str(drogue_folder(1)), "--out", str(out)])
    captured = capsys.readouterr()
    assert code == 2
    assert len(captured.err.strip().splitlines()) == 1 and str(out) in captured.err
    assert "solving" not in captured.out  # refused before the estimator was built
    assert not list(tmp_path.glob(".cpas-out-*"))


@pytest.mark.skipif(not Path("/proc/self").is_dir(), reason="needs /proc")
@pytest.mark.parametrize("out", ["/proc/x/out", "/proc/self/x/out"])
def test_an_out_path_where_no_folder_can_be_made_is_refused(out, tmp_path, capsys):
    """Permissions do not tell (root may "write" /proc): the folder is tried, and the
    failure is the user's path, not an internal error."""
    code = main(["simulate", "drogue", "--out", out, "--seed", "1"])
    err = capsys.readouterr().err.strip()
    assert code == 2
    assert len(err.splitlines()) == 1 and out in err and "Traceback" not in err, err


@pytest.mark.parametrize("address, why", [
    ("tcp://host:99999", "Port out of range"), ("tcp://host:x", "integer"),
    ("foo://host:1", "unknown scheme 'foo'"), ("tcp://[::1:8786", "IPv6"),
    ("tcp://[zz]:1", "zz"), ("tcp://host:0", "port"), ("tcp://h:8786/x", "more than"),
    ("", "empty"), ("tcp://a b:1", "space"), ("tcp://-x:1", "-x"),
])
def test_a_bad_scheduler_address_is_refused_before_the_work(address, why, tmp_path, capsys):
    """Dask's own parser would fail only when the tasks are sent, as an internal error."""
    code = main(["campaign", str(tmp_path / "nowhere"), "--out", str(tmp_path / "c"),
                 "--scheduler", address])
    err = capsys.readouterr().err.strip()
    assert code == 2
    assert len(err.splitlines()) == 1 and "--scheduler" in err and why in err, err
    assert repr(address) in err and "nowhere" not in err  # refused before the folders


@pytest.mark.parametrize("address", ["tcp://host:8786", "host:8786", "tcp://10.0.0.2",
                                     "tls://[::1]:8786", "ws://sched.example.org:80",
                                     "inproc://10.0.0.1/4242/1", "ucx://node_7:13337"])
def test_a_scheduler_address_dask_reads_is_accepted(address) -> None:
    from distributed.comm.addressing import parse_address

    from cpas_ocp.cli.arguments import scheduler

    assert scheduler(address) == address
    assert parse_address(address)[0] in ("tcp", "tls", "ws", "inproc", "ucx")


@pytest.mark.parametrize("name, key", [("model.json", r"bad\nkey"),
                                       (r"two\nlines.json", "CdS[x]")])
def test_a_line_break_in_a_name_stays_one_line(name, key, drogue_folder, tmp_path, capsys):
    """A file name or a JSON key holding a line break is named escaped, on one line."""
    model = tmp_path / name.replace(r"\n", "\n")
    model.write_text(json.dumps({"effects": ["canopy_inflation"],
                                 "fix": {key.replace(r"\n", "\n"): 1.0}}))
    code = main(["reduce", str(drogue_folder(1)), "--model", str(model),
                 "--out", str(tmp_path / "r")])
    err = capsys.readouterr().err.strip()
    assert code == 2
    assert len(err.splitlines()) == 1 and name in err and key in err, err
    assert not (tmp_path / "r").exists()


def test_demo_does_not_delete_a_folder_it_did_not_write(tmp_path, capsys):
    keep = tmp_path / "demo" / "test" / "notes.txt"
    keep.parent.mkdir(parents=True)
    keep.write_text("mine")
    assert main(["demo", "--out", str(tmp_path / "demo")]) == 2
    assert "truth.json" in capsys.readouterr().err
    assert keep.read_text() == "mine"


def test_a_plug_in_that_exits_at_import_is_an_input_error(tmp_path, capsys):
    plugin = tmp_path / "quits.py"
    plugin.write_text("import sys\nsys.exit(0)\n")
    assert main(["effects", "--plugin", str(plugin)]) == 2
    err = capsys.readouterr().err
    assert "quits.py" in err and "SystemExit" in err


_PLUGIN_HEAD = """from dataclasses import dataclass

from cpas_ocp.physics.effects import Effect


@dataclass(frozen=True)
class Gust(Effect):
    name: str = "gust"
"""


@pytest.mark.parametrize("body, names", [
    ("    def force(self, ctx):\n        ctx.f = ctx.f\n", ("Gust.force", "'forces'")),
    ("    def parameters(self, test):\n        return []\n", ("Gust", "forces, observations")),
])
def test_a_plug_in_that_would_contribute_nothing_is_refused(tmp_path, capsys, body,
                                                              names) -> None:
    """A misspelt hook, or no hook that acts, would be accepted and listed as an effect
    that changes nothing: it is the user's mistake, named in one line."""
    plugin = tmp_path / "gust.py"
    plugin.write_text(_PLUGIN_HEAD + "\n" + body)
    assert main(["effects", "--plugin", str(plugin)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "gust.py" in err[0] and all(n in err[0] for n in names)


def test_an_internal_error_is_one_line_exit_1_with_a_log(monkeypatch, tmp_path, capsys):
    import cpas_ocp.cli as cli

    def broken(args):
        raise RuntimeError("a defect of the tool\nsecond line")

    monkeypatch.setenv("CPAS_OCP_CACHE", str(tmp_path / "cache"))
    monkeypatch.setattr(cli.commands, "problems", broken)
    assert main(["problems"]) == 1
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and err.startswith("internal error: RuntimeError")
    log = Path(err.split("traceback is in ")[1])
    assert "Traceback" in log.read_text() and "a defect of the tool" in log.read_text()
