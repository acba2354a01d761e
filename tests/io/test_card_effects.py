"""A flight card's model block is checked when the card is read: an effect the library does
not register is refused then, not at the fit of the folder imported with it."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import pytest

from cpas_ocp.cli import main
from cpas_ocp.errors import InputError
from cpas_ocp.io.example_flight import fly
from cpas_ocp.io.flight_card import load_card
from cpas_ocp.physics.effects.registry import BUILTIN
from tests.io.test_rocket_log_import import CARD, COLUMN_MAP, write_mapped

PLUGINS = Path(__file__).resolve().parents[1] / "plugins"


def _card(tmp_path: Path, model: dict) -> Path:
    path = tmp_path / "card.json"
    path.write_text(json.dumps({**CARD, "model": model}))
    return path


def test_a_card_naming_an_unknown_effect_is_refused_at_import(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """`warp_drive` in model.effects: exit 2 from `import`, one line naming the card file,
    the field and the library's effects; no folder written."""
    write_mapped(fly(), tmp_path / "log.csv", seed=5)
    (tmp_path / "map.json").write_text(json.dumps(COLUMN_MAP))
    card = _card(tmp_path, {"effects": ["canopy_inflation", "forebody_drag", "rigid_riser",
                                        "baro", "warp_drive"]})
    code = main(["import", str(tmp_path / "log.csv"), "--columns", str(tmp_path / "map.json"),
                 "--card", str(card), "--out", str(tmp_path / "test")])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and len(err) == 1, err
    assert err[0].startswith(f"error: {card}: model.effects[4]:"), err
    assert "'warp_drive'" in err[0] and all(name in err[0] for name in BUILTIN), err
    assert not (tmp_path / "test").exists()


def test_an_effect_option_the_effect_does_not_take_is_refused_when_the_card_is_read(
        tmp_path: Path) -> None:
    card = _card(tmp_path, {"effects": ["canopy_inflation", {"effect": "baro", "gain": 2}]})
    with pytest.raises(InputError) as err:
        load_card(str(card))
    assert err.value.file == str(card) and err.value.field == "model.effects[1].gain"


def test_a_card_naming_a_plug_in_effect_still_imports(tmp_path: Path) -> None:
    """An effect of a plug-in the block names is known only once the plug-in is loaded with
    the folder: the card reads, keeps its block as written, and the log imports."""
    shutil.copy(PLUGINS / "breathing.py", tmp_path / "breathing.py")
    model = {"effects": ["canopy_inflation", "forebody_drag", "rigid_riser", "baro",
                         "breathing"], "plugins": ["breathing.py"]}
    card = _card(tmp_path, model)
    assert load_card(str(card)).model == model
    write_mapped(fly(), tmp_path / "log.csv", seed=5)
    (tmp_path / "map.json").write_text(json.dumps(COLUMN_MAP))
    assert main(["import", str(tmp_path / "log.csv"), "--columns", str(tmp_path / "map.json"),
                 "--card", str(card), "--out", str(tmp_path / "test")]) == 0
