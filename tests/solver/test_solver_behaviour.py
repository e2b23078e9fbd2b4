"""The constraint solver's behaviour (constraint issue): kinds, chains, priorities, COM, properties.

Numbers asserted are millimetres and radians on real poses of our idle motion, played still
(speed 0) unless a test says otherwise, so every difference comes from the solver.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
from hypothesis import example, given, settings
from hypothesis import strategies as st

from conftest import MOTIONS_DIR
from ecs_anim.components import MotionPlayer, Placement
from ecs_anim.core.body_points import GROUPS, body_point
from ecs_anim.core.errors import EcsAnimError
from ecs_anim.core.morphology import Morphology, bone_lengths_of, centres_of_mass, with_lengths_m
from ecs_anim.core.rotations import rot_axis
from ecs_anim.core.skeleton import BONE_JOINTS, JOINTS
from ecs_anim.core.skeleton import JOINT_INDEX as J
from ecs_anim.io.importing import import_bvh
from ecs_anim.motion.constraint_table import Area
from ecs_anim.motion.constraints import Activation
from ecs_anim.runtime.simulation import Simulation
from ecs_anim.solver.shell import DEFAULT_SETTINGS

IS_BONE = np.array([a >= 0 for a, _ in BONE_JOINTS])
ALWAYS = Activation(0.0, 1e9)
ADULT = Morphology.preset("adult_male")


@pytest.fixture(scope="module")
def floating(idle):
    """The idle motion without its foot contacts: every group is free to move."""
    return replace(idle, constraints=[])


def still(motion, body=ADULT, com_control=False, n=1):
    sim = Simulation({"m": motion})
    entities = [sim.spawn(f"c{i}", body, MotionPlayer("m", speed=0.0), Placement((0.0, 2.0 * i)),
                          com_control=com_control) for i in range(n)]
    sim.step()
    return sim, entities


def settle(sim, ticks=2):
    for _ in range(ticks):
        sim.step()
    return sim.store.positions.copy()


def moved_joints(before, after, tol=1e-9):
    return {JOINTS[j] for j in np.flatnonzero(np.linalg.norm(after - before, axis=-1) > tol)}


def bones_exact(positions, body=ADULT):
    np.testing.assert_allclose(bone_lengths_of(positions)[..., IS_BONE], np.broadcast_to(
        body.lengths[IS_BONE], bone_lengths_of(positions)[..., IS_BONE].shape), atol=1e-9)


def facing(p):
    """Unit horizontal direction (3,) the body with joint positions ``p`` faces (its right foot)."""
    forward = p[J["toe_r"]] - p[J["ankle_r"]]
    forward[2] = 0.0
    return forward / np.linalg.norm(forward)


def head_centre(p):
    return 0.5 * (p[J["head"]] + p[J["head_top"]])


def dodging(sim, e, fist, radius):
    """A constraint keeping the head's centre ``radius`` metres out of a sphere about ``fist``."""
    return sim.add_constraint(e, "dodge", "head", 1, ALWAYS, tuple(fist), kind="area", fraction=0.5,
                              chain=("head", "trunk"), area=Area("sphere", radius_m=radius, inside=False))


# --- only the chain moves: one test per group ---------------------------------------------------

CHAINS = [
    # point, chain, target offset from the point (m), joints allowed to move
    ("ankle_r", ("leg_r",), (0.15, -0.05, 0.20), {"knee_r", "ankle_r", "toe_r"}),
    ("ankle_l", ("leg_l",), (0.20, 0.05, 0.25), {"knee_l", "ankle_l", "toe_l"}),
    ("head_top", ("head",), (0.05, 0.04, -0.03), {"head", "head_top"}),
    ("wrist_r", ("arm_r",), (0.20, -0.10, 0.25), {"elbow_r", "wrist_r", "hand_r"}),
    ("wrist_l", ("arm_l",), (0.20, 0.10, 0.25), {"elbow_l", "wrist_l", "hand_l"}),
    ("neck", ("trunk",), "lean",
     {"spine_1", "spine_2", "neck", "head", "head_top", "shoulder_l", "elbow_l", "wrist_l",
      "hand_l", "shoulder_r", "elbow_r", "wrist_r", "hand_r"}),
]


@pytest.mark.parametrize("point, chain, offset, allowed", CHAINS, ids=[c[1][0] for c in CHAINS])
def test_only_the_chain_moves(floating, point, chain, offset, allowed):
    sim, (e,) = still(floating)
    before = sim.store.positions[0].copy()
    if offset == "lean":  # a rotation about the spine's base only turns the neck on a sphere
        base = before[J["pelvis"]]
        target = base + rot_axis(1, np.radians(10.0)) @ (before[J[point]] - base)
    else:
        target = before[J[point]] + np.array(offset)
    k = sim.add_constraint(e, "c", point, 1, ALWAYS, tuple(target), chain=chain)
    after = settle(sim)[0]
    # The spine bends along its spline, which brings its end a little closer to its base than
    # a rigid turn would: the lean's neck lands within a few millimetres (84 mm away before).
    tolerance = 5e-3 if offset == "lean" else 1e-3
    assert np.linalg.norm(after[J[point]] - target) < tolerance
    assert moved_joints(before, after) <= allowed
    assert sim.constraints.error[k] < tolerance
    bones_exact(after)


