"""No pops: the solver's segments turn at most ``max_joint_speed_rad_s`` faster than the motion's
(ecs_anim.solver.joint_speed and its compiled kernel)."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

import ecs_anim.systems.constraint_solve as system
from conftest import SCENARIOS_DIR
from ecs_anim.core.errors import UsageError
from ecs_anim.core.normalized import decode as numpy_decode
from ecs_anim.runtime.kernels import joint_speed as compiled
from ecs_anim.runtime.metrics import MetricsRecorder
from ecs_anim.scenario import build_simulation, load_scenario
from ecs_anim.solver import joint_speed as reference
from ecs_anim.solver import shell as solver_shell
from ecs_anim.solver.shell import SolverSettings
from support.solve import random_poses


def packed_random(rng, n):
    return reference.pack(random_poses(rng, n))


def test_compiled_pack_equals_numpy():
    poses = random_poses(np.random.default_rng(5), 30)
    np.testing.assert_array_equal(compiled.pack(poses), reference.pack(poses))


@pytest.mark.parametrize("max_step", [0.02, 0.3, 1.0, 10.0])
def test_compiled_limit_equals_numpy(max_step):
    rng = np.random.default_rng(17)
    n = 60
    poses = random_poses(rng, n)
    clip_now, clip_before, pose_before = (packed_random(rng, n) for _ in range(3))
    pose_before[:5] = 0.0  # no last tick: nothing to limit
    planted = rng.uniform(size=(n, 2)) < 0.4
    expected, expected_held = reference.limit_motion(poses, clip_now, clip_before, pose_before,
                                                     planted, max_step)
    got, held = compiled.limit_motion(poses.take(np.arange(n)), clip_now, clip_before,
                                      pose_before, planted, max_step)
    for name, value in expected.arrays().items():
        np.testing.assert_allclose(getattr(got, name), value, rtol=0, atol=1e-9, err_msg=name)
    np.testing.assert_array_equal(held, expected_held)
    assert not held[:5].any()
    if max_step < 1.0:
        assert held.sum() > n // 2  # random poses move a lot: most are held back


def segment_steps(before, after):
    frames, directions, shifts = reference._steps(before, after)
    return np.stack(frames + directions + shifts, axis=1)  # (r, 18)


def test_a_held_back_segment_turns_by_the_step_plus_the_motions_own():
    rng = np.random.default_rng(3)
    n, max_step = 40, 0.1
    poses = random_poses(rng, n)
    clip_before = packed_random(rng, n)
    clip_now = clip_before.copy()  # the motion stands still: every turn is the solver's
    pose_before = packed_random(rng, n)
    planted = np.zeros((n, 2), bool)
    planted[:10, 0] = True
    limited, held = reference.limit_motion(poses, clip_now, clip_before, pose_before, planted,
                                           max_step)
    assert held.all()
    moved = segment_steps(pose_before, limited)
    legs = np.array([g in (0, 1) for g in np.concatenate([reference.FRAME_GROUP,
                                                          reference.DIRECTION_GROUP,
                                                          reference.SHIFT_GROUP])])
    left_leg = np.array([g == 0 for g in np.concatenate([reference.FRAME_GROUP,
                                                         reference.DIRECTION_GROUP,
                                                         reference.SHIFT_GROUP])])
    free = ~(planted[:, 0, None] & left_leg[None])
    assert moved[free].max() <= max_step + 1e-9
    # each group's most held-back segment goes exactly the step; a planted leg as solved
    assert np.isclose(moved[:, ~legs].max(axis=1), max_step, atol=1e-9).all()
    np.testing.assert_array_equal(limited.leg_frame[:10, 0], poses.leg_frame[:10, 0])
    # the motion's own turn is allowed on top: a clip turning as far lets it all through
    same, none_held = reference.limit_motion(poses, reference.pack(poses), pose_before,
                                             pose_before, planted, max_step)
    assert not none_held.any()
    for name, value in poses.arrays().items():
        np.testing.assert_array_equal(getattr(same, name), value)


def test_a_scenario_sets_the_bound_and_a_bad_one_is_one_line(tmp_path):
    """``solver: {max_joint_speed_rad_s: 4}`` reaches the simulation's settings; a typo or a
    speed out of range names the file, the line and the key."""
    from ecs_anim.core.errors import InputError

    for bound in (4, None):
        with build_simulation(punch_with_trunk(tmp_path, bound)) as sim:
            assert sim.solver_settings.max_joint_speed_rad_s == bound
    for text, message in (("solver: {max_joint_speed: 4}", r"solver.max_joint_speed: unknown key"),
                          ("solver: {max_joint_speed_rad_s: 0}", r"solver.max_joint_speed_rad_s")):
        path = tmp_path / "bad.yaml"
        good = punch_with_trunk(tmp_path, 4).path
        lines = open(good).read().splitlines()
        lines[-1] = text
        path.write_text("\n".join(lines) + "\n")
        with pytest.raises(InputError, match=rf"bad.yaml:{len(lines)}: {message}"):
            load_scenario(path)


def test_settings_refuse_a_speed_that_is_not_positive():
    for bad in (0.0, -1.0, float("nan"), float("inf")):
        with pytest.raises(UsageError, match="max_joint_speed_rad_s"):
            SolverSettings(max_joint_speed_rad_s=bad)
    assert SolverSettings(max_joint_speed_rad_s=None).max_joint_speed_rad_s is None


def punch_with_trunk(tmp_path, bound=None):
    """The fight (scenarios/fight_training.yaml) with ``trunk`` in every punch's chain, as the
    docs allow (without a bound the trunk folds in a tick as the punch eases out), and with
    ``bound`` the scenario's ``solver: {max_joint_speed_rad_s: bound}`` (docs/scenarios.md)."""
    text = (SCENARIOS_DIR / "fight_training.yaml").read_text()
    assert text.count("chain: [arm_r]") == 4  # the punches'
    text = text.replace("chain: [arm_r]", "chain: [arm_r, trunk]")
    text = text.replace(": motions/", f": {SCENARIOS_DIR / 'motions'}/")
    if bound is not None:
        text += f"solver: {{max_joint_speed_rad_s: {bound}}}\n"
    path = tmp_path / f"punch_with_trunk_{bound}.yaml"
    path.write_text(text)
    return load_scenario(path)


