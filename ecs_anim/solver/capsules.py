"""A body for collisions: capsules derived from the morphology (DESIGN §8b).

Each character has :data:`N_CAPSULES` capsules, each a segment between two points of its
posture and a radius; the numpy functions here are the reference the compiled
:mod:`ecs_anim.runtime.kernels.capsules` mirrors (to 1e-9 m).

The capsules and their radii, as shares of the body's own segment lengths (so a child's are a
child's); the shares give an adult male of 1.75 m the girths of an anthropometric table
(calf 0.32 m, thigh 0.48 m, upper arm 0.29 m, forearm 0.24 m round; chest 0.22 m deep, head
0.18 m wide):

=============  ==========================  ==================================  =========
capsule        axis (joints, fractions)    radius                              1.75 m
=============  ==========================  ==================================  =========
shank l/r      knee -> ankle               0.12 x shank                        51 mm
thigh l/r      hip -> knee                 0.18 x thigh                        76 mm
pelvis         hip_l -> hip_r              1.0 x pelvis half-width             90 mm
trunk          pelvis -> neck              0.22 x spine (lower+middle+upper)   106 mm
head           head -> head_top, 0.25-0.6  0.4 x head                          88 mm
upper arm l/r  shoulder -> elbow           0.14 x upper arm                    45 mm
forearm l/r    elbow -> wrist              0.15 x forearm                      38 mm
hand l/r       wrist -> hand               0.25 x hand                         35 mm
=============  ==========================  ==================================  =========

A body point's own radius (:func:`point_radii`: how far its surface lies from it) is its
segment's capsule's radius; segments without a capsule of their own take the capsule they lie in (foot: shank, clavicle:
upper arm, spine parts: trunk); the neck (between trunk and head) has none: a target on it
stays a point.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from ecs_anim.core.skeleton import JOINT_INDEX as J
from ecs_anim.core.skeleton import LENGTH_INDEX as L

F64 = NDArray[np.float64]
I64 = NDArray[np.int64]

#: The capsules, in the order of the store's columns.
CAPSULES = ("shank_l", "shank_r", "thigh_l", "thigh_r", "pelvis", "trunk", "head",
            "upper_arm_l", "upper_arm_r", "forearm_l", "forearm_r", "hand_l", "hand_r")
N_CAPSULES = len(CAPSULES)
CAPSULE_INDEX = {name: i for i, name in enumerate(CAPSULES)}

_AXES = {  # capsule -> (joint a, joint b, fraction of a->b where the axis starts, ends)
    "shank_l": ("knee_l", "ankle_l", 0.0, 1.0), "shank_r": ("knee_r", "ankle_r", 0.0, 1.0),
    "thigh_l": ("hip_l", "knee_l", 0.0, 1.0), "thigh_r": ("hip_r", "knee_r", 0.0, 1.0),
    "pelvis": ("hip_l", "hip_r", 0.0, 1.0), "trunk": ("pelvis", "neck", 0.0, 1.0),
    "head": ("head", "head_top", 0.25, 0.6),
    "upper_arm_l": ("shoulder_l", "elbow_l", 0.0, 1.0),
    "upper_arm_r": ("shoulder_r", "elbow_r", 0.0, 1.0),
    "forearm_l": ("elbow_l", "wrist_l", 0.0, 1.0), "forearm_r": ("elbow_r", "wrist_r", 0.0, 1.0),
    "hand_l": ("wrist_l", "hand_l", 0.0, 1.0), "hand_r": ("wrist_r", "hand_r", 0.0, 1.0),
}
#: (N_CAPSULES, 2) the joints each capsule's axis lies between.
CAPSULE_JOINTS = np.array([[J[_AXES[c][0]], J[_AXES[c][1]]] for c in CAPSULES], np.int64)
#: (N_CAPSULES, 2) where along joint a -> b the axis starts and ends.
CAPSULE_SPAN = np.array([[_AXES[c][2], _AXES[c][3]] for c in CAPSULES])

_SPINE = (L["spine_lower"], L["spine_middle"], L["spine_upper"])
_RADII = {  # capsule -> (share, the length indices summed)
    "shank_l": (0.12, (L["shank_l"],)), "shank_r": (0.12, (L["shank_r"],)),
    "thigh_l": (0.18, (L["thigh_l"],)), "thigh_r": (0.18, (L["thigh_r"],)),
    "pelvis": (1.0, (L["pelvis_l"],)), "trunk": (0.22, _SPINE), "head": (0.4, (L["head"],)),
    "upper_arm_l": (0.14, (L["upper_arm_l"],)), "upper_arm_r": (0.14, (L["upper_arm_r"],)),
    "forearm_l": (0.15, (L["forearm_l"],)), "forearm_r": (0.15, (L["forearm_r"],)),
    "hand_l": (0.25, (L["hand_l"],)), "hand_r": (0.25, (L["hand_r"],)),
}
#: (N_CAPSULES, N_LENGTHS-wide) weights: radii = lengths @ RADIUS_WEIGHTS.T.
RADIUS_WEIGHTS = np.zeros((N_CAPSULES, len(L)))
for _c, _name in enumerate(CAPSULES):
    _share, _of = _RADII[_name]
    RADIUS_WEIGHTS[_c, list(_of)] = _share

#: segment (LENGTHS index) -> the capsule its points lie in (-1: none).
_SEGMENT_CAPSULE = {
    "shank_l": "shank_l", "shank_r": "shank_r", "foot_l": "shank_l", "foot_r": "shank_r",
    "thigh_l": "thigh_l", "thigh_r": "thigh_r", "pelvis_l": "pelvis", "pelvis_r": "pelvis",
    "spine_lower": "trunk", "spine_middle": "trunk", "spine_upper": "trunk",
    "head": "head", "clavicle_l": "upper_arm_l", "clavicle_r": "upper_arm_r",
    "upper_arm_l": "upper_arm_l", "upper_arm_r": "upper_arm_r", "forearm_l": "forearm_l",
    "forearm_r": "forearm_r", "hand_l": "hand_l", "hand_r": "hand_r",
}
SEGMENT_CAPSULE = np.full(len(L), -1, np.int64)
for _seg, _cap in _SEGMENT_CAPSULE.items():
    SEGMENT_CAPSULE[L[_seg]] = CAPSULE_INDEX[_cap]


def capsule_radii(lengths: F64) -> F64:
    """(..., N_CAPSULES) each capsule's radius, m, from segment lengths (..., N_LENGTHS)."""
    radii: F64 = lengths @ RADIUS_WEIGHTS.T
    return radii