def test_foot_contacts_keep_the_feet_while_an_arm_and_the_trunk_reach(idle):
    sim, (e,) = still(idle, com_control=True)
    before = sim.store.positions[0].copy()
    target = before[J["shoulder_r"]] + [1.0, -0.2, -0.5]  # beyond the arm: the trunk bends
    sim.add_constraint(e, "far", "wrist_r", 1, ALWAYS, tuple(target), chain=("arm_r", "trunk"))
    after = settle(sim, 4)[0]
    feet = [J["ankle_l"], J["ankle_r"]]
    np.testing.assert_allclose(after[feet], before[feet], atol=1e-9)
    # The trunk helped: the wrist is closer than the arm alone could take it.
    arm = ADULT["upper_arm_r"] + ADULT["forearm_r"]
    alone = np.linalg.norm(target - before[J["shoulder_r"]]) - arm
    assert np.linalg.norm(after[J["wrist_r"]] - target) < alone - 0.05
    bones_exact(after)


@pytest.mark.parametrize("elevation_deg, share", [(-20.0, 0.80), (10.0, 0.90), (35.0, 0.90)])
def test_the_trunk_bends_to_reach_what_the_arm_alone_cannot(floating, elevation_deg, share):
    """A target in front, low, level or high, at ``share`` of pelvis-to-shoulder plus arm (a
    spine bent far forward is a curve, its chord shorter than standing): the trunk brings the
    shoulder within reach and the arm meets it. (Turning the trunk to aim the wrist alone
    stalled once the arm was straight: 17, 11 and 7 cm short here.)"""
    sim, (e,) = still(floating)
    before = sim.store.positions[0].copy()
    pelvis, shoulder = before[J["pelvis"]], before[J["shoulder_r"]]
    arm = ADULT["upper_arm_r"] + ADULT["forearm_r"]
    forward = facing(before)
    side = np.cross([0.0, 0.0, 1.0], forward)
    up = np.radians(90.0 - elevation_deg)  # from vertical
    direction = np.cos(up) * np.array([0.0, 0.0, 1.0]) + np.sin(up) * forward
    target = pelvis + share * (np.linalg.norm(shoulder - pelvis) + arm) * direction - 0.15 * side
    k = sim.add_constraint(e, "far", "wrist_r", 1, ALWAYS, tuple(target), chain=("arm_r", "trunk"))
    after = settle(sim, 3)[0]
    assert sim.constraints.error[k] < 1e-3
    assert np.linalg.norm(after[J["wrist_r"]] - target) < 1e-3
    bones_exact(after)


@pytest.mark.parametrize("point, fraction, chain", [
    ("upper_arm_r", 0.5, ("arm_r", "trunk")), ("elbow_r", None, ("arm_r", "trunk")),
    ("forearm_l", 0.5, ("arm_l", "trunk")), ("neck", 0.5, ("head", "trunk")),
    ("head", 0.5, ("head", "trunk"))])
def test_points_on_every_bone_of_the_arms_and_head_reach_with_the_trunk(floating, point, fraction, chain):
    """Forward and down, 80 % of the way the straight pelvis-to-point chain reaches: met, whichever
    bone the point is on (a point on the first bone, upper arm or neck, reaches only its own
    distance from the shoulder or neck)."""
    sim, (e,) = still(floating)
    before = sim.store.positions[0].copy()
    pelvis = before[J["pelvis"]]
    start = point_positions_now(sim, point, fraction)
    forward = facing(before)
    direction = np.cos(np.radians(60.0)) * np.array([0.0, 0.0, 1.0]) + np.sin(np.radians(60.0)) * forward
    target = pelvis + 0.8 * straight_reach(before, point, fraction) * direction
    assert np.linalg.norm(start - target) > 0.1
    k = sim.add_constraint(e, "far", point, 1, ALWAYS, tuple(target), chain=chain, fraction=fraction)
    settle(sim, 3)
    assert sim.constraints.error[k] < 1e-3


def point_positions_now(sim, point, fraction):
    from ecs_anim.core.body_points import point_positions
    from ecs_anim.core.normalized import decode

    bp = body_point(point, fraction)
    dec = decode(sim.store.poses, sim.store.lengths)
    return point_positions(dec, np.array([0]), np.array([bp.segment]), np.array([bp.fraction]),
                           np.array([bp.offset_m]))[0]


