"""The compiled goals, targets and constraint errors (ecs_anim.runtime.kernels.goals) against the
numpy ones (ecs_anim.solver.goals' tick_goals, target_points, constraint_errors and
errors_on_result, the references): every field of every tick's goals, every target and every error equal to 1e-9, on
the bench scene, on every shipped scenario and on a scene with every kind of constraint (box,
sphere and half-space areas to stay in and to leave, a sphere sweeping past and letting go, a
distance to another character, orientations along a direction and looking at a point, a target
on the same body, a character added mid-run)."""

from __future__ import annotations

import copy
from dataclasses import fields, replace

import numpy as np
import pytest

import ecs_anim.systems.constraint_solve as system
from conftest import MOTIONS_DIR, SCENARIOS_DIR
from ecs_anim.components import MotionPlayer, Placement
from ecs_anim.core.body_points import TRUNK
from ecs_anim.core.morphology import Morphology
from ecs_anim.core.skeleton import JOINT_INDEX as J
from ecs_anim.io.importing import import_bvh
from ecs_anim.motion.constraint_table import Area
from ecs_anim.motion.constraints import Activation
from ecs_anim.runtime.bench_scene import walkers_on_bumps
from ecs_anim.runtime.kernels import goals as compiled
from ecs_anim.runtime.kernels.decode import decode
from ecs_anim.runtime.simulation import Simulation
from ecs_anim.solver import goals as solver_shell
from support.scenarios import run
from support.solve import bench_run

ALWAYS = Activation(0.0, 1e9)
ADULT = Morphology.preset("adult_male")


class Compare:
    """Wraps the system's goals and errors: each call is made with the numpy reference (which
    the tick then uses) and with the compiled one, on copies of the same arguments, and the
    results are compared field by field."""

    def __init__(self, monkeypatch: pytest.MonkeyPatch) -> None:
        self.goals = self.errors = self.targets = self.surfaces = 0

        def tick_goals(*args):
            reference = solver_shell.tick_goals(*copy.deepcopy(args))
            result = compiled.tick_goals(*copy.deepcopy(args))
            if reference is None:
                assert result is None
                return None
            assert result is not None
            assert_same_goals(result, reference)
            self.goals += 1
            return reference

        def compared(name: str, counter: str):
            """The system's ``name``: the numpy reference's result, the compiled one's equal to
            it within 1e-9 m; the call counted in ``counter``."""

            def call(*args):
                reference = getattr(solver_shell, name)(*args)
                np.testing.assert_allclose(getattr(compiled, name)(*args), reference, rtol=0,
                                           atol=1e-9)
                setattr(self, counter, getattr(self, counter) + 1)
                return reference

            return call

        def on_other_surfaces(*args):
            reference = solver_shell.on_other_surfaces(*args)
            np.testing.assert_allclose(compiled.on_other_surfaces(*args), reference, rtol=0,
                                       atol=1e-9)
            self.surfaces += solver_shell.other_surface_rows(args[0]).size > 0
            return reference

        monkeypatch.setattr(system, "tick_goals", tick_goals)
        monkeypatch.setattr(system, "on_other_surfaces", on_other_surfaces)
        monkeypatch.setattr(system, "target_points", compared("target_points", "targets"))
        monkeypatch.setattr(system, "constraint_errors", compared("constraint_errors", "errors"))
        monkeypatch.setattr(system, "errors_on_result", compared("errors_on_result", "errors"))


def assert_same_goals(result: solver_shell.TickGoals, reference: solver_shell.TickGoals) -> None:
    for f in fields(reference):
        expected, got = getattr(reference, f.name), getattr(result, f.name)
        if expected is None:
            assert got is None, f.name
            continue
        assert got.shape == expected.shape and got.dtype == expected.dtype, f.name
        if expected.dtype == np.float64:
            np.testing.assert_allclose(got, expected, rtol=0, atol=1e-9, err_msg=f.name)
        else:
            np.testing.assert_array_equal(got, expected, err_msg=f.name)


def test_compiled_goals_equal_numpy_on_the_bench_scene(monkeypatch):
    compare = Compare(monkeypatch)
    bench_run(monkeypatch, n=6, ticks=12)
    assert compare.goals == 12 and compare.errors == 12
    assert compare.targets == 12  # world targets: once a tick (none on a body to read again)


@pytest.mark.parametrize("name", sorted(p.stem for p in SCENARIOS_DIR.glob("*.yaml")))
def test_compiled_goals_equal_numpy_on_every_scenario(monkeypatch, name):
    compare = Compare(monkeypatch)
    run(name)
    assert compare.errors >= compare.goals
    if name == "fight_training":  # kicks and ward-offs at the other fighter's body
        assert compare.surfaces > 30


