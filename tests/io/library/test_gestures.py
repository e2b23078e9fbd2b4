"""The authored gestures (ecs_anim/library_gestures.py), read back the way a user reads them: from
the shipped BVH files through the importer, with its own contact detection.

Bounds used below, and why:
* joint speed < 6 m/s (brisk human gestures), except the kicking leg and the striking arms
  < 12 m/s (a front kick's foot and a punch's fist reach 8-14 m/s in people);
* joint acceleration (second difference at 30 fps) < 80 m/s², kicking leg < 250 m/s²: C1 keys
  give bounded accelerations; a velocity jump of 1 m/s within a frame would show as 900 m/s²;
* a planted foot moves < 1 mm per frame and stands at the body's ankle height (< 1 mm).
"""

from __future__ import annotations

import itertools

import numpy as np
import pytest

from conftest import MOTIONS_DIR
from ecs_anim.components import MotionPlayer, Placement, QueuedClip
from ecs_anim.core.morphology import Morphology, bone_lengths_of
from ecs_anim.core.normalized import decode
from ecs_anim.core.skeleton import BONE_JOINTS, JOINTS
from ecs_anim.core.skeleton import JOINT_INDEX as J
from ecs_anim.io.contacts import true_runs
from ecs_anim.io.importing import import_bvh
from ecs_anim.io.library.gestures import GESTURE_TIMINGS, GESTURES, NEUTRAL, sample_keys
from ecs_anim.io.library.shipped import main as library_main
from ecs_anim.runtime.metrics import MetricsRecorder
from ecs_anim.runtime.simulation import Simulation

FPS = 30.0
ADULT = Morphology.preset("adult_male")
LEG = ADULT.leg_length
ARM = ADULT["upper_arm_r"] + ADULT["forearm_r"]
IS_BONE = np.array([a >= 0 for a, _ in BONE_JOINTS])
FAST = {"kick": ("hip_r", "knee_r", "ankle_r", "toe_r"),
        "ward_off_punch": ("elbow_l", "wrist_l", "hand_l", "elbow_r", "wrist_r", "hand_r")}


@pytest.fixture(scope="module")
def clips():
    """name -> (imported NormalizedMotion, joint positions (F, 22, 3) on its source body)."""
    out = {}
    for name in GESTURES:
        motion = import_bvh(MOTIONS_DIR / f"{name}.bvh")
        out[name] = (motion, decode(motion.poses, motion.source_morphology.lengths).positions)
    return out


def frame(t_s: float) -> int:
    return round(t_s * FPS)


def test_every_gesture_is_shipped_with_its_timings(clips):
    assert set(GESTURE_TIMINGS) == set(GESTURES) == {
        "guard", "kick", "ward_off_punch", "dodge", "talk", "reach", "dance"}
    for name, (motion, _) in clips.items():
        timing = GESTURE_TIMINGS[name]
        assert motion.fps == FPS
        assert timing["loop"] == GESTURES[name].loop
        # One-shots hold a frame at both ends; a loop's last frame leads back to its first.
        period = motion.n_frames / FPS if timing["loop"] else motion.duration_s
        clip_length_s = timing["duration_s"]  # the clip's authored length, not a measured time
        assert period == pytest.approx(clip_length_s, abs=1e-9), name
        assert all(v <= clip_length_s for k, v in timing.items()
                   if k.endswith("_s") and k != "duration_s" and isinstance(v, float))


def test_shipped_files_equal_their_generators():
    assert library_main(["--check"]) == 0


@pytest.mark.parametrize("name", list(GESTURES))
def test_bones_rigid_and_equal_to_the_authored_body(clips, name):
    motion, positions = clips[name]
    lengths = bone_lengths_of(positions)[:, IS_BONE]
    error = np.abs(lengths - ADULT.lengths[IS_BONE]).max()
    assert error < 1e-6, f"{name}: bone lengths differ from adult_male by {error:.2e} m"
    np.testing.assert_allclose(motion.source_morphology.lengths[IS_BONE], ADULT.lengths[IS_BONE],
                               atol=1e-6)