def straight_reach(p, point, fraction):
    """Pelvis to the point's limb root, plus the limb straightened out to the point (m)."""
    side = point[-1]
    if point.startswith(("neck", "head")):
        root, bones = p[J["neck"]], [("neck", "head"), ("head", "head_top")]
    else:
        root, bones = p[J[f"shoulder_{side}"]], [(f"shoulder_{side}", f"elbow_{side}"),
                                                   (f"elbow_{side}", f"wrist_{side}")]
    lengths = [np.linalg.norm(p[J[b]] - p[J[a]]) for a, b in bones]
    first_bone = point.startswith(("upper_arm", "neck"))
    along = {"elbow_r": lengths[0]}.get(point, (fraction or 1.0) * lengths[0] if first_bone
                                        else lengths[0] + (fraction or 1.0) * lengths[1])
    return np.linalg.norm(root - p[J["pelvis"]]) + along


# --- kinds and points ---------------------------------------------------------------------------

def test_a_point_along_the_forearm_reaches_its_target(floating):
    sim, (e,) = still(floating)
    p = sim.store.positions[0]
    target = p[J["shoulder_r"]] + [0.30, -0.15, 0.05]
    sim.add_constraint(e, "mid", "forearm_r", 1, ALWAYS, tuple(target), fraction=0.5)
    q = settle(sim)[0]
    middle = 0.5 * (q[J["elbow_r"]] + q[J["wrist_r"]])
    assert np.linalg.norm(middle - target) < 1e-3


def test_distance_between_the_two_hands_of_one_body(floating):
    sim, (e,) = still(floating)
    # Hold a 0.3 m box: the left wrist 0.3 m from the right one (this tick's, no lag).
    sim.add_constraint(e, "box", "wrist_l", 1, ALWAYS, target_entity=e, target_point="wrist_r",
                       kind="distance", distance_m=0.30)
    for _ in range(3):
        q = settle(sim, 1)[0]
        assert abs(np.linalg.norm(q[J["wrist_l"]] - q[J["wrist_r"]]) - 0.30) < 1e-3
    # A smaller box, at higher priority: it wins the arm, the box swivels what is left.
    sim.add_constraint(e, "ball", "wrist_l", 2, ALWAYS, target_entity=e, target_point="wrist_r",
                       kind="distance", distance_m=0.22)
    q = settle(sim, 1)[0]
    assert abs(np.linalg.norm(q[J["wrist_l"]] - q[J["wrist_r"]]) - 0.22) < 1e-3


def test_areas_keep_a_point_inside_or_outside(floating):
    sim, (e,) = still(floating)
    wrist = sim.store.positions[0, J["wrist_r"]].copy()
    table_top = wrist[2] + 0.10  # the idle wrist is 10 cm below the table top
    area = Area("box", low_m=(-1.0, -1.0, 0.0), high_m=(1.0, 1.0, 1.0))
    k = sim.add_constraint(e, "above", "wrist_r", 1, ALWAYS, (wrist[0], wrist[1], table_top),
                           kind="area", area=area)
    q = settle(sim)[0]
    assert q[J["wrist_r"], 2] >= table_top - 1e-3
    assert sim.constraints.error[k] < 1e-3
    # A sphere to stay out of: the left wrist pushed to its surface.
    wrist_l = q[J["wrist_l"]]
    centre = wrist_l + [0.05, 0.0, 0.0]
    sim.add_constraint(e, "avoid", "wrist_l", 1, ALWAYS, tuple(centre), kind="area",
                       area=Area("sphere", radius_m=0.15, inside=False))
    q = settle(sim)[0]
    assert np.linalg.norm(q[J["wrist_l"]] - centre) >= 0.15 - 1e-3
    # A half-space (z >= 1.2 m) on the head: met, by the head and trunk.
    sim.add_constraint(e, "tall", "head_top", 1, ALWAYS, (0.0, 0.0, q[J["head_top"], 2] - 0.02),
                       kind="area", area=Area("half_space", normal=(0.0, 0.0, -1.0)),
                       chain=("head", "trunk"))
    q2 = settle(sim, 4)[0]
    assert q2[J["head_top"], 2] <= q[J["head_top"], 2] - 0.02 + 1e-3


