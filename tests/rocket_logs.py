"""Rocket logs for the tests and benchmarks that fit them: the seeded flights of
`test_rocket_log_import`, logged by one recorder and imported under a card."""

from __future__ import annotations

import json
from pathlib import Path

from cpas_ocp.cli import main
from cpas_ocp.io.example_flight import Flight, fly
from tests.io.test_rocket_log_import import CARD, COLUMN_MAP, write_mapped


def altimeter_log(folder: Path, rate_hz: float, seed: int = 5, still_air: bool = False
                  ) -> Path:
    """A rocket log of the altimeter alone at `rate_hz` (thrust for a 17.6 s apogee, the
    drogue's charge at apogee, the main at 300 m; noise drawn from `seed`), imported
    into folder/test with a card whose model estimates the air's vertical motion, the
    altimeter's bias and its lag; with `still_air`, under the rocket default model in
    still air (`import --still-air`) instead."""
    flight = fly(thrust_n=1600.0, drogue_delay_s=0.0)
    every = round(1.0 / (rate_hz * (flight.t[1] - flight.t[0])))
    flight = Flight(flight.t[::every], flight.h[::every], flight.v[::every],
                    flight.f[::every], flight.events)
    write_mapped(flight, folder / "log.csv", seed=seed)
    (folder / "map.json").write_text(json.dumps(
        {k: v for k, v in COLUMN_MAP.items() if k != "acceleration"}))
    card = {**CARD, "model": {"effects": [
        {"effect": "wind_process", "components": ["up"], "knot_s": 4.0, "tau_s": 20.0,
         "sigma_vertical": 1.0},
        "canopy_inflation", "forebody_drag", "rigid_riser", "baro", "baro_bias", "baro_lag"]}}
    if still_air:
        card = {k: v for k, v in CARD.items() if k != "model"}
    (folder / "card.json").write_text(json.dumps(card))
    assert main(["import", str(folder / "log.csv"), "--columns", str(folder / "map.json"),
                 "--card", str(folder / "card.json"), "--out", str(folder / "test"),
                 *(["--still-air"] if still_air else [])]) == 0
    return folder / "test"