def capsules_from_positions(positions: F64, lengths: F64) -> tuple[F64, F64]:
    """Every character's capsules: endpoints (n, N_CAPSULES, 2, 3) world metres and radii
    (n, N_CAPSULES) m, from joint positions (n, N_JOINTS, 3) and lengths (n, N_LENGTHS)."""
    a = positions[:, CAPSULE_JOINTS[:, 0]]
    b = positions[:, CAPSULE_JOINTS[:, 1]]
    ends = a[:, :, None] + CAPSULE_SPAN[None, :, :, None] * (b - a)[:, :, None]
    return ends, capsule_radii(lengths)


def closest_on_segment(p: F64, a: F64, b: F64) -> tuple[F64, F64]:
    """The point of segment ``a``-``b`` nearest ``p`` (..., 3), and its fraction along it
    (...,) (0 at ``a``; a degenerate segment gives ``a``)."""
    ab = b - a
    t = np.clip(np.sum((p - a) * ab, axis=-1) / np.maximum(np.sum(ab * ab, axis=-1), 1e-18),
                0.0, 1.0)
    return a + t[..., None] * ab, t


def closest_between_segments(p1: F64, q1: F64, p2: F64, q2: F64) -> tuple[F64, F64]:
    """The nearest points of segments ``p1``-``q1`` and ``p2``-``q2`` (..., 3) to each other
    (Ericson, Real-Time Collision Detection, 5.1.9; degenerate segments are points)."""
    d1, d2, r = q1 - p1, q2 - p2, p1 - p2
    a = np.sum(d1 * d1, axis=-1)
    e = np.sum(d2 * d2, axis=-1)
    f = np.sum(d2 * r, axis=-1)
    c = np.sum(d1 * r, axis=-1)
    b = np.sum(d1 * d2, axis=-1)
    denom = a * e - b * b
    s = np.where(denom > 1e-18, np.clip((b * f - c * e) / np.maximum(denom, 1e-18), 0.0, 1.0), 0.0)
    s = np.where(a > 1e-18, s, 0.0)
    t = np.where(e > 1e-18, (b * s + f) / np.maximum(e, 1e-18), 0.0)
    # t outside [0, 1]: clamp it and recompute s for it.
    t_clamped = np.clip(t, 0.0, 1.0)
    s = np.where((t != t_clamped) & (a > 1e-18),
                 np.clip((t_clamped * b - c) / np.maximum(a, 1e-18), 0.0, 1.0), s)
    t = t_clamped
    return p1 + s[..., None] * d1, p2 + t[..., None] * d2


def point_radii(lengths: F64, segment: I64) -> F64:
    """(k,) the radius of the capsule each body point's segment lies in (0: none);
    ``lengths`` (k, N_LENGTHS) each point's body, ``segment`` (k,) its segment."""
    capsule = SEGMENT_CAPSULE[segment]
    radii = capsule_radii(lengths)
    out: F64 = np.where(capsule >= 0, radii[np.arange(segment.size), np.maximum(capsule, 0)], 0.0)
    return out


def surface_points(target: F64, axis_a: F64, axis_b: F64, radius: F64, effector: F64) -> F64:
    """Targets moved onto a capsule's surface (k, 3): from the nearest point of the capsule's
    axis ``axis_a``-``axis_b`` (k, 3) to ``target`` (k, 3), out by ``radius`` (k,) (the
    capsule's and the effector's together) toward ``effector`` (k, 3), square to the axis
    (within its ends; off an end, straight toward the effector). An effector on the axis goes
    out along any direction square to it."""
    on_axis, t = closest_on_segment(target, axis_a, axis_b)
    ab = axis_b - axis_a
    ab_len = np.linalg.norm(ab, axis=-1, keepdims=True)
    along = ab / np.maximum(ab_len, 1e-12)
    way = effector - on_axis
    inner = (t > 0.0) & (t < 1.0)
    way = np.where(inner[:, None], way - np.sum(way * along, axis=-1, keepdims=True) * along, way)
    length = np.linalg.norm(way, axis=-1, keepdims=True)
    # No way out (the effector on the axis): any direction square to the axis.
    other = np.where(np.abs(along[:, :1]) < 0.9, [[1.0, 0.0, 0.0]], [[0.0, 1.0, 0.0]])
    square = other - np.sum(other * along, axis=-1, keepdims=True) * along
    square /= np.maximum(np.linalg.norm(square, axis=-1, keepdims=True), 1e-12)
    direction = np.where(length > 1e-9, way / np.maximum(length, 1e-12), square)
    out: F64 = on_axis + direction * radius[:, None]
    return out


__all__ = ["CAPSULES", "CAPSULE_INDEX", "CAPSULE_JOINTS", "CAPSULE_SPAN", "N_CAPSULES",
           "SEGMENT_CAPSULE", "capsule_radii", "capsules_from_positions",
           "closest_between_segments", "closest_on_segment", "point_radii", "surface_points"]