def test_a_point_dodging_a_moving_sphere_stays_on_its_side(floating):
    """An obstacle (a fist) sweeps through where the motion holds the head, from 0.5 m in front
    to 1 m behind it, 5 cm a tick: the head leans back ahead of it, is never caught inside it,
    never passes through it to the front, and moves smoothly; once the obstacle has gone by,
    the head goes back to the motion at the release speed (1.5 m/s), not in one tick."""
    sim, (e,) = still(floating)
    p = sim.store.positions[0]
    head, forward, radius = head_centre(p), facing(p), 0.2
    k = dodging(sim, e, head + 0.5 * forward, radius)
    heads = []
    path = np.concatenate([np.linspace(0.5, -1.0, 31), np.full(10, -1.0)])
    for along in path:
        fist = head + along * forward
        sim.set_target(k, tuple(fist))
        q = settle(sim, 1)[0]
        heads.append(head_centre(q))
        assert np.linalg.norm(heads[-1] - fist) >= radius - 2e-3  # never caught
        if along > -0.3:
            assert np.dot(heads[-1] - fist, forward) < 0.0  # behind the fist as it comes
    steps = np.linalg.norm(np.diff(np.array(heads), axis=0), axis=1)
    assert steps.max() < 0.08  # no jump: the fist moves 5 cm a tick, the release 5 cm
    np.testing.assert_allclose(heads[-1], head, atol=1e-9)  # back to the motion
    away = np.linalg.norm(np.array(heads) - head, axis=1)
    peak = int(away.argmax())
    back = peak + int(np.argmax(away[peak:] < 1e-6))
    assert away[peak] > 0.3 and back - peak >= away[peak] / 0.05  # ... at 5 cm a tick


def test_a_character_added_mid_run_changes_no_one_elses_side(floating):
    """A character spawned while another dodges has no last posture yet: the dodging head keeps
    its side (no flip through the sphere), and a target on the newcomer is read at once."""
    sim, (e,) = still(floating)
    p = sim.store.positions[0]
    head, forward = head_centre(p), facing(p)
    k = dodging(sim, e, head + 0.5 * forward, 0.2)
    for along in np.linspace(0.5, -0.1, 13):
        fist = head + along * forward
        sim.set_target(k, tuple(fist))
        if along < -0.04 and sim.store.n == 1:
            late = sim.spawn("late", ADULT, MotionPlayer("m", speed=0.0), Placement((0.0, 1.0)))
            touch = sim.add_constraint(late, "touch", "wrist_r", 1, ALWAYS, target_entity=e,
                                       target_point="hand_l")
        q = settle(sim, 1)[0]
        h = head_centre(q)
        assert np.dot(h - fist, forward) < 0.0 and np.linalg.norm(h - fist) > 0.2 - 2e-3
    assert sim.store.n == 2 and sim.constraints.enabled[touch] and not sim.messages
    assert np.isfinite(sim.constraints.error[touch])


def test_a_target_on_the_own_body_is_measured_where_it_ended(floating):
    """The left wrist holds the right hand while the right arm and trunk reach far: the reported
    error is the gap between them on the result, wherever the solve took the hand."""
    sim, (e,) = still(floating)
    p = sim.store.positions[0]
    forward = facing(p)
    hold = sim.add_constraint(e, "hold", "wrist_l", 10, ALWAYS, target_entity=e, target_point="hand_r",
                              chain=("arm_l",))
    sim.add_constraint(e, "far", "wrist_r", 5, ALWAYS,
                       tuple(p[J["shoulder_r"]] + 0.85 * forward - [0.0, 0.0, 0.3]), chain=("arm_r", "trunk"))
    q = settle(sim, 2)[0]
    gap = np.linalg.norm(q[J["wrist_l"]] - q[J["hand_r"]])
    assert sim.constraints.error[hold] == pytest.approx(gap, abs=1e-9)


def test_reported_errors_measure_the_constraint_not_the_solver_goal(floating):
    """An area's error is the distance to its allowed region (0 anywhere in it), a distance's
    how far from the distance: on the result, whatever goal point the solver aimed at."""
    sim, (e,) = still(floating)
    p = sim.store.positions[0]
    # Already inside a box the motion keeps: nothing to do, error 0 (not "not evaluated").
    inside = sim.add_constraint(e, "kept", "wrist_r", 1, ALWAYS, tuple(p[J["wrist_r"]]), kind="area",
                                area=Area("box", low_m=(-0.3, -0.3, -0.3), high_m=(0.3, 0.3, 0.3)))
    # The left wrist 0.25 m from a point 0.4 m away, on any side of it.
    centre = p[J["wrist_l"]] + [0.0, 0.0, 0.4]
    apart = sim.add_constraint(e, "apart", "wrist_l", 1, ALWAYS, tuple(centre), kind="distance",
                               distance_m=0.25)
    q = settle(sim, 2)[0]
    errors = sim.constraints.error
    assert errors[inside] == 0.0
    assert errors[apart] == pytest.approx(abs(np.linalg.norm(q[J["wrist_l"]] - centre) - 0.25), abs=1e-12)
    assert errors[apart] < 1e-3


