"""Points on a body: which segment, where along it, and which group of the solver moves it.

A body point is a segment (a bone of :data:`ecs_anim.core.skeleton.LENGTHS`, e.g. ``forearm_r``), a
``fraction`` along it from its proximal joint (0) to its distal joint (1), and an ``offset_m`` in
the segment's frame. A joint name is shorthand for the distal end of the bone that ends there
(``wrist_r`` = ``forearm_r`` at 1).

Segment frames (axes as columns, world): limb bones (thigh, shank, foot, upper arm, forearm,
hand) have ``z`` along the bone and ``x`` the limb half-plane's normal (``y = z × x``); the lower
spine uses the pelvis frame, the middle and upper spine, the clavicles and the neck the thorax
frame, the head the head frame.

The solver's groups (paper §9), in the order one iteration visits them: the two legs, the head,
the two arms, the trunk. Each point belongs to one group; a constraint's chain lists the groups
allowed to move for it.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from ecs_anim.core.errors import UsageError, did_you_mean
from ecs_anim.core.normalized import DecodedPose
from ecs_anim.core.rotations import frame_from_axes
from ecs_anim.core.skeleton import BONE_JOINTS, JOINTS, LENGTH_INDEX, LENGTHS
from ecs_anim.core.skeleton import JOINT_INDEX as J

F64 = NDArray[np.float64]
I64 = NDArray[np.int64]

GROUPS = ("leg_l", "leg_r", "head", "arm_l", "arm_r", "trunk")
GROUP_INDEX = {g: i for i, g in enumerate(GROUPS)}
LEG_L, LEG_R, HEAD, ARM_L, ARM_R, TRUNK = range(6)
#: Groups whose points the trunk carries (a trunk move serves their constraints too).
ABOVE_TRUNK = (HEAD, ARM_L, ARM_R, TRUNK)

#: Frame a segment's offset is given in: limb slot 0..3 (leg_l, leg_r, arm_l, arm_r: z along the
#: bone, x the limb normal), or one of the body frames.
FRAME_PELVIS, FRAME_THORAX, FRAME_HEAD = 4, 5, 6

#: segment -> (group, bone within the group, frame). Bones of a limb: 0 upper, 1 lower,
#: 2 distal (foot, hand); of the head group: 0 neck, 1 head. The pelvis bones (pelvis -> hip)
#: belong to the root, which only the centre-of-mass control moves: they take no constraints.
SEGMENTS: dict[str, tuple[int, int, int]] = {}
for _k, _s in enumerate("lr"):
    SEGMENTS[f"thigh_{_s}"] = (LEG_L + _k, 0, _k)
    SEGMENTS[f"shank_{_s}"] = (LEG_L + _k, 1, _k)
    SEGMENTS[f"foot_{_s}"] = (LEG_L + _k, 2, _k)
    SEGMENTS[f"upper_arm_{_s}"] = (ARM_L + _k, 0, 2 + _k)
    SEGMENTS[f"forearm_{_s}"] = (ARM_L + _k, 1, 2 + _k)
    SEGMENTS[f"hand_{_s}"] = (ARM_L + _k, 2, 2 + _k)
    SEGMENTS[f"clavicle_{_s}"] = (TRUNK, 0, FRAME_THORAX)
SEGMENTS.update({
    "spine_lower": (TRUNK, 0, FRAME_PELVIS), "spine_middle": (TRUNK, 0, FRAME_THORAX),
    "spine_upper": (TRUNK, 0, FRAME_THORAX), "neck": (HEAD, 0, FRAME_THORAX),
    "head": (HEAD, 1, FRAME_HEAD),
})

#: A joint used as a point: the bone it ends (fraction 1).
JOINT_AS_POINT = {JOINTS[b]: name for name, (a, b) in zip(LENGTHS, BONE_JOINTS, strict=False)
                  if b >= 0 and name in SEGMENTS}

#: Chains a point's group may extend to: its own group, plus the trunk above the head and arms
#: (the legs hang from the root, which only centre-of-mass control moves).
ALLOWED_CHAIN = {g: ({g, TRUNK} if g in ABOVE_TRUNK else {g}) for g in range(len(GROUPS))}


@dataclass(frozen=True)
class BodyPoint:
    """A point on a body: segment (a length index), fraction along it, offset in its frame."""

    segment: int
    fraction: float = 1.0
    offset_m: tuple[float, float, float] = (0.0, 0.0, 0.0)

    @property
    def name(self) -> str:
        return LENGTHS[self.segment]

    @property
    def group(self) -> int:
        return SEGMENTS[self.name][0]

    @property
    def bone(self) -> int:
        return SEGMENTS[self.name][1]

    @property
    def frame(self) -> int:
        return SEGMENTS[self.name][2]


#: Points only a target can name (the root's): the pelvis bones and their joints.
TARGET_ONLY_SEGMENTS = ("pelvis_l", "pelvis_r")
TARGET_ONLY_JOINTS = {"pelvis": ("pelvis_l", 0.0), "hip_l": ("pelvis_l", 1.0), "hip_r": ("pelvis_r", 1.0)}


def body_point(name: str, fraction: float | None = None,
               offset_m: tuple[float, float, float] = (0.0, 0.0, 0.0),
               as_target: bool = False, segment: bool = False) -> BodyPoint:
    """A point from a segment or joint name; raises ValueError with a suggestion when unknown.
    ``as_target``: the point is a target, which may also be on the root (pelvis, hips).
    ``segment``: a name that is both a joint and a segment means the segment (orientations).

    A name that is both (``head``, ``neck``, ``hand_l``) is the joint unless a ``fraction`` is
    given; a segment without one is its middle (0.5)."""
    if name in JOINT_AS_POINT and ((fraction is None and not segment) or name not in SEGMENTS):
        if fraction is not None:
            raise UsageError(f"{name!r} is a joint; give fraction with a segment "
                             f"(e.g. {JOINT_AS_POINT[name]!r})")
        seg, fraction = JOINT_AS_POINT[name], 1.0
    elif as_target and name in TARGET_ONLY_JOINTS and fraction is None:
        seg, fraction = TARGET_ONLY_JOINTS[name]
    elif name in SEGMENTS or (as_target and name in TARGET_ONLY_SEGMENTS):
        seg, fraction = name, 0.5 if fraction is None else fraction
    else:
        if name in LENGTH_INDEX or name in J:
            raise UsageError(f"{name!r} belongs to the root (pelvis), which only centre-of-mass "
                             f"control moves; constrain another point")
        names = sorted(set(SEGMENTS) | set(JOINT_AS_POINT)
                       | (set(TARGET_ONLY_JOINTS) | set(TARGET_ONLY_SEGMENTS) if as_target else set()))
        hint = did_you_mean(name, names)
        raise UsageError(f"unknown body point {name!r}{hint} (segments: {', '.join(sorted(SEGMENTS))}; "
                         f"or a joint: {', '.join(sorted(JOINT_AS_POINT))})")
    if not (np.isfinite(fraction) and 0.0 <= fraction <= 1.0):
        raise UsageError(f"fraction along {seg!r} must be in [0, 1], got {fraction}")
    if not all(np.isfinite(v) and abs(v) <= 10.0 for v in offset_m):
        raise UsageError(f"offset_m {offset_m} must be finite and within 10 m")
    x, y, z = (float(v) for v in offset_m)
    return BodyPoint(LENGTH_INDEX[seg], float(fraction), (x, y, z))


#: Per length index: proximal and distal joints, group, bone, frame (-1 where not a point).
SEG_PROXIMAL = np.array([a for a, _ in BONE_JOINTS])
SEG_DISTAL = np.array([b for _, b in BONE_JOINTS])
SEG_FRAME = np.array([SEGMENTS[n][2] if n in SEGMENTS else FRAME_PELVIS for n in LENGTHS])


def segment_frames(decoded: DecodedPose, rows: I64, segment: I64) -> F64:
    """World frames (k, 3, 3) of ``segment`` (k,) length indices on characters ``rows`` (k,)."""
    p = decoded.positions
    frame_kind = SEG_FRAME[segment]
    out = np.empty((rows.size, 3, 3))
    # A body frame (pelvis, thorax, head) is read; a bone's is made from its limb's: each only
    # where asked (a bench of 8,000 targets on the walkers' shoulders made every kind for all).
    bone = frame_kind < FRAME_PELVIS
    fixed = np.flatnonzero(~bone)
    if fixed.size:
        which = frame_kind[fixed] - FRAME_PELVIS
        r = rows[fixed]
        for k, frames in enumerate((decoded.pelvis2world, decoded.thorax2world,
                                    decoded.head2world)):
            at = which == k
            out[fixed[at]] = frames[r[at]]
    made = np.flatnonzero(bone)
    if made.size:
        r, seg = rows[made], segment[made]
        limb_slot = frame_kind[made]
        limb = np.where((limb_slot < 2)[:, None, None], decoded.leg2world[r, limb_slot % 2],
                        decoded.arm2world[r, limb_slot % 2])
        along = p[r, SEG_DISTAL[seg]] - p[r, SEG_PROXIMAL[seg]]
        out[made] = frame_from_axes(along, limb[:, :, 0], 2, 0, fallback_secondary=limb[:, :, 1])
    return out


def point_positions(decoded: DecodedPose, rows: I64, segment: I64, fraction: F64, offset: F64) -> F64:
    """World positions (k, 3) of body points: ``rows`` (k,) characters, ``segment`` (k,) length
    indices, ``fraction`` (k,), ``offset`` (k, 3) metres in the segment frame."""
    p = decoded.positions
    a, b = p[rows, SEG_PROXIMAL[segment]], p[rows, SEG_DISTAL[segment]]
    point: F64 = a + fraction[:, None] * (b - a)
    has_offset = np.flatnonzero(np.any(offset != 0.0, axis=1))
    if has_offset.size:
        frames = segment_frames(decoded, rows[has_offset], segment[has_offset])
        point[has_offset] += np.einsum("kij,kj->ki", frames, offset[has_offset])
    return point


__all__ = ["GROUPS", "SEGMENTS", "BodyPoint", "body_point", "point_positions", "segment_frames"]