#: The bound the tests run with (rad/s; the settings' default is none).
BOUND = 4.0


def run_report(scenario, speed=None, ticks=None):
    """Run ``scenario`` (``speed``: the bound, rad/s, None for the scenario's) and return its
    report."""
    with build_simulation(scenario) as sim:
        if speed is not None:
            sim.solver_settings = replace(sim.solver_settings, max_joint_speed_rad_s=speed)
        metrics = MetricsRecorder(sim)
        for _ in range(ticks or round(scenario.duration_s * scenario.fps)):
            sim.step()
            metrics.record()
        return metrics.report()


def speeds(report):
    return {c["name"]: (c["joint_speed_m_s_max"], c["clip_joint_speed_m_s_max"])
            for c in report["characters"]}


def test_a_trunk_in_the_punch_chain_bends_over_several_ticks(tmp_path):
    popped = speeds(run_report(punch_with_trunk(tmp_path)))
    scenario = punch_with_trunk(tmp_path, BOUND)
    assert scenario.solver == {"max_joint_speed_rad_s": BOUND}
    bounded = run_report(scenario)
    held = speeds(bounded)
    for name in ("defender_1", "defender_2", "defender_3", "defender_4"):
        fastest, own = held[name]
        assert fastest <= 1.5 * own, name
    # without the bound the trunk's fold takes a head to 10-14 m/s (its motion's: 0.1-0.7)
    assert max(popped[f"defender_{k}"][0] for k in range(1, 5)) > 1.5 * min(
        popped[f"defender_{k}"][1] for k in range(1, 5))
    for c in bounded["characters"]:
        assert c["foot_sliding_mm_per_frame"]["max"] <= 1.0, c["name"]
        assert c["com_error_mm_max"] < 10.0, c["name"]
    # What the bound costs: the reachable kicks still land (0.0 mm, as without it); the
    # ward-offs chase a kicking ankle (up to 10 m/s) a little late (0-30 mm, 0 without).
    errors = {(k["character"], k["name"]): k["error_mm_max_fully_active"]
              for k in bounded["constraints"]}
    for pair in (1, 2, 3):
        assert errors[(f"kicker_{pair}", "kick_torso")] == 0.0
    assert max(errors[(f"defender_{pair}", "ward_off")] for pair in range(1, 5)) < 40.0


def test_the_fight_with_numpy_steps_ends_as_with_the_compiled_ones(monkeypatch, tmp_path):
    """The whole tick with the goals, the solver, the errors, the limit and the decode swapped
    for their numpy references: every joint and error within 1e-9 m, on the fight with the
    trunk in the punches' chains (where the bound holds segments back), 1.8 s of it."""
    scenario = punch_with_trunk(tmp_path)
    numpy = solver_shell.NUMPY_STEPS

    def run_positions():
        with build_simulation(scenario) as sim:
            sim.solver_settings = replace(sim.solver_settings, max_joint_speed_rad_s=BOUND)
            positions, errors = [], []
            for _ in range(54):
                sim.step()
                positions.append(sim.store.positions.copy())
                errors.append(sim.constraints.error.copy())
            return np.array(positions), np.array(errors)

    result = run_positions()
    monkeypatch.setattr(system, "tick_goals", numpy.goals)
    monkeypatch.setattr(system, "solve", numpy.solve)
    monkeypatch.setattr(system, "constraint_errors", numpy.errors)
    monkeypatch.setattr(system, "limit_motion", reference.limit_motion)
    monkeypatch.setattr(system, "pack", reference.pack)
    monkeypatch.setattr(system, "decode", numpy_decode)
    expected = run_positions()
    np.testing.assert_allclose(result[0], expected[0], rtol=0, atol=1e-9)
    np.testing.assert_allclose(result[1], expected[1], rtol=0, atol=1e-9)