def test_orientation_of_the_head_and_of_a_hand(floating):
    sim, (e,) = still(floating)
    look = np.array([0.6, -0.6, -0.2])
    sim.add_constraint(e, "look", "head", 1, ALWAYS, tuple(look), kind="orientation",
                       axis=(1.0, 0.0, 0.0))
    sim.add_constraint(e, "palm", "hand_r", 1, ALWAYS, (0.0, 0.0, -1.0), kind="orientation")
    settle(sim)
    head2world = sim.store.posture.head2world[0]
    forward = head2world[:, 0]
    assert np.degrees(np.arccos(np.clip(forward @ (look / np.linalg.norm(look)), -1, 1))) < 0.1
    q = sim.store.positions[0]
    hand = (q[J["hand_r"]] - q[J["wrist_r"]]) / ADULT["hand_r"]
    assert np.degrees(np.arccos(np.clip(hand @ [0.0, 0.0, -1.0], -1, 1))) < 0.1


# --- priorities (paper fig. 13) -----------------------------------------------------------------

def test_lower_priority_never_costs_the_higher_one(floating):
    sim, (e,) = still(floating)
    shoulder = sim.store.positions[0, J["shoulder_r"]]
    wrist_target = shoulder + [0.25, -0.25, -0.30]
    elbow_target = shoulder + [-0.5, -0.6, 0.4]  # not on the elbow's circle
    w = sim.add_constraint(e, "wrist", "wrist_r", 10, ALWAYS, tuple(wrist_target))
    alone = settle(sim)[0]
    elbow_alone = np.linalg.norm(alone[J["elbow_r"]] - elbow_target)
    k = sim.add_constraint(e, "elbow", "elbow_r", 1, ALWAYS, tuple(elbow_target))
    both = settle(sim)[0]
    np.testing.assert_allclose(both[J["wrist_r"]], alone[J["wrist_r"]], atol=1e-9)
    assert sim.constraints.error[w] < 1e-3
    assert sim.constraints.error[k] <= elbow_alone + 1e-9
    assert sim.constraints.error[k] < elbow_alone - 0.05  # and the swivel did bring it closer



def test_a_lower_goal_turning_the_trunk_leaves_an_unreachable_higher_one_where_it_was(floating):
    """An elbow goal 1 m left of the pelvis (priority 100, 587.2 mm out of reach), then a wrist
    goal at the same point (priority 0), both with the trunk. Once the elbow's goal stalls the
    trunk turns for the wrist; a turn that took the elbow no further as a rigid turn about the
    pelvis bent the spine, whose vertebrae keep their lengths along it, so the shoulder (and the
    elbow) ended 2.6 mm further (589.79 mm, the wrist too: 451.96 mm). The veto now measures the
    decoded turn: neither gets worse."""
    sim, (e,) = still(floating, body=Morphology.from_stature(1.0))
    target = tuple(sim.store.positions[0, J["pelvis"]] + [0.0, 1.0, 0.0])
    elbow = sim.add_constraint(e, "elbow", "elbow_l", 100, ALWAYS, target, chain=("arm_l", "trunk"))
    settle(sim, 2)
    alone = sim.constraints.error[elbow]
    assert alone == pytest.approx(0.5872, abs=1e-4)
    wrist = sim.add_constraint(e, "wrist", "wrist_l", 0, ALWAYS, target, chain=("arm_l", "trunk"))
    for _ in range(3):
        sim.step()
        assert sim.constraints.error[elbow] <= alone + 1e-6
        assert sim.constraints.error[wrist] == pytest.approx(0.4494, abs=1e-4)

# --- centre of mass -----------------------------------------------------------------------------

def test_com_within_a_centimetre_while_the_trunk_bends(idle):
    drifts = {}
    for control in (True, False):
        sim, (e,) = still(idle, com_control=control)
        st = sim.store
        desired = centres_of_mass(st.positions, st.segment_mass_kg, st.segment_com_fraction)[0]
        target = st.positions[0, J["shoulder_r"]] + [1.1, -0.1, -0.6]
        sim.add_constraint(e, "far", "wrist_r", 1, ALWAYS, tuple(target), chain=("arm_r", "trunk"))
        feet = st.positions[0, [J["ankle_l"], J["ankle_r"]]].copy()
        settle(sim, 3)
        com = centres_of_mass(st.positions, st.segment_mass_kg, st.segment_com_fraction)[0]
        drifts[control] = np.linalg.norm(com[:2] - desired[:2])
        np.testing.assert_allclose(st.positions[0, [J["ankle_l"], J["ankle_r"]]], feet, atol=1e-9)
        if control:
            assert st.com_error_m[0] < 0.01
    assert drifts[True] < 0.01 < drifts[False]


