"""The compiled solver (ecs_anim.runtime.kernels.solve and its step modules) against the numpy solver
(ecs_anim.solver.shell.solve, the reference): the whole solve on the bench scene and on every
shipped scenario, each step on real solve states, and each step's own behaviour on one to three
characters."""

from __future__ import annotations

import copy
import math
import os
import subprocess
import sys
from dataclasses import replace

import numpy as np
import pytest

import ecs_anim.systems.constraint_solve as system
from conftest import SCENARIOS_DIR
from ecs_anim.components import MotionPlayer, Placement
from ecs_anim.core.ground_adapt import MAX_LEG_EXTENSION
from ecs_anim.core.morphology import Morphology, centres_of_mass
from ecs_anim.core.rotations import matrix_from_quat
from ecs_anim.core.skeleton import JOINT_INDEX as J
from ecs_anim.core.skeleton import LENGTH_INDEX as L
from ecs_anim.motion.constraints import Activation
from ecs_anim.runtime.bench_scene import BenchScene
from ecs_anim.runtime.kernels import solve as compiled
from ecs_anim.runtime.kernels import solve_math as compiled_math
from ecs_anim.runtime.kernels.decode import DecodedArrays, PoseArrays
from ecs_anim.runtime.kernels.lanes import BLOCK, Column
from ecs_anim.runtime.kernels.solve_head import solve_head
from ecs_anim.runtime.kernels.solve_limbs import arm_lanes, arm_scratch, scatter_arm, solve_limbs
from ecs_anim.runtime.kernels.solve_points import Goals, centre_of_mass, goal_error
from ecs_anim.runtime.kernels.solve_root import com_shortfall, root_scratch, solve_root
from ecs_anim.runtime.kernels.solve_trunk import solve_trunk
from ecs_anim.runtime.kernels.vec import on_numba_import, with_numba
from ecs_anim.runtime.simulation import Simulation
from ecs_anim.solver import shell as solver_shell
from support.scenarios import run
from support.solve import Capture, assert_same_solve, bench_run

ALWAYS = Activation(0.0, 1e9)
ADULT = Morphology.preset("adult_male")
S = solver_shell.DEFAULT_SETTINGS
T = compiled.TABLES


def test_compiled_solve_equals_numpy_on_the_bench_scene(monkeypatch):
    calls = bench_run(monkeypatch)
    assert len(calls) == 12
    for args in calls:
        assert_same_solve(args)


@pytest.mark.parametrize("name", sorted(p.stem for p in SCENARIOS_DIR.glob("*.yaml")))
def test_compiled_solve_equals_numpy_on_every_scenario(monkeypatch, name):
    capture = Capture(monkeypatch)
    run(name)
    for args in capture.calls[::3]:
        assert_same_solve(args)


def test_the_scenarios_end_the_same_with_either_solver(monkeypatch):
    """The whole tick, the goals, the solver and the errors swapped for the numpy ones: every
    constraint's error and every joint within 1e-9 m on the scenario with the most
    constraints."""
    numpy = solver_shell.NUMPY_STEPS
    monkeypatch.setattr(system, "tick_goals", numpy.goals)
    monkeypatch.setattr(system, "solve", numpy.solve)
    monkeypatch.setattr(system, "constraint_errors", numpy.errors)
    monkeypatch.setattr(system, "target_points", numpy.targets)
    monkeypatch.setattr(system, "on_other_surfaces", numpy.surfaces)
    reference = run("fight_training")
    monkeypatch.undo()
    result = run("fight_training")
    np.testing.assert_allclose(result["positions"], reference["positions"], rtol=0, atol=1e-9)
    np.testing.assert_allclose(result["errors"], reference["errors"], rtol=0, atol=1e-9)



def test_compiled_solve_equals_numpy_where_the_trunk_undoes_a_turn(monkeypatch, idle):
    """An unreachable elbow goal and a lower wrist goal at the same point, both with the trunk,
    on a body without foot contacts nor centre-of-mass control: the trunk's turns for the wrist
    are undone (they would take
    the elbow further)."""
    capture = Capture(monkeypatch)
    sim = Simulation({"m": replace(idle, constraints=[])})
    e = sim.spawn("c", Morphology.from_stature(1.0), MotionPlayer("m", speed=0.0), Placement((0.0, 0.0)),
                  com_control=False)
    sim.step()
    target = tuple(sim.store.positions[0, J["pelvis"]] + [0.0, 1.0, 0.0])
    sim.add_constraint(e, "elbow", "elbow_l", 100, ALWAYS, target, chain=("arm_l", "trunk"))
    sim.add_constraint(e, "wrist", "wrist_l", 0, ALWAYS, target, chain=("arm_l", "trunk"))
    sim.step()
    sim.step()
    sim.close()
    assert len(capture.calls) == 2
    for args in capture.calls:
        assert_same_solve(args)

def test_a_solve_stops_at_the_first_pass_that_leaves_nothing_to_do(idle):
    """Goals the limbs meet, no centre-of-mass control: the first pass is the result (no
    iteration); with the centre of mass held, iterations only until the root stays, the
    wrist met after each."""
    def wrist_and_elbow(sim, entities, p):
        for e in entities:
            sim.add_constraint(e, "wrist", "wrist_r", 5, ALWAYS,
                               tuple(p[0, J["shoulder_r"]] + [0.3, -0.25, 0.1]))
            sim.add_constraint(e, "elbow", "elbow_r", 1, ALWAYS,
                               tuple(p[0, J["elbow_r"]] + [0.0, -0.3, 0.0]))

    for com_control, most in ((False, 0), (True, 3)):
        _, args = one_state(idle, wrist_and_elbow, com_control=com_control)
        for solve in (solver_shell.solve, compiled.solve):
            _, used, dec = solve(*copy.deepcopy(args))
            assert 0 < used[0] <= most if com_control else used[0] == 0
            goals = args[2]
            assert solver_shell._errors(goals, dec)[goals.table_index == 0][0] < 1e-9
            com = centres_of_mass(dec.positions, args[3], args[4])[0]
            assert not com_control or (np.hypot(*(com[:2] - goals.com_desired[0, :2]))
                                       <= 0.1 * S.com_tolerance_m)