@pytest.mark.parametrize("name", list(GESTURES))
def test_no_joint_jumps(clips, name):
    _, p = clips[name]
    if GESTURES[name].loop:  # the seam is a frame like any other
        p = np.concatenate([p, p[:2]])
    speed = np.linalg.norm(np.diff(p, axis=0), axis=-1) * FPS  # (F-1, 22)
    accel = np.linalg.norm(np.diff(p, 2, axis=0), axis=-1) * FPS**2
    fast = [J[j] for j in FAST.get(name, ())]
    slow = [i for i in range(len(JOINTS)) if i not in fast]
    assert speed[:, slow].max() < 6.0, (name, JOINTS[slow[int(speed[:, slow].max(0).argmax())]])
    assert speed.max() < 12.0
    kick_leg = [J[j] for j in FAST["kick"]] if name == "kick" else []
    others = [i for i in range(len(JOINTS)) if i not in kick_leg]
    assert accel[:, others].max() < 80.0, (name, float(accel[:, others].max()))
    assert accel.max() < 250.0


def test_interpolation_is_c1_with_zero_end_velocity_and_no_overshoot():
    keys = [(0.0, (0.0,)), (0.5, (1.0,)), (1.0, (1.0,)), (1.5, (3.0,)), (2.0, (0.0,))]
    t = np.linspace(0.0, 2.0, 4001)
    x = sample_keys(keys, t)[:, 0]
    v = np.gradient(x, t)
    assert abs(v[0]) < 0.05 and abs(v[-1]) < 0.05  # one-sided differences: O(a dt)
    # No velocity jump anywhere: between samples 0.5 ms apart the velocity changes by about
    # |a| dt < 0.05 m/s; piecewise-linear keys would jump by 2-6 m/s at each key.
    assert np.abs(np.diff(v)).max() < 0.1
    assert x.min() >= -1e-12 and x.max() <= 3.0 + 1e-12
    assert np.all(np.abs(x[(t >= 0.5) & (t <= 1.0)] - 1.0) < 1e-12)  # a hold holds exactly
    loop = sample_keys([(0.0, (0.0,)), (1.0, (1.0,)), (2.0, (0.0,))], np.array([0.0, 2.0]),
                       loop=True)
    assert loop[0, 0] == loop[1, 0]
    with pytest.raises(ValueError, match="looping channel"):
        sample_keys([(0.0, (0.0,)), (1.0, (1.0,))], t, loop=True)


@pytest.mark.parametrize("name", list(GESTURES))
def test_planted_feet_stand_still_on_the_ground(clips, name):
    """Authored stance (the ankle at its standing height): exactly still. The importer's detected
    contacts cover every stance frame; its hysteresis (contact ends only above 1.5 x 5 cm) may
    carry a contact up to 3 frames into a swing, where the foot is still low."""
    motion, p = clips[name]
    contact = motion.contacts()
    assert contact.any(axis=0).all(), f"{name}: a foot never touches the ground"
    for side, s in enumerate("lr"):
        ankle = p[:, J[f"ankle_{s}"]]
        height = ankle[:, 2] - ADULT[f"ankle_height_{s}"]
        stance = height < 1e-3
        assert height.min() > -1e-3, (name, s, float(height.min()))  # never below the ground
        both = stance[1:] & stance[:-1]
        slide = np.linalg.norm(np.diff(ankle, axis=0), axis=-1)[both]
        assert slide.max() < 1e-3, (name, s, float(slide.max()))
        detected = contact[:, side]
        assert detected[stance].all(), (name, s, np.flatnonzero(stance & ~detected))
        for a, b in true_runs(detected):
            extra = np.flatnonzero(~stance[a:b + 1])
            assert len(extra) <= 3 and (height[a:b + 1] < 0.08).all(), (name, s, a, b, extra)


def test_fight_clips_and_reach_start_and_end_in_their_stance(clips):
    guard = clips["guard"][1][0]
    for name in ("kick", "ward_off_punch", "dodge"):
        p = clips[name][1]
        for end in (p[0], p[-1]):
            assert np.linalg.norm(end - guard, axis=-1).max() < 1e-3, name
    reach = clips["reach"][1]
    assert np.linalg.norm(reach[0] - reach[-1], axis=-1).max() < 1e-3
    ankles = reach[0, [J["ankle_l"], J["ankle_r"]], 1] / LEG
    np.testing.assert_allclose(ankles, [NEUTRAL["ankle_l"][1], NEUTRAL["ankle_r"][1]], atol=1e-3)