def test_compiled_goals_equal_numpy_for_every_kind_of_constraint(monkeypatch):
    compare = Compare(monkeypatch)
    idle = import_bvh(MOTIONS_DIR / "idle.bvh")
    sim = Simulation({"m": replace(idle, constraints=[])})
    a = sim.spawn("a", ADULT, MotionPlayer("m", speed=0.0), Placement((0.0, 0.0)))
    b = sim.spawn("b", Morphology.from_stature(1.4), MotionPlayer("m", speed=0.0),
                  Placement((0.0, 1.0)), com_control=False)
    sim.step()
    p = sim.store.positions[0]
    head = p[J["head"]]
    forward = np.array([1.0, 0.0, 0.0])
    fist = sim.add_constraint(a, "fist", "head", 1, ALWAYS, tuple(head + 0.5 * forward),
                              kind="area", area=Area("sphere", radius_m=0.2, inside=False),
                              chain=("head", "trunk"))
    sim.add_constraint(a, "table", "wrist_r", 2, ALWAYS, tuple(p[J["wrist_r"]] + [0, 0, 0.1]),
                       kind="area", area=Area("box", low_m=(-1, -1, 0), high_m=(1, 1, 1)))
    sim.add_constraint(a, "out_of_box", "wrist_l", 2, ALWAYS, tuple(p[J["wrist_l"]]),
                       kind="area", area=Area("box", low_m=(-0.1, -0.05, -0.2),
                                              high_m=(0.1, 0.3, 0.05), inside=False))
    sim.add_constraint(a, "in_ball", "ankle_l", 1, ALWAYS, tuple(p[J["ankle_l"]] + [0.3, 0, 0]),
                       kind="area", area=Area("sphere", radius_m=0.1))
    sim.add_constraint(a, "low", "head_top", 0, ALWAYS, (0.0, 0.0, p[J["head_top"], 2] - 0.02),
                       kind="area", area=Area("half_space", normal=(0.0, 0.0, -1.0)),
                       chain=("head", "trunk"))
    sim.add_constraint(a, "palm", "hand_r", 1, ALWAYS, (0.0, 0.0, -1.0), kind="orientation")
    sim.add_constraint(a, "clasp", "elbow_l", 0, ALWAYS, target_entity=a, target_point="knee_r",
                       offset_m=(0.0, 0.05, 0.0))
    sim.add_constraint(b, "look", "head", 1, ALWAYS, target_entity=a, target_point="head",
                       kind="orientation", axis=(1.0, 0.0, 0.0))
    sim.add_constraint(b, "apart", "wrist_l", 2, ALWAYS, target_entity=a, target_point="wrist_r",
                       kind="distance", distance_m=0.25, chain=("arm_l", "trunk"))
    held = []
    for along in np.linspace(0.5, -1.0, 16):  # the fist sweeps past the head, then lets it go
        sim.set_target(fist, tuple(head + along * forward))
        if along < 0.0 and sim.store.n == 2:
            late = sim.spawn("late", ADULT, MotionPlayer("m", speed=0.0), Placement((1.0, 0.0)))
            sim.add_constraint(late, "touch", "wrist_r", 1, ALWAYS, target_entity=a,
                               target_point="hand_l")
        sim.step()
        held.append(bool(sim.constraints.held.any()))
    for _ in range(6):
        sim.step()
    sim.close()
    assert compare.goals == 22 and compare.errors == 22 and compare.targets >= 22
    assert compare.surfaces == 16  # the late touch's target on another body, from its spawn
    assert any(held) and not sim.constraints.held.any()  # the sphere held the head, let it go


def test_compiled_surfaces_equal_numpy_where_poses_are_missing():
    """A character with no posture yet (NaN: the frame budget decodes only those it solves), a
    constrained point on a segment without a capsule of its own and no last tick: the compiled
    targets on other bodies are the numpy ones (NaN rows left where they were)."""
    rng = np.random.default_rng(7)
    sim = Simulation({"m": replace(import_bvh(MOTIONS_DIR / "idle.bvh"), constraints=[])})
    a = sim.spawn("a", ADULT, MotionPlayer("m", speed=0.0), Placement((0.0, 0.0)))
    b = sim.spawn("b", ADULT, MotionPlayer("m", speed=0.0), Placement((0.0, 0.6)))
    for name, target in (("wrist_r", "spine_middle"), ("ankle_l", "head"), ("neck", "knee_r"),
                         ("hand_l", "neck"), ("toe_r", "wrist_l")):
        sim.add_constraint(a, name, name, 1, ALWAYS, target_entity=b, target_point=target)
        sim.add_constraint(b, name, name, 1, ALWAYS, target_entity=a, target_point=target)
    sim.step()
    sim.step()
    table, st = sim.constraints, sim.store
    decoded = decode(st.poses, st.lengths)
    previous = copy.deepcopy(decoded)
    previous.positions[:] += rng.normal(0.0, 0.05, previous.positions.shape)
    targets = system.target_points(table, decoded, previous)
    for prev in (previous, None):
        for missing in (None, 0, 1):
            dec = copy.deepcopy(decoded)
            if missing is not None:
                dec.positions[missing] = np.nan
            got = compiled.on_other_surfaces(table, targets, st.lengths, dec, prev)
            want = solver_shell.on_other_surfaces(table, targets, st.lengths, dec, prev)
            np.testing.assert_allclose(got, want, rtol=0, atol=1e-9)
            assert got is not targets
    sim.close()


