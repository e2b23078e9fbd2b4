"""The ECS as users extend it: every system processes exactly the characters its query gives,
and components, systems and store columns of the user's own go in through the public API."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pytest

from conftest import MOTIONS_DIR
from ecs_anim import (
    JOINT_INDEX,
    EcsAnimError,
    Morphology,
    MotionPlayer,
    Placement,
    Simulation,
    System,
    import_bvh,
)
from ecs_anim.components import Constraint
from ecs_anim.systems import SCHEDULE, ConstraintSolve, MotionPlayback, PostureConvert

WRIST = JOINT_INDEX["wrist_r"]
PELVIS = JOINT_INDEX["pelvis"]
#: In front of an adult's right shoulder, within reach (metres, world).
TARGET_IN_WORLD = (0.40, -0.30, 1.15)


def idle_with_reach(take_constraint_away: bool, constrained: bool = True) -> Simulation:
    sim = Simulation({"idle": import_bvh(MOTIONS_DIR / "idle.bvh")})
    entity = sim.spawn("a", Morphology.preset("adult_male"), MotionPlayer("idle"))
    if constrained:
        sim.add_constraint(entity, "reach", "wrist_r", 10.0, target_in_world=TARGET_IN_WORLD)
    if take_constraint_away:
        sim.remove_component(entity, Constraint)
    for _ in range(30):
        sim.step()
    return sim


def wrist_to_target_mm(sim: Simulation) -> float:
    return float(np.linalg.norm(sim.store.positions[0, WRIST] - TARGET_IN_WORLD) * 1e3)


def test_a_character_without_a_constraint_component_is_not_solved():
    solved = idle_with_reach(take_constraint_away=False)
    assert wrist_to_target_mm(solved) < 1.0
    left_out = idle_with_reach(take_constraint_away=True)
    free = idle_with_reach(take_constraint_away=False, constrained=False)
    assert wrist_to_target_mm(left_out) > 100.0
    np.testing.assert_allclose(left_out.store.positions, free.store.positions, atol=1e-9)
    assert np.isnan(left_out.constraints.error).all()  # inactive: not measured


def test_a_character_without_a_motion_player_plays_nothing_and_holds_its_pose():
    sim = Simulation({"walk": import_bvh(MOTIONS_DIR / "walk.bvh")})
    still = sim.spawn("still", Morphology.preset("adult_male"), MotionPlayer("walk"))
    walker = sim.spawn("walker", Morphology.preset("adult_male"), MotionPlayer("walk"),
                       Placement((0.0, 2.0), 0.0))
    sim.step()
    sim.remove_component(still, MotionPlayer)
    start = sim.store.positions.copy()
    clock = float(sim.store.clip_time_s[sim.row(still)])
    for _ in range(30):
        sim.step()
    moved_m = np.linalg.norm(sim.store.positions[:, PELVIS] - start[:, PELVIS], axis=1)
    assert moved_m[sim.row(still)] < 1e-4  # its pose held; GroundAdapt still settles the feet
    assert moved_m[sim.row(walker)] > 0.5
    assert sim.store.clip_time_s[sim.row(still)] == clock
    assert sim.component(still, MotionPlayer) is None
    sim.add_component(still, MotionPlayer("walk"))
    sim.step()
    assert sim.store.clip_time_s[sim.row(still)] > clock


@dataclass(frozen=True)
class Marked:
    label: str


class CountMarked(System):
    """Counts, in a column of its own, the ticks each Marked character was processed."""

    query = (Marked,)
    reads = ("columns.ticks_marked",)
    writes = ("columns.ticks_marked",)

    def run(self, dt: float) -> None:
        self.sim.store.columns["ticks_marked"][self.rows()] += 1


def test_a_system_of_ones_own_runs_in_the_schedule_on_its_query_with_its_own_column():
    sim = Simulation({"idle": import_bvh(MOTIONS_DIR / "idle.bvh")})
    column = sim.store.add_column("ticks_marked", dtype=np.int64)
    assert column.shape == (0,)
    made = sim.add_system(CountMarked, before=ConstraintSolve)
    order = [type(s) for s in sim.systems]
    assert order.index(CountMarked) == order.index(ConstraintSolve) - 1
    assert order[:3] == list(SCHEDULE[:3])
    a, b, c = (sim.spawn(n, Morphology.preset("child"), MotionPlayer("idle")) for n in "abc")
    sim.add_component(a, Marked("first"))
    sim.add_component(c, Marked("third"))
    for _ in range(3):
        sim.step()
    assert sim.store.columns["ticks_marked"].tolist() == [3, 0, 3]
    assert [e for e, _ in sim.query(Marked)] == [a, c]
    assert sim.query(Marked)[1][1] == (Marked("third"),)
    sim.remove(b)  # the column's rows move with the characters
    assert sim.store.columns["ticks_marked"].tolist() == [3, 3]
    d = sim.spawn("d", Morphology.preset("child"), MotionPlayer("idle"))
    assert sim.store.columns["ticks_marked"].tolist() == [3, 3, 0]
    sim.add_component(d, Marked("late"))
    sim.step()
    assert sim.store.columns["ticks_marked"].tolist() == [4, 4, 1]
    assert made.ticks == 4


def test_schedule_and_component_mistakes_are_one_line_errors():
    sim = Simulation({"idle": import_bvh(MOTIONS_DIR / "idle.bvh")})
    entity = sim.spawn("a", Morphology.preset("child"), MotionPlayer("idle"))
    sim.add_system(CountMarked)  # default: after PostureConvert
    assert [type(s) for s in sim.systems].index(CountMarked) == \
        [type(s) for s in sim.systems].index(PostureConvert) + 1
    with pytest.raises(EcsAnimError, match="in the schedule already"):
        sim.add_system(CountMarked)
    with pytest.raises(EcsAnimError, match="expected a System subclass"):
        sim.add_system(CountMarked(sim))  # type: ignore[arg-type]
    with pytest.raises(EcsAnimError, match="after or before, not both"):
        sim.add_system(System, after=MotionPlayback, before=ConstraintSolve)
    with pytest.raises(EcsAnimError, match="has no Constraint component"):
        sim.remove_component(entity, Constraint)
    with pytest.raises(EcsAnimError, match="expected a component object"):
        sim.add_component(entity, Marked)
    with pytest.raises(ValueError, match="has a column or field of that name"):
        sim.store.add_column("positions")
    with pytest.raises(EcsAnimError, match="no character with entity id"):
        sim.add_component(10_000, Marked("x"))
