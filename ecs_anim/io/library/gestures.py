"""Authored gestures for the fight, table, grasp and dance scenes (keyframes, no captured data).

Each motion is a small table of keyframes per body channel, in morphology-free units; a channel
a motion does not key keeps its stance value. Channels, all in the character's own axes
(``x`` forward, ``y`` left, ``z`` up; every motion faces +x like the walk):

* ``pelvis`` (x, y, dz): leg lengths (thigh + shank); ``dz`` from the straight-legged height.
* ``pelvis_rot`` (yaw, pitch, roll) degrees; pitch > 0 tips the pelvis forward.
* ``ankle_l`` / ``ankle_r`` (x, y, z): leg lengths, ``z`` above the ankle's height when standing.
  A foot whose ankle key stays at z = 0 stands still (equal keys hold exactly).
* ``foot_l`` / ``foot_r`` (pitch, yaw) degrees; pitch 0 is a flat foot, > 0 points the toes down.
* ``trunk`` (lean, side, twist) degrees: thorax relative to pelvis; lean > 0 forward, side > 0
  to the character's left, twist > 0 turns the chest to the left.
* ``head`` (pitch, yaw) degrees relative to the thorax; pitch > 0 nods down.
* ``wrist_l`` / ``wrist_r`` (forward, out, up): the wrist from its shoulder in the thorax frame
  (or, for a gesture with ``arms_in="heading"``, in the upright frame turned with the pelvis'
  heading), in arm lengths (upper arm + forearm); ``out`` > 0 away from the body's midline.
* ``elbow_l`` / ``elbow_r`` (forward, out, up): the side the elbow bends to, same frame.
* ``hand_l`` / ``hand_r`` (w,): 0 continues the forearm, 1 points the hand along the chest's
  forward axis (a fist in guard).

Keys are interpolated by monotone cubic Hermite splines (C1; zero velocity at the ends of a
one-shot clip, at every hold and at every turning point, so nothing overshoots), sampled at 30 fps
on the adult reference body, assembled with the walk's helpers (knees and elbows by the
two-sphere construction, the pelvis lowered where a standing leg could not reach: the paper's
min rule), then encoded and written like every authored motion by ``python -m ecs_anim.io.library.authoring``.
Foot contacts are not stored in the BVH: the importer detects them (the feet are exactly still
while planted).

All fight clips start and end in the same guard pose (orthodox: left foot forward, fists up, the
pelvis turned 25 degrees to the right), reach in the neutral stance, so they queue and cross-fade;
guard, talk and dance loop seamlessly. Timings (also in :data:`GESTURE_TIMINGS`, for timing
constraint activations); distances in leg lengths (L, thigh + shank) or arm lengths (A, upper
arm + forearm) scale with the body; metres are on the adult_male body (1.75 m, L = 0.846 m,
A = 0.571 m) that the files are written on:

* ``guard`` (2.4 s, loop): fighting stance, light bounce, fists circling a little; feet planted.
* ``kick`` (1.5 s): front kick with the rear (right) leg. Weight onto the left foot by 0.28 s;
  right foot off the ground at 0.30 s; knee chambered at 0.50 s; **ankle at its peak at
  0.70 s**, 0.96 L (0.81 m) in front of the pelvis and 0.16 L (0.13 m) above the right hip
  (ankle 1.00 m above the ground), leg nearly straight, trunk leaning back 20 degrees, hips
  thrust forward: the ankle is 1.18 L (1.00 m) and the ball of the foot 1.13 m in front of the
  pelvis' starting place; re-chambered at 0.90 s; lands back on its own footprint at 1.20 s;
  guard at 1.5 s. The left foot stays planted. Kicking ankle up to 7.3 m/s.
* ``ward_off_punch`` (2.0 s): the left forearm rises across the chest (0.30 s), then sweeps down
  and out: **ward-off window 0.50-0.75 s**, forearm middle lowest at 0.60 s, 0.28 m in front of
  the pelvis at 1.0 m height; back to guard with the right fist cocked at 1.0 s; the lead (left)
  foot slides in 0.25 L (0.95-1.15 s) for a **right straight punch: wrist at its peak at
  1.20 s** (held to 1.30 s), 0.96 A from the shoulder, at the body's own head height (1.41 m),
  0.58 m in front of the pelvis (0.23 m in guard); the wrist is 0.71 m and the knuckles 0.83 m
  in front of the pelvis' starting place; chest turned left; the lead foot slides back
  (1.45-1.65 s), guard at 1.8 s. The rear foot stays planted.
* In a pair of adult_male bodies facing each other 1.2 m apart (pelvis to pelvis), ``kick`` and
  ``ward_off_punch`` started together, unconstrained: at the kick's peak the ball of the foot is
  0.12 m from the defender's lower spine (at its height, 1.0 m); the kicking ankle passes
  0.28 m from the middle of the warding forearm (at 0.67 s); at the punch's peak the knuckles are
  0.31 m from the kicker's head (0.40 m at 1.3 m apart): the constraints close these gaps.
* ``dodge`` (1.5 s): lean back from 0.15 s, **deepest 0.55-0.80 s** (head 0.33 m behind its
  guard position, trunk 24 degrees back of guard, weight on the rear foot), back in guard at
  1.30 s. Feet planted.
* ``talk`` (7.2 s, loop): standing, hands gesturing between waist and chest (wrists 0.97-1.25 m),
  both spread at 2.3 s, **dipping onto the thighs 3.6-4.4 s** (wrists down to 0.82 m, trunk
  leaning 16 degrees), the right hand pointing forward at 5.0 s; head turns to listeners on both
  sides. Feet planted.
* ``reach`` (3.0 s): far forward and downward reach with the right hand: starts at 0.30 s,
  **wrist furthest at 1.30 s, held (the grasp) until 1.90 s**: 0.52 L in front of the toes, at
  0.75 L (0.64 m) above the ground, trunk bent about 80 degrees, hips back 0.25 L; back to
  standing at 2.80 s. Feet planted.
* ``dance`` (8.0 s, loop, 120 beats per minute): "out, out, in, in" then "forward, forward,
  back, back", twice: one step on every beat (0.5 s, right foot first), the feet alternate, each
  foot 0.3 s in the air with 0.12 L of lift; the pelvis moves over the supporting foot and dips
  after each landing; arms swing out and pump up.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray

from ecs_anim.core.morphology import Morphology
from ecs_anim.core.normalized import limb_frames, two_bone_middle
from ecs_anim.core.rotations import normalize, rot_axis
from ecs_anim.core.skeleton import JOINT_INDEX as J
from ecs_anim.core.skeleton import N_JOINTS
from ecs_anim.io.library.authoring import FPS, lower_pelvis_to_reach, place_legs

F64 = NDArray[np.float64]
Key = tuple[float, Sequence[float]]

# --------------------------------------------------------------------------------------------
# Interpolation


def _hermite_tangents(times: F64, values: F64, loop: bool) -> F64:
    """Monotone (Fritsch-Carlson) tangents at keys: Catmull-Rom, zero at turning points and
    holds, limited so no span overshoots. Zero at the ends unless ``loop``. (K, D) -> (K, D)."""
    k = len(times)
    if loop:
        period = times[-1] - times[0]
        t_ext = np.concatenate([[times[-2] - period], times, [times[1] + period]])
        v_ext = np.concatenate([values[-2:-1], values, values[1:2]])
    else:
        t_ext = np.concatenate([[times[0] - 1.0], times, [times[-1] + 1.0]])
        v_ext = np.concatenate([values[:1], values, values[-1:]])
    secant = np.diff(v_ext, axis=0) / np.diff(t_ext)[:, None]  # (K+1, D)
    before, after = secant[:-1], secant[1:]
    catmull = (v_ext[2:] - v_ext[:-2]) / (t_ext[2:] - t_ext[:-2])[:, None]
    same_sign = before * after > 0
    limit = 3.0 * np.minimum(np.abs(before), np.abs(after))
    tangent = np.where(same_sign, np.clip(catmull, -limit, limit), 0.0)
    if not loop:
        tangent[0] = tangent[k - 1] = 0.0
    return tangent


def sample_keys(keys: Sequence[Key], t: F64, loop: bool = False) -> F64:
    """A keyed channel at times ``t`` (F,): C1 monotone cubic Hermite through the keys.

    ``keys``: (time s, value tuple) with strictly increasing times; outside them the end values
    hold. With ``loop`` the first and last keys must be equal and the tangents wrap. -> (F, D).
    """
    times = np.array([k[0] for k in keys], dtype=np.float64)
    values = np.array([k[1] for k in keys], dtype=np.float64).reshape(len(keys), -1)
    if len(keys) == 1:
        return np.broadcast_to(values[0], (len(t), values.shape[1])).copy()
    if np.any(np.diff(times) <= 0):
        raise ValueError(f"key times must increase: {times.tolist()}")
    if loop and not np.allclose(values[0], values[-1]):
        raise ValueError("a looping channel must end on its first value")
    tangent = _hermite_tangents(times, values, loop)
    tc = np.clip(t, times[0], times[-1])
    span = np.clip(np.searchsorted(times, tc, side="right") - 1, 0, len(times) - 2)
    h = (times[span + 1] - times[span])[:, None]
    u = ((tc - times[span])[:, None]) / h
    h00, h10 = 2 * u**3 - 3 * u**2 + 1, u**3 - 2 * u**2 + u
    h01, h11 = -2 * u**3 + 3 * u**2, u**3 - u**2
    return (h00 * values[span] + h10 * h * tangent[span]
            + h01 * values[span + 1] + h11 * h * tangent[span + 1])


def steps(start: Sequence[float], moves: Sequence[tuple[float, float, Sequence[float]]],
          lift: float = 0.12) -> list[Key]:
    """Ankle keys for a foot that steps: ``moves`` are (lift-off s, landing s, new (x, y)).

    The foot holds still on the ground between steps and swings on a raised arc (``lift`` leg
    lengths at mid-swing, 85 % of it already at 30 % of the swing: a clear lift-off, so contact
    detection lets go quickly). Returns keys for an ``ankle_*`` channel.
    """
    x, y = start[0], start[1]
    keys: list[Key] = [(0.0, (x, y, 0.0))]
    for t0, t1, (nx, ny) in moves:
        if t0 > keys[-1][0]:
            keys.append((t0, (x, y, 0.0)))
        for u, height in ((0.3, 0.85), (0.5, 1.0), (0.7, 0.85)):
            keys.append((t0 + u * (t1 - t0), (x + u * (nx - x), y + u * (ny - y), height * lift)))
        x, y = nx, ny
        keys.append((t1, (x, y, 0.0)))
    return keys


# --------------------------------------------------------------------------------------------
# Stances and the body builder


NEUTRAL: dict[str, tuple[float, ...]] = {
    "pelvis": (0.0, 0.0, -0.025), "pelvis_rot": (0.0, 0.0, 0.0),
    "ankle_l": (0.0, 0.12, 0.0), "ankle_r": (0.0, -0.12, 0.0),
    "foot_l": (0.0, 8.0), "foot_r": (0.0, -8.0),
    "trunk": (3.0, 0.0, 0.0), "head": (0.0, 0.0),
    "wrist_l": (0.10, 0.06, -0.92), "wrist_r": (0.10, 0.06, -0.92),
    "elbow_l": (-1.0, 0.3, 0.0), "elbow_r": (-1.0, 0.3, 0.0),
    "hand_l": (0.0,), "hand_r": (0.0,),
}

GUARD: dict[str, tuple[float, ...]] = {
    "pelvis": (0.0, -0.01, -0.07), "pelvis_rot": (-25.0, 0.0, 0.0),
    "ankle_l": (0.24, 0.11, 0.0), "ankle_r": (-0.22, -0.15, 0.0),
    "foot_l": (0.0, -5.0), "foot_r": (0.0, -40.0),
    "trunk": (8.0, 0.0, -5.0), "head": (10.0, 28.0),
    "wrist_l": (0.55, -0.15, 0.22), "wrist_r": (0.42, -0.30, 0.28),
    "elbow_l": (0.0, 0.35, -1.0), "elbow_r": (0.0, 0.35, -1.0),
    "hand_l": (0.7,), "hand_r": (0.7,),
}

#: Knees bend towards the front and a little up (so a leg raised forward still has a knee side).
KNEE_HINT_IN_PELVIS = normalize(np.array([1.0, 0.0, 0.6]))


@dataclass(frozen=True)
class Gesture:
    """A keyframed motion: ``tracks`` override the ``stance`` channels (see module docstring)."""

    duration_s: float
    stance: dict[str, tuple[float, ...]]
    tracks: dict[str, list[Key]] = field(default_factory=dict)
    loop: bool = False
    arms_in: str = "thorax"  # or "heading": wrist and elbow keys in the upright heading frame

    def n_frames(self) -> int:
        n = round(self.duration_s * FPS)
        return n if self.loop else n + 1  # one-shots end exactly on their last key

    def channels(self, t: F64) -> dict[str, F64]:
        unknown = set(self.tracks) - set(self.stance)
        if unknown:
            raise KeyError(f"unknown channels {sorted(unknown)}; "
                           f"channels are {sorted(self.stance)}")
        return {name: sample_keys(self.tracks.get(name, [(0.0, value)]), t, self.loop)
                for name, value in self.stance.items()}


def _deg(x: F64) -> F64:
    return np.radians(x)


def gesture_positions(gesture: Gesture, morph: Morphology) -> F64:
    """Joint positions (frames, N_JOINTS, 3), metres, Z up, of a gesture on ``morph``."""
    m = morph
    n = gesture.n_frames()
    t = np.arange(n) / FPS
    c = gesture.channels(t)
    leg = m.leg_length
    arm = 0.5 * (m["upper_arm_l"] + m["forearm_l"] + m["upper_arm_r"] + m["forearm_r"])
    ah = 0.5 * (m["ankle_height_l"] + m["ankle_height_r"])
    foot = 0.5 * (m["foot_l"] + m["foot_r"])
    hip_drop = 0.25 * (m["pelvis_l"] + m["pelvis_r"])  # REST_HIP_DIR_LEFT: hips 30 deg below
    ball_height = 0.025 * leg / 0.86
    flat_pitch = np.arcsin(np.clip((ah - ball_height) / foot, -1, 1))

    pelvis = c["pelvis"] * leg
    pelvis[:, 2] += ah + leg + hip_drop
    yaw, pitch, roll = _deg(c["pelvis_rot"]).T
    pelvis2world = rot_axis(2, yaw) @ rot_axis(1, pitch) @ rot_axis(0, roll)

    ankles = np.stack([c["ankle_l"], c["ankle_r"]], axis=1) * leg
    ankles[..., 2] += ah
    foot_pitch = flat_pitch + _deg(np.stack([c["foot_l"][:, 0], c["foot_r"][:, 0]], axis=1))
    foot_yaw = _deg(np.stack([c["foot_l"][:, 1], c["foot_r"][:, 1]], axis=1))
    toes = ankles + foot * np.stack([np.cos(foot_pitch) * np.cos(foot_yaw),
                                     np.cos(foot_pitch) * np.sin(foot_yaw),
                                     -np.sin(foot_pitch)], axis=-1)
    # The paper's min rule, for standing feet only: a foot in the air never lowers the pelvis.
    standing = ankles[..., 2] < ah + 1e-9
    reach_targets = np.where(standing[..., None], ankles, pelvis[:, None, :])
    pelvis = lower_pelvis_to_reach(pelvis, pelvis2world, reach_targets, m)

    out = np.zeros((n, N_JOINTS, 3))
    place_legs(out, m, pelvis, pelvis2world, ankles, toes, pelvis2world @ KNEE_HINT_IN_PELVIS)

    # Trunk: the lean spread over the three spine segments (20 %, 40 %, 40 %), then the twist.
    lean, side, twist = _deg(c["trunk"]).T

    def bent(fraction: float) -> F64:
        return pelvis2world @ rot_axis(0, -fraction * side) @ rot_axis(1, fraction * lean)

    s1 = pelvis + bent(0.2)[:, :, 2] * m["spine_lower"]
    s2 = s1 + bent(0.6)[:, :, 2] * m["spine_middle"]
    thorax = bent(1.0) @ rot_axis(2, twist)
    neck = s2 + thorax[:, :, 2] * m["spine_upper"]
    out[:, J["spine_1"]], out[:, J["spine_2"]], out[:, J["neck"]] = s1, s2, neck
    head_pitch, head_yaw = _deg(c["head"]).T
    head_frame = thorax @ rot_axis(2, head_yaw) @ rot_axis(1, head_pitch)
    head = neck + head_frame[:, :, 2] * m["neck"]
    out[:, J["head"]] = head
    out[:, J["head_top"]] = head + (head_frame @ rot_axis(1, 0.5 * head_pitch))[:, :, 2] * m["head"]

    arm_frame = thorax if gesture.arms_in == "thorax" else rot_axis(2, yaw)
    for s, sign in (("l", 1.0), ("r", -1.0)):
        mirror = np.array([1.0, sign, 1.0])
        clav = normalize(np.array([-0.15, 0.97 * sign, -0.12]))
        shoulder = neck + (thorax @ clav) * m[f"clavicle_{s}"]
        wrist_target = shoulder + (arm_frame @ (c[f"wrist_{s}"] * mirror)[..., None])[..., 0] * arm
        hint = (arm_frame @ normalize(c[f"elbow_{s}"] * mirror)[..., None])[..., 0]
        upper, fore = m[f"upper_arm_{s}"], m[f"forearm_{s}"]
        frame = limb_frames(shoulder, shoulder + hint, wrist_target, hint)
        elbow, wrist = two_bone_middle(frame, shoulder, np.full(n, upper), np.full(n, fore),
                                       np.linalg.norm(wrist_target - shoulder, axis=-1))
        out[:, J[f"shoulder_{s}"]], out[:, J[f"elbow_{s}"]] = shoulder, elbow
        out[:, J[f"wrist_{s}"]] = wrist
        w = c[f"hand_{s}"]
        hand_dir = normalize((1.0 - w) * normalize(wrist - elbow) + w * thorax[:, :, 0])
        out[:, J[f"hand_{s}"]] = wrist + hand_dir * m[f"hand_{s}"]
    return out


# --------------------------------------------------------------------------------------------
# The motions: one table each


def _guard(name: str) -> tuple[float, ...]:
    return GUARD[name]


def _neutral(name: str) -> tuple[float, ...]:
    return NEUTRAL[name]


GUARD_LOOP = Gesture(2.4, GUARD, loop=True, tracks={
    "pelvis": [(0.0, (0.0, -0.01, -0.07)), (0.6, (0.01, 0.0, -0.085)), (1.2, (0.0, -0.02, -0.07)),
               (1.8, (-0.01, -0.01, -0.085)), (2.4, (0.0, -0.01, -0.07))],
    "pelvis_rot": [(0.0, (-25.0, 0.0, 0.0)), (1.2, (-21.0, 0.0, 1.0)), (2.4, (-25.0, 0.0, 0.0))],
    "trunk": [(0.0, (8.0, 0.0, -5.0)), (0.6, (10.0, 1.0, -3.0)), (1.2, (8.0, 0.0, -7.0)),
              (1.8, (10.0, -1.0, -5.0)), (2.4, (8.0, 0.0, -5.0))],
    "head": [(0.0, (10.0, 28.0)), (1.2, (12.0, 24.0)), (2.4, (10.0, 28.0))],
    "wrist_l": [(0.0, _guard("wrist_l")), (0.6, (0.58, -0.12, 0.18)), (1.2, (0.53, -0.17, 0.24)),
                (1.8, (0.57, -0.15, 0.27)), (2.4, _guard("wrist_l"))],
    "wrist_r": [(0.0, _guard("wrist_r")), (0.6, (0.40, -0.28, 0.25)), (1.2, (0.44, -0.31, 0.30)),
                (1.8, (0.41, -0.29, 0.31)), (2.4, _guard("wrist_r"))],
})

KICK = Gesture(1.5, GUARD, tracks={
    # Weight onto the front (left) foot, the rear (right) leg kicks forward and comes back.
    "pelvis": [(0.0, _guard("pelvis")), (0.28, (0.12, 0.06, -0.08)), (0.50, (0.18, 0.07, -0.07)),
               (0.70, (0.22, 0.06, -0.06)), (0.90, (0.17, 0.06, -0.07)),
               (1.20, (0.06, 0.03, -0.08)), (1.5, _guard("pelvis"))],
    "pelvis_rot": [(0.0, _guard("pelvis_rot")), (0.30, (-18.0, 0.0, 0.0)),
                   (0.50, (-8.0, -8.0, 0.0)),
                   (0.70, (-4.0, -16.0, 0.0)), (0.90, (-10.0, -8.0, 0.0)),
                   (1.20, (-20.0, 0.0, 0.0)), (1.5, _guard("pelvis_rot"))],
    "ankle_r": [(0.0, _guard("ankle_r")), (0.30, _guard("ankle_r")), (0.50, (0.10, -0.10, 0.42)),
                (0.70, (1.18, -0.06, 1.10)), (0.90, (0.14, -0.10, 0.44)),
                (1.20, _guard("ankle_r")), (1.5, _guard("ankle_r"))],
    "foot_r": [(0.0, _guard("foot_r")), (0.30, (10.0, -30.0)), (0.50, (40.0, -10.0)),
               (0.70, (-60.0, 0.0)), (0.90, (40.0, -10.0)), (1.15, (5.0, -35.0)),
               (1.20, _guard("foot_r")), (1.5, _guard("foot_r"))],
    "trunk": [(0.0, _guard("trunk")), (0.30, (4.0, 0.0, -3.0)), (0.50, (-8.0, 0.0, 0.0)),
              (0.70, (-20.0, 0.0, 5.0)), (0.90, (-6.0, 0.0, 0.0)), (1.20, (6.0, 0.0, -5.0)),
              (1.5, _guard("trunk"))],
    "head": [(0.0, _guard("head")), (0.50, (18.0, 10.0)), (0.70, (30.0, 4.0)), (0.90, (18.0, 12.0)),
             (1.20, (10.0, 24.0)), (1.5, _guard("head"))],
    "wrist_l": [(0.0, _guard("wrist_l")), (0.50, (0.50, -0.05, 0.15)), (0.70, (0.45, 0.05, 0.10)),
                (1.0, (0.52, -0.10, 0.18)), (1.5, _guard("wrist_l"))],
    "wrist_r": [(0.0, _guard("wrist_r")), (0.50, (0.30, -0.05, -0.10)), (0.70, (0.05, 0.15, -0.45)),
                (1.0, (0.30, -0.10, 0.05)), (1.5, _guard("wrist_r"))],
})

_LEAD = GUARD["ankle_l"]
WARD_OFF_PUNCH = Gesture(2.0, GUARD, tracks={
    "pelvis": [(0.0, _guard("pelvis")), (0.30, (0.0, 0.0, -0.09)), (0.60, (0.02, 0.0, -0.11)),
               (0.75, (0.02, 0.0, -0.11)), (1.0, (-0.01, -0.02, -0.08)),
               (1.20, (0.15, 0.01, -0.10)), (1.30, (0.15, 0.01, -0.10)),
               (1.70, (0.0, -0.01, -0.075)), (1.8, _guard("pelvis")), (2.0, _guard("pelvis"))],
    # The lead foot slides in for the punch and back out.
    "ankle_l": steps(_LEAD[:2], [(0.95, 1.15, (_LEAD[0] + 0.25, _LEAD[1])),
                                 (1.45, 1.65, _LEAD[:2])], lift=0.05) + [(2.0, _LEAD)],
    "pelvis_rot": [(0.0, _guard("pelvis_rot")), (0.30, (-32.0, 0.0, 0.0)),
                   (0.60, (-20.0, 5.0, 0.0)),
                   (0.75, (-20.0, 5.0, 0.0)), (1.0, (-30.0, 0.0, 0.0)),
                   (1.20, (-5.0, 0.0, 0.0)), (1.30, (-5.0, 0.0, 0.0)), (1.8, _guard("pelvis_rot")),
                   (2.0, _guard("pelvis_rot"))],
    "trunk": [(0.0, _guard("trunk")), (0.30, (10.0, 0.0, -15.0)), (0.60, (18.0, -4.0, 8.0)),
              (0.75, (18.0, -4.0, 8.0)), (1.0, (8.0, 0.0, -12.0)), (1.20, (14.0, 0.0, 25.0)),
              (1.30, (14.0, 0.0, 24.0)), (1.8, _guard("trunk")), (2.0, _guard("trunk"))],
    "head": [(0.0, _guard("head")), (0.30, (18.0, 40.0)), (0.60, (25.0, 22.0)),
             (0.75, (25.0, 22.0)),
             (1.0, (10.0, 38.0)), (1.20, (6.0, 2.0)), (1.30, (6.0, 3.0)), (1.8, _guard("head")),
             (2.0, _guard("head"))],
    # Ward-off: the left forearm rises across the chest, then sweeps down and out.
    "wrist_l": [(0.0, _guard("wrist_l")), (0.30, (0.40, -0.45, 0.15)), (0.60, (0.62, 0.40, -0.55)),
                (0.75, (0.60, 0.42, -0.50)), (1.0, (0.50, -0.10, 0.15)),
                (1.20, (0.40, -0.10, 0.20)),
                (1.8, _guard("wrist_l")), (2.0, _guard("wrist_l"))],
    "elbow_l": [(0.0, _guard("elbow_l")), (0.30, (0.0, 0.6, -0.8)), (0.60, (0.2, 0.4, -1.0)),
                (1.0, _guard("elbow_l")), (2.0, _guard("elbow_l"))],
    # Punch: the right fist cocks at the chin, then drives straight at head height.
    "wrist_r": [(0.0, _guard("wrist_r")), (0.60, (0.38, -0.30, 0.26)), (1.0, (0.35, -0.32, 0.30)),
                (1.20, (0.88, -0.14, 0.35)), (1.30, (0.86, -0.14, 0.34)),
                (1.8, _guard("wrist_r")), (2.0, _guard("wrist_r"))],
    "elbow_r": [(0.0, _guard("elbow_r")), (1.0, _guard("elbow_r")), (1.20, (0.0, 0.9, -0.45)),
                (1.30, (0.0, 0.9, -0.45)), (1.8, _guard("elbow_r")), (2.0, _guard("elbow_r"))],
})

DODGE = Gesture(1.5, GUARD, tracks={
    "pelvis": [(0.0, _guard("pelvis")), (0.15, _guard("pelvis")), (0.55, (-0.10, -0.04, -0.10)),
               (0.80, (-0.11, -0.04, -0.10)), (1.30, _guard("pelvis")), (1.5, _guard("pelvis"))],
    "pelvis_rot": [(0.0, _guard("pelvis_rot")), (0.15, _guard("pelvis_rot")),
                   (0.55, (-30.0, -7.0, 0.0)),
                   (0.80, (-30.0, -8.0, 0.0)), (1.30, _guard("pelvis_rot")),
                   (1.5, _guard("pelvis_rot"))],
    "trunk": [(0.0, _guard("trunk")), (0.15, _guard("trunk")), (0.55, (-14.0, -4.0, -5.0)),
              (0.80, (-16.0, -4.0, -5.0)), (1.30, _guard("trunk")), (1.5, _guard("trunk"))],
    "head": [(0.0, _guard("head")), (0.15, _guard("head")), (0.55, (-5.0, 32.0)),
             (0.80, (-8.0, 32.0)),
             (1.30, _guard("head")), (1.5, _guard("head"))],
    "wrist_l": [(0.0, _guard("wrist_l")), (0.55, (0.45, -0.10, 0.32)), (0.80, (0.45, -0.10, 0.32)),
                (1.30, _guard("wrist_l")), (1.5, _guard("wrist_l"))],
    "wrist_r": [(0.0, _guard("wrist_r")), (0.55, (0.30, -0.22, 0.38)), (0.80, (0.30, -0.22, 0.38)),
                (1.30, _guard("wrist_r")), (1.5, _guard("wrist_r"))],
})

_WAIST = (0.42, -0.02, -0.62)
_CHEST = (0.55, 0.04, -0.32)
_WIDE = (0.50, 0.38, -0.42)
_LOW = (0.28, 0.06, -0.90)

TALK = Gesture(7.2, NEUTRAL, loop=True, tracks={
    "pelvis": [(0.0, (0.0, 0.0, -0.025)), (1.8, (0.005, 0.03, -0.025)), (3.0, (0.0, 0.01, -0.03)),
               (3.6, (-0.04, 0.0, -0.07)), (4.4, (-0.04, 0.0, -0.07)), (5.0, (0.0, -0.02, -0.03)),
               (5.4, (0.005, -0.03, -0.025)), (7.2, (0.0, 0.0, -0.025))],
    "pelvis_rot": [(0.0, (0.0, 0.0, 0.0)), (1.8, (4.0, 0.0, -2.0)), (3.6, (0.0, 0.0, 0.0)),
                   (5.4, (-4.0, 0.0, 2.0)), (7.2, (0.0, 0.0, 0.0))],
    "trunk": [(0.0, (3.0, 0.0, 0.0)), (0.8, (6.0, 0.0, -6.0)), (2.3, (2.0, 0.0, 4.0)),
              (3.0, (4.0, 0.0, 2.0)), (3.6, (16.0, 0.0, 0.0)), (4.4, (16.0, 0.0, 0.0)),
              (5.0, (8.0, 0.0, -10.0)), (6.2, (3.0, 0.0, 5.0)),
              (7.2, (3.0, 0.0, 0.0))],
    "head": [(0.0, (0.0, 0.0)), (0.8, (8.0, -20.0)), (1.2, (2.0, -18.0)), (1.6, (8.0, -15.0)),
             (2.3, (-3.0, 5.0)), (3.0, (4.0, 25.0)), (3.6, (10.0, 20.0)), (4.4, (6.0, 15.0)),
             (5.0, (0.0, -10.0)), (5.6, (6.0, 0.0)), (6.4, (2.0, 10.0)), (7.2, (0.0, 0.0))],
    "wrist_r": [(0.0, _WAIST), (0.8, _CHEST), (1.2, (0.48, 0.02, -0.50)), (1.6, _CHEST),
                (2.3, _WIDE), (3.0, _WAIST), (3.6, _LOW), (4.4, _LOW),
                (5.0, (0.80, 0.0, -0.15)), (5.6, _CHEST), (6.4, (0.45, 0.08, -0.55)),
                (7.2, _WAIST)],
    "wrist_l": [(0.0, _WAIST), (0.8, (0.40, 0.0, -0.66)), (1.4, (0.50, 0.05, -0.40)),
                (2.3, _WIDE), (3.0, _WAIST), (3.6, _LOW), (4.4, _LOW),
                (5.0, (0.40, 0.05, -0.62)), (5.6, _CHEST), (6.4, (0.40, 0.05, -0.60)),
                (7.2, _WAIST)],
    "elbow_l": [(0.0, (-0.6, 1.0, -0.4))], "elbow_r": [(0.0, (-0.6, 1.0, -0.4))],
})

REACH = Gesture(3.0, NEUTRAL, arms_in="heading", tracks={
    "pelvis": [(0.0, _neutral("pelvis")), (0.3, _neutral("pelvis")), (1.3, (-0.25, 0.01, -0.16)),
               (1.9, (-0.25, 0.01, -0.16)), (2.8, _neutral("pelvis")), (3.0, _neutral("pelvis"))],
    "pelvis_rot": [(0.0, _neutral("pelvis_rot")), (0.3, _neutral("pelvis_rot")),
                   (1.3, (8.0, 40.0, 0.0)),
                   (1.9, (8.0, 40.0, 0.0)), (2.8, _neutral("pelvis_rot")),
                   (3.0, _neutral("pelvis_rot"))],
    "trunk": [(0.0, _neutral("trunk")), (0.3, _neutral("trunk")), (1.3, (42.0, -4.0, 12.0)),
              (1.9, (42.0, -4.0, 12.0)), (2.8, _neutral("trunk")), (3.0, _neutral("trunk"))],
    "head": [(0.0, _neutral("head")), (0.3, (5.0, 0.0)), (1.3, (-30.0, 0.0)), (1.9, (-30.0, 0.0)),
             (2.8, _neutral("head")), (3.0, _neutral("head"))],
    # Wrists in the upright frame: the right one forward and down, the left one hangs back.
    "wrist_r": [(0.0, _neutral("wrist_r")), (0.3, _neutral("wrist_r")), (0.8, (0.55, 0.0, -0.70)),
                (1.3, (0.74, -0.05, -0.64)), (1.9, (0.74, -0.05, -0.64)), (2.4, (0.45, 0.0, -0.80)),
                (2.8, _neutral("wrist_r")), (3.0, _neutral("wrist_r"))],
    "wrist_l": [(0.0, _neutral("wrist_l")), (0.3, _neutral("wrist_l")), (1.3, (-0.10, 0.15, -0.90)),
                (1.9, (-0.10, 0.15, -0.90)), (2.8, _neutral("wrist_l")),
                (3.0, _neutral("wrist_l"))],
    "elbow_r": [(0.0, _neutral("elbow_r")), (0.8, (-0.5, 0.6, 0.0)), (1.3, (0.0, 0.6, 1.0)),
                (1.9, (0.0, 0.6, 1.0)), (2.4, (-0.5, 0.6, 0.0)), (2.8, _neutral("elbow_r"))],
})


Move = tuple[float, float, tuple[float, float]]


def _dance_steps() -> tuple[list[Move], list[Move]]:
    """"Out, out, in, in" then "forward, forward, back, back", twice: the feet alternate, one
    step on every beat (0.5 s), each foot 0.3 s in the air. Returns the left and right moves."""
    y_l, y_r, side, fwd, swing = 0.12, -0.12, 0.16, 0.28, 0.3
    left: list[Move] = []
    right: list[Move] = []
    for t0 in (0.0, 4.0):
        right.append((t0 + 0.0, t0 + swing, (0.0, y_r - side)))       # out
        left.append((t0 + 0.5, t0 + 0.5 + swing, (0.0, y_l + side)))  # out
        right.append((t0 + 1.0, t0 + 1.0 + swing, (0.0, y_r)))        # in
        left.append((t0 + 1.5, t0 + 1.5 + swing, (0.0, y_l)))         # in
        right.append((t0 + 2.0, t0 + 2.0 + swing, (fwd, y_r)))        # forward
        left.append((t0 + 2.5, t0 + 2.5 + swing, (fwd, y_l)))         # forward
        right.append((t0 + 3.0, t0 + 3.0 + swing, (0.0, y_r)))        # back
        left.append((t0 + 3.5, t0 + 3.5 + swing, (0.0, y_l)))         # back
    return left, right


def _pelvis_over_support(left: list[Move], right: list[Move], start: tuple[float, float],
                         period: float) -> list[Key]:
    """Pelvis keys for stepping: over the supporting foot (70 %) at each lift-off, between the
    feet at each landing (+0.08 s, dipping: the bounce); loops back to its first key
    (``start``: the feet's y at t = 0, leg lengths)."""
    events = sorted([(m, 0) for m in left] + [(m, 1) for m in right])
    feet = [np.array([0.0, start[0]]), np.array([0.0, start[1]])]
    keys: list[Key] = []
    for (t0, t1, (nx, ny)), side in events:
        support = feet[1 - side]
        over = 0.7 * support + 0.3 * feet[side]
        keys.append((t0, (over[0], over[1], -0.045)))
        feet[side] = np.array([nx, ny])
        mid = 0.5 * (feet[0] + feet[1])
        keys.append((t1 + 0.08, (mid[0], mid[1], -0.09)))
    if keys[0][0] > 0.0:
        keys.insert(0, (0.0, keys[-1][1]))
    keys.append((period, keys[0][1]))
    return keys


_DANCE_LEFT, _DANCE_RIGHT = _dance_steps()

DANCE = Gesture(8.0, NEUTRAL, loop=True, tracks={
    "ankle_l": steps((0.0, 0.12), _DANCE_LEFT) + [(8.0, (0.0, 0.12, 0.0))],
    "ankle_r": steps((0.0, -0.12), _DANCE_RIGHT) + [(8.0, (0.0, -0.12, 0.0))],
    "pelvis": _pelvis_over_support(_DANCE_LEFT, _DANCE_RIGHT, (0.12, -0.12), 8.0),
    "pelvis_rot": [(0.0, (0.0, 0.0, 0.0)), (0.5, (-8.0, 0.0, -4.0)), (1.5, (8.0, 0.0, 4.0)),
                   (2.5, (-10.0, 4.0, 0.0)), (3.5, (10.0, -2.0, 0.0)), (4.0, (0.0, 0.0, 0.0)),
                   (4.5, (-8.0, 0.0, -4.0)), (5.5, (8.0, 0.0, 4.0)), (6.5, (-10.0, 4.0, 0.0)),
                   (7.5, (10.0, -2.0, 0.0)), (8.0, (0.0, 0.0, 0.0))],
    "trunk": [(0.0, (3.0, 0.0, 0.0)), (0.5, (5.0, 6.0, 8.0)), (1.5, (5.0, -6.0, -8.0)),
              (2.5, (8.0, 0.0, 10.0)), (3.5, (0.0, 0.0, -10.0)), (4.0, (3.0, 0.0, 0.0)),
              (4.5, (5.0, 6.0, 8.0)), (5.5, (5.0, -6.0, -8.0)), (6.5, (8.0, 0.0, 10.0)),
              (7.5, (0.0, 0.0, -10.0)), (8.0, (3.0, 0.0, 0.0))],
    "head": [(0.0, (0.0, 0.0)), (1.0, (-5.0, -10.0)), (2.0, (5.0, 10.0)), (3.0, (-5.0, 0.0)),
             (4.0, (0.0, 0.0)), (5.0, (-5.0, -10.0)), (6.0, (5.0, 10.0)), (7.0, (-5.0, 0.0)),
             (8.0, (0.0, 0.0))],
    # Arms: swing out to the stepping side, then pump up and down on the forward figure.
    "wrist_r": [(0.0, (0.30, 0.10, -0.70)), (0.5, (0.35, 0.55, -0.35)), (1.0, (0.45, -0.10, -0.40)),
                (1.5, (0.30, 0.10, -0.75)), (2.0, (0.40, 0.05, -0.45)), (2.5, (0.45, 0.25, 0.45)),
                (3.0, (0.40, 0.05, -0.45)), (3.5, (0.45, 0.25, 0.45)), (4.0, (0.30, 0.10, -0.70)),
                (4.5, (0.35, 0.55, -0.35)), (5.0, (0.45, -0.10, -0.40)), (5.5, (0.30, 0.10, -0.75)),
                (6.0, (0.40, 0.05, -0.45)), (6.5, (0.45, 0.25, 0.45)), (7.0, (0.40, 0.05, -0.45)),
                (7.5, (0.45, 0.25, 0.45)), (8.0, (0.30, 0.10, -0.70))],
    "wrist_l": [(0.0, (0.30, 0.10, -0.70)), (0.5, (0.45, -0.10, -0.40)), (1.0, (0.35, 0.55, -0.35)),
                (1.5, (0.45, -0.10, -0.40)), (2.0, (0.45, 0.25, 0.45)), (2.5, (0.40, 0.05, -0.45)),
                (3.0, (0.45, 0.25, 0.45)), (3.5, (0.40, 0.05, -0.45)), (4.0, (0.30, 0.10, -0.70)),
                (4.5, (0.45, -0.10, -0.40)), (5.0, (0.35, 0.55, -0.35)),
                (5.5, (0.45, -0.10, -0.40)), (6.0, (0.45, 0.25, 0.45)), (6.5, (0.40, 0.05, -0.45)),
                (7.0, (0.45, 0.25, 0.45)), (7.5, (0.40, 0.05, -0.45)), (8.0, (0.30, 0.10, -0.70))],
    "elbow_l": [(0.0, (-0.5, 1.0, -0.5))], "elbow_r": [(0.0, (-0.5, 1.0, -0.5))],
})

#: Every authored gesture, in the order the scenes need them.
GESTURES: dict[str, Gesture] = {
    "guard": GUARD_LOOP, "kick": KICK, "ward_off_punch": WARD_OFF_PUNCH, "dodge": DODGE,
    "talk": TALK, "reach": REACH, "dance": DANCE,
}


def _generator(gesture: Gesture) -> Callable[[Morphology], F64]:
    def generate(morph: Morphology) -> F64:
        return gesture_positions(gesture, morph)
    return generate


#: Generators in the form ``ecs_anim.io.library.authoring`` writes and checks: name -> f(morph) -> positions.
GESTURE_GENERATORS = {name: _generator(g) for name, g in GESTURES.items()}


#: Key times of each gesture (seconds from the clip's start), for timing constraint activations;
#: distances as in the module docstring. ``tests/io/library/test_gestures.py`` checks them on the files.
GESTURE_TIMINGS: dict[str, dict[str, Any]] = {
    "guard": {"duration_s": 2.4, "loop": True},
    "kick": {"duration_s": 1.5, "loop": False, "kicking_ankle": "ankle_r",
             "weight_shifted_s": 0.28, "lift_off_s": 0.30, "chamber_s": 0.50, "peak_s": 0.70,
             "rechamber_s": 0.90, "land_s": 1.20,
             "peak_ankle_in_front_of_pelvis_L": 0.96, "peak_ankle_above_hip_L": 0.16,
             "peak_ankle_in_front_of_start_L": 1.18},
    "ward_off_punch": {"duration_s": 2.0, "loop": False, "ward_off_forearm": "l",
                       "ward_off_start_s": 0.50, "ward_off_lowest_s": 0.60,
                       "ward_off_end_s": 0.75, "cocked_s": 1.0, "punching_wrist": "wrist_r",
                       "step_in_s": (0.95, 1.15), "punch_peak_s": 1.20, "punch_hold_end_s": 1.30,
                       "step_back_s": (1.45, 1.65), "guard_again_s": 1.80,
                       "punch_reach_A": 0.96},
    "dodge": {"duration_s": 1.5, "loop": False, "lean_start_s": 0.15, "deepest_s": 0.55,
              "deepest_end_s": 0.80, "guard_again_s": 1.30, "head_back_m_adult": 0.33},
    "talk": {"duration_s": 7.2, "loop": True, "spread_s": 2.3, "hands_low_s": (3.6, 4.4),
             "point_s": 5.0},
    "reach": {"duration_s": 3.0, "loop": False, "reaching_wrist": "wrist_r", "start_s": 0.30,
              "peak_s": 1.30, "hold_end_s": 1.90, "back_s": 2.80,
              "wrist_in_front_of_toes_L": 0.52, "wrist_height_L": 0.75},
    "dance": {"duration_s": 8.0, "loop": True, "beat_s": 0.5, "steps": 16, "first_foot": "r",
              "air_s": 0.3},
}
