"""Authoring a body's motion from footprints and keyframes, and the walk, run and idle clips.

Each generator builds canonical joint positions for a body frame by frame as arrays: footprints
that stay put for the whole stance, swing feet on smooth arcs, the pelvis lowered where a leg
could not reach (the paper's ``min(h1, h2, h3)`` rule), knees and elbows by the two-sphere
construction, then the clip goes through the same encoder and BVH writer as captured data.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
from numpy.typing import NDArray

from ecs_anim.core.ground_adapt import vertical_slack_for_reach
from ecs_anim.core.morphology import Morphology
from ecs_anim.core.normalized import (
    limb_frames,
    two_bone_middle,
)
from ecs_anim.core.rotations import normalize, rot_axis
from ecs_anim.core.skeleton import JOINT_INDEX as J
from ecs_anim.core.skeleton import N_JOINTS, REST_HIP_DIR_LEFT

F64 = NDArray[np.float64]

#: The authored clips' frame rate (Hz).
FPS = 30.0


def _smoothstep(u: F64) -> F64:
    """0 -> 1 with zero velocity at both ends (cycloid)."""
    return u - np.sin(2 * np.pi * u) / (2 * np.pi)


def hip_positions(morph: Morphology, pelvis: F64, pelvis2world: F64) -> F64:
    """Left and right hip joints (F, 2, 3) of a pelvis at ``pelvis`` (F, 3), ``pelvis2world``."""
    return np.stack([pelvis + (pelvis2world @ (np.array(REST_HIP_DIR_LEFT) * [1.0, sign, 1.0]))
                     * morph[f"pelvis_{s}"] for s, sign in (("l", 1.0), ("r", -1.0))], axis=1)


def place_legs(out: F64, morph: Morphology, pelvis: F64, pelvis2world: F64, ankles: F64,
                toes: F64, knee_hint: F64) -> None:
    """Write pelvis, hips, knees (two-sphere construction), ankles and toes into ``out``.

    ``out`` (F, N_JOINTS, 3); ``ankles``/``toes`` (F, 2, 3) targets (an ankle out of reach ends
    where the straight leg points); ``knee_hint`` (F, 3) or (F, 2, 3): the side the knees bend to.
    """
    m = morph
    n = pelvis.shape[0]
    out[:, J["pelvis"]] = pelvis
    hips = hip_positions(morph, pelvis, pelvis2world)
    hints = np.broadcast_to(knee_hint[:, None] if knee_hint.ndim == 2 else knee_hint, (n, 2, 3))
    for k, s in enumerate("lr"):
        hip = hips[:, k]
        thigh, shank = m[f"thigh_{s}"], m[f"shank_{s}"]
        leg = limb_frames(hip, hip + hints[:, k], ankles[:, k], hints[:, k])
        knee, ankle = two_bone_middle(leg, hip, np.full(n, thigh), np.full(n, shank),
                                      np.linalg.norm(ankles[:, k] - hip, axis=-1))
        out[:, J[f"hip_{s}"]], out[:, J[f"knee_{s}"]], out[:, J[f"ankle_{s}"]] = hip, knee, ankle
        out[:, J[f"toe_{s}"]] = ankle + normalize(toes[:, k] - ankles[:, k]) * m[f"foot_{s}"]


def _body(morph: Morphology, pelvis: F64, pelvis2world: F64, ankles: F64, toes: F64,
          lean_rad: F64, thorax_yaw: F64, arm_swing: F64, elbow_bend: F64,
          head_pitch: F64) -> F64:
    """Assemble joint positions (F, N_JOINTS, 3) from pelvis, feet and a few trunk/arm angles.

    ``ankles``/``toes`` (F, 2, 3); angles (F,) radians, ``arm_swing`` and ``elbow_bend`` (F, 2).
    """
    m = morph
    n = pelvis.shape[0]
    out = np.zeros((n, N_JOINTS, 3))
    place_legs(out, morph, pelvis, pelvis2world, ankles, toes, pelvis2world[:, :, 0])
    # Trunk: pelvis frame, leaned forward about its left axis, thorax turned against the pelvis.
    trunk = pelvis2world @ rot_axis(1, lean_rad)
    up = trunk[:, :, 2]
    s1 = pelvis + up * m["spine_lower"]
    bend = trunk @ rot_axis(1, 0.5 * lean_rad)
    s2 = s1 + bend[:, :, 2] * m["spine_middle"]
    thorax = bend @ rot_axis(2, thorax_yaw) @ rot_axis(1, 0.5 * lean_rad)
    neck = s2 + thorax[:, :, 2] * m["spine_upper"]
    out[:, J["spine_1"]], out[:, J["spine_2"]], out[:, J["neck"]] = s1, s2, neck
    head_frame = thorax @ rot_axis(1, head_pitch)
    head = neck + head_frame[:, :, 2] * m["neck"]
    out[:, J["head"]] = head
    out[:, J["head_top"]] = head + (head_frame @ rot_axis(1, 0.5 * head_pitch))[:, :, 2] * m["head"]
    for k, s in enumerate("lr"):
        sign = 1.0 if s == "l" else -1.0
        clav = normalize(np.array([-0.15, 0.97 * sign, -0.12]))
        shoulder = neck + (thorax @ clav) * m[f"clavicle_{s}"]
        # Arms hang slightly outwards and swing about the thorax' left axis.
        hang = thorax @ rot_axis(0, np.full(n, -0.08 * sign))
        upper_frame = hang @ rot_axis(1, -arm_swing[:, k])
        elbow = shoulder - upper_frame[:, :, 2] * m[f"upper_arm_{s}"]
        fore_frame = upper_frame @ rot_axis(1, -elbow_bend[:, k])
        wrist = elbow - fore_frame[:, :, 2] * m[f"forearm_{s}"]
        hand = wrist - fore_frame[:, :, 2] * m[f"hand_{s}"]
        out[:, J[f"shoulder_{s}"]], out[:, J[f"elbow_{s}"]] = shoulder, elbow
        out[:, J[f"wrist_{s}"]], out[:, J[f"hand_{s}"]] = wrist, hand
    return out


def lower_pelvis_to_reach(pelvis: F64, pelvis2world: F64, ankles: F64, morph: Morphology,
                           max_extension: float = 0.985) -> F64:
    """Pelvis heights lowered where a leg could not reach its ankle (paper §7's min rule),
    smoothly; the clip is treated as periodic (our generators make whole cycles)."""
    hips = hip_positions(morph, pelvis, pelvis2world)
    reach = max_extension * np.array([morph["thigh_l"] + morph["shank_l"],
                                      morph["thigh_r"] + morph["shank_r"]])
    slack = vertical_slack_for_reach(hips, ankles, np.broadcast_to(reach, ankles.shape[:2]))
    # Lower by the deficit, dilated then blurred over the same circular window: the result is
    # smooth (no kink where a leg becomes the limiting one) and never less than the deficit.
    deficit = np.maximum(-slack.min(axis=1), 0.0)
    half = round(0.12 * FPS)
    shifts = range(-half, half + 1)
    dilated = np.max(np.stack([np.roll(deficit, k) for k in shifts]), axis=0)
    smooth = np.mean(np.stack([np.roll(dilated, k) for k in shifts]), axis=0)
    out = pelvis.copy()
    out[:, 2] -= smooth
    return out


def _gait_feet(morph: Morphology, phase: F64, stride: float, stance: float,
               lift_per_leg: float, swing_pitch: float) -> tuple[F64, F64]:
    """Ankles and toes (F, 2, 3) of a gait along +x at gait ``phase`` (F,) (cycles; the left
    foot lands at each whole cycle, the right half a cycle later): each footprint
    stays put for the ``stance`` fraction of the cycle, then the foot swings ``stride`` metres
    forward on a smooth arc ``lift_per_leg`` leg lengths high, toes pitched by ``swing_pitch``."""
    n = phase.shape[0]
    ah = 0.5 * (morph["ankle_height_l"] + morph["ankle_height_r"])
    foot = 0.5 * (morph["foot_l"] + morph["foot_r"])
    ball_height = 0.025 * morph.leg_length / 0.86
    flat_pitch = np.arcsin(np.clip((ah - ball_height) / foot, -1, 1))
    ankles = np.zeros((n, 2, 3))
    toes = np.zeros((n, 2, 3))
    for k, offset in enumerate((0.0, 0.5)):
        cycle = np.floor(phase - offset)
        psi = phase - offset - cycle
        land_x = (cycle + offset + stance / 2) * stride  # mid-stance under the pelvis
        swing_u = np.clip((psi - stance) / (1 - stance), 0.0, 1.0)
        in_swing = psi >= stance
        x = land_x + np.where(in_swing, _smoothstep(swing_u) * stride, 0.0)
        lift = lift_per_leg * morph.leg_length * np.sin(np.pi * swing_u) ** 1.5
        ankles[:, k, 0] = x
        ankles[:, k, 1] = (0.11 if k == 0 else -0.11) * morph.leg_length
        ankles[:, k, 2] = ah + np.where(in_swing, lift, 0.0)
        pitch = flat_pitch + np.where(in_swing, swing_pitch * np.sin(np.pi * swing_u) *
                                      np.cos(np.pi * swing_u), 0.0)
        toes[:, k] = ankles[:, k] + np.stack([np.cos(pitch), np.zeros(n), -np.sin(pitch)], -1) * foot
    return ankles, toes


def generate_walk(morph: Morphology, cycles: int = 4, period_s: float = 1.1,
                  stride_m: float | None = None) -> F64:
    """A straight walk along +x: ``cycles`` gait cycles (two steps each), loopable.

    Returns joint positions (frames, N_JOINTS, 3), metres, Z up.
    """
    stride = 1.62 * morph.leg_length if stride_m is None else stride_m
    n = round(cycles * period_s * FPS)
    t = np.arange(n) / FPS
    phase = t / period_s
    speed = stride / period_s
    ah = 0.5 * (morph["ankle_height_l"] + morph["ankle_height_r"])
    ankles, toes = _gait_feet(morph, phase, stride, 0.6, 0.11, 0.35)
    pelvis = np.zeros((n, 3))
    pelvis[:, 0] = speed * t
    pelvis[:, 1] = 0.025 * morph.leg_length * np.cos(2 * np.pi * (phase - 0.3))
    standing = ah + 0.5 * (morph["thigh_l"] + morph["shank_l"] + morph["thigh_r"] + morph["shank_r"])
    pelvis[:, 2] = standing * 0.985 + 0.012 * np.cos(4 * np.pi * (phase - 0.3))
    yaw = 0.07 * np.sin(2 * np.pi * (phase - 0.05))
    roll = 0.04 * np.sin(2 * np.pi * (phase - 0.3) + np.pi / 2)
    pelvis2world = rot_axis(2, yaw) @ rot_axis(0, roll)
    pelvis = lower_pelvis_to_reach(pelvis, pelvis2world, ankles, morph)
    swing = np.stack([-0.3 * np.cos(2 * np.pi * (phase - 0.25)),
                      0.3 * np.cos(2 * np.pi * (phase - 0.25))], axis=-1)
    elbow = 0.3 + 0.2 * np.maximum(swing, 0.0)
    return _body(morph, pelvis, pelvis2world, ankles, toes,
                 lean_rad=np.full(n, 0.06), thorax_yaw=-1.5 * yaw, arm_swing=swing,
                 elbow_bend=elbow, head_pitch=np.full(n, -0.05))


def generate_run(morph: Morphology, cycles: int = 4, period_s: float = 0.7) -> F64:
    """A straight run along +x: ``cycles`` gait cycles, loopable; each foot is down for 32 % of
    a cycle, so both are in the air twice a cycle (flight). Stride 2.2 leg lengths a cycle
    (adult_male: 2.66 m/s), the pelvis lowest in mid-stance and highest in flight, the trunk
    leaning forward, elbows bent about 80 degrees, arms swinging wider than the walk's.

    Returns joint positions (frames, N_JOINTS, 3), metres, Z up.
    """
    stride = 2.2 * morph.leg_length
    n = round(cycles * period_s * FPS)
    t = np.arange(n) / FPS
    phase = t / period_s
    ah = 0.5 * (morph["ankle_height_l"] + morph["ankle_height_r"])
    ankles, toes = _gait_feet(morph, phase, stride, 0.32, 0.22, 0.6)
    pelvis = np.zeros((n, 3))
    pelvis[:, 0] = stride / period_s * t
    pelvis[:, 1] = 0.015 * morph.leg_length * np.cos(2 * np.pi * (phase - 0.16))
    standing = ah + 0.5 * (morph["thigh_l"] + morph["shank_l"] + morph["thigh_r"] + morph["shank_r"])
    # Mid-stance of the left foot is at phase 0.16, of the right at 0.66: lowest there.
    pelvis[:, 2] = standing * 0.95 - 0.03 * morph.leg_length * np.cos(4 * np.pi * (phase - 0.16))
    yaw = 0.09 * np.sin(2 * np.pi * phase)
    roll = 0.03 * np.sin(2 * np.pi * (phase - 0.16) + np.pi / 2)
    pelvis2world = rot_axis(2, yaw) @ rot_axis(0, roll)
    pelvis = lower_pelvis_to_reach(pelvis, pelvis2world, ankles, morph)
    swing = np.stack([-0.6 * np.cos(2 * np.pi * (phase - 0.11)),
                      0.6 * np.cos(2 * np.pi * (phase - 0.11))], axis=-1)
    elbow = 1.35 + 0.15 * np.maximum(swing, 0.0)
    return _body(morph, pelvis, pelvis2world, ankles, toes,
                 lean_rad=np.full(n, 0.16), thorax_yaw=-1.5 * yaw, arm_swing=swing,
                 elbow_bend=elbow, head_pitch=np.full(n, -0.12))


def generate_idle(morph: Morphology, seconds: float = 8.0) -> F64:
    """Standing at rest: weight shifts, breathing, a slow look around; feet planted; loopable."""
    n = round(seconds * FPS)
    t = np.arange(n) / FPS
    w = 2 * np.pi / seconds
    ah = 0.5 * (morph["ankle_height_l"] + morph["ankle_height_r"])
    foot = 0.5 * (morph["foot_l"] + morph["foot_r"])
    ball_height = 0.025 * morph.leg_length / 0.86
    pitch = np.arcsin(np.clip((ah - ball_height) / foot, -1, 1))
    ankles = np.zeros((n, 2, 3))
    ankles[:, 0] = [0.0, 0.12 * morph.leg_length, ah]
    ankles[:, 1] = [0.02, -0.12 * morph.leg_length, ah]
    toes = ankles + np.array([np.cos(pitch) * np.cos(0.15), 0.0, -np.sin(pitch)]) * foot
    toes[:, 0, 1] += np.sin(0.15) * foot
    toes[:, 1, 1] -= np.sin(0.15) * foot
    pelvis = np.zeros((n, 3))
    pelvis[:, 0] = 0.01 + 0.008 * np.sin(w * t)
    pelvis[:, 1] = 0.03 * morph.leg_length * np.sin(w * t)
    standing = ah + 0.5 * (morph["thigh_l"] + morph["shank_l"] + morph["thigh_r"] + morph["shank_r"])
    pelvis[:, 2] = standing * 0.975 - 0.005 * np.cos(2 * w * t)
    yaw = 0.04 * np.sin(w * t + 0.5)
    pelvis2world = rot_axis(2, yaw) @ rot_axis(0, -0.03 * np.sin(w * t))
    pelvis = lower_pelvis_to_reach(pelvis, pelvis2world, ankles, morph)
    breathe = 0.015 * np.sin(4 * w * t)
    swing = np.stack([0.05 * np.sin(w * t), -0.05 * np.sin(w * t + 0.7)], axis=-1)
    elbow = np.full((n, 2), 0.25) + 0.05 * np.sin(4 * w * t)[:, None]
    return _body(morph, pelvis, pelvis2world, ankles, toes,
                 lean_rad=0.02 + breathe, thorax_yaw=0.15 * np.sin(2 * w * t) - yaw,
                 arm_swing=swing, elbow_bend=elbow, head_pitch=0.05 * np.sin(w * t + 1.0))


GENERATORS: dict[str, Callable[[Morphology], F64]] = {"walk": generate_walk, "run": generate_run,
                                                      "idle": generate_idle}
