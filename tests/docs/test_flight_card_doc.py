"""docs/flight-card.md is the reference for the flight card and the column map, and it is
true as printed.

* Every property of `data_schemas/flight_card.schema.json` and
  `data_schemas/column_map.schema.json` (nested blocks included, the card's model block
  through `model.schema.json`), and every field of the manifest's vehicle and parachutes
  that a card passes through, is a row of the page's field tables; and every row names a
  field the schemas have, so that neither the page nor a schema can drift alone.
* Every JSON block on the page says what it is in its fence's info string (```json card,
  ```json map or ```json fragment); each card validates against the card schema and each
  map against the map schema.
* The worked examples (c), an altitude-only log in feet above the pad with a 400 Hz
  accelerometer and a 20 Hz altimeter in one file, and (d), a filtered export whose
  accelerometer is zeroed after apogee, with GNSS in a second file and the main given by
  the card at its 870 m crossing, are run as printed: the page's card and map are written
  beside a log in that layout, flown by the seeded generator of
  `tests/io/test_rocket_log_import.py`, and the page's `cpas-ocp import` command exits 0 with
  a folder that loads.  The main of (d) is the card's crossing, with the card's sigma.
  The Altus Metrum (a) and CATS (b) examples are imported the same way from the
  generator's AltOS export and CATS export folder.  No reconstruction: a few seconds.
"""

from __future__ import annotations

import json
import re
import shlex
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd
import pytest

import tests.io.test_rocket_log_import as generator
from cpas_ocp.cli import main
from cpas_ocp.io.example_flight import (
    H_TABLE,
    P_TABLE,
    SITE,
    Flight,
    fly,
    sample_time,
    sensor_readings,
)
from cpas_ocp.io.flight_test import load_test
from cpas_ocp.io.json_files import validate_block
from cpas_ocp.physics.atmosphere import pressure_altitude
from cpas_ocp.physics.units import FACTORS, G0
from tests.io.test_rocket_log_import import DT

ROOT = Path(__file__).resolve().parents[2]
PAGE = ROOT / "docs" / "flight-card.md"
SCHEMAS = ROOT / "data_schemas"
FENCE = re.compile(r"^```(?P<info>[^\n]*)\n(?P<body>.*?)^```", re.MULTILINE | re.DOTALL)
# Sub-blocks of the column map that every sensor block shares: documented once, as BLOCK.
SHARED_DEFS = {"#/$defs/time", "#/$defs/file"}


def schema(name: str) -> dict[str, Any]:
    return json.loads((SCHEMAS / name).read_text())


def fields(node: Any, path: str, root: dict[str, Any]) -> list[str]:
    """The dotted paths of every named property under schema `node` (at `path`): array
    items as ``[]``, free-named keys (additionalProperties) as ``NAME``, the column map's
    shared sub-blocks under ``BLOCK``; the card's model block through its own schema.  The
    value and unit of a quantity ({value, unit}) are the page's convention, not rows."""
    if not isinstance(node, dict):
        return []
    out: list[str] = []
    ref = node.get("$ref")
    if ref == "cpas-ocp/model.schema.json":
        out += fields(schema("model.schema.json"), path, schema("model.schema.json"))
    elif isinstance(ref, str) and ref.startswith("#/$defs/"):
        out += fields(root["$defs"][ref.split("/")[-1]], path, root)
    props = node.get("properties", {})
    for name, sub in props.items():
        if name in ("value", "unit") and "value" in props:
            continue
        child = f"{path}.{name}" if path else name
        if isinstance(sub, dict) and sub.get("$ref") in SHARED_DEFS:
            child = f"BLOCK.{name}"
        out.append(child)
        out += fields(sub, child, root)
    for key in ("allOf", "oneOf", "anyOf"):
        for sub in node.get(key, []):
            out += fields(sub, path, root)
    if isinstance(node.get("items"), dict):
        out += fields(node["items"], f"{path}[]", root)
    if isinstance(node.get("additionalProperties"), dict):
        out += fields(node["additionalProperties"], f"{path}.NAME", root)
    return list(dict.fromkeys(out))


def card_fields() -> list[str]:
    return fields(schema("flight_card.schema.json"), "", schema("flight_card.schema.json"))


def map_fields() -> list[str]:
    return fields(schema("column_map.schema.json"), "", schema("column_map.schema.json"))


def passed_through() -> list[str]:
    """The manifest's vehicle and parachute fields, which a card gives and the import
    copies into the manifest (the card schema leaves them to the manifest's)."""
    manifest = schema("manifest.schema.json")["properties"]
    return ([f"vehicle.{n}" for n in manifest["vehicle"]["properties"]]
            + [f"parachutes[].{n}" for n in manifest["parachutes"]["items"]["properties"]])