def test_the_bench_characters_stop_once_the_root_stays(monkeypatch):
    """The bench's walkers (feet planted, centre of mass held, a wrist and an unreachable
    elbow goal on the arm): no limb goal keeps the loop going, only the centre of mass, which
    the root brings within a tenth of its tolerance in two or three iterations (the loop took
    three or four when the limbs' goals, moved by each root step, kept it going)."""
    used = np.concatenate([solver_shell.solve(*copy.deepcopy(args))[1]
                           for args in bench_run(monkeypatch, n=6, ticks=6)])
    assert used.max() <= 3
    assert used.mean() < 2.5


def test_the_root_step_lands_for_walkers_with_targets_on_their_body(monkeypatch):
    """The bench's walkers now (feet planted, centre of mass held, wrist and elbow targets on
    their own shoulder): the root's predicted step lands the centre of mass within the tenth
    of its tolerance once the legs re-plant, so one iteration is all but every solve takes
    (two or three each before the prediction)."""
    capture = Capture(monkeypatch)
    scene = BenchScene(6, constrained=True)
    for _ in range(6):
        scene.tick()
    scene.sim.close()
    used = np.concatenate([solver_shell.solve(*copy.deepcopy(args))[1] for args in capture.calls])
    assert used.size == 36 and used.max() <= 2
    assert np.mean(used == 1) > 0.9


def solved_in_chunks(args, chunks, leftover=0.0):
    """:func:`compiled.solve`'s state after ``solve_rows`` over the rows ``chunks`` ((lo, hi)
    each, one after the other) of the solve ``args``, and the iterations each row took; its
    scratch arrays hold ``leftover`` on entry (as reused memory would)."""
    poses, lengths, goals, masses, com_fraction, settings, decoded = copy.deepcopy(args)[:7]
    state = compiled.prepare(poses, lengths, goals, masses, com_fraction, decoded, settings)
    r, k = lengths.shape[0], state.goals.start[-1]
    used, kinds, arms, scratch = (np.zeros(r, np.int64), np.full(r, 7, np.int64),
                                  arm_scratch(r), root_scratch(r))
    arms[:], scratch[:] = leftover, leftover
    for lo, hi in chunks:
        compiled.solve_rows(lo, hi, state.pose, state.dec, state.goals, state.winners,
                            state.bodies, T, used, np.full(k, leftover), np.ones(k, np.bool_),
                            np.full(k, leftover), np.ones(k, np.bool_), kinds, arms, scratch,
                            float(settings.tolerance_m),
                            float(settings.tolerance_rad), float(settings.com_tolerance_m),
                            float(settings.max_ccd_step_rad), float(settings.root_gain),
                            float(settings.stall_fraction), float(MAX_LEG_EXTENSION))
    return state, used


def mixed_block(args):
    """The bench walkers' solve ``args`` (own-body goals: each root step predicted) with
    characters by ``c % 6`` made to take other ways through a block: 0 as they are (the first
    root step waits for the block's), 1 a world target (its goals no longer follow the body:
    not predicted), 2 a goal with the trunk in its chain (iterating), 3 no iteration allowed,
    4 one, 5 the centre of mass already where it is wanted after the first pass (the root
    stays). Returns the args and each character's variant (r,)."""
    args = copy.deepcopy(args)
    goals, masses, com_fraction, settings = args[2], args[3], args[4], args[5]
    r = goals.rows.size
    variant = np.arange(r) % 6
    stays = np.isin(goals.owner[goals.on_self], np.flatnonzero(variant == 1))
    for name in ("on_self", "self_segment", "self_fraction", "self_offset", "self_start"):
        setattr(goals, name, getattr(goals, name)[~stays])
    trunk = np.flatnonzero((variant[goals.owner] == 2) & (goals.table_index >= 0))
    goals.chain[trunk] |= 1 << compiled._TRUNK
    goals.row_iterations = np.full(r, int(settings.iterations), np.int64)
    goals.row_iterations[variant == 3] = 0
    goals.row_iterations[variant == 4] = 1
    first_pass = copy.deepcopy(args)
    first_pass[2].row_iterations[:] = 0
    com = centres_of_mass(solver_shell.solve(*first_pass)[2].positions, masses, com_fraction)
    goals.com_desired[variant == 5, :2] = com[variant == 5, :2]
    return args, variant


def mixed_arms(args):
    """The bench walkers' solve ``args`` with their right arm's goals (a wrist goal, an elbow
    goal below it) changed by ``c % 4``: 0 as they are (the first pass's arm waits for its
    block's), 1 the second goal a point halfway down the forearm (waits, a second point on the
    lower bone), 2 the elbow goal above the wrist's (solved alone: its first goal is not the
    wrist), 3 the wrist goal out of the arm's reach (solved alone: ``reach_end`` does not
    apply). In place; returns each character's variant (r,)."""
    goals, decoded = args[2], args[6]
    variant = np.arange(goals.rows.size) % 4
    user = goals.table_index >= 0
    elbow, wrist = user & (goals.bone == 0), user & (goals.bone == 1)
    lower = elbow & (variant[goals.owner] == 1)
    goals.segment[lower], goals.bone[lower], goals.fraction[lower] = L["forearm_r"], 1, 0.5
    goals.priority[elbow & (variant[goals.owner] == 2)] = 20.0
    far = np.flatnonzero(wrist & (variant[goals.owner] == 3))
    shoulder = decoded.positions[goals.owner[far], J["shoulder_r"]]
    goals.goal[far] = shoulder + 3.0 * (goals.goal[far] - shoulder)
    return variant


