"""The API validates before it mutates (issue 35, items 4 and 12): every public mutating call of
Simulation given garbage raises EcsAnimError in one line and leaves the simulation exactly as it
was (30 ticks later its store is bit for bit that of a twin that never saw the call); a closed
simulation refuses any use.

The garbage is garbage to the type checker too: the argument types of these calls are not checked
in this file."""

# mypy: disable-error-code="arg-type, list-item"

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from typing import Any

import numpy as np
import pytest

from conftest import shipped_motion
from ecs_anim.components import GroundQuery, Morphology, MotionPlayer, Placement
from ecs_anim.core.errors import EcsAnimError, UsageError
from ecs_anim.core.ground import Plane
from ecs_anim.motion.constraints import Activation
from ecs_anim.runtime.simulation import Simulation
from ecs_anim.runtime.system_base import System
from ecs_anim.runtime.triggers import AtTime, MoveTarget, Play, SetBody, Trigger
from ecs_anim.systems import PostureConvert

TICKS = 30


@pytest.fixture(scope="module")
def motions():
    return {name: shipped_motion(name) for name in ("walk", "idle")}


@dataclasses.dataclass
class World:
    sim: Simulation
    walker: int
    idler: int
    reach: int  # a constraint id on the idler's right wrist


def _world(motions) -> World:
    sim = Simulation(motions)
    walker = sim.spawn("walker", Morphology.from_stature(1.75, "male"), MotionPlayer("walk"),
                       Placement((0.0, 0.0), 0.3))
    idler = sim.spawn("idler", Morphology.from_stature(1.6, "female"), MotionPlayer("idle"),
                      Placement((2.0, 1.0), 1.0))
    reach = sim.add_constraint(idler, "reach", "wrist_r", 1.0, target_in_world=(2.3, 0.8, 1.2))
    sim.step()
    return World(sim, walker, idler, reach)


class BadHeight:
    """A ground answering the wrong shape."""

    def height(self, xy):
        return np.zeros(3)


class BadQuery(System):
    query = ("Placement",)  # type: ignore[assignment]

    def run(self, dt: float) -> None:
        pass


