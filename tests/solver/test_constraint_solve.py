"""ConstraintSolve, first cut: wrist and elbow position constraints by priority (paper fig. 13)."""

from __future__ import annotations

import numpy as np
import pytest

from conftest import REPO
from ecs_anim.components import MotionPlayer, Placement
from ecs_anim.core.errors import EcsAnimError
from ecs_anim.core.morphology import Morphology, bone_lengths_of
from ecs_anim.core.skeleton import BONE_JOINTS
from ecs_anim.core.skeleton import JOINT_INDEX as J
from ecs_anim.motion.constraints import Activation
from ecs_anim.runtime.simulation import Simulation

IS_BONE = np.array([a >= 0 for a, _ in BONE_JOINTS])
ALWAYS = Activation(0.0, 1e9)


def _sim(idle, n=1, speed=1.0, com_control=True):
    sim = Simulation({"idle": idle})
    entities = [sim.spawn(f"c{i}", Morphology.preset("adult_male"), MotionPlayer("idle", speed=speed),
                          Placement((0.0, 2.0 * i)), com_control=com_control) for i in range(n)]
    return sim, entities


def test_reachable_wrist_target_is_met(idle):
    sim, (e,) = _sim(idle)
    sim.step()
    shoulder = sim.store.positions[0, J["shoulder_r"]].copy()
    target = shoulder + np.array([0.35, -0.1, 0.15])
    sim.add_constraint(e, "reach", "wrist_r", 10, ALWAYS, tuple(target))
    for _ in range(3):
        sim.step()
    p = sim.store.positions[0]
    assert np.linalg.norm(p[J["wrist_r"]] - target) < 1e-3
    np.testing.assert_allclose(bone_lengths_of(p)[IS_BONE], Morphology.preset("adult_male").lengths[IS_BONE], atol=1e-9)


def test_unreachable_target_stretches_the_arm_without_jitter(idle):
    sim, (e,) = _sim(idle)
    sim.step()
    target = sim.store.positions[0, J["shoulder_r"]] + np.array([2.0, -1.0, 0.5])
    sim.add_constraint(e, "far", "wrist_r", 10, ALWAYS, tuple(target))
    errors = []
    for _ in range(10):
        sim.step()
        p = sim.store.positions[0]
        errors.append(np.linalg.norm(p[J["wrist_r"]] - target)
                      - (np.linalg.norm(target - p[J["shoulder_r"]])
                         - Morphology.preset("adult_male")["upper_arm_r"]
                         - Morphology.preset("adult_male")["forearm_r"]))
    assert np.abs(errors).max() < 1e-3  # the geometric minimum, every tick
    assert np.all(np.isfinite(sim.store.positions))


def test_wrist_high_elbow_low(idle):
    # A still body without COM control: the shoulder stays, so the targets stay a pose the arm
    # can take (with COM control the root would shift and the elbow target leave the circle).
    sim, (e,) = _sim(idle, speed=0.0, com_control=False)
    sim.step()
    p = sim.store.positions[0]
    m = Morphology.preset("adult_male")
    shoulder = p[J["shoulder_r"]]
    # A pose the arm can take: elbow out to the side, wrist forward.
    out = np.array([0.05, -0.9, -0.436])
    elbow_target = shoulder + out / np.linalg.norm(out) * m["upper_arm_r"]
    wrist_target = elbow_target + np.array([m["forearm_r"], 0.0, 0.0])
    sim.add_constraint(e, "wrist", "wrist_r", 10, ALWAYS, tuple(wrist_target))
    sim.add_constraint(e, "elbow", "elbow_r", 1, ALWAYS, tuple(elbow_target))
    for _ in range(3):
        sim.step()
    q = sim.store.positions[0]
    assert np.linalg.norm(q[J["wrist_r"]] - wrist_target) < 1e-3
    assert np.linalg.norm(q[J["elbow_r"]] - elbow_target) < 1e-3
    # Elbow target out of reach of the elbow circle: wrist still met, elbow as close as it gets.
    sim.add_constraint(e, "elbow2", "elbow_r", 2, ALWAYS, tuple(shoulder + [0, -2.0, 1.0]))
    sim.step()
    q = sim.store.positions[0]
    assert np.linalg.norm(q[J["wrist_r"]] - wrist_target) < 1e-3


def test_target_on_another_character_reads_its_previous_posture(idle):
    sim, (a, b) = _sim(idle, 2)
    sim.add_constraint(a, "touch", "wrist_r", 5, ALWAYS, target_entity=b, target_point="head")
    heads = []
    for _ in range(6):
        heads.append(sim.store.positions[1, J["head"]].copy())  # b's posture before this tick
        sim.step()
    wrist = sim.store.positions[0, J["wrist_r"]]
    shoulder = sim.store.positions[0, J["shoulder_r"]]
    # b's head is 2 m away: out of reach, so the arm points at where b's head was last tick.
    direction = (wrist - shoulder) / np.linalg.norm(wrist - shoulder)
    wanted = (heads[-1] - shoulder) / np.linalg.norm(heads[-1] - shoulder)
    assert np.dot(direction, wanted) > 1 - 1e-9