def test_com_target_given_by_the_scenario(idle):
    sim = Simulation({"m": idle})
    e = sim.spawn("a", ADULT, MotionPlayer("m", speed=0.0), com_target_xy=(0.03, -0.02))
    sim.step()
    sim.add_constraint(e, "reach", "wrist_r", 1, ALWAYS,
                       tuple(sim.store.positions[0, J["shoulder_r"]] + [0.3, -0.1, 0.0]))
    settle(sim, 2)
    st = sim.store
    com = centres_of_mass(st.positions, st.segment_mass_kg, st.segment_com_fraction)[0]
    assert np.linalg.norm(com[:2] - [0.03, -0.02]) < 0.01


# --- bad input ----------------------------------------------------------------------------------

@pytest.mark.parametrize("kwargs, message", [
    (dict(point="wrist_x"), "unknown body point 'wrist_x'; did you mean 'wrist_r'?"),
    (dict(point="pelvis"), "only centre-of-mass control moves"),
    (dict(chain=()), "empty chain"),
    (dict(chain=("arm_l",)), "must include 'arm_r'"),
    (dict(chain=("arm_r", "leg_l")), "cannot be moved by leg_l"),
    (dict(chain=("arm_r", "trunc")), "unknown chain group 'trunc'"),
    (dict(kind="area"), "needs its area"),
    (dict(kind="orientation", point="forearm_r"), "cannot be constrained"),
    (dict(kind="distance", distance_m=-1.0), "distance_m must be >= 0"),
    (dict(fraction=1.5, point="forearm_r"), "fraction along 'forearm_r' must be in [0, 1]"),
])
def test_bad_constraints_are_refused_with_their_name(floating, kwargs, message):
    sim, (e,) = still(floating)
    args = dict(point="wrist_r", target_in_world=(0.0, 0.0, 1.0))
    args.update(kwargs)
    point = args.pop("point")
    with pytest.raises(EcsAnimError) as err:
        sim.add_constraint(e, "bad", point, 1, ALWAYS, **args)
    assert message in str(err.value) and str(err.value).startswith("constraint 'bad':")


def test_an_unknown_character_is_a_clear_error(floating):
    sim, (e,) = still(floating)
    with pytest.raises(EcsAnimError, match="no character with entity id 999"):
        sim.add_constraint(999, "x", "wrist_r", 1, ALWAYS, (0.0, 0.0, 1.0))
    with pytest.raises(EcsAnimError, match="no character with entity id 999"):
        sim.add_constraint(e, "x", "wrist_r", 1, ALWAYS, target_entity=999, target_point="head")
    with pytest.raises(EcsAnimError, match="no character with entity id 999"):
        sim.set_body(999, ADULT)


def test_a_nan_target_switches_off_one_constraint_and_the_others_go_on(floating, capsys):
    sim, (a, b) = still(floating, n=2)
    ka = sim.add_constraint(a, "a", "wrist_r", 1, ALWAYS, (0.3, -0.3, 1.2))
    kb = sim.add_constraint(b, "b", "wrist_r", 1, ALWAYS, (0.3, 1.7, 1.2))
    settle(sim, 1)
    sim.set_target(ka, (np.nan, 0.0, 1.0))
    q = settle(sim, 2)
    assert "'a' has a target that is not finite" in " ".join(sim.messages)
    assert np.all(np.isfinite(q))
    assert sim.constraints.error[kb] < 1e-3 and not sim.constraints.enabled[ka]


# --- properties ---------------------------------------------------------------------------------

POINTS = ["wrist_l", "wrist_r", "elbow_l", "elbow_r", "hand_r", "head_top", "ankle_l", "knee_r",
          "forearm_l", "neck"]


FLOATING = replace(import_bvh(MOTIONS_DIR / "idle.bvh"), constraints=[])


@settings(max_examples=60, deadline=None, derandomize=True)  # the same cases on every run
@given(stature=st.floats(1.0, 2.1), legs=st.floats(0.85, 1.15),
       picks=st.lists(st.tuples(st.sampled_from(POINTS), st.integers(0, 20),
                                st.tuples(*[st.floats(-1.2, 1.2)] * 3), st.booleans()),
                      min_size=1, max_size=4))
# Found by a search: an unreachable neck target drifted 3.6 mm while an arm-only elbow goal kept
# the loop going (the trunk now stops turning for a goal that has stalled).
@example(stature=1.4402034402789332, legs=0.9484956092574444,
         picks=[("neck", 0, (-1.084290435723114, 1.1311791537951967, 1.1897171626930805), True),
                ("elbow_r", 3, (-1.079236196294697, -0.19249646541511556, -0.5621111947884702), False)])
# Found by CI: an unreachable head_top goal 0.03 mm worse once a lower neck goal turned the trunk
# (within the veto's tolerance).
@example(stature=1.0, legs=1.0,
         picks=[("head_top", 0, (1.0, 0.0, 1.0), True), ("wrist_l", 0, (0.0, 0.0, 0.0), False),
                ("wrist_l", 0, (0.0, 0.0, 0.0), False), ("neck", 0, (1.0, 0.0, 1.0), False)])