body = Morphology.from_stature(1.7, "male")
GARBAGE: dict[str, Callable[[World], Any]] = {
    # add_constraint: targets, points, kinds and the rest
    "constraint two-value target": lambda w: w.sim.add_constraint(
        w.walker, "c", "wrist_r", target_in_world=(1.0, 2.0)),
    "constraint numpy (4,) target": lambda w: w.sim.add_constraint(
        w.walker, "c", "wrist_r", target_in_world=np.ones(4)),
    "constraint text target": lambda w: w.sim.add_constraint(
        w.walker, "c", "wrist_r", target_in_world="up"),
    "constraint text numbers": lambda w: w.sim.add_constraint(
        w.walker, "c", "wrist_r", target_in_world=("1", "2", "3")),
    "constraint NaN target": lambda w: w.sim.add_constraint(
        w.walker, "c", "wrist_r", target_in_world=(np.nan, 0.0, 1.0)),
    "constraint int point": lambda w: w.sim.add_constraint(w.walker, "c", 5, target_in_world=(1, 1, 1)),
    "constraint unknown point": lambda w: w.sim.add_constraint(
        w.walker, "c", "wirst_r", target_in_world=(1, 1, 1)),
    "constraint int kind": lambda w: w.sim.add_constraint(
        w.walker, "c", "wrist_r", target_in_world=(1, 1, 1), kind=3),
    "constraint list kind": lambda w: w.sim.add_constraint(
        w.walker, "c", "wrist_r", target_in_world=(1, 1, 1), kind=["position"]),
    "constraint unknown kind": lambda w: w.sim.add_constraint(
        w.walker, "c", "wrist_r", target_in_world=(1, 1, 1), kind="pose"),
    "constraint text chain": lambda w: w.sim.add_constraint(
        w.walker, "c", "wrist_r", target_in_world=(1, 1, 1), chain="arm_r"),
    "constraint junk chain item": lambda w: w.sim.add_constraint(
        w.walker, "c", "wrist_r", target_in_world=(1, 1, 1), chain=("arm_r", 3)),
    "constraint text priority": lambda w: w.sim.add_constraint(
        w.walker, "c", "wrist_r", "high", target_in_world=(1, 1, 1)),
    "constraint junk activation": lambda w: w.sim.add_constraint(
        w.walker, "c", "wrist_r", activation=(0, 1), target_in_world=(1, 1, 1)),
    "constraint junk area": lambda w: w.sim.add_constraint(
        w.walker, "c", "wrist_r", target_in_world=(1, 1, 1), kind="area", area="box"),
    "constraint two-value offset": lambda w: w.sim.add_constraint(
        w.walker, "c", "wrist_r", target_in_world=(1, 1, 1), offset_m=(0.1, 0.0)),
    "constraint text distance": lambda w: w.sim.add_constraint(
        w.walker, "c", "wrist_r", target_in_world=(1, 1, 1), kind="distance", distance_m="1"),
    "constraint junk target entity": lambda w: w.sim.add_constraint(
        w.walker, "c", "wrist_r", target_entity="idler", target_point="head"),
    "constraint unknown target point": lambda w: w.sim.add_constraint(
        w.walker, "c", "wrist_r", target_entity=w.idler, target_point="nose"),
    "constraint int name": lambda w: w.sim.add_constraint(w.walker, 7, "wrist_r",
                                                          target_in_world=(1, 1, 1)),
    "constraint name taken": lambda w: w.sim.add_constraint(w.idler, "reach", "wrist_l",
                                                            target_in_world=(1, 1, 1)),
    # set_target / set_targets: shapes, types, ids
    "set_target two values": lambda w: w.sim.set_target(w.reach, (1.0, 2.0)),
    "set_target numpy (4,)": lambda w: w.sim.set_target(w.reach, np.zeros(4)),
    "set_target numpy (2, 3)": lambda w: w.sim.set_target(w.reach, np.zeros((2, 3))),
    "set_target text": lambda w: w.sim.set_target(w.reach, "here"),
    "set_target text uid": lambda w: w.sim.set_target("reach", (1.0, 1.0, 1.0)),
    "set_target unknown uid": lambda w: w.sim.set_target(99, (1.0, 1.0, 1.0)),
    "set_targets (k, 2)": lambda w: w.sim.set_targets(np.array([w.reach]), np.zeros((1, 2))),
    "set_targets k mismatch": lambda w: w.sim.set_targets(np.array([w.reach]), np.zeros((2, 3))),
    "set_targets 2-D uids": lambda w: w.sim.set_targets(np.array([[w.reach]]), np.zeros((1, 3))),
    "set_targets float uids": lambda w: w.sim.set_targets(np.array([0.5]), np.zeros((1, 3))),
    "set_targets object targets": lambda w: w.sim.set_targets(
        np.array([w.reach]), np.array([[1, "a", None]], dtype=object)),
    "set_targets one unknown uid": lambda w: w.sim.set_targets(
        np.array([w.reach, 99]), np.ones((2, 3))),
    # set_ground / set_body
    "set_ground text": lambda w: w.sim.set_ground(w.walker, "plane"),
    "set_ground number": lambda w: w.sim.set_ground(w.walker, 0.0),
    "set_ground wrong heights": lambda w: w.sim.set_ground(w.walker, BadHeight()),
    "set_body text": lambda w: w.sim.set_body(w.walker, "tall"),
    "set_body None": lambda w: w.sim.set_body(w.walker, None),
    "set_body text blend": lambda w: w.sim.set_body(w.walker, body, blend_s="1"),
    "set_body negative blend": lambda w: w.sim.set_body(w.walker, body, blend_s=-1.0),
    # spawn / spawn_many: players, placements, bodies, names, grounds
    "spawn text player": lambda w: w.sim.spawn("x", body, "walk"),
    "spawn unknown clip": lambda w: w.sim.spawn("x", body, MotionPlayer("run")),
    "spawn int clip": lambda w: w.sim.spawn("x", body, MotionPlayer(3)),
    "spawn text speed": lambda w: w.sim.spawn("x", body, MotionPlayer("walk", speed="fast")),
    "spawn junk queue": lambda w: w.sim.spawn("x", body, MotionPlayer("walk", queue=("idle",))),
    "spawn tuple placement": lambda w: w.sim.spawn("x", body, MotionPlayer("walk"), (1.0, 2.0)),
    "spawn three-value position": lambda w: w.sim.spawn(
        "x", body, MotionPlayer("walk"), Placement((1.0, 2.0, 3.0))),
    "spawn NaN placement": lambda w: w.sim.spawn(
        "x", body, MotionPlayer("walk"), Placement((np.nan, 0.0))),
    "spawn text body": lambda w: w.sim.spawn("x", "adult", MotionPlayer("walk")),
    "spawn int name": lambda w: w.sim.spawn(5, body, MotionPlayer("walk")),
    "spawn junk com target": lambda w: w.sim.spawn("x", body, MotionPlayer("walk"),
                                                   com_target_xy=(1.0,)),
    "spawn text ground": lambda w: w.sim.spawn("x", body, MotionPlayer("walk"), ground="plane"),
    "spawn wrong-height ground": lambda w: w.sim.spawn("x", body, MotionPlayer("walk"),
                                                       ground=BadHeight()),
    "spawn_many lengths": lambda w: w.sim.spawn_many(["x", "y"], [body], [MotionPlayer("walk")] * 2),
    "spawn_many one bad": lambda w: w.sim.spawn_many(
        ["x", "y"], [body, body], [MotionPlayer("walk"), MotionPlayer("walk", start_s=np.inf)],
        grounds=[Plane(0.1), None]),
    "spawn_many text names": lambda w: w.sim.spawn_many("xy", [body] * 2, [MotionPlayer("walk")] * 2),
    # add_trigger / add_target_track
    "trigger text": lambda w: w.sim.add_trigger("on start"),
    "trigger text condition": lambda w: w.sim.add_trigger(
        Trigger("t", "at 1 s", (Play(w.walker, "idle"),))),
    "trigger text action": lambda w: w.sim.add_trigger(Trigger("t", AtTime(1.0), ("play",))),
    "trigger actions not a tuple": lambda w: w.sim.add_trigger(
        Trigger("t", AtTime(1.0), Play(w.walker, "idle"))),
    "trigger two-value move": lambda w: w.sim.add_trigger(
        Trigger("t", AtTime(0.1), (MoveTarget(w.reach, (1.0, 2.0)),))),
    "trigger text body": lambda w: w.sim.add_trigger(
        Trigger("t", AtTime(0.1), (SetBody(w.walker, "tall"),))),
    "trigger unknown clip": lambda w: w.sim.add_trigger(
        Trigger("t", AtTime(0.1), (Play(w.walker, "run"),))),
    "trigger text delay": lambda w: w.sim.add_trigger(
        Trigger("t", AtTime(0.1), (Play(w.walker, "idle"),), delay_s="soon")),
    "track two-value points": lambda w: w.sim.add_target_track(w.reach, [0.0, 1.0],
                                                               [(1, 1), (2, 2)]),
    "track text times": lambda w: w.sim.add_target_track(w.reach, "0 1", [(1, 1, 1), (2, 2, 2)]),
    "track unknown uid": lambda w: w.sim.add_target_track(99, [0.0], [(1, 1, 1)]),
    # add_component / remove_component / add_system
    "add_component None": lambda w: w.sim.add_component(w.walker, None),
    "add_component number": lambda w: w.sim.add_component(w.walker, 3),
    "add_component class": lambda w: w.sim.add_component(w.walker, Placement),
    "add_component text ground": lambda w: w.sim.add_component(w.walker, GroundQuery("plane")),
    "add_component int-clip player": lambda w: w.sim.add_component(w.walker, MotionPlayer(3)),
    "remove_component text": lambda w: w.sim.remove_component(w.walker, "Placement"),
    "remove_component absent": lambda w: w.sim.remove_component(w.walker, GroundQuery),
    "add_system text": lambda w: w.sim.add_system("CountMarked"),
    "add_system text query": lambda w: w.sim.add_system(BadQuery),
    "add_system text anchor": lambda w: w.sim.add_system(System, after="PostureConvert"),
    "add_system twice": lambda w: w.sim.add_system(PostureConvert),
    # steering calls
    "steer NaN heading": lambda w: w.sim.steer(w.walker, heading_rad=np.nan),
    "steer text heading": lambda w: w.sim.steer(w.walker, heading_rad="north"),
    "steer text speed": lambda w: w.sim.steer(w.walker, 0.0, speed_m_s="fast"),
    "follow_path texts": lambda w: w.sim.follow_path(w.walker, [["1", "2"]]),
    "walk_to number": lambda w: w.sim.walk_to(w.walker, 5.0),
    "set_locomotion int walk": lambda w: w.sim.set_locomotion(w.walker, 3),
    "set_solver_focus text": lambda w: w.sim.set_solver_focus("eye"),
}


