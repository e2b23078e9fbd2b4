"""The ECS: the schedule, each system's declared reads and writes, and the rows its query gives.

Small worlds, one fresh simulation per test (STYLE 11)."""

from __future__ import annotations

import dataclasses
import re
import sys
from typing import Any

import esper
import numpy as np
import pytest

from ecs_anim.components import (
    CharacterRow,
    Constraint,
    GroundQuery,
    Morphology,
    MotionPlayer,
    Name,
    NormalizedPose,
    Placement,
    Posture,
)
from ecs_anim.core.ground import Plane, Stairs
from ecs_anim.motion.constraint_table import ConstraintTable
from ecs_anim.runtime.simulation import Simulation
from ecs_anim.runtime.store import SPEC_FIELDS, CharacterStore
from ecs_anim.systems import SCHEDULE

#: Every store field's writers in tick order (DESIGN §6), derived from the declarations below.
#: What starting a clip writes (a queued clip, a gait's, a trigger's play).
CLIP_START = ("clip", "clip_time_s", "loop", "fade_clip", "fade_time_s", "fade_loop", "fade_s",
              "fade_elapsed_s", "fade_keeps_contacts", "fade_speed", "placement_xy",
              "placement_heading", "fade_placement_xy", "fade_placement_heading", "locked")
#: Every store field's writers in tick order (DESIGN §6), derived from the declarations below.
EXPECTED_WRITERS = {
    **{name: ["ApplyReactions", "QueuedClips", "Steering", "DetectEvents"] for name in CLIP_START},
    **{name: ["ApplyReactions", "QueuedClips", "Steering", "MotionPlayback", "DetectEvents"]
       for name in ("clip_time_s", "fade_time_s", "fade_s", "fade_elapsed_s")},
    **{name: ["ApplyReactions", "QueuedClips", "Steering", "MorphologyAdapt", "GroundAdapt",
              "DetectEvents"] for name in ("placement_xy", "fade_placement_xy")},
    "locked": ["ApplyReactions", "QueuedClips", "Steering", "MorphologyAdapt", "GroundAdapt",
               "DetectEvents"],
    **{name: ["ApplyReactions", "DetectEvents"] for name in (
        "constraints.target_world", "constraints.activation", "queue_clip", "queue_fade_s",
        "queue_loop", "queue_len")},
    "queue_head": ["ApplyReactions", "QueuedClips", "DetectEvents"],
    **{name: ["Steering"] for name in (
        "speed", "steer_mode", "steer_heading_rad", "steer_speed_m_s", "path_progress_m", "gait")},
    "poses": ["MotionPlayback", "MorphologyAdapt", "GroundAdapt", "ConstraintSolve",
              "CollisionSeparate"],
    "contact_weight": ["MotionPlayback"],
    "sole_roll": ["MotionPlayback"],
    **{name: ["MorphologyAdapt"] for name in (
        "lengths", "segment_mass_kg", "segment_com_fraction")},
    **{name: ["GroundAdapt"] for name in ("pivot", "ground_ref")},
    "footprint": ["GroundAdapt"],
    **{name: ["ConstraintSolve"] for name in (
        "goals", "solved", "com_desired", "constraints.error", "constraints.weight",
        "constraints.held", "last_clip_values", "last_pose_values", "last_pose_positions",
        "last_clip_positions", "last_kept", "clip_positions")},
    "constraints.enabled": ["ApplyReactions", "ConstraintSolve", "DetectEvents"],
    "com": ["COMControl"],
    "com_error_m": ["COMControl"],
    **{name: ["PostureConvert", "CollisionSeparate"] for name in (
        "positions", "posture", "local_rotations", "vertebrae")},
    "frozen": ["PostureConvert"],
    **{name: ["CollisionSeparate"] for name in ("capsule_ends", "capsule_radii", "overlap_m")},
}
#: Fields a system reads as the previous tick left them, before this tick's writer.
LAST_TICK = {"posture", "footprint", "contact_weight", "positions"}
#: The store's own fields (``columns`` holds the user's systems' columns, written by them).
STORE_FIELDS = {f.name for f in dataclasses.fields(CharacterStore)
                if not f.name.startswith("_") and f.name != "columns"}
TABLE_FIELDS = {f.name for f in dataclasses.fields(ConstraintTable)}