@pytest.mark.parametrize("name", ["guard", "talk", "dance"])
def test_loops_close_without_a_seam(clips, name):
    """Going from the last frame back to the first is a step like the others: the pose after the
    last frame, predicted from the last three frames, is the first frame within 1 mm... allowing
    for the clip's own largest change of acceleration between frames."""
    _, p = clips[name]
    q = np.concatenate([p, p[:1]])
    predicted = 3 * q[-2] - 3 * q[-3] + q[-4]  # quadratic extrapolation
    seam = np.linalg.norm(predicted - q[-1], axis=-1).max()
    inside = np.linalg.norm(3 * p[2:-1] - 3 * p[1:-2] + p[:-3] - p[3:], axis=-1).max()
    assert seam <= max(inside, 1e-3) + 1e-9, (name, seam, inside)
    assert np.linalg.norm(p[-1] - p[0], axis=-1).max() < 0.05  # and no big jump either


def test_kick_peak_is_in_front_at_hip_height(clips):
    motion, p = clips["kick"]
    tm = GESTURE_TIMINGS["kick"]
    ankle = p[:, J["ankle_r"]]
    assert abs(int(ankle[:, 2].argmax()) - frame(tm["peak_s"])) <= 1
    f = frame(tm["peak_s"])
    forward = ankle[f, 0] - p[f, J["pelvis"], 0]
    above_hip = ankle[f, 2] - p[f, J["hip_r"], 2]
    assert forward / LEG == pytest.approx(tm["peak_ankle_in_front_of_pelvis_L"], abs=0.02)
    assert above_hip / LEG == pytest.approx(tm["peak_ankle_above_hip_L"], abs=0.02)
    assert 0.75 < forward < 0.9 and 0.9 < ankle[f, 2] < 1.1  # metres on the adult body
    from_start = (ankle[f, 0] - p[0, J["pelvis"], 0]) / LEG
    assert from_start == pytest.approx(tm["peak_ankle_in_front_of_start_L"], abs=0.02)
    contact = motion.contacts()
    assert contact[:, 0].all()  # the standing foot never leaves the ground
    air = ~contact[:, 1]
    assert air[frame(tm["chamber_s"]):frame(tm["rechamber_s"]) + 1].all()
    assert not air[: frame(tm["lift_off_s"])].any() and not air[frame(tm["land_s"]) + 3:].any()
    # The trunk leans back at the peak: the neck behind the pelvis, compared with guard.
    lean = p[:, J["neck"], 0] - p[:, J["pelvis"], 0]
    assert lean[f] < lean[0] - 0.1


def test_ward_off_sweeps_down_and_punch_extends_forward(clips):
    _, p = clips["ward_off_punch"]
    tm = GESTURE_TIMINGS["ward_off_punch"]
    mid = 0.5 * (p[:, J["elbow_l"]] + p[:, J["wrist_l"]])  # middle of the left forearm
    assert abs(int(mid[:, 2].argmin()) - frame(tm["ward_off_lowest_s"])) <= 1
    lo = frame(tm["ward_off_lowest_s"])
    assert mid[0, 2] - mid[lo, 2] > 0.2  # from guard, down by more than 20 cm
    assert mid[lo, 0] - p[lo, J["pelvis"], 0] > 0.2  # ... in front of the body
    reach = np.linalg.norm(p[:, J["wrist_r"]] - p[:, J["shoulder_r"]], axis=-1) / ARM
    f = frame(tm["punch_peak_s"])
    assert abs(int(reach.argmax()) - f) <= 2 and reach[f] > 0.93
    assert reach[f] == pytest.approx(tm["punch_reach_A"], abs=0.02)
    forward = p[:, J["wrist_r"], 0] - p[:, J["pelvis"], 0]
    assert forward[f] - forward[0] > 0.25  # the fist travels forward at least 25 cm
    assert abs(p[f, J["wrist_r"], 2] - p[f, J["head"], 2]) < 0.1  # at head height
    assert reach[frame(tm["ward_off_lowest_s"])] < 0.9  # the right fist stays home meanwhile
    # The lead foot slides in for the punch and back to its footprint; the rear foot stays.
    motion, _ = clips["ward_off_punch"]
    contact = motion.contacts()
    assert contact[:, 1].all()
    lead = p[:, J["ankle_l"], 0]
    (a0, a1), (b0, b1) = tm["step_in_s"], tm["step_back_s"]
    assert not contact[frame(0.5 * (a0 + a1)), 0] and not contact[frame(0.5 * (b0 + b1)), 0]
    assert lead[frame(a1):frame(b0) + 1].min() - lead[0] > 0.2 * LEG
    assert abs(lead[-1] - lead[0]) < 1e-3