def test_a_solve_does_not_depend_on_its_blocks_nor_chunks(monkeypatch):
    """``solve_rows`` computes the first pass's arms and first root steps of a block's waiting
    characters together (in the lanes of the vector units, the rest in the loop's scalar
    remainder), the others' alone: over 40 bench walkers (a block of 32 and one of 8) of which
    some wait and the others do not (:func:`mixed_block`, :func:`mixed_arms`), each character
    gets the same bits in one call, in two chunks (0:37, 37:40: the first's second block of 5
    rows) and row by row (each step alone); the numpy reference agrees to 1e-9 m."""
    capture = Capture(monkeypatch)
    scene = BenchScene(40, constrained=True)
    for _ in range(3):
        scene.tick()
    scene.sim.close()
    arm_variant = mixed_arms(capture.calls[-1])
    args, variant = mixed_block(capture.calls[-1])
    assert_same_solve(args)
    # The arms of variants 0 and 1 wait for their block's in the first pass, the others not.
    poses, lengths, goals, masses, com_fraction = copy.deepcopy(args[:5])
    s = compiled.prepare(poses, lengths, goals, masses, com_fraction, copy.deepcopy(args[6]))
    waits = [solve_limbs(c, s.pose, s.dec, s.goals, s.winners, s.bodies, T, S.tolerance_m,
                         MAX_LEG_EXTENSION, arm_scratch(1)[0], Column(0), True)
             for c in range(40)]
    np.testing.assert_array_equal(waits, arm_variant < 2)
    whole, used = solved_in_chunks(args, [(0, 40)])
    goals = args[2]
    user = goals.table_index >= 0
    free = np.bincount(goals.owner[user & ((goals.chain & (1 << compiled._TRUNK)) == 0)
                                   & np.isin(np.arange(goals.k), goals.on_self)],
                       minlength=40)
    predicted = free == np.bincount(goals.owner[user], minlength=40)
    np.testing.assert_array_equal(predicted, np.isin(variant, (0, 3, 4, 5)))
    # Those that wait took their first root step (the block's); the others none, or their own.
    assert np.all(used[variant == 0] >= 1)
    assert np.all(used[variant == 4] == 1)
    assert np.all(used[(variant == 3) | (variant == 5)] == 0)
    assert np.all(used[(variant == 1) | (variant == 2)] >= 1)
    # (also with the scratch holding NaN or a subnormal, as memory reused from an earlier tick
    # may: nothing of it is read before it is written; the block's zeroing is for speed only)
    for chunks, leftover in (([(0, 37), (37, 40)], 0.0), ([(c, c + 1) for c in range(40)], 0.0),
                             ([(0, 40)], np.nan), ([(0, 37), (37, 40)], 5e-324)):
        state, used_here = solved_in_chunks(args, chunks, leftover)
        np.testing.assert_array_equal(used_here, used)
        for name in DecodedArrays._fields:
            np.testing.assert_array_equal(getattr(state.dec, name), getattr(whole.dec, name),
                                          err_msg=name)
        for name in PoseArrays._fields:
            np.testing.assert_array_equal(getattr(state.pose, name), getattr(whole.pose, name),
                                          err_msg=name)
        np.testing.assert_array_equal(state.goals.goal, whole.goals.goal)


def test_a_blocks_arms_on_the_lanes_give_each_arm_alone_its_bits(monkeypatch):
    """The first pass's arms that wait for their block (:func:`mixed_arms`' variants 0 and 1)
    solved together by ``arm_lanes`` and put back by ``scatter_arm`` give every pose and
    decoded array the bits of each arm solved alone (``solve_limbs`` not waiting), whatever the
    block's scratch held before (NaN)."""
    capture = Capture(monkeypatch)
    scene = BenchScene(40, constrained=True)
    for _ in range(3):
        scene.tick()
    scene.sim.close()
    args = capture.calls[-1]
    mixed_arms(args)
    alone, lanes = (compiled.prepare(poses, lengths, goals, masses, com_fraction,
                                     copy.deepcopy(args[6]))
                    for poses, lengths, goals, masses, com_fraction in
                    (copy.deepcopy(args[:5]) for _ in range(2)))
    for c in range(40):
        assert not solve_limbs(c, alone.pose, alone.dec, alone.goals, alone.winners,
                               alone.bodies, T, S.tolerance_m, MAX_LEG_EXTENSION,
                               arm_scratch(1)[0], Column(0), False)
    block = arm_scratch(40)[0]
    block[:] = np.nan
    waited = [c for c in range(BLOCK)
              if solve_limbs(c, lanes.pose, lanes.dec, lanes.goals, lanes.winners, lanes.bodies,
                             T, S.tolerance_m, MAX_LEG_EXTENSION, block, Column(c), True)]
    assert len(waited) == 16  # variants 0 and 1 of the first block's 32
    arm_lanes(block, Column(0), Column(BLOCK))
    for c in waited:
        scatter_arm(c, lanes.pose, lanes.dec, T, block, Column(c))
    for c in range(BLOCK, 40):
        solve_limbs(c, lanes.pose, lanes.dec, lanes.goals, lanes.winners, lanes.bodies, T,
                    S.tolerance_m, MAX_LEG_EXTENSION, block, Column(0), False)
    for part, fields in (("dec", DecodedArrays._fields), ("pose", PoseArrays._fields)):
        for name in fields:
            a, b = (getattr(getattr(state, part), name) for state in (alone, lanes))
            np.testing.assert_array_equal(a.view(np.int64), b.view(np.int64), err_msg=name)


