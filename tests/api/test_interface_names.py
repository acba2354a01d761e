"""The interface's names: every one reaches the package as the interface's own, and a
library effect is had by the name a model block gives it."""

from __future__ import annotations

import pytest

import cpas_ocp
import cpas_ocp as co
from cpas_ocp import api
from cpas_ocp.errors import InputError
from cpas_ocp.physics.effects import AddedMass
from cpas_ocp.physics.effects.wind_process import WindProcess


def test_the_package_gives_every_name_of_the_interface() -> None:
    assert cpas_ocp.__all__ == api.__all__
    assert all(getattr(cpas_ocp, name) is getattr(api, name) for name in api.__all__)
    assert not hasattr(cpas_ocp, "no_such_workflow")


def test_an_effect_is_built_by_its_model_block_name_with_its_options() -> None:
    assert isinstance(co.effect("added_mass"), AddedMass)
    wind = co.effect("wind_process", knot_s=2.0)
    assert isinstance(wind, WindProcess) and wind.knot_s == 2.0
    names = [e.name for e in co.baseline_effects()]
    assert names[0] == "canopy_inflation" and "added_mass" not in names


def test_an_unknown_effect_or_option_is_named() -> None:
    with pytest.raises(InputError, match="got 'nope'"):
        co.effect("nope")
    with pytest.raises(InputError, match="colour"):
        co.effect("added_mass", colour=1)