def _state(sim: Simulation) -> dict[str, Any]:
    st = sim.store
    arrays = {f.name: getattr(st, f.name).copy() for f in dataclasses.fields(st)
              if isinstance(getattr(st, f.name), np.ndarray)}
    table = sim.constraints
    arrays.update({f"constraints.{k}": getattr(table, k).copy() for k in table.__dataclass_fields__
                   if isinstance(getattr(table, k), np.ndarray)})
    return {"arrays": arrays, "constraint names": list(table.names), "next uid": table.next_uid,
            "grounds": len(sim.grounds), "names": sim.names(), "triggers": len(sim.reactions.triggers),
            "tracks": len(sim.reactions.tracks), "systems": [type(s) for s in sim.systems],
            "focus": sim.solver_settings.focus_in_world}


@pytest.mark.parametrize("call", list(GARBAGE.values()), ids=list(GARBAGE))
def test_a_refused_call_leaves_the_simulation_as_it_was(motions, call):
    refused, twin = _world(motions), _world(motions)
    with pytest.raises(EcsAnimError) as caught:
        call(refused)
    assert "\n" not in str(caught.value) and str(caught.value)
    for _ in range(TICKS):
        refused.sim.step()
        twin.sim.step()
    a, b = _state(refused.sim), _state(twin.sim)
    assert a.keys() == b.keys() and a["arrays"].keys() == b["arrays"].keys()
    for key in a["arrays"]:
        np.testing.assert_array_equal(a["arrays"][key], b["arrays"][key], err_msg=key, strict=True)
    assert refused.sim.store.positions.tobytes() == twin.sim.store.positions.tobytes()
    for key in a.keys() - {"arrays"}:
        assert a[key] == b[key], key