# --- each step against its numpy counterpart, on real solve states -------------------------

@pytest.fixture(scope="module")
def states():
    """Solve arguments of a few ticks of the bench scene and of the reach and fight scenarios."""
    patch = pytest.MonkeyPatch()
    try:
        calls = bench_run(patch, n=3, ticks=4)
        capture = Capture(patch)
        run("reach_and_touch")
        run("fight_training")
        calls += capture.calls[::7]
    finally:
        patch.undo()
    return calls


def both_states(args):
    poses, lengths, goals, masses, com_fraction, settings, decoded = copy.deepcopy(args)[:7]
    reference = solver_shell._Solve(poses, lengths, goals, masses, com_fraction, settings, decoded)
    state = compiled.prepare(*copy.deepcopy((poses, lengths, goals, masses, com_fraction)),
                             decoded=copy.deepcopy(decoded))
    return reference, state


def assert_same_state(reference, state):
    np.testing.assert_allclose(state.dec.positions, reference.dec.positions, rtol=0, atol=1e-9)
    for name in ("leg_fraction", "arm_fraction", "root_position", "spine_points", "neck_dir"):
        np.testing.assert_allclose(getattr(state.pose, name), getattr(reference.poses, name),
                                   rtol=0, atol=1e-9)
    for name in ("thorax", "head"):
        np.testing.assert_allclose(matrix_from_quat(getattr(state.pose, name)),
                                   matrix_from_quat(getattr(reference.poses, name)), rtol=0, atol=1e-9)
    # A limb's frame where it is bent (a straight limb's twist is decided by rounding).
    for name, fraction in (("leg_frame", "leg_fraction"), ("arm_frame", "arm_fraction")):
        bent = (getattr(reference.poses, fraction) < 0.999)[..., None, None]
        np.testing.assert_allclose(np.where(bent, matrix_from_quat(getattr(state.pose, name)), 0.0),
                                   np.where(bent, matrix_from_quat(getattr(reference.poses, name)), 0.0),
                                   rtol=0, atol=1e-9)


def limbs(s):
    for c in range(s.bodies.lengths.shape[0]):
        solve_limbs(c, s.pose, s.dec, s.goals, s.winners, s.bodies, T, S.tolerance_m,
                    MAX_LEG_EXTENSION, arm_scratch(1)[0], Column(0), False)


def test_the_limb_steps_angle_wrap_is_numpys_modulo_to_the_bit():
    """``wrap_angle`` (the flexion candidates' wrap into [-pi, pi), its modulo replaced by one
    exact step where one is enough) gives numpy's ``(a + pi) % (2 pi) - pi`` bit for bit, at
    the edges of each of its ranges and on either side of them too."""
    rng = np.random.default_rng(7)
    edges = np.array([-5.0, -3.0, -1.0, 0.0, 1.0, 3.0, 5.0]) * np.pi
    near = np.concatenate([edges, np.nextafter(edges, np.inf), np.nextafter(edges, -np.inf)])
    angles = np.concatenate([near, -near, rng.uniform(-30.0, 30.0, 20_000),
                             rng.uniform(-4.0, 4.0, 20_000), [0.0, -0.0, 1e-300, -1e-300]])
    expected = (angles + np.pi) % (2 * np.pi) - np.pi
    got = np.array([compiled_math.wrap_angle(float(a)) for a in angles])
    mismatched = np.flatnonzero(got.view(np.int64) != expected.view(np.int64))
    assert mismatched.size == 0, angles[mismatched[:5]]


def test_a_limbs_end_reached_without_trigonometry_is_numpys_reach_point():
    """``reach_end`` (a limb's end onto its goal: the span taken as the distance, the turn by
    Rodrigues' formula) gives the numpy ``reach_point``'s frame, fraction and end to 1e-12, for
    goals within reach, beyond it (the straightest flexion allowed) and near the folded limb,
    where ``solve_limbs`` takes it (not nearer than a thousandth of the limb beyond the folded
    span, not at the straight arm, nor behind the limb's axis)."""
    from ecs_anim.core.rotations import normalize
    from ecs_anim.solver import steps

    rng = np.random.default_rng(11)
    taken = 0
    for _ in range(3000):
        upper, lower = rng.uniform(0.2, 0.5, 2)
        extension = float(rng.choice([MAX_LEG_EXTENSION, 1.0]))
        q = rng.normal(size=4)
        frame = matrix_from_quat(q / np.linalg.norm(q))
        root = rng.uniform(-2.0, 2.0, 3)
        direction = normalize(frame[:, 2] + rng.normal(scale=0.7, size=3))
        distance = rng.uniform(0.0, 1.1) * (upper + lower)
        to_goal = direction * distance
        distance = float(np.linalg.norm(to_goal))
        if not compiled_math.reach_end_applies(float(upper), float(lower), distance,
                                               float(frame[:, 2] @ to_goal), extension):
            continue
        taken += 1
        fraction = rng.uniform(0.3, 0.99)
        want_frame, want_fraction, want_point = steps.reach_point(
            root[None], frame[None], np.array([upper]), np.array([lower]), np.array([fraction]),
            np.array([True]), np.array([[0.0, 0.0, lower]]), (root + to_goal)[None], extension)
        x_axis, y_axis, z_axis = (tuple(float(v) for v in frame[:, i]) for i in range(3))
        axes = ((x_axis[0], x_axis[1], x_axis[2]), (y_axis[0], y_axis[1], y_axis[2]),
                (z_axis[0], z_axis[1], z_axis[2]))
        got_frame, got_fraction, got_point = compiled_math.reach_end(
            tuple(root), axes, float(upper), float(lower), tuple(to_goal), distance, extension)
        np.testing.assert_allclose(np.array(got_frame).T, want_frame[0], rtol=0, atol=1e-12)
        assert got_fraction == pytest.approx(want_fraction[0], abs=1e-12)
        np.testing.assert_allclose(got_point, want_point[0], rtol=0, atol=1e-12)
    assert taken > 1000