def test_activation_ramp_has_no_jump_and_nan_target_disables_only_that_one(idle, capsys):
    """The weight follows the ramp tick by tick; at the activation's start and stop no joint
    moves further in a tick than the motion's own joints do (plus 1 mm), and between them the
    move is spread over the eases; a NaN target switches off only its own constraint."""
    from ecs_anim.motion.constraints import ramp_weight

    sim, (a, b, _twin) = _sim(idle, 3)  # the twin plays the same motion, unconstrained
    sim.step()
    target = sim.store.positions[0, J["shoulder_r"]] + np.array([0.4, 0.0, 0.2])
    activation = Activation(0.5, 3.0, 1.0, 1.0)
    ramp = sim.add_constraint(a, "ramp", "wrist_r", 5, activation, tuple(target))
    other = sim.add_constraint(b, "other", "wrist_l", 5, ALWAYS,
                               tuple(sim.store.positions[1, J["shoulder_l"]] + [0.3, 0.2, 0.0]))
    distance = np.linalg.norm(target - sim.store.positions[0, J["wrist_r"]])
    positions, weights, times = [], [], []
    for _ in range(110):
        times.append(sim.time_s)
        sim.step()
        positions.append(sim.store.positions[[0, 2]].copy())
        weights.append(sim.constraints.weight[ramp])
    np.testing.assert_allclose(weights, ramp_weight(np.array(times), 0.5, 3.0, 1.0, 1.0), atol=1e-12)
    steps = np.linalg.norm(np.diff(np.array(positions), axis=0), axis=-1)  # (ticks, 2, joints)
    own = steps[:, 1].max()  # the motion's own largest step of any joint
    active = np.flatnonzero(np.array(weights) > 0)
    first, last = active[0], active[-1] + 1  # the ticks the constraint starts and stops moving it
    assert steps[first - 1, 0].max() <= own + 1e-3 and steps[last - 1, 0].max() <= own + 1e-3
    # A smooth ramp, not a jump: the wrist's fastest tick is the quintic's peak rate (1.875)
    # times the move spread over the 1 s ease (30 ticks).
    assert steps[:, 0, J["wrist_r"]].max() < 1.875 * distance / 30 + own
    sim.set_target(other, (np.nan, 0.0, 0.0))
    sim.step()
    assert "'other' has a target that is not finite" in sim.messages[-1]  # and logged (ecs_anim)
    assert np.all(np.isfinite(sim.store.positions))
    with pytest.raises(EcsAnimError, match="unknown body point 'knee_x'; did you mean"):
        sim.add_constraint(a, "bad", "knee_x", 1, ALWAYS, (0.0, 0.0, 0.0))
    with pytest.raises(EcsAnimError, match="finite"):
        sim.add_constraint(a, "nan", "wrist_l", 1, ALWAYS, (np.nan, 0.0, 0.0))


def test_scenario_constraints_are_wired_by_name():

    from ecs_anim.scenario import build_simulation, load_scenario

    repo = REPO
    scenario = load_scenario(repo / "scenarios" / "reach_and_touch.yaml")
    with build_simulation(scenario) as sim:
        for _ in range(int(2.0 * 30)):  # fully active from 1.1 s
            sim.step()
        wrist = sim.store.positions[0, J["wrist_r"]]
        assert np.linalg.norm(wrist - [0.45, -0.35, 1.25]) < 1e-3
        assert sim.constraints.target_row[2] == 0  # the friend's target is the reacher


def test_scenario_constraint_errors(tmp_path):

    from ecs_anim.core.errors import InputError
    from ecs_anim.scenario import load_scenario

    repo = REPO
    text = (repo / "scenarios" / "reach_and_touch.yaml").read_text()
    cases = [
        (text.replace("character: reacher", "character: reachr"), "no character named 'reachr'; did you mean 'reacher'?"),
        (text.replace("point: wrist_l", "point: wrist_left"), "unknown body point 'wrist_left'; did you mean 'wrist_l'?"),
        (text.replace("joint: head_top", "joint: headtop"), "unknown body point 'headtop'; did you mean 'head_top'?"),
        (text.replace("ease_out_s: 0.5}", "ease_out_s: 9.0}"), "activation ease_in_s + ease_out_s"),
    ]
    for k, (broken, fragment) in enumerate(cases):
        path = repo / "scenarios" / f".tmp_constraint_{k}.yaml"  # beside the motions it names
        path.write_text(broken)
        try:
            with pytest.raises(InputError) as err:
                load_scenario(path)
            assert fragment in str(err.value) and str(err.value).startswith(f"{path}:")
        finally:
            path.unlink()


@pytest.mark.parametrize("control", [True, False])
def test_com_control_brings_the_centre_of_mass_back(idle, control):
    from ecs_anim.core.morphology import centres_of_mass

    sim = Simulation({"idle": idle})
    e = sim.spawn("a", Morphology.preset("adult_male"), MotionPlayer("idle", speed=0.0),
                  com_control=control)
    sim.step()

    def com():
        st = sim.store
        return centres_of_mass(st.positions, st.segment_mass_kg, st.segment_com_fraction)[0]

    desired = com()
    feet = sim.store.positions[0, [J["ankle_l"], J["ankle_r"]]].copy()
    target = sim.store.positions[0, J["shoulder_r"]] + [0.9, -0.1, -0.3]  # a far reach forward
    sim.add_constraint(e, "far", "wrist_r", 10, ALWAYS, tuple(target))
    for _ in range(3):
        sim.step()
    drift = np.linalg.norm(com()[:2] - desired[:2])
    if control:
        assert drift < 0.01  # within 1 cm of where the motion had it
    else:
        assert drift > 0.01  # the reference: the reach pulls the COM forward
    np.testing.assert_allclose(sim.store.positions[0, [J["ankle_l"], J["ankle_r"]]], feet, atol=1e-9)
    bones = bone_lengths_of(sim.store.positions[0])[IS_BONE]
    np.testing.assert_allclose(bones, Morphology.preset("adult_male").lengths[IS_BONE], atol=1e-9)
