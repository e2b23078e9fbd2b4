"""Issue 35, item 10: a target from code that is absurd (1e154 m: its squares overflow) never
freezes a character or publishes it at the origin, and the constraint works again once its
target is sane; a character whose pose went non-finite is published again once it is finite."""

from __future__ import annotations

import numpy as np
import pytest

from conftest import MOTIONS_DIR
from ecs_anim import Simulation
from ecs_anim.components import MotionPlayer, Placement
from ecs_anim.core.morphology import Morphology
from ecs_anim.core.skeleton import JOINT_INDEX as J
from ecs_anim.io.importing import import_bvh
from ecs_anim.motion.constraints import Activation

ALWAYS = Activation(0.0, 100.0, 0.0, 0.0)


@pytest.fixture(scope="module")
def walk():
    return import_bvh(MOTIONS_DIR / "walk.bvh")


@pytest.fixture(scope="module")
def idle():
    return import_bvh(MOTIONS_DIR / "idle.bvh")


@pytest.mark.parametrize("far_m", [1e154, 1.7e308, 2e6])
@pytest.mark.parametrize("ticks_before", [0, 5])
def test_an_absurd_target_switches_its_constraint_off_until_a_sane_one(idle, far_m, ticks_before):
    sim = Simulation({"idle": idle})
    twin = Simulation({"idle": idle})
    entity = sim.spawn("a", Morphology.preset("adult_male"), MotionPlayer("idle"), Placement())
    twin.spawn("a", Morphology.preset("adult_male"), MotionPlayer("idle"), Placement())
    for _ in range(ticks_before):
        sim.step()
        twin.step()
    uid = sim.add_constraint(entity, "reach", "wrist_r", 5, ALWAYS, (far_m, -far_m, far_m),
                             chain=("arm_r", "trunk"))
    for _ in range(3):
        sim.step()
        twin.step()
        # the motion's own posture (the constraint off), never frozen, never the origin
        np.testing.assert_array_equal(sim.store.positions, twin.store.positions)
    assert not sim.store.frozen[0]
    assert "'reach' has a target that is not finite or beyond 1,000 km" in sim.messages[0]
    target = twin.store.positions[0, J["shoulder_r"]] + [0.3, -0.2, -0.1]
    sim.set_target(uid, tuple(target))
    for _ in range(30):
        sim.step()
    assert sim.constraints.enabled[0] and sim.constraints.error[0] < 1e-3
    np.testing.assert_allclose(sim.store.positions[0, J["wrist_r"]],
                               sim.constraints.target_world[0], atol=1e-3)


def test_a_frozen_character_is_published_again_once_its_pose_is_finite(walk):
    sim = Simulation({"walk": walk})
    sim.spawn("a", Morphology.preset("adult_male"), MotionPlayer("walk"), Placement())
    sim.step()
    good_lengths = sim.store.lengths.copy()
    sim.store.lengths[0, 2] = np.nan  # a body corrupted behind the API's back
    sim.step()
    held = sim.store.positions[0].copy()
    sim.step()
    assert sim.store.frozen[0]
    np.testing.assert_array_equal(sim.store.positions[0], held)
    sim.store.lengths[:] = good_lengths
    sim.step()
    assert not sim.store.frozen[0] and not np.array_equal(sim.store.positions[0], held)
    assert np.all(np.isfinite(sim.store.positions))
    assert sum("non-finite pose" in m for m in sim.messages) == 1