def test_a_limb_reach_point_folds_or_of_no_length_is_not_reached_without_trigonometry():
    """Where ``reach_point`` folds the limb at its least flexion (a lower bone a five-hundredth of
    the upper one, the goal beyond reach: the straightest span allowed is within a thousandth of
    the folded one), or a bone has no length, or a figure is NaN, ``solve_limbs`` keeps
    ``reach_point`` (``reach_end`` would stretch the first and divide by zero in the second)."""
    applies = compiled_math.reach_end_applies
    assert applies(0.5, 0.4, 0.6, 0.3, MAX_LEG_EXTENSION)  # (the usual limb)
    assert not applies(0.5, 0.001, 0.608, 0.6, MAX_LEG_EXTENSION)  # (the span, not the distance)
    assert not applies(0.0, 0.0, 0.0, 0.0, 1.0)
    assert not applies(0.5, 0.0, 0.4, 0.4, 1.0)
    assert not applies(0.5, 0.4, float("nan"), 0.3, 1.0)
    assert not applies(0.5, 0.4, 0.6, -0.31, 1.0)  # (behind the limb's axis)
    assert not applies(0.5, 0.4, 0.9, 0.9, 1.0)  # (the straight limb)


def test_the_second_goals_swivel_is_numpys_turn_about_axis():
    """The swivel about the axis that keeps a limb's first goal (its angle's sine and cosine
    from the projections, no arc tangent) is numpy's ``turn_about_axis`` to 1e-12, the
    identity where the point or the goal lies on the axis."""
    from ecs_anim.solver import steps

    rng = np.random.default_rng(5)
    for i in range(2000):
        root, through, point, goal = rng.uniform(-1.0, 1.0, (4, 3))
        if i % 10 == 0:  # the point on the axis
            point = root + 0.3 * (through - root)
        want = steps.turn_about_axis(root[None], through[None], point[None], goal[None])[0]
        got = np.array(compiled_math.turn_about_axis(tuple(root), tuple(through), tuple(point),
                                                     tuple(goal))).T
        np.testing.assert_allclose(got, want, rtol=0, atol=1e-12)


def test_limb_step_equals_numpy(states):
    for args in states:
        reference, s = both_states(args)
        reference.limbs()
        limbs(s)
        assert_same_state(reference, s)


def test_head_step_equals_numpy(states):
    for args in states:
        reference, s = both_states(args)
        reference.head()
        for c in range(s.bodies.lengths.shape[0]):
            solve_head(c, s.pose, s.dec, s.goals, s.winners, s.bodies, T)
        assert_same_state(reference, s)


def goal_errors(s, c):
    g = s.goals
    err = np.zeros(g.priority.size)
    for j in range(g.start[c], g.start[c + 1]):
        err[j] = goal_error(s.dec, c, g, j, T)
    return err


def test_trunk_step_equals_numpy(states):
    turned = 0
    for args in states:
        reference, s = both_states(args)
        reference.trunk()
        stalled = np.zeros(s.goals.priority.size, bool)
        for c in range(s.bodies.lengths.shape[0]):
            turned += solve_trunk(c, s.pose, s.dec, s.bodies.lengths[c], s.goals, s.winners,
                                  goal_errors(s, c),
                                  stalled, T, S.tolerance_m, S.tolerance_rad, S.max_ccd_step_rad)
        assert_same_state(reference, s)
    assert turned > 0


def root(s, c, predicted=True):
    b = s.bodies
    ex, ey = com_shortfall(c, s.dec.positions, b.masses, b.com_fraction, b.com_desired, b.com_on,
                           T.mass_proximal, T.mass_distal)
    return solve_root(c, s.pose, s.dec, s.goals, s.winners, b, T, ex, ey, S.com_tolerance_m,
                      S.tolerance_m, S.root_gain, MAX_LEG_EXTENSION, predicted, root_scratch(1)[0],
                      Column(0), False)


@pytest.mark.parametrize(("after_a_pass", "predicted"), [(False, True), (True, True), (True, False)])
def test_root_step_equals_numpy(states, after_a_pass, predicted):
    """The root's predicted step (and its fallback) the same as numpy's, from the decoded
    motion (the feet on their footprints, the arms off their goals) and after a pass (every
    limb on its goal where it can reach it); and the gain's step where none is predicted."""
    for args in states:
        reference, s = both_states(args)
        if after_a_pass:
            reference.limbs()
            limbs(s)
        reference.predicted[:] = predicted
        before = reference.root()
        for c in range(s.bodies.lengths.shape[0]):
            assert root(s, c, predicted) == pytest.approx(before[c], abs=1e-12)
        assert_same_state(reference, s)


# --- each step's behaviour on one to three characters ---------------------------------------