@pytest.mark.parametrize("call", [
    lambda w: w.sim.set_target(w.reach, np.zeros(4)),
    lambda w: w.sim.add_constraint(w.walker, "c", "wrist_r", target_in_world=np.ones(2)),
    lambda w: w.sim.set_targets(np.array([w.reach]), np.zeros((1, 2))),
    lambda w: w.sim.spawn("x", body, "walk"),
    lambda w: w.sim.set_ground(w.walker, "plane"),
], ids=["set_target", "add_constraint", "set_targets", "spawn", "set_ground"])
def test_api_type_errors_are_usage_errors(motions, call):
    with pytest.raises(UsageError):  # an EcsAnimError that is also a ValueError
        call(_world(motions))


def test_valid_calls_with_numpy_values_are_taken(motions):
    w = _world(motions)
    uid = w.sim.add_constraint(w.walker, "fist", "wrist_r", np.float64(2.0),
                               target_in_world=np.array([0.4, -0.2, 1.1]),
                               offset_m=np.zeros(3), activation=Activation(0.0, 5.0))
    w.sim.set_target(uid, np.array([0.5, -0.1, 1.2]))
    w.sim.set_targets(np.array([uid, w.reach]), [[0.5, -0.1, 1.2], [2.3, 0.8, 1.1]])
    w.sim.add_target_track(w.reach, np.array([0.5, 1.0]), np.array([[2.3, 0.8, 1.2], [2.2, 0.9, 1.3]]))
    w.sim.set_ground(w.walker, Plane(0.0))
    w.sim.set_ground(w.walker, None)
    w.sim.set_body(w.walker, body, blend_s=np.float64(0.5))
    w.sim.set_solver_focus(np.array([0.0, -3.0, 1.6]))
    w.sim.spawn("x", body, MotionPlayer("walk", speed=np.float64(1.2)),
                Placement(np.array([3.0, 3.0]), np.float32(0.5)), com_target_xy=np.array([3.0, 3.0]))
    for _ in range(5):
        w.sim.step()
    assert np.all(np.isfinite(w.sim.store.positions))


