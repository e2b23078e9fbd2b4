"""Issue 35, item 11: a body whose legs differ (one thigh 5 % or half shorter: 2 cm and 22 cm
on an adult) plants both feet on the ground and does not slide, with centre-of-mass control and
a target the trunk bends for (an adult's planted foot floated 8.6-11.6 mm with a thigh 2 cm
shorter, 100 mm at 25 cm, and slid up to 87.5 mm a frame)."""

from __future__ import annotations

import pytest

from conftest import SCENARIOS_DIR
from ecs_anim.core.morphology import with_lengths_m
from ecs_anim.scenario import load_scenario, measured_run


@pytest.mark.parametrize("shorter", [0.05, 0.5])
@pytest.mark.parametrize("scenario", ["grasp_com", "terrain_walk"])
def test_unequal_legs_keep_both_soles_planted(scenario, shorter):
    """Every character of the scenario (the far reach with the trunk in its chain, with and
    without COM control; a child, an adult and a tall body walking over stairs and bumps) with
    its left thigh shorter by the share ``shorter`` of it."""
    loaded = load_scenario(SCENARIOS_DIR / f"{scenario}.yaml")
    for character in loaded.characters:
        body = character.morphology
        character.morphology = with_lengths_m(body, {"thigh_l": (1 - shorter) * body["thigh_l"]})
    for character in measured_run(loaded)["characters"]:
        assert character["floating_mm_max"] <= 1.0, character["name"]
        assert character["ground_penetration_mm_max"] <= 1.0, character["name"]
        assert character["foot_sliding_mm_per_frame"]["max"] <= 1.0, character["name"]