# Found in the full suite: an unreachable elbow goal 2.6 mm worse once a lower wrist goal turned
# the trunk (the veto judged the turn as rigid; the bent spine carried the shoulder further).
@example(stature=1.0, legs=1.0,
         picks=[("elbow_l", 0, (0.0, 1.0, 0.0), True), ("wrist_l", 0, (0.0, 0.0, 0.0), False),
                ("wrist_l", 0, (0.0, 1.0, 0.0), True)])
def test_random_bodies_targets_and_priorities(stature, legs, picks):
    """Finite poses, exact bones, and the highest-priority constraint (priority 100, added first
    and solved alone for two ticks) no worse, beyond the solver's 0.1 mm tolerance (the trunk's
    veto allows that much), once lower-priority ones join it. Without
    COM control: with it, the root moves for all the constraints together (the paper's
    adaptRoot), which by design may move an unreachable high-priority target's limb root."""
    base = Morphology.from_stature(stature)
    body = with_lengths_m(base, {k: base[k] * legs for k in ("thigh_l", "thigh_r", "shank_l", "shank_r")})
    sim, (e,) = still(FLOATING, body=body)
    pelvis = sim.store.positions[0, J["pelvis"]]
    first, error_alone = -1, np.inf
    for k, (point, priority, offset, trunk) in enumerate(picks):
        group = GROUPS[body_point(point, 0.5 if point == "forearm_l" else None).group]
        chain = (group, "trunk") if trunk and group in ("head", "arm_l", "arm_r") else None
        index = sim.add_constraint(e, f"c{k}", point, 100 if k == 0 else priority, ALWAYS,
                                   tuple(pelvis + np.array(offset)), chain=chain,
                                   fraction=0.5 if point == "forearm_l" else None)
        if k == 0:
            first = index
            settle(sim, 2)
            error_alone = sim.constraints.error[first]
    q = settle(sim, 2)[0]
    assert np.all(np.isfinite(q))
    bones_exact(q, body)
    assert sim.constraints.error[first] <= error_alone + DEFAULT_SETTINGS.tolerance_m


# --- constraints stored with a motion (import --constraints) ------------------------------------

HOLD_BOX = """\
# Hold a 0.27 m box between the wrists from 0.5 s to 2.5 s of the motion.
constraints:
  - name: hold_box
    kind: distance
    point: wrist_l
    target: {point: wrist_r}
    distance_m: 0.27
    priority: 5
    activation: {start_s: 0.5, stop_s: 2.5, ease_in_s: 0.2, ease_out_s: 0.2}
"""


def test_constraints_given_at_import_play_with_the_motion_on_every_body(tmp_path, capsys):
    from ecs_anim.apps.cli.main import main
    from ecs_anim.motion.clip import load_nmo

    (tmp_path / "box.yaml").write_text(HOLD_BOX)
    assert main(["import", str(MOTIONS_DIR / "idle.bvh"), "-o", str(tmp_path),
                 "--constraints", str(tmp_path / "box.yaml")]) == 0
    assert "1 stored constraint(s)" in capsys.readouterr().out
    motion = load_nmo(tmp_path / "idle.nmo")
    assert [c.name for c in motion.constraints if c.kind != "foot_contact"] == ["hold_box"]
    sim = Simulation({"idle": motion})
    for i, preset in enumerate(("child", "tall")):
        sim.spawn(preset, Morphology.preset(preset), MotionPlayer("idle", loop=False),
                  Placement((0.0, 1.5 * i)))
    gap_rows = []
    for _ in range(90):
        sim.step()
        q = sim.store.positions
        gap_rows.append(np.linalg.norm(q[:, J["wrist_l"]] - q[:, J["wrist_r"]], axis=1))
    gaps = np.array(gap_rows)  # (ticks, 2); tick k shows motion time k / 30 s
    held = slice(21, 69)  # 0.7 s .. 2.3 s: fully active
    np.testing.assert_allclose(gaps[held], 0.27, atol=1e-3)
    assert np.all(np.abs(gaps[:10] - 0.27) > 0.005)  # before: the motion's own hands


def test_a_bad_constraints_file_is_refused_before_importing(tmp_path, capsys):
    from ecs_anim.apps.cli.main import main

    bad = tmp_path / "bad.yaml"
    bad.write_text(HOLD_BOX.replace("target: {point: wrist_r}", "target: {world_m: [0, 0, 1]}"))
    assert main(["import", str(MOTIONS_DIR / "idle.bvh"), "-o", str(tmp_path / "out"),
                 "--constraints", str(bad)]) != 0
    err = capsys.readouterr().err
    assert f"{bad}:6: constraints[0].target: a motion's constraint aims at a point" in err
    assert not (tmp_path / "out" / "idle.nmo").exists()


