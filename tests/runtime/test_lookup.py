"""Characters and constraints looked up by name: ``Simulation.entity(name)`` and
``Simulation.constraint_index(entity, name)`` (issue 14 item 6: the fight has four ``kick_torso``,
one per kicker)."""

from __future__ import annotations

import numpy as np
import pytest

from conftest import MOTIONS_DIR, REPO
from ecs_anim import EcsAnimError, Morphology, MotionPlayer, Placement, Simulation
from ecs_anim.core.skeleton import JOINT_INDEX
from ecs_anim.io.importing import import_bvh
from ecs_anim.motion.constraint_table import TARGET_BODY, TARGET_WORLD
from ecs_anim.scenario import build_simulation, load_scenario


def test_each_kickers_kick_torso_is_its_own_constraint_and_moves_its_own_ankle():
    with build_simulation(load_scenario(REPO / "scenarios" / "fight_training.yaml")) as sim:
        kickers = [sim.entity(f"kicker_{i}") for i in range(1, 5)]
        uids = [sim.constraint_index(k, "kick_torso") for k in kickers]
        assert len(set(uids)) == 4
        rows = sim.constraints.rows_of(np.array(uids))
        assert [int(sim.constraints.owner[r]) for r in rows] == [sim.row(k) for k in kickers]
        # Moving kicker_3's target moves only kicker_3's: the others still aim at their defender.
        far = (40.0, 40.0, 1.0)
        sim.set_target(uids[2], far)
        assert np.array_equal(sim.constraints.target_world[rows[2]], far)
        assert list(sim.constraints.target_kind[rows]) == [TARGET_BODY, TARGET_BODY, TARGET_WORLD,
                                                            TARGET_BODY]


def test_entity_names_the_character_the_scenario_named():
    with build_simulation(load_scenario(REPO / "scenarios" / "fight_training.yaml")) as sim:
        e = sim.entity("defender_2")
        assert sim.names()[sim.row(e)] == "defender_2"
        sim.remove(sim.entity("kicker_1"))  # rows move down; entities stay
        assert sim.entity("defender_2") == e and sim.names()[sim.row(e)] == "defender_2"


def test_unknown_names_say_what_exists_and_the_closest():
    with build_simulation(load_scenario(REPO / "scenarios" / "fight_training.yaml")) as sim:
        with pytest.raises(EcsAnimError, match=r"^no character 'kicker_9' in this simulation "
                           r"\(characters: kicker_1, defender_1, .* \(\+2 more\)\); did you mean "
                           r"'kicker_\d'\?$"):
            sim.entity("kicker_9")
        with pytest.raises(EcsAnimError, match=r"^no constraint 'kick_torzo' on this character "
                           r"\(it has: kick_torso, lean_back\); did you mean 'kick_torso'\?$"):
            sim.constraint_index(sim.entity("kicker_1"), "kick_torzo")
        with pytest.raises(EcsAnimError, match=r"^no character 'nobody' in this simulation "
                           r"\(characters: [^)]*\(\+2 more\)\)$"):
            sim.entity("nobody")


def test_two_characters_of_one_name_are_refused_by_name_not_guessed():
    idle = import_bvh(MOTIONS_DIR / "idle.bvh")
    with Simulation({"idle": idle}) as sim:
        a = sim.spawn("twin", Morphology.preset("child"), MotionPlayer("idle"))
        sim.spawn("twin", Morphology.preset("tall"), MotionPlayer("idle"), Placement((1.0, 0.0)))
        with pytest.raises(EcsAnimError, match=r"^2 characters are named 'twin': use the "
                           "entities spawn returned$"):
            sim.entity("twin")
        reach = sim.add_constraint(a, "reach", "wrist_r", 1.0, target_in_world=(0.25, -0.2, 0.7),
                                   chain=("arm_r", "trunk"))
        assert sim.constraint_index(a, "reach") == reach
        for _ in range(10):
            sim.step()
        wrist = sim.store.positions[sim.row(a), JOINT_INDEX["wrist_r"]]
        assert np.linalg.norm(wrist - (0.25, -0.2, 0.7)) < 1e-3  # the lookup's id is the one solved