def test_a_non_finite_target_from_code_still_switches_its_constraint_off_then_on(motions):
    w = _world(motions)
    w.sim.set_target(w.reach, (np.nan, 0.0, 1.0))  # documented (docs/api.md): off, with a warning
    w.sim.step()
    assert not w.sim.constraints.enabled[0] and "not finite or beyond 1,000 km" in w.sim.messages[-1]
    w.sim.set_target(w.reach, (2.3, 0.8, 1.2))
    w.sim.step()
    assert w.sim.constraints.enabled[0]


CLOSED_USES: dict[str, Callable[[World], Any]] = {
    "step": lambda w: w.sim.step(),
    "names": lambda w: w.sim.names(),
    "entity": lambda w: w.sim.entity("walker"),
    "ground": lambda w: w.sim.ground,
    "spawn": lambda w: w.sim.spawn("x", body, MotionPlayer("walk")),
    "spawn_many": lambda w: w.sim.spawn_many(["x"], [body], [MotionPlayer("walk")]),
    "add_constraint": lambda w: w.sim.add_constraint(w.walker, "c", "wrist_r",
                                                     target_in_world=(1, 1, 1)),
    "set_target": lambda w: w.sim.set_target(w.reach, (1.0, 1.0, 1.0)),
    "set_targets": lambda w: w.sim.set_targets(np.array([w.reach]), np.ones((1, 3))),
    "set_ground": lambda w: w.sim.set_ground(w.walker, None),
    "set_body": lambda w: w.sim.set_body(w.walker, body),
    "add_trigger": lambda w: w.sim.add_trigger(Trigger("t", AtTime(1.0), (Play(w.walker, "idle"),))),
    "add_target_track": lambda w: w.sim.add_target_track(w.reach, [0.0], [(1, 1, 1)]),
    "add_component": lambda w: w.sim.add_component(w.walker, Placement()),
    "remove_component": lambda w: w.sim.remove_component(w.walker, Placement),
    "add_system": lambda w: w.sim.add_system(System),
    "remove": lambda w: w.sim.remove(w.walker),
    "steer": lambda w: w.sim.steer(w.walker, 0.0),
    "posture": lambda w: w.sim.posture(w.walker),
}


@pytest.mark.parametrize("use", list(CLOSED_USES.values()), ids=list(CLOSED_USES))
def test_a_closed_simulation_refuses_any_use_in_one_line(motions, use):
    w = _world(motions)
    w.sim.close()
    w.sim.close()  # closing again is harmless (a with block after an explicit close)
    with pytest.raises(UsageError, match=r"^this simulation is closed") as caught:
        use(w)
    assert "\n" not in str(caught.value)