def one_state(idle, add, n=1, com_control=False):
    """The solve state of the first constrained tick of ``n`` still idle characters, after
    ``add(sim, entities, positions)`` added their constraints."""
    patch = pytest.MonkeyPatch()
    try:
        capture = Capture(patch)
        sim = Simulation({"m": idle})
        entities = [sim.spawn(f"c{i}", ADULT, MotionPlayer("m", speed=0.0), Placement((0.0, 2.0 * i)),
                              com_control=com_control) for i in range(n)]
        sim.step()
        add(sim, entities, sim.store.positions.copy())
        sim.step()
        sim.close()
    finally:
        patch.undo()
    args = capture.calls[0]
    poses, lengths, goals, masses, com_fraction = args[:5]
    return compiled.prepare(poses, lengths, goals, masses, com_fraction, decoded=args[6]), args


def user_goal(s, table_index):
    """Index in the sorted goals of the constraint added ``table_index``-th."""
    return int(np.flatnonzero(s.goals.table_index == table_index)[0])


def test_a_limb_reaches_a_reachable_goal_exactly_and_a_second_goal_swivels_it(idle):
    def wrist(sim, entities, p):
        for i, e in enumerate(entities):
            sim.add_constraint(e, "wrist", "wrist_r", 5, ALWAYS,
                               tuple(p[i, J["shoulder_r"]] + [0.3, -0.25 - 0.05 * i, 0.1]))

    s, _ = one_state(idle, wrist, n=3)
    limbs(s)
    for c in range(3):
        assert goal_error(s.dec, c, s.goals, user_goal(s, c), T) < 1e-9

    def wrist_and_elbow(sim, entities, p):
        wrist(sim, entities, p)
        for i, e in enumerate(entities):
            sim.add_constraint(e, "elbow", "elbow_r", 1, ALWAYS, tuple(p[i, J["elbow_r"]] + [0.0, -0.3, 0.0]))

    s2, _ = one_state(idle, wrist_and_elbow, n=3)
    limbs(s2)
    closer = 0
    for c in range(3):
        # The wrist stays on its goal; the elbow swung toward its own, no further from it than
        # where the wrist goal alone left it.
        assert goal_error(s2.dec, c, s2.goals, user_goal(s2, c), T) < 1e-9
        elbow_goal = s2.goals.goal[user_goal(s2, 3 + c)]
        swivelled = np.linalg.norm(s2.dec.positions[c, J["elbow_r"]] - elbow_goal)
        alone = np.linalg.norm(s.dec.positions[c, J["elbow_r"]] - elbow_goal)
        assert swivelled <= alone + 1e-12
        closer += swivelled < alone - 1e-3
    assert closer >= 1


def test_a_limb_with_both_its_goals_met_is_left_alone(idle):
    """An arm meeting its wrist goal and its elbow goal is not solved again (its frame,
    fraction, hand and joints stay to the bit): the bench's arms, carried by the root with both
    their goals on the body, were re-solved on every pass."""
    def wrist_and_elbow(sim, entities, p):
        for i, e in enumerate(entities):
            sim.add_constraint(e, "wrist", "wrist_r", 5, ALWAYS,
                               tuple(p[i, J["shoulder_r"]] + [0.3, -0.25 - 0.05 * i, 0.1]))
        for i, e in enumerate(entities):
            sim.add_constraint(e, "elbow", "elbow_r", 1, ALWAYS, tuple(p[i, J["elbow_r"]]))

    s, _ = one_state(idle, wrist_and_elbow, n=3)
    limbs(s)
    for c in range(3):  # the elbow's goal where the wrist's reach left it: both met
        s.goals.goal[user_goal(s, 3 + c)] = s.dec.positions[c, J["elbow_r"]]
    arm = (s.pose.arm_frame, s.pose.arm_fraction, s.pose.hand_dir, s.dec.arm2world,
           s.dec.positions)
    before = [a.copy() for a in arm]
    limbs(s)
    for was, now in zip(before, arm, strict=True):
        np.testing.assert_array_equal(now, was)


def test_the_head_reaches_its_goal(idle):
    def nod(sim, entities, p):
        sim.add_constraint(entities[0], "nod", "head_top", 3, ALWAYS,
                           tuple(p[0, J["head_top"]] + [0.08, 0.02, -0.04]))

    s, _ = one_state(idle, nod)
    before = s.dec.positions[0].copy()
    solve_head(0, s.pose, s.dec, s.goals, s.winners, s.bodies, T)
    assert goal_error(s.dec, 0, s.goals, user_goal(s, 0), T) < 1e-9
    # Only the head moved.
    moved = np.flatnonzero(np.linalg.norm(s.dec.positions[0] - before, axis=1) > 1e-12)
    assert set(moved) <= {J["head"], J["head_top"]}


def thorax_turn(before, after):
    relative = matrix_from_quat(after) @ matrix_from_quat(before).T
    return math.acos(np.clip((np.trace(relative) - 1.0) / 2.0, -1.0, 1.0))