def section(heading: str) -> str:
    """The page's text under `heading` (a ## line) up to the next ## heading."""
    text = PAGE.read_text()
    start = text.index(heading + "\n")
    rest = text[start + len(heading) + 1:]
    end = re.search(r"^## ", rest, re.MULTILINE)
    return rest[: end.start()] if end else rest


def table_fields(text: str) -> list[str]:
    """The first cells (without backticks) of every table row whose table's first header
    is ``field``."""
    out, inside = [], False
    for line in text.splitlines():
        if not line.startswith("|"):
            inside = False
            continue
        cells = [c.strip() for c in line.strip().strip("|").split("|")]
        if cells[0] == "field":
            inside = True
        elif inside and not set(cells[0]) <= set("-: "):
            out.append(cells[0].strip("`"))
    return out


def blocks() -> list[tuple[list[str], str]]:
    """(info-string words, body) of every fenced block on the page."""
    return [(_words(m["info"]), m["body"]) for m in FENCE.finditer(PAGE.read_text())]


def _words(info: str) -> list[str]:
    """A fence's info string as words: ``json`` or the classes of ``{.json .card .example-a}``
    (the attribute form Markdown renders with the tags kept)."""
    return [w.lstrip(".") for w in info.strip().strip("{}").split()]


def example(kind: str, tag: str) -> str:
    """The body of the page's block ```<kind> ... example-<tag>."""
    [body] = [b for info, b in blocks() if info[:1] == [kind.split()[0]]
              and info[1:-1] == kind.split()[1:] and info[-1:] == [f"example-{tag}"]]
    return body


# --- the page names every field, and only fields the schemas have ----------------------

@pytest.mark.parametrize("name", card_fields() + passed_through())
def test_every_card_field_is_a_row_of_the_card_tables(name: str) -> None:
    assert name in table_fields(section("## The flight card")), \
        f"docs/flight-card.md's card tables have no row `{name}`"


@pytest.mark.parametrize("name", map_fields())
def test_every_column_map_field_is_a_row_of_the_map_tables(name: str) -> None:
    assert name in table_fields(section("## The column map")), \
        f"docs/flight-card.md's column-map tables have no row `{name}`"


def test_every_row_is_a_field_of_the_schemas() -> None:
    card = set(card_fields()) | set(passed_through())
    stray = [f for f in table_fields(section("## The flight card")) if f not in card]
    stray += [f for f in table_fields(section("## The column map")) if f not in map_fields()]
    assert not stray, f"rows naming no field of the schemas: {stray}"


def test_the_tables_are_found() -> None:
    """The walk and the table parser see the blocks they should (a guard on the guards)."""
    assert {"events.NAME.altitude", "parachutes[].deployment", "site.pressure",
            "model.priors.NAME.sigma", "nominal.NAME.source"} <= set(card_fields())
    assert {"BLOCK.time.offset", "BLOCK.file", "gnss.satellites", "acceleration.axis",
            "time.offset"} <= set(map_fields())
    assert len(table_fields(section("## The flight card"))) >= len(card_fields())


# --- every JSON block is a valid card or map, or says it is a fragment ------------------

def test_every_json_block_is_marked_and_valid() -> None:
    seen = {"card": 0, "map": 0}
    for info, body in blocks():
        if info[:1] != ["json"]:
            continue
        assert info[1:2] in (["card"], ["map"], ["fragment"]), \
            f"a ```json block without card, map or fragment: {body[:60]!r}"
        obj = json.loads(body)
        if info[1] == "fragment":
            continue
        seen[info[1]] += 1
        validate_block(obj, {"card": "flight_card.schema.json",
                             "map": "column_map.schema.json"}[info[1]], f"page {info}")
    assert seen["card"] >= 4 and seen["map"] >= 2, seen


def test_the_readme_and_the_guide_link_the_page() -> None:
    readme = (ROOT / "README.md").read_text()
    start = readme.index("## A rocket's flight log\n")
    assert "docs/flight-card.md" in readme[start:readme.index("\n## ", start + 1)]
    guide = (ROOT / "docs" / "guide.md").read_text()
    start = guide.index("### Importing a rocket log\n")
    assert "(flight-card.md)" in guide[start:guide.index("\n### ", start + 1)]


# --- the worked examples (c) and (d), run as printed -----------------------------------

def command(tag: str) -> list[str]:
    """The `cpas-ocp import` command of example `tag`, as printed, without `cpas-ocp`."""
    [line] = [c for c in example("sh", tag).splitlines() if c.startswith("cpas-ocp import ")]
    return shlex.split(line)[1:]