KEEP_OUT = """constraints:
  - name: elbow_clear
    kind: area
    point: wrist_l
    target: {point: head}
    area: {shape: sphere, radius_m: 0.3, inside: false}
"""


def test_a_stored_area_plays_and_a_stored_constraint_past_the_clip_is_refused(tmp_path, capsys):
    """An area stored with a motion (its corners and normal come back from the .nmo as JSON
    lists) plays; a constraint that would start after the clip ends is refused at import; a
    damaged stored constraint is refused when the .nmo is read, naming the file."""
    from dataclasses import replace as dc_replace

    from ecs_anim.apps.cli.main import main
    from ecs_anim.core.errors import InputError
    from ecs_anim.motion.clip import load_nmo, save_nmo

    (tmp_path / "keep.yaml").write_text(KEEP_OUT)
    assert main(["import", str(MOTIONS_DIR / "idle.bvh"), "-o", str(tmp_path),
                 "--constraints", str(tmp_path / "keep.yaml")]) == 0
    motion = load_nmo(tmp_path / "idle.nmo")
    sim = Simulation({"idle": motion})
    sim.spawn("a", ADULT, MotionPlayer("idle"))
    for _ in range(5):
        sim.step()
    q = sim.store.positions[0]
    assert np.linalg.norm(q[J["wrist_l"]] - q[J["head"]]) >= 0.3 - 1e-3
    capsys.readouterr()

    late = KEEP_OUT + "    activation: {start_s: 100, stop_s: 200}\n"
    (tmp_path / "late.yaml").write_text(late)
    assert main(["import", str(MOTIONS_DIR / "idle.bvh"), "-o", str(tmp_path / "late"),
                 "--constraints", str(tmp_path / "late.yaml")]) == 1
    assert "after the clip ends" in capsys.readouterr().err
    assert not (tmp_path / "late" / "idle.nmo").exists()

    stored = next(c for c in motion.constraints if c.kind != "foot_contact")
    for damage in ({"segment": "tail"}, {"chain": ("leg_l",)},
                   {"params": {**stored.params, "target_point": "wing"}}):
        broken = dc_replace(motion, constraints=[dc_replace(stored, **damage)])
        save_nmo(broken, tmp_path / "broken.nmo", force=True)
        with pytest.raises(InputError, match=r"broken.nmo: damaged .nmo header: constraint 'elbow_clear'"):
            load_nmo(tmp_path / "broken.nmo")



def test_a_characters_result_does_not_depend_on_who_else_is_solved(idle, monkeypatch):
    """Each character stops when its own goals are met or stalled: alone, or solved in one batch
    with a character whose target is out of reach (which keeps iterating), it takes the same
    iterations and ends the same."""
    import ecs_anim.systems.constraint_solve as system

    iterations: list[int] = []

    def counting(*args, **kwargs):
        result = system_solve(*args, **kwargs)
        iterations.append(result[1][0])
        return result

    system_solve = system.solve
    monkeypatch.setattr(system, "solve", counting)

    def reaching(with_unreachable):
        sim = Simulation({"m": idle})
        e = sim.spawn("reacher", ADULT, MotionPlayer("m", speed=1.0), Placement((0.0, 0.0)),
                      com_control=True)
        if with_unreachable:
            far = sim.spawn("far", ADULT, MotionPlayer("m", speed=1.0), Placement((0.0, 3.0)),
                            com_control=True)
        sim.step()
        p = sim.store.positions[0]
        sim.add_constraint(e, "reach", "wrist_r", 5, ALWAYS, tuple(p[J["shoulder_r"]] + [0.3, -0.2, 0.2]))
        sim.add_constraint(e, "elbow", "elbow_r", 1, ALWAYS, tuple(p[J["elbow_r"]] + [0.0, -0.1, 0.0]))
        if with_unreachable:
            q = sim.store.positions[1]
            sim.add_constraint(far, "far", "wrist_l", 5, ALWAYS, tuple(q[J["shoulder_l"]] + [3.0, 1.0, 0.5]),
                               chain=("arm_l", "trunk"))
            sim.add_constraint(far, "look", "head_top", 1, ALWAYS, tuple(q[J["head_top"]] + [0.5, 0.3, -0.4]))
        out = []
        for _ in range(8):
            sim.step()
            out.append((sim.store.positions[0].copy(), sim.constraints.error[:2].copy()))
        return out

    alone = reaching(False)
    alone_iterations, iterations[:] = list(iterations), []
    batched = reaching(True)
    assert iterations == alone_iterations and max(iterations) < DEFAULT_SETTINGS.iterations
    for (p_alone, err_alone), (p_batched, err_batched) in zip(alone, batched, strict=True):
        np.testing.assert_allclose(p_batched, p_alone, rtol=0, atol=1e-12)
        np.testing.assert_allclose(err_batched, err_alone, rtol=0, atol=1e-12)