def test_the_schedule_is_the_design_cards():
    assert [s.__name__ for s in SCHEDULE] == [
        "ApplyReactions", "QueuedClips", "Steering",  # what each plays this tick
        "MotionPlayback", "MorphologyAdapt", "GroundAdapt", "ConstraintSolve", "COMControl",
        "PostureConvert",  # the design card's seven (DESIGN §6)
        "CollisionSeparate", "DetectEvents", "Render"]


def test_every_declared_name_is_a_store_field_or_a_constraint_table_column():
    for system in SCHEDULE:
        for name in system.reads + system.writes:
            if name.startswith("constraints."):
                assert name.split(".", 1)[1] in TABLE_FIELDS, (system.__name__, name)
            else:
                assert name in STORE_FIELDS or name == "constraints", (system.__name__, name)


def test_each_fields_writers_in_schedule_order():
    writers: dict[str, list[str]] = {}
    for system in SCHEDULE:
        assert len(set(system.writes)) == len(system.writes), system.__name__
        for name in system.writes:
            writers.setdefault(name, []).append(system.__name__)
    assert writers == EXPECTED_WRITERS


def test_every_store_field_is_written_by_a_system_or_is_a_specification():
    written = {name for system in SCHEDULE for name in system.writes}
    assert STORE_FIELDS <= written | set(SPEC_FIELDS), STORE_FIELDS - written - set(SPEC_FIELDS)


def test_every_field_read_is_written_earlier_or_is_an_input():
    earlier: set[str] = set()
    for system in SCHEDULE:
        for name in system.reads:
            ok = (name in SPEC_FIELDS or name in earlier or name in system.writes
                  or name in LAST_TICK)
            assert ok, f"{system.__name__} reads {name!r} before anything writes it"
        earlier |= set(system.writes)


def test_the_declarations_match_the_docstrings():
    for system in SCHEDULE:
        doc = sys.modules[system.__module__].__doc__ or ""
        reads_part = doc[doc.index("Reads:"):doc.index("Writes:")]
        writes_part = doc[doc.index("Writes:"):]

        def mentioned(name: str, text: str) -> bool:
            bare = name.removeprefix("constraints.")
            stars = {m.group(1) for m in re.finditer(r"(\w+?)_\*", text)}
            return (re.search(rf"\b{re.escape(bare)}\b", text) is not None
                    or any(bare.startswith(s + "_") for s in stars))

        for name in system.reads:
            assert mentioned(name, reads_part), (system.__name__, "reads", name)
        for name in system.writes:
            assert mentioned(name, writes_part), (system.__name__, "writes", name)


def _sim(walk, n=3, **kwargs):
    sim = Simulation({"walk": walk}, **kwargs)
    entities = sim.spawn_many([f"c{i}" for i in range(n)], [Morphology.preset("adult_male")] * n,
                              [MotionPlayer("walk")] * n,
                              [Placement((2.0 * i, 0.0)) for i in range(n)])
    return sim, [int(e) for e in entities]


def system(sim, name):
    return next(s for s in sim.systems if type(s).__name__ == name)


def test_a_character_without_a_constraint_is_not_in_the_solve(walk):
    sim, (a, b, _c) = _sim(walk)
    solve, playback = system(sim, "ConstraintSolve"), system(sim, "MotionPlayback")
    assert solve.rows().tolist() == [] and playback.rows().tolist() == [0, 1, 2]
    uid = sim.add_constraint(b, "reach", "wrist_r", 1.0, target_in_world=(0.3, 0.0, 1.2))
    assert solve.rows().tolist() == [1] and system(sim, "COMControl").rows().tolist() == [1]
    with sim._active():
        assert esper.component_for_entity(b, Constraint) == Constraint((uid,), ("reach",))
        assert not esper.has_component(a, Constraint)
    sim.step()
    assert playback.all_rows() and not solve.all_rows()


def test_rows_are_cached_until_the_structure_changes(walk):
    sim, (a, _b, _c) = _sim(walk)
    posture = system(sim, "PostureConvert")
    first = posture.rows()
    sim.step()
    sim.step()
    assert posture.rows() is first  # not recomputed per tick
    assert not first.flags.writeable
    version = sim.structure_version
    sim.spawn("d", Morphology.preset("child"), MotionPlayer("walk"))
    assert sim.structure_version > version
    assert posture.rows() is not first and posture.rows().tolist() == [0, 1, 2, 3]
    sim.remove(a)
    assert posture.rows().tolist() == [0, 1, 2]
    assert sim.names() == ["c1", "c2", "d"]