def test_the_trunk_turn_is_capped_and_vetoed_when_it_worsens_a_higher_goal(idle):
    def low_reach(sim, entities, p):
        sim.add_constraint(entities[0], "reach", "wrist_r", 1, ALWAYS,
                           tuple(p[0, J["shoulder_r"]] + [0.6, -0.2, -0.9]), chain=("arm_r", "trunk"))

    s, _ = one_state(idle, low_reach)
    thorax = s.pose.thorax[0].copy()
    err = goal_errors(s, 0)
    stalled = np.zeros(err.size, bool)
    cap = 0.05
    assert solve_trunk(0, s.pose, s.dec, s.bodies.lengths[0], s.goals, s.winners, err, stalled, T,
                       S.tolerance_m, S.tolerance_rad, cap)
    assert thorax_turn(thorax, s.pose.thorax[0]) == pytest.approx(cap, abs=1e-9)

    def with_a_held_left_hand(sim, entities, p):
        low_reach(sim, entities, p)
        # Held back, at the left arm's full reach: the turn takes the shoulder forward, and the
        # hand out of the arm's reach (a hand the arm could still reach would not veto it).
        arm = ADULT.lengths[L["upper_arm_l"]] + ADULT.lengths[L["forearm_l"]]
        back = np.array([-1.0, 0.3, 0.0]) / np.linalg.norm([-1.0, 0.3, 0.0])
        sim.add_constraint(entities[0], "hold", "wrist_l", 9, ALWAYS,
                           tuple(p[0, J["shoulder_l"]] + 0.999 * arm * back))

    s2, _ = one_state(idle, with_a_held_left_hand)
    # As in the solve: the turn comes after a pass has met the held hand.
    solve_limbs(0, s2.pose, s2.dec, s2.goals, s2.winners, s2.bodies, T, S.tolerance_m,
                MAX_LEG_EXTENSION, arm_scratch(1)[0], Column(0), False)
    thorax, positions = s2.pose.thorax[0].copy(), s2.dec.positions[0].copy()
    err = goal_errors(s2, 0)
    assert not solve_trunk(0, s2.pose, s2.dec, s2.bodies.lengths[0], s2.goals, s2.winners, err,
                           np.zeros(err.size, bool), T, S.tolerance_m, S.tolerance_rad, cap)
    # The turn is undone: the pose as it was, and its joints decoded where they were.
    np.testing.assert_array_equal(s2.pose.thorax[0], thorax)
    np.testing.assert_allclose(s2.dec.positions[0], positions, rtol=0, atol=1e-12)


def test_the_root_moves_the_centre_of_mass_back_and_lowers_for_reach(idle):
    """Three characters standing, a wrist goal each: the root's step puts the centre of mass on
    its place once the next pass has re-planted the feet (the first, within the tenth of its
    tolerance at which the solve stops); lowers the root where the planted legs could not
    reach (the second, a long step); and where the step cannot be predicted (the third's feet
    not in contact: the legs would leave their reach) moves every joint by the error times
    ``root_gain``. The numpy reference takes the same steps."""
    def hold(sim, entities, p):
        for i, e in enumerate(entities):
            sim.add_constraint(e, "hold", "wrist_r", 1, ALWAYS, tuple(p[i, J["wrist_r"]]))

    _, args = one_state(idle, hold, n=3, com_control=True)
    goals = args[2]
    com = centres_of_mass(args[6].positions, args[3], args[4])
    error = np.array([[0.02, -0.01], [0.35, 0.0], [0.35, 0.0]])
    goals.com_desired[:, :2] = com[:, :2] + error
    assert goals.in_contact.all()
    goals.in_contact[2] = False
    reference, s = both_states(args)
    b = s.bodies
    before = s.dec.positions.copy()
    np.testing.assert_allclose(reference.root(), np.linalg.norm(error, axis=1), atol=1e-12)
    for c in range(3):
        assert root(s, c) == pytest.approx(np.linalg.norm(error[c]), abs=1e-12)
    assert_same_state(reference, s)
    moved = np.array([centre_of_mass(s.dec, c, b.masses[c], b.com_fraction[c], T) for c in range(3)])
    # Every joint moved with the root: past the desired place, by the gain's share where unpredicted.
    np.testing.assert_allclose(b.com_desired[2, :2] - moved[2, :2], (1 - S.root_gain) * error[2],
                               atol=1e-12)
    assert np.all(np.linalg.norm(b.com_desired[:2, :2] - moved[:2, :2], axis=1) > 1e-3)
    drop = s.dec.positions[:, [J["hip_l"], J["hip_r"]], 2] - before[:, [J["hip_l"], J["hip_r"]], 2]
    assert np.allclose(drop[0], 0.0) and np.all(drop[1] < -1e-3) and np.allclose(drop[2], 0.0)
    lengths = b.lengths[1]
    reach = MAX_LEG_EXTENSION * (lengths[[T.thigh[0], T.thigh[1]]] + lengths[[T.shank[0], T.shank[1]]])
    to_footprint = np.linalg.norm(s.dec.positions[1, [J["hip_l"], J["hip_r"]]] - b.footprint[1], axis=1)
    assert np.all(to_footprint <= reach + 1e-9)
    # The next pass re-plants the feet (the wrist's goal carried with the body, as the bench's
    # targets on the shoulder are: the arm is left alone): the predicted centre of mass is met.
    hold = np.flatnonzero(s.goals.table_index >= 0)[0]
    s.goals.goal[hold] += s.dec.positions[0, J["wrist_r"]] - before[0, J["wrist_r"]]
    limbs(s)
    after = np.array(centre_of_mass(s.dec, 0, b.masses[0], b.com_fraction[0], T))
    assert np.linalg.norm(b.com_desired[0, :2] - after[:2]) < 0.1 * S.com_tolerance_m
    np.testing.assert_allclose(s.dec.positions[0, [J["ankle_l"], J["ankle_r"]]], b.footprint[0],
                               atol=1e-9)


def test_the_root_stays_without_centre_of_mass_control(idle):
    """A character whose centre of mass is not held: the root step measures no error and
    moves nothing, the kernel as numpy."""
    _, args = one_state(idle, lambda sim, entities, p: sim.add_constraint(
        entities[0], "hold", "wrist_r", 1, ALWAYS, tuple(p[0, J["wrist_r"]] + [0.1, 0.0, 0.0])),
        com_control=False)
    reference, s = both_states(args)
    positions = s.dec.positions.copy()
    assert reference.root()[0] == 0.0 and root(s, 0) == 0.0
    np.testing.assert_array_equal(s.dec.positions, positions)
    assert_same_state(reference, s)