def assert_identical_goals(result: solver_shell.TickGoals | None,
                           expected: solver_shell.TickGoals | None) -> None:
    """Every field of two ticks' goals the same to the bit (shape, type and values)."""
    assert (result is None) == (expected is None)
    if result is None or expected is None:
        return
    for f in fields(expected):
        want, got = getattr(expected, f.name), getattr(result, f.name)
        if want is None:
            assert got is None, f.name
            continue
        assert got.dtype == want.dtype, f.name
        np.testing.assert_array_equal(got, want, err_msg=f.name)


def test_kept_goal_layout_gives_the_goals_made_afresh(monkeypatch):
    """ConstraintSolve's goals with their layout kept from tick to tick (GoalLayouts) are those
    made afresh every tick, to the bit, while the table changes under them: a priority and a
    chain changed in place, a target moved from a body into the world (in place), a constraint
    switched off at once and on again, one added mid-run, a character removed, a zero offset
    made -0.0."""
    kept = compiled.GoalLayouts()
    calls = {"ticks": 0}
    made: list[int] = []  # the ticks whose layout was made afresh

    def tick_goals(*args):
        expected = compiled.tick_goals(*copy.deepcopy(args))
        same_layout = kept._same(args[0], args[1] > 0)
        result = kept(*args)
        assert_identical_goals(result, expected)
        calls["ticks"] += 1
        if not same_layout:
            made.append(calls["ticks"] - 1)
        return result

    monkeypatch.setattr(system, "tick_goals", tick_goals)
    sim, _ = walkers_on_bumps(6, crossing=False)
    entities = sim.store.entity.tolist()
    wrists = [sim.add_constraint(e, f"w{i}", "wrist_r", 10, ALWAYS, target_entity=e,
                                 target_point="shoulder_r", target_offset_m=(0.3, -0.1, -0.2))
              for i, e in enumerate(entities)]
    for i, e in enumerate(entities[::2]):
        sim.add_constraint(e, f"e{i}", "elbow_r", 1, ALWAYS, (0.0, 0.0, 1.0))
    table = sim.constraints
    for tick in range(16):
        if tick == 3:
            table.priority[table.rows_of(np.array(wrists[:1]))] = 0.5
        if tick == 5:
            table.chain[table.rows_of(np.array(wrists[1:2]))] |= 1 << TRUNK
        if tick == 7:
            sim.set_target(wrists[2], (0.5, 0.0, 1.2))
        if tick == 8:
            table.offset[table.rows_of(np.array(wrists[2:3])), 0] *= -1.0  # 0.0 to -0.0
        if tick == 9:
            table.enabled[table.rows_of(np.array(wrists[3:4]))] = False
        if tick == 11:
            table.enabled[:] = True
            sim.add_constraint(entities[4], "late", "wrist_l", 2, ALWAYS, (0.3, 0.3, 1.0))
        if tick == 13:
            sim.remove(entities[0])
        sim.step()
    sim.close()
    # made afresh on the first tick and after each change but the priority's (not kept)
    assert calls["ticks"] == 16 and made == [0, 5, 7, 8, 9, 11, 13]


def test_compiled_weights_equal_the_tables_bit_for_bit():
    """``goals.weights`` (ConstraintSolve's activation weights) against
    ``ConstraintTable.weights``: the same bits (a -0.0 kept, NaN where numpy gives NaN) on ramps
    easing in and out, steps (no ease, a negative one), infinite and NaN ends, constraints on a
    clip's time (the owner playing that clip or another, or no clip given) and switched off."""
    from ecs_anim.motion.constraint_table import ConstraintTable

    rng = np.random.default_rng(2036)
    m, n = 600, 7
    table = ConstraintTable()
    table.owner = rng.integers(0, n, m)
    table.enabled = rng.random(m) < 0.9
    table.clock = np.where(rng.random(m) < 0.4, rng.integers(0, 3, m), -1)
    special = np.array([0.0, -0.0, 1e-13, -1.0, np.inf, -np.inf, np.nan, 2.0, 1e-12])
    activation = rng.uniform(-1.0, 4.0, (m, 4))
    pick = rng.random((m, 4)) < 0.3
    activation[pick] = rng.choice(special, pick.sum())
    table.activation = activation
    clip = rng.integers(0, 3, n)
    clip_time = rng.choice(np.array([0.0, -0.0, 0.5, 1.7, np.nan, 3.0]), n)
    for time_s in (0.0, -0.0, 0.3, 1.0, 2.5, 10.0):
        for clip_args in ((clip, clip_time), (None, None), (clip, None)):
            with np.errstate(invalid="ignore"):  # (inf - inf: NaN, as asked)
                want = table.weights(time_s, *clip_args)
            got = compiled.weights(table, time_s, *clip_args)
            np.testing.assert_array_equal(got.view(np.int64), want.view(np.int64))