def test_dodge_moves_the_head_back(clips):
    _, p = clips["dodge"]
    tm = GESTURE_TIMINGS["dodge"]
    back = p[0, J["head"], 0] - p[:, J["head"], 0]
    window = slice(frame(tm["deepest_s"]), frame(tm["deepest_end_s"]) + 1)
    assert back[window].min() >= 0.15
    assert back.max() == pytest.approx(tm["head_back_m_adult"], abs=0.02)
    assert abs(back[frame(tm["guard_again_s"]):]).max() < 0.01


def test_talk_hands_between_waist_and_chest_and_sometimes_lower(clips):
    _, p = clips["talk"]
    tm = GESTURE_TIMINGS["talk"]
    wrists = p[:, [J["wrist_l"], J["wrist_r"]], 2]
    pelvis, neck = p[:, J["pelvis"], 2], p[:, J["neck"], 2]
    lo, hi = frame(tm["hands_low_s"][0]), frame(tm["hands_low_s"][1])
    outside = np.r_[0:lo - 15, hi + 15:len(p)]
    assert np.all(wrists[outside] > pelvis[outside, None] - 0.06)  # waist and up
    assert np.all(wrists < neck[:, None] - 0.1)  # below the chest's top
    assert np.all(wrists[lo:hi + 1] < pelvis[lo:hi + 1, None] - 0.06)  # the dip, both hands
    assert np.ptp(wrists[:, 1]) > 0.3  # the hands really move
    spread = frame(tm["spread_s"])
    gap = np.linalg.norm(p[:, J["wrist_l"]] - p[:, J["wrist_r"]], axis=-1)
    assert gap[spread] > gap[0] + 0.15


def test_reach_goes_far_forward_and_down_then_back(clips):
    _, p = clips["reach"]
    tm = GESTURE_TIMINGS["reach"]
    wrist = p[:, J["wrist_r"]]
    toes = p[0, J["toe_r"], 0]
    peak, hold = frame(tm["peak_s"]), frame(tm["hold_end_s"])
    assert np.linalg.norm(wrist[peak:hold + 1] - wrist[peak], axis=-1).max() < 1e-3  # held
    assert (wrist[peak, 0] - toes) / LEG == pytest.approx(tm["wrist_in_front_of_toes_L"], abs=0.02)
    assert wrist[peak, 2] / LEG == pytest.approx(tm["wrist_height_L"], abs=0.02)
    assert wrist[peak, 0] - wrist[0, 0] > 0.4 and wrist[0, 2] - wrist[peak, 2] > 0.15
    assert abs(int(wrist[:, 0].argmax()) - peak) <= hold - peak  # furthest during the hold
    assert np.linalg.norm(p[frame(tm["back_s"])] - p[0], axis=-1).max() < 1e-3
    # The hips go back to balance the reach.
    assert p[peak, J["pelvis"], 0] - p[0, J["pelvis"], 0] < -0.15