def _numpy_sorted_goals(goals, goal_iterations):
    """What :func:`compiled.sorted_goals` gives, in numpy calls (its code before
    :func:`compiled.goal_starts`): the goals (all but ``start``'s and the winners'), ``start``
    and the order."""
    r, k = goals.rows.size, goals.k
    order = np.argsort(goals.owner, kind="stable")
    start = np.zeros(r + 1, np.int64)
    np.cumsum(np.bincount(goals.owner[order], minlength=r), out=start[1:])
    dense = {"on_self": np.zeros(k, bool), "self_segment": np.zeros(k, np.int64),
             "self_fraction": np.zeros(k), "self_offset": np.zeros((k, 3)),
             "self_at": np.zeros((k, 3))}
    dense["on_self"][goals.on_self] = True
    for name, given in (("self_segment", goals.self_segment),
                        ("self_fraction", goals.self_fraction),
                        ("self_offset", goals.self_offset), ("self_at", goals.self_start)):
        dense[name][goals.on_self] = given
    fields = {name: getattr(goals, name)[order] for name in Goals._fields
              if name not in dense and name not in ("start", "iterations")}
    fields.update({name: value[order] for name, value in dense.items()},
                  iterations=goal_iterations[order])
    return fields, start, order


def _random_goals(rng, r):
    """TickGoals of ``r`` characters with 0-4 user goals each (two feet after them), sorted by
    character, some following their own body (their offsets' zeros -0.0 for some)."""
    from ecs_anim.solver.goals import TickGoals

    per = rng.integers(0, 5, r) + 2
    owner = np.repeat(np.arange(r), per)
    k = owner.size
    offset = rng.normal(size=(k, 3)) * (rng.random((k, 1)) < 0.5)
    offset[rng.random((k, 3)) < 0.2] = -0.0
    on_self = np.flatnonzero(rng.random(k) < 0.3)
    s = on_self.size
    self_offset = rng.normal(size=(s, 3))
    self_offset[rng.random((s, 3)) < 0.3] = -0.0
    return TickGoals(
        rows=np.arange(r) * 2, owner=owner, table_index=rng.integers(-1, 50, k),
        orientation=rng.random(k) < 0.2, group=rng.integers(0, 6, k), bone=rng.integers(0, 3, k),
        segment=rng.integers(0, 20, k), fraction=rng.random(k), offset=offset,
        chain=rng.integers(1, 64, k), priority=rng.integers(0, 3, k).astype(float),
        goal=rng.normal(size=(k, 3)), weight=rng.random(k), axis=rng.normal(size=(k, 3)),
        footprint=rng.normal(size=(r, 2, 3)), in_contact=rng.random((r, 2)) < 0.5,
        com_desired=rng.normal(size=(r, 3)), com_on=rng.random(r) < 0.5, on_self=on_self,
        self_segment=rng.integers(0, 20, s), self_fraction=rng.random(s),
        self_offset=self_offset, self_start=rng.normal(size=(s, 3)),
        held=np.zeros(k, bool))


@pytest.mark.parametrize("r", [0, 1, 7, 300])
def test_sorted_goals_compiled_pass_gives_numpys_layout_to_the_bit(r):
    """:func:`compiled.sorted_goals`' compiled pass (:func:`compiled.goal_starts`: each
    character's range, the goals following their own body laid out by goal) gives what the
    numpy calls gave, to the bit (-0.0 kept), on goals sorted by character and on the same goals
    shuffled (the numpy path's)."""
    rng = np.random.default_rng(3601 + r)
    goals = _random_goals(rng, r)
    caps = rng.integers(1, 4, goals.k)
    shuffle = rng.permutation(goals.k)
    back = np.argsort(shuffle)
    shuffled = replace(goals, **{name: getattr(goals, name)[shuffle] for name in
                                 ("owner", "table_index", "orientation", "group", "bone",
                                  "segment", "fraction", "offset", "chain", "priority", "goal",
                                  "weight", "axis", "held")},
                       on_self=back[goals.on_self])
    for given, given_caps in ((goals, caps), (shuffled, caps[shuffle])):
        g, _, order = compiled.sorted_goals(given, given_caps)
        fields, start, want_order = _numpy_sorted_goals(given, given_caps)
        np.testing.assert_array_equal(order, want_order)
        np.testing.assert_array_equal(g.start, start)
        for name, want in fields.items():
            got = getattr(g, name)
            assert got.dtype == want.dtype, name
            np.testing.assert_array_equal(got.view(np.uint8), want.view(np.uint8), err_msg=name)
    # sorted: the goals' own arrays, not copies (the solve moves ``goal`` in place)
    g, _, _ = compiled.sorted_goals(goals, caps)
    assert g.goal is goals.goal and g.offset is goals.offset


def test_a_hook_registered_once_numba_is_imported_runs_at_once() -> None:
    # (a kernel module imported after a tick ran: the solver's prefetch is such a hook)
    with_numba()
    ran: list[bool] = []
    on_numba_import(lambda: ran.append(True))
    assert ran == [True]


def test_the_prefetch_runs_as_python_where_numba_runs_the_kernels_as_python() -> None:
    done = subprocess.run(
        [sys.executable, "-c",
         "import numpy as np\n"
         "from ecs_anim.runtime.kernels import solve\n"
         "from ecs_anim.runtime.kernels.vec import with_numba\n"
         "with_numba()\n"
         "solve.prefetch_rows(np.zeros(20), 3, 10)\n"
         "print(type(solve.prefetch).__name__)\n"],
        capture_output=True, text=True, timeout=120, check=False,
        env={**os.environ, "NUMBA_DISABLE_JIT": "1"})
    assert done.returncode == 0, done.stderr
    assert done.stdout.split() == ["function"]