def test_the_constraint_component_goes_with_the_last_constraint(walk, capsys):
    sim, (a, b, _c) = _sim(walk)
    uid = sim.add_constraint(a, "punch", "wrist_r", 1.0, target_entity=b, target_point="head")
    sim.add_constraint(b, "look", "wrist_l", 1.0, target_in_world=(0.0, 1.0, 1.0))
    assert system(sim, "ConstraintSolve").rows().tolist() == [0, 1]
    sim.remove(b)  # a's punch aimed at b: gone with it, and a's Constraint component too
    with sim._active():
        assert not esper.has_component(a, Constraint)
    assert system(sim, "ConstraintSolve").rows().tolist() == []
    assert "punch" in sim.messages[-1]
    with pytest.raises(Exception, match=f"constraint id {uid}"):
        sim.set_target(uid, (0.0, 0.0, 1.0))


def test_a_character_may_stand_on_a_ground_of_its_own(walk):
    stairs = Stairs(rise_m=0.15, run_m=0.3, steps=4, start_m=1.0)
    sim, (_a, b, _c) = _sim(walk, ground=Plane())
    sim.set_ground(b, stairs)
    on_stairs = sim.spawn("d", Morphology.preset("child"), MotionPlayer("walk"),
                          Placement((2.5, 0.0)), ground=stairs)
    assert sim.store.ground_ref[3] == pytest.approx(0.6)  # on the top of its own stairs
    sim.remove(on_stairs)
    ground = system(sim, "GroundAdapt")
    groups = ground.ground_groups()
    assert [g for g, _ in groups] == [sim.grounds[0], stairs]
    assert [rows.tolist() for _, rows in groups] == [[0, 2], [1]]
    assert sim.store.ground_index.tolist() == [0, 1, 0]
    with sim._active():
        assert esper.component_for_entity(b, GroundQuery).ground is stairs
    sim.set_ground(b, None)
    assert [rows.tolist() for _, rows in ground.ground_groups()] == [[0, 1, 2]]
    with sim._active():
        assert not esper.has_component(b, GroundQuery)
    sim.step()
    assert np.all(np.isfinite(sim.store.positions))


def test_specifications_are_replaced_not_mutated(walk):
    sim, (a, b, _c) = _sim(walk)
    with sim._active():
        for component in (Morphology, MotionPlayer, Placement, CharacterRow, Name):
            spec: Any = esper.component_for_entity(a, component)  # a frozen dataclass
            with pytest.raises(dataclasses.FrozenInstanceError):
                spec.__setattr__(dataclasses.fields(spec)[0].name, None)
    sim.step()
    tall = Morphology.preset("tall")
    sim.set_body(b, tall)
    with sim._active():
        assert esper.component_for_entity(b, Morphology) is tall
    sim.step()  # MorphologyAdapt takes the new body in
    np.testing.assert_array_equal(sim.store.lengths[1], tall.lengths)
    np.testing.assert_array_equal(sim.store.lengths[0], Morphology.preset("adult_male").lengths)


def test_pose_and_posture_are_views_of_the_characters_row(walk):
    sim, (_a, b, _c) = _sim(walk)
    sim.step()
    pose, posture = sim.pose(b), sim.posture(b)
    assert posture.local_rotations.shape == (0, 3, 3)  # rotations not asked for
    assert isinstance(pose, NormalizedPose) and isinstance(posture, Posture)
    assert pose.row == posture.row == 1
    assert np.shares_memory(posture.positions, sim.store.positions)
    np.testing.assert_array_equal(posture.positions, sim.store.positions[1])
    np.testing.assert_array_equal(pose.pose.root_position[0], sim.store.poses.root_position[1])
    with sim._active():
        assert esper.component_for_entity(b, Name).name == "c1"


def test_row_ground_answers_each_row_from_its_own_ground(walk):
    rng = np.random.default_rng(3)
    stairs = Stairs(rise_m=0.15, run_m=0.3, steps=4, start_m=-1.0)
    sim, (_a, b, _c) = _sim(walk, ground=Plane(0.1))
    ground = system(sim, "GroundAdapt")
    xy = rng.uniform(-2, 2, (3, 2, 2))
    np.testing.assert_array_equal(ground.row_ground().height(xy), sim.ground.height(xy))
    sim.set_ground(b, stairs)
    heights = ground.row_ground().height(xy)
    np.testing.assert_array_equal(heights[[0, 2]], sim.ground.height(xy[[0, 2]]))
    np.testing.assert_array_equal(heights[1], stairs.height(xy[1]))