def place(tag: str, folder: Path) -> tuple[list[str], dict[str, Any], dict[str, Any], Path]:
    """The example's card and map written under the names its command gives; (argv with
    paths under `folder`, card, map, log path)."""
    argv = command(tag)
    card_text = example("json card", tag)
    map_text = example("json map", tag) if "--columns" in argv else "{}"
    log = folder / argv[1]
    (folder / argv[argv.index("--card") + 1]).write_text(card_text)
    if "--columns" in argv:
        (folder / argv[argv.index("--columns") + 1]).write_text(map_text)
    keep = {0, argv.index("--format") + 1} if "--format" in argv else {0}  # import, altus
    argv = [a if a.startswith("-") or i in keep else str(folder / a) for i, a in enumerate(argv)]
    return argv, json.loads(card_text), json.loads(map_text), log


def resampled(flight: Flight, rate_hz: float) -> Flight:
    """The generator's flight at another sample rate (the truth interpolated)."""
    t = np.round(np.arange(flight.t[0], flight.t[-1], 1.0 / rate_hz), 6)
    return Flight(t, np.interp(t, flight.t, flight.h), np.interp(t, flight.t, flight.v),
                  np.interp(t, flight.t, flight.f), flight.events)


def seconds(block: dict[str, Any], main_unit: str) -> float:
    return FACTORS["time"][block.get("unit", main_unit)]


def write_example_c(flight: Flight, column_map: dict[str, Any], log: Path, seed: int) -> None:
    """The hobby altimeter of example (c): a 400 Hz accelerometer (g, gravity included) and
    a 20 Hz altitude in feet above the pad (the standard atmosphere's height of the
    pressure less the pad's, the map's offset), each with its own time column in one CSV,
    the 20 Hz columns blank below their end."""
    fast, slow = resampled(flight, 400.0), resampled(flight, 20.0)
    _, a = sensor_readings(fast, seed)
    p, _ = sensor_readings(slow, seed + 1)
    alt, acc = column_map["altitude"], column_map["acceleration"]
    feet = FACTORS["length"][alt["unit"]]
    table = pd.DataFrame({
        acc["time"]["column"]: np.round(fast.t / seconds(acc["time"], column_map["time"]["unit"]),
                                        3),
        acc["column"]: np.round((a + G0) / FACTORS["acceleration"][acc["unit"]], 4)})
    table[column_map["time"]["column"]] = pd.Series(
        np.round(slow.t / seconds(column_map["time"], "s"), 3))
    table[alt["column"]] = pd.Series(np.round(pressure_altitude(p) / feet - alt["offset"], 1))
    table.to_csv(log, index=False)


def write_example_d(flight: Flight, column_map: dict[str, Any], log: Path, seed: int) -> None:
    """The filtered export of example (d): pressure through a 0.11 s running median (the
    charges' pressure pulses gone), the accelerometer (gravity subtracted) written as 0
    from apogee on, a title line above the header, the map's delimiter; GNSS fixes at 1 Hz
    (altitude above mean sea level, 2 m noise, every seventh with three satellites) in
    the file the map names, written alike (the map's title lines and delimiter hold for
    every file), on a clock the map's offset puts onto the log's."""
    p, a = sensor_readings(flight, seed)
    p = pd.Series(p).rolling(11, center=True, min_periods=1).median().to_numpy()
    a[flight.t >= flight.events["apogee"]] = 0.0
    main_time = column_map["time"]
    press, acc = column_map["pressure"], column_map["acceleration"]
    table = pd.DataFrame({
        main_time["column"]: np.round(flight.t / seconds(main_time, "s"), 3),
        press["column"]: np.round(p / FACTORS["pressure"][press["unit"]], 3),
        acc["column"]: np.round(a / FACTORS["acceleration"][acc["unit"]], 3)})
    with log.open("w") as f:
        f.write("filtered export of flight 7\n" * column_map.get("skip_rows", 0))
        table.to_csv(f, index=False, sep=column_map.get("delimiter", ","))
    gnss = column_map["gnss"]
    rng = np.random.default_rng(seed + 40)
    fix = np.isclose(flight.t % 1.0, 0.0, atol=1e-6) & (flight.t >= 0.0)
    t_fix = flight.t[fix]
    clock = gnss["time"]
    fixes = pd.DataFrame({
        clock["column"]: np.round((t_fix - clock.get("offset", 0.0))
                                  / seconds(clock, main_time["unit"]), 3),
        gnss["latitude"]: 32.94 + 1e-5 * t_fix, gnss["longitude"]: -106.9 + 2e-5 * t_fix,
        gnss["altitude"]["column"]: np.round(
            (SITE.elevation_m + flight.h[fix] + rng.normal(0.0, 2.0, t_fix.size))
            / FACTORS["length"][gnss["altitude"]["unit"]], 1),
        gnss["satellites"]: np.where(np.arange(t_fix.size) % 7 == 3, 3, 9)})
    with (log.parent / gnss["file"]).open("w") as f:  # written alike: the map's skip_rows
        f.write("filtered export of flight 7, GNSS\n" * column_map.get("skip_rows", 0))
        fixes.to_csv(f, index=False, sep=column_map.get("delimiter", ","))