def test_dance_steps_alternate(clips):
    motion, p = clips["dance"]
    tm = GESTURE_TIMINGS["dance"]
    contact = motion.contacts()
    assert contact.any(axis=1).all()  # never both feet in the air
    flights = sorted((a, side) for side in (0, 1) for a, _ in true_runs(~contact[:, side]))
    # A flight that wraps across the loop's seam counts once.
    wraps = [side for side in (0, 1) if not contact[0, side] and not contact[-1, side]]
    assert len(flights) - len(wraps) == tm["steps"]
    sides = [side for _, side in flights]
    assert all(a != b for a, b in itertools.pairwise(sides)), sides
    assert sides[0] == (1 if tm["first_foot"] == "r" else 0)
    starts = np.array([a for a, _ in flights]) / FPS
    np.testing.assert_allclose(np.diff(starts), tm["beat_s"], atol=2.5 / FPS)
    lift = p[:, [J["ankle_l"], J["ankle_r"]], 2].max(axis=0) - ADULT["ankle_height_l"]
    assert np.all(lift > 0.07 * LEG)  # real steps, not shuffles
    # The footprints move: stepping out, forward and back.
    ankles = p[:, [J["ankle_l"], J["ankle_r"]], :2]
    assert np.ptp(ankles[:, :, 0]) > 0.2 and np.ptp(ankles[:, 1, 1]) > 0.1


def test_every_gesture_plays_on_a_child_and_a_tall_body(clips):
    """Through the real-time pipeline: feet stay planted (< 1 mm per frame), no ground
    penetration, bones exact."""
    sim = Simulation({name: motion for name, (motion, _) in clips.items()})
    for i, name in enumerate(GESTURES):
        for k, preset in enumerate(("child", "tall")):
            sim.spawn(f"{name}_{preset}", Morphology.preset(preset), MotionPlayer(name),
                      Placement((2.0 * i, 2.0 * k)))
    metrics = MetricsRecorder(sim)
    for _ in range(int(8.0 * FPS)):
        sim.step()
        metrics.record()
    report = metrics.report()
    assert not report["messages"]
    for c in report["characters"]:
        assert c["foot_sliding_mm_per_frame"]["max"] < 1.0, c
        assert c["ground_penetration_mm_max"] < 1.0, c
        assert c["bone_length_error_m_max"] < 1e-6, c
        assert not c["frozen"], c
    dancers = {c["name"]: c for c in report["characters"] if c["name"].startswith("dance")}
    child = dancers["dance_child"]
    assert child["stride_m_median"] is not None and child["stride_per_leg_length"] > 0.1
    assert Morphology.preset("child").stature == pytest.approx(1.20, abs=0.01)


def test_fight_sequence_queues_and_crossfades_without_a_jump(clips):
    """guard -> kick -> dodge -> guard and guard -> ward_off_punch -> guard, as the fight scene
    will queue them, on two different bodies facing each other."""
    sim = Simulation({name: motion for name, (motion, _) in clips.items()})
    sim.spawn("kicker", Morphology.preset("adult_female"), MotionPlayer(
        "guard", loop=False, queue=(QueuedClip("kick", 0.2), QueuedClip("dodge", 0.2),
                                    QueuedClip("guard", 0.3, loop=True))))
    sim.spawn("defender", Morphology.preset("tall"), MotionPlayer(
        "guard", loop=False, queue=(QueuedClip("ward_off_punch", 0.2),
                                    QueuedClip("guard", 0.3, loop=True))), Placement((1.3, 0.0), np.pi))
    metrics = MetricsRecorder(sim)
    positions = []
    for _ in range(int(7.0 * FPS)):
        sim.step()
        metrics.record()
        positions.append(sim.store.positions.copy())
    p = np.array(positions)
    speed = np.linalg.norm(np.diff(p, axis=0), axis=-1) * FPS  # (ticks, characters, joints)
    assert speed.max() < 12.0
    pelvis_speed = speed[:, :, J["pelvis"]]
    assert pelvis_speed.max() < 2.0  # no teleport at any switch
    assert speed[-30:].max() < 1.0  # back in a calm guard at the end
    assert sim.store.clip.tolist() == [sim.bank.index("guard")] * 2
    for c in metrics.report()["characters"]:
        assert c["foot_sliding_mm_per_frame"]["max"] < 1.0, c
        assert c["ground_penetration_mm_max"] < 1.0, c