def import_example(argv: list[str]) -> dict[str, Any]:
    assert main(argv) == 0
    out = Path(argv[argv.index("--out") + 1])
    load_test(out)
    return json.loads((out / "import.json").read_text())


def test_example_c_imports_as_printed(tmp_path: Path) -> None:
    """Two time bases in one file: the altimeter's samples at 20 Hz, the accelerometer's at
    400 Hz; the charges found within three of their sigmas of the truth."""
    flight = fly()
    argv, _, column_map, log = place("c", tmp_path)
    write_example_c(flight, column_map, log, seed=21)
    report = import_example(argv)
    # Each channel read on its own clock: the rows each merged from (the import's note,
    # before the straight stretches became means) are 20 and 400 a second of the phase.
    seconds = report["phase_s"][1] - report["phase_s"][0]
    for name, rate in (("baro", 20.0), ("accelerometer", 400.0)):
        [note] = [n for n in report["notes"] if n.startswith(f"{name}: ")
                  and "samples merged into" in n]
        rows = int(note.split(": ")[1].split(" samples")[0])
        assert rows == pytest.approx(rate * seconds, rel=0.1), name
    for name in ("drogue", "main"):
        event = report["flight_events"][name]
        assert abs(event["time_s"] - flight.events[name]) <= 3 * event["sigma_s"] + 0.05, name
    assert any(n.startswith("drogue: no diameter in the card") for n in report["notes"])


def test_example_d_imports_as_printed_with_the_cards_main(tmp_path: Path) -> None:
    """The main's charge is invisible (no pulse, the accelerometer dead after apogee): the
    main's mortar fire is where the altimeter's reading first comes below the card's
    870 m above the pad, with the card's sigma; the dead accelerometer is left out with a
    note; GNSS from the second file fits the lapse rate and is the gps_altitude sensor."""
    flight = fly(thrust_n=1500.0, main_agl_m=870.0)  # high enough for an 870 m main
    argv, card, column_map, log = place("d", tmp_path)
    write_example_d(flight, column_map, log, seed=22)
    report = import_example(argv)
    out = Path(argv[argv.index("--out") + 1])
    height = card["events"]["main"]["altitude"]["value"]
    main_event = report["flight_events"]["main"]
    assert f"{height:.0f} m crossing" in main_event["source"]
    assert main_event["sigma_s"] == card["events"]["main"]["sigma"]["value"]
    reading = pressure_altitude(np.interp(flight.h, H_TABLE, P_TABLE)) \
        - pressure_altitude(SITE.pressure_pa)
    crossing = flight.t[(flight.t > flight.events["apogee"]) & (reading <= height)][0]
    assert abs(main_event["time_s"] - crossing) <= 2 * DT + 0.02
    assert abs(main_event["time_s"] - sample_time(flight, flight.events["main"])) < 3.0
    test = load_test(out)
    charge = test.event("mortar_fire", "main")
    assert charge.time == pytest.approx(main_event["time_s"], abs=1e-3)
    assert charge.sigma == pytest.approx(main_event["sigma_s"])
    assert {s.kind for s in test.sensors} == {"baro", "gps_altitude"}
    assert any(n.startswith("accelerometer:") and "did not measure" in n
               for n in report["notes"])
    assert report["lapse_fit"] is not None
    assert report["dropped"]["gnss_fixes_with_too_few_satellites"] > 0


def test_examples_a_and_b_import_as_printed(tmp_path: Path) -> None:
    """The Altus Metrum and CATS cards, with the generator's AltOS export and CATS export
    folder under the names the commands give: both import, (a) read as its card's
    data.format says; the altimeter's apogee holds the drogue's opening in (a)'s rocket
    default model (an AltOS log has states, none for apogee), and (b)'s canopies get
    their diameters from the descent."""
    flight = fly()
    argv, _, _, log = place("a", tmp_path)
    generator.write_altus(flight, log, seed=23)
    import_example(argv)
    manifest = json.loads((Path(argv[argv.index("--out") + 1]) / "manifest.json").read_text())
    # (the accelerometer reads that opening: its fill constant is fitted, its growth held)
    assert set(manifest["model"]["fix"]) == {"expopen[drogue,open]"}
    argv, _, _, log = place("b", tmp_path)
    generator.write_cats(flight, log, seed=24)
    report = import_example(argv)
    assert sum(": no diameter in the card;" in n for n in report["notes"]) == 2
