"""The normalized, morphology-independent pose (paper §4, DESIGN §3) and its two directions.

:func:`encode` turns canonical joint positions plus body-part orientations into
:class:`NormalizedPoses`; :func:`decode` turns normalized poses plus segment lengths back into
joint positions (paper §6 eq. 2 and §8). Both take any leading batch shape: frames of a clip at
import, characters in the tick. Decoding with the morphology the poses were encoded with gives the
input back (no loss: the round-trip tests check 0.1 mm; the arithmetic gives about 1e-12 m).

Frames used (all rotation matrices with axes as columns, ``x`` forward, ``y`` left, ``z`` up at
rest):

* pelvis frame: the root orientation, split into a heading (yaw about world Z) and the local rest;
* leg / arm frame (the paper's half-plane, fig. 4): ``z`` from hip (shoulder) to ankle (wrist),
  ``y`` towards the knee (elbow) side, ``x = y × z``;
* shank / forearm frame: ``z`` along the shank (forearm), ``x`` the limb frame's ``x`` (normal of
  the half-plane), ``y = z × x``; feet and hands are stored in it so they follow the bend;
* thorax frame (relative to the pelvis) and head frame (relative to the thorax).
"""

from __future__ import annotations

from dataclasses import dataclass, fields
from typing import Any

import numpy as np
from numpy.typing import NDArray

from ecs_anim.core.morphology import leg_length
from ecs_anim.core.rotations import (
    frame_from_axes,
    matrix_from_quat,
    normalize,
    quat_from_matrix,
    rot_axis,
    yaw_of,
)
from ecs_anim.core.skeleton import BONE_JOINTS, N_JOINTS, N_LENGTHS
from ecs_anim.core.skeleton import JOINT_INDEX as J
from ecs_anim.core.skeleton import LENGTH_INDEX as L

F64 = NDArray[np.float64]

SIDE_JOINTS = {
    "hip": (J["hip_l"], J["hip_r"]), "knee": (J["knee_l"], J["knee_r"]),
    "ankle": (J["ankle_l"], J["ankle_r"]), "toe": (J["toe_l"], J["toe_r"]),
    "shoulder": (J["shoulder_l"], J["shoulder_r"]), "elbow": (J["elbow_l"], J["elbow_r"]),
    "wrist": (J["wrist_l"], J["wrist_r"]), "hand": (J["hand_l"], J["hand_r"]),
}
SIDE_LENGTHS = {
    name: (L[f"{name}_l"], L[f"{name}_r"])
    for name in ("pelvis", "thigh", "shank", "foot", "clavicle", "upper_arm", "forearm", "hand",
                 "ankle_height")
}
SPINE_LENGTHS = (L["spine_lower"], L["spine_middle"], L["spine_upper"])

# Where a limb is straight its half-plane is undefined; these hints (in the parent part's frame)
# choose it: knees bend forward, elbows backward. Slightly tilted so a limb pointing exactly
# along a hint still gets a frame.
KNEE_HINT_IN_PELVIS = normalize(np.array([1.0, 0.0, 0.2]))
ELBOW_HINT_IN_THORAX = normalize(np.array([-1.0, 0.0, -0.2]))


@dataclass
class NormalizedPoses:
    """Morphology-independent poses. Leading shape ``B`` = frames or characters.

    Attributes (quaternions scalar-last; every direction a unit vector)
    ----------
    root_position : (*B, 3) pelvis position in world divided by leg length (mean thigh+shank).
    root_heading : (*B,) yaw of the pelvis' forward axis about world Z, radians.
    pelvis_local : (*B, 4) pelvis orientation in the heading frame (``pelvis2heading``).
    hip_dir : (*B, 2, 3) pelvis origin -> hip joint, pelvis frame; [left, right] on axis -2.
    leg_frame : (*B, 2, 4) ``leg2pelvis`` half-plane frames.
    leg_fraction : (*B, 2) hip-ankle distance / (thigh + shank).
    foot_dir : (*B, 2, 3) ankle -> toe, shank frame.
    spine_points : (*B, 3, 3) spine_1, spine_2, neck in the pelvis frame / spine length: the
        control points of the spine spline (the pelvis origin is the first, implicit one).
    thorax : (*B, 4) ``thorax2pelvis``.
    neck_dir : (*B, 3) neck -> head, thorax frame.
    head : (*B, 4) ``head2thorax``.
    head_top_dir : (*B, 3) head -> head top, head frame.
    clavicle_dir : (*B, 2, 3) neck -> shoulder, thorax frame.
    arm_frame : (*B, 2, 4) ``arm2thorax`` half-plane frames.
    arm_fraction : (*B, 2) shoulder-wrist distance / (upper arm + forearm).
    hand_dir : (*B, 2, 3) wrist -> hand end, forearm frame.
    stretch : (*B, N_LENGTHS) measured / morphology length of each segment in the source
        (1 for rigid skeletons such as BVH; markers give some spread). Used only when decoding
        on the source body to reproduce the source exactly.
    """

    root_position: F64
    root_heading: F64
    pelvis_local: F64
    hip_dir: F64
    leg_frame: F64
    leg_fraction: F64
    foot_dir: F64
    spine_points: F64
    thorax: F64
    neck_dir: F64
    head: F64
    head_top_dir: F64
    clavicle_dir: F64
    arm_frame: F64
    arm_fraction: F64
    hand_dir: F64
    stretch: F64

    @property
    def batch_shape(self) -> tuple[int, ...]:
        return tuple(self.root_heading.shape)

    def arrays(self) -> dict[str, F64]:
        return {f.name: getattr(self, f.name) for f in fields(self)}

    def take(self, index: Any) -> NormalizedPoses:
        """Select along the leading axis (frames), e.g. ``poses.take(slice(0, 10))``."""
        return NormalizedPoses(**{k: v[index] for k, v in self.arrays().items()})


#: Per-field trailing shape (after the batch axes), for validation of stored files.
TRAILING_SHAPES: dict[str, tuple[int, ...]] = {
    "root_position": (3,), "root_heading": (), "pelvis_local": (4,), "hip_dir": (2, 3),
    "leg_frame": (2, 4), "leg_fraction": (2,), "foot_dir": (2, 3), "spine_points": (3, 3),
    "thorax": (4,), "neck_dir": (3,), "head": (4,), "head_top_dir": (3,),
    "clavicle_dir": (2, 3), "arm_frame": (2, 4), "arm_fraction": (2,), "hand_dir": (2, 3),
    "stretch": (N_LENGTHS,),
}
QUATERNION_FIELDS = ("pelvis_local", "leg_frame", "thorax", "head", "arm_frame")
DIRECTION_FIELDS = ("hip_dir", "foot_dir", "neck_dir", "head_top_dir", "clavicle_dir", "hand_dir")


def _in_frame(frame: F64, v: F64) -> F64:
    """Express world vectors in a frame: frame^T v. frame (..., 3, 3), v (..., 3)."""
    in_frame: F64 = np.einsum("...ji,...j->...i", frame, v)
    return in_frame


def _to_world(frame: F64, v: F64) -> F64:
    in_world: F64 = np.einsum("...ij,...j->...i", frame, v)
    return in_world


def _swap(x: F64) -> F64:
    return np.swapaxes(x, -1, -2)


def limb_frames(root: F64, mid: F64, end: F64, hint: F64) -> F64:
    """Half-plane frames: z root->end, y towards ``mid``; ``hint`` where the limb is straight.

    All (..., 3) in one frame; returns (..., 3, 3) in that frame.
    """
    axis = end - root
    return frame_from_axes(axis, mid - root, 2, 1, fallback_secondary=hint)


def distal_frames(limb: F64, mid: F64, end: F64) -> F64:
    """Shank / forearm frames: z mid->end, x the limb frame's x, y = z × x. (..., 3, 3)."""
    return frame_from_axes(end - mid, limb[..., :, 0], 2, 0, fallback_secondary=limb[..., :, 1])


def frames_from_positions(positions: F64) -> tuple[F64, F64, F64]:
    """Pelvis, thorax and head frames derived from joint positions alone (for marker data and
    authored motions, which carry no joint orientations).

    ``positions`` (..., N_JOINTS, 3) -> three (..., 3, 3) frames in world.
    """
    p = positions
    pelvis2world = frame_from_axes(p[..., J["hip_l"], :] - p[..., J["hip_r"], :],
                                   p[..., J["spine_1"], :] - p[..., J["pelvis"], :], 1, 2)
    thorax2world = frame_from_axes(p[..., J["shoulder_l"], :] - p[..., J["shoulder_r"], :],
                                   p[..., J["neck"], :] - p[..., J["spine_2"], :], 1, 2)
    head2world = frame_from_axes(p[..., J["head_top"], :] - p[..., J["head"], :],
                                 thorax2world[..., :, 1], 2, 1,
                                 fallback_secondary=thorax2world[..., :, 0])
    return pelvis2world, thorax2world, head2world


def measured_stretch(positions: F64, lengths: F64) -> F64:
    """Per-frame bone length / morphology length (1 where not a bone). -> (..., N_LENGTHS)."""
    out = np.ones(positions.shape[:-2] + (N_LENGTHS,))
    for k, (a, b) in enumerate(BONE_JOINTS):
        if a >= 0:
            out[..., k] = np.linalg.norm(positions[..., b, :] - positions[..., a, :],
                                         axis=-1) / lengths[..., k]
    return out


def encode(positions: F64, pelvis2world: F64, thorax2world: F64, head2world: F64,
           lengths: F64) -> NormalizedPoses:
    """Normalize poses (paper eq. 1).

    Parameters
    ----------
    positions : (*B, N_JOINTS, 3) canonical joint positions in world, metres, Z up.
    pelvis2world, thorax2world, head2world : (*B, 3, 3) body-part orientations.
    lengths : (N_LENGTHS,) or (*B, N_LENGTHS) the source morphology's segment lengths.
    """
    p = positions
    lengths = np.broadcast_to(lengths, p.shape[:-2] + (N_LENGTHS,))
    stretch = measured_stretch(p, lengths)
    actual = lengths * stretch
    pelvis = p[..., J["pelvis"], :]
    heading = yaw_of(pelvis2world)
    heading2world = rot_axis(2, heading)
    pelvis_local = _swap(heading2world) @ pelvis2world
    hips = p[..., SIDE_JOINTS["hip"], :]
    knees = p[..., SIDE_JOINTS["knee"], :]
    ankles = p[..., SIDE_JOINTS["ankle"], :]
    toes = p[..., SIDE_JOINTS["toe"], :]
    pw = pelvis2world[..., None, :, :]  # broadcast over sides
    leg2world = limb_frames(hips, knees, ankles, _to_world(pw, KNEE_HINT_IN_PELVIS))
    shank2world = distal_frames(leg2world, knees, ankles)
    thigh_plus_shank = actual[..., SIDE_LENGTHS["thigh"]] + actual[..., SIDE_LENGTHS["shank"]]
    spine_len = lengths[..., SPINE_LENGTHS].sum(axis=-1)
    spine_joints = p[..., [J["spine_1"], J["spine_2"], J["neck"]], :]

    neck = p[..., J["neck"], :]
    shoulders = p[..., SIDE_JOINTS["shoulder"], :]
    elbows = p[..., SIDE_JOINTS["elbow"], :]
    wrists = p[..., SIDE_JOINTS["wrist"], :]
    tw = thorax2world[..., None, :, :]
    arm2world = limb_frames(shoulders, elbows, wrists, _to_world(tw, ELBOW_HINT_IN_THORAX))
    forearm2world = distal_frames(arm2world, elbows, wrists)
    upper_plus_fore = actual[..., SIDE_LENGTHS["upper_arm"]] + actual[..., SIDE_LENGTHS["forearm"]]

    return NormalizedPoses(
        root_position=pelvis / leg_length(lengths)[..., None],
        root_heading=heading,
        pelvis_local=quat_from_matrix(pelvis_local),
        hip_dir=normalize(_in_frame(pw, hips - pelvis[..., None, :])),
        leg_frame=quat_from_matrix(_swap(pw) @ leg2world),
        leg_fraction=np.linalg.norm(ankles - hips, axis=-1) / thigh_plus_shank,
        foot_dir=normalize(_in_frame(shank2world, toes - ankles)),
        spine_points=_in_frame(pelvis2world[..., None, :, :], spine_joints - pelvis[..., None, :])
        / spine_len[..., None, None],
        thorax=quat_from_matrix(_swap(pelvis2world) @ thorax2world),
        neck_dir=normalize(_in_frame(thorax2world, p[..., J["head"], :] - neck)),
        head=quat_from_matrix(_swap(thorax2world) @ head2world),
        head_top_dir=normalize(_in_frame(head2world, p[..., J["head_top"], :] - p[..., J["head"], :])),
        clavicle_dir=normalize(_in_frame(tw, shoulders - neck[..., None, :])),
        arm_frame=quat_from_matrix(_swap(tw) @ arm2world),
        arm_fraction=np.linalg.norm(wrists - shoulders, axis=-1) / upper_plus_fore,
        hand_dir=normalize(_in_frame(forearm2world, p[..., SIDE_JOINTS["hand"], :] - wrists)),
        stretch=stretch,
    )


@dataclass
class DecodedPose:
    """World-space result of :func:`decode`; leading shape ``B``.

    positions : (*B, N_JOINTS, 3) metres, world Z up.
    pelvis2world, thorax2world, head2world : (*B, 3, 3).
    leg2world, arm2world : (*B, 2, 3, 3) half-plane frames [left, right].
    """

    positions: F64
    pelvis2world: F64
    thorax2world: F64
    head2world: F64
    leg2world: F64
    arm2world: F64

    def take(self, index: Any) -> DecodedPose:
        """Select along the leading axis (a copy for an index array)."""
        return DecodedPose(self.positions[index], self.pelvis2world[index], self.thorax2world[index],
                           self.head2world[index], self.leg2world[index], self.arm2world[index])


def two_sphere_middle(upper: F64, lower: F64, span: F64, tiny: float = 1e-12) -> tuple[F64, F64]:
    """Where the middle joint (knee, elbow) of a limb lies in its half-plane: the intersection of
    the spheres of radius ``upper`` about the root and ``lower`` about the end, ``span`` from the
    root along z. Returns (y, z), each (...), metres; ``span`` (...) should lie within
    ``[|upper - lower|, upper + lower]`` (divisions use at least ``tiny``)."""
    z = (upper**2 - lower**2 + span**2) / (2.0 * np.maximum(span, tiny))
    y = np.sqrt(np.maximum(upper**2 - z**2, 0.0))
    return y, z


def two_bone_middle(limb2world: F64, root: F64, upper: F64, lower: F64, reach: F64) -> tuple[F64, F64]:
    """Knee or elbow by the two-sphere intersection in the half-plane (paper §8).

    ``reach`` (the root-end distance) is clamped to what the two bones can span.
    Returns (middle joint, end joint), each (..., 3). Shapes: frames (..., 3, 3), others (...).
    """
    reach = np.clip(reach, np.abs(upper - lower), upper + lower)
    y, z = two_sphere_middle(upper, lower, reach, 1e-9)
    middle = root + limb2world[..., :, 1] * y[..., None] + limb2world[..., :, 2] * z[..., None]
    end = root + limb2world[..., :, 2] * reach[..., None]
    return middle, end


def _span_coefficients(control: F64) -> F64:
    """Polynomial coefficients of the uniform Catmull-Rom spline through ``control`` (..., 4, 3).

    ``t`` in [0, 3] runs through the four control points (at 0, 1, 2, 3) in three spans; end
    tangents come from mirrored phantom points; beyond 3 the curve continues straight along its
    end tangent, the fourth span. Returns (..., 4 spans, 4 powers, 3) with point = Σ c_k u^k."""
    q = control
    padded = np.concatenate([2 * q[..., :1, :] - q[..., 1:2, :], q,
                             2 * q[..., 3:, :] - q[..., 2:3, :]], axis=-2)  # (..., 6, 3)
    p0, p1, p2, p3 = padded[..., 0:3, :], padded[..., 1:4, :], padded[..., 2:5, :], padded[..., 3:6, :]
    spans = np.stack([p1, 0.5 * (p2 - p0), 0.5 * (2 * p0 - 5 * p1 + 4 * p2 - p3),
                      0.5 * (3 * p1 - p0 - 3 * p2 + p3)], axis=-2)  # (..., 3, 4, 3)
    end = q[..., 3, :]
    extension = np.stack([end, end - q[..., 2, :], np.zeros_like(end), np.zeros_like(end)], axis=-2)
    return np.concatenate([spans, extension[..., None, :, :]], axis=-3)


def _curve_at(coefficients: F64, t: F64) -> tuple[F64, F64]:
    """Point and tangent (d/dt) at one parameter per batch element; t >= 3 is the extension.

    ``coefficients`` from :func:`_span_coefficients`, ``t`` (...) -> two (..., 3) arrays.
    """
    span = np.minimum(np.floor(np.maximum(t, 0.0)), 3.0).astype(np.int64)
    u = (t - span)[..., None]
    flat = coefficients.reshape((-1,) + coefficients.shape[-3:])
    c = flat[np.arange(flat.shape[0]), span.reshape(-1)].reshape(t.shape + (4, 3))
    point = c[..., 0, :] + u * (c[..., 1, :] + u * (c[..., 2, :] + u * c[..., 3, :]))
    tangent = c[..., 1, :] + u * (2 * c[..., 2, :] + 3 * u * c[..., 3, :])
    return point, tangent


def spine_joints(control: F64, segment_lengths: F64, iterations: int = 6) -> F64:
    """Vertebra joints along the spine spline at the given chord lengths (paper §8).

    Walks from the first control point: each joint is the point along the curve at exactly its
    segment's distance from the previous joint (Newton's method on the curve parameter, started
    where the lengths' proportions put it), so bone lengths are exact; with the encoding
    morphology the joints land on the control points.

    control : (..., 4, 3) spline control points (first = pelvis origin).
    segment_lengths : (..., n) chord lengths, metres. Returns (..., n, 3).
    """
    batch = control.shape[:-2]
    coefficients = _span_coefficients(control)
    chords = np.linalg.norm(np.diff(control, axis=-2), axis=-1)  # (..., 3)
    prev_t = np.zeros(batch)
    prev_p = control[..., 0, :]
    out = []
    for k in range(segment_lengths.shape[-1]):
        length = segment_lengths[..., k]
        t = prev_t + length / np.maximum(chords[..., min(k, 2)], 1e-9)  # exact if they match
        point, tangent = _curve_at(coefficients, t)
        for _ in range(iterations):
            d = point - prev_p
            g = np.sum(d * d, axis=-1) - length**2
            if np.all(np.abs(g) <= 1e-13 * length**2):  # converged (quadratically) everywhere
                break
            slope = 2.0 * np.sum(d * tangent, axis=-1)
            safe = np.abs(slope) > 1e-12
            t = np.clip(t - np.where(safe, g / np.where(safe, slope, 1.0), 0.0), prev_t + 1e-6, 9.0)
            point, tangent = _curve_at(coefficients, t)
        point = _at_distance(prev_p, point, tangent, length)
        prev_t = t
        prev_p = point
        out.append(prev_p)
    return np.stack(out, axis=-2)


def _at_distance(start: F64, point: F64, tangent: F64, length: F64) -> F64:
    """``point`` moved along the ray from ``start`` to exactly ``length`` from it, (..., 3).

    Newton lands on the curve at the bone's length wherever the spline is well formed; where it
    did not converge (a spline folded on itself, as between two frames whose spines point
    opposite ways in the pelvis frame) the joint keeps the direction it reached, so bones stay
    exact whatever the control points (the curve's tangent, then the z axis of the frame the
    control points are in, when that direction is undefined).
    """
    offset = point - start
    up = np.zeros_like(offset)
    up[..., 2] = 1.0
    has_offset = np.linalg.norm(offset, axis=-1, keepdims=True) > 1e-9
    has_tangent = np.linalg.norm(tangent, axis=-1, keepdims=True) > 1e-9
    direction = np.where(has_offset, normalize(offset), np.where(has_tangent, normalize(tangent), up))
    return start + direction * length[..., None]


def vertebrae(poses: NormalizedPoses, lengths: F64, count: int) -> F64:
    """``count`` evenly spaced vertebra joints along each spine (paper §8: the spline "could be
    subdivided into as many segments as wished"), from the pelvis origin to the neck.

    Each of the ``count`` segments has the same chord length, a ``count``-th of the body's spine
    length. Returns (*B, count, 3) world positions (the last one is the neck base when the
    body's spine proportions match the motion's, and close to it otherwise).
    """
    if count < 1:
        raise ValueError(f"count must be >= 1, got {count}")
    batch = poses.batch_shape
    base = np.broadcast_to(lengths, batch + (N_LENGTHS,))
    spine_len = base[..., SPINE_LENGTHS].sum(axis=-1)
    control = np.concatenate([np.zeros(batch + (1, 3)),
                              poses.spine_points * spine_len[..., None, None]], axis=-2)
    local = spine_joints(control, np.repeat((spine_len / count)[..., None], count, axis=-1))
    pelvis2world = rot_axis(2, poses.root_heading) @ matrix_from_quat(poses.pelvis_local)
    pelvis = poses.root_position * leg_length(base)[..., None]
    return pelvis[..., None, :] + _to_world(pelvis2world[..., None, :, :], local)


@dataclass
class DecodedLegs:
    """Leg joints of :func:`decode_legs`: each (*B, 2, 3) [left, right], frames (*B, 2, 3, 3)."""

    pelvis: F64
    pelvis2world: F64
    hips: F64
    knees: F64
    ankles: F64
    toes: F64
    leg2world: F64
    shank2world: F64


def decode_legs(poses: NormalizedPoses, seg: F64, base: F64) -> DecodedLegs:
    """The root and both legs only (what ground adaptation needs), from segment lengths ``seg``
    (*B, N_LENGTHS) and the unstretched ``base`` lengths that normalize the root."""
    pelvis2world = rot_axis(2, poses.root_heading) @ matrix_from_quat(poses.pelvis_local)
    pelvis = poses.root_position * leg_length(base)[..., None]
    pw = pelvis2world[..., None, :, :]
    hips = pelvis[..., None, :] + _to_world(pw, poses.hip_dir) * seg[..., SIDE_LENGTHS["pelvis"]][..., None]
    leg2world = pw @ matrix_from_quat(poses.leg_frame)
    thigh, shank = seg[..., SIDE_LENGTHS["thigh"]], seg[..., SIDE_LENGTHS["shank"]]
    knees, ankles = two_bone_middle(leg2world, hips, thigh, shank,
                                    poses.leg_fraction * (thigh + shank))
    shank2world = distal_frames(leg2world, knees, ankles)
    toes = ankles + _to_world(shank2world, poses.foot_dir) * seg[..., SIDE_LENGTHS["foot"]][..., None]
    return DecodedLegs(pelvis, pelvis2world, hips, knees, ankles, toes, leg2world, shank2world)


def decode(poses: NormalizedPoses, lengths: F64, use_stretch: bool = False) -> DecodedPose:
    """Joint positions of normalized poses on a body (paper eq. 2 and §8).

    ``lengths`` (N_LENGTHS,) or (*B, N_LENGTHS). ``use_stretch`` applies the source's measured
    per-frame segment stretch: only meaningful on the source morphology, where it reproduces the
    source exactly even if its segments were not rigid.
    """
    batch = poses.batch_shape
    base = np.broadcast_to(lengths, batch + (N_LENGTHS,))
    seg = base * poses.stretch if use_stretch else base
    out = np.empty(batch + (N_JOINTS, 3))
    legs = decode_legs(poses, seg, base)
    pelvis, pelvis2world, leg2world = legs.pelvis, legs.pelvis2world, legs.leg2world
    out[..., J["pelvis"], :] = pelvis
    out[..., SIDE_JOINTS["hip"], :] = legs.hips
    out[..., SIDE_JOINTS["knee"], :] = legs.knees
    out[..., SIDE_JOINTS["ankle"], :] = legs.ankles
    out[..., SIDE_JOINTS["toe"], :] = legs.toes

    spine_len = base[..., SPINE_LENGTHS].sum(axis=-1)
    control = np.concatenate([np.zeros(batch + (1, 3)), poses.spine_points * spine_len[..., None, None]],
                             axis=-2)
    spine_local = spine_joints(control, seg[..., SPINE_LENGTHS])
    spine_world = pelvis[..., None, :] + _to_world(pelvis2world[..., None, :, :], spine_local)
    out[..., [J["spine_1"], J["spine_2"], J["neck"]], :] = spine_world
    neck = spine_world[..., 2, :]

    thorax2world = pelvis2world @ matrix_from_quat(poses.thorax)
    head2world = thorax2world @ matrix_from_quat(poses.head)
    head = neck + _to_world(thorax2world, poses.neck_dir) * seg[..., L["neck"]][..., None]
    out[..., J["head"], :] = head
    out[..., J["head_top"], :] = head + _to_world(head2world, poses.head_top_dir) * seg[..., L["head"]][..., None]

    tw = thorax2world[..., None, :, :]
    shoulders = neck[..., None, :] + _to_world(tw, poses.clavicle_dir) * seg[..., SIDE_LENGTHS["clavicle"]][..., None]
    arm2world = tw @ matrix_from_quat(poses.arm_frame)
    upper, fore = seg[..., SIDE_LENGTHS["upper_arm"]], seg[..., SIDE_LENGTHS["forearm"]]
    elbows, wrists = two_bone_middle(arm2world, shoulders, upper, fore,
                                     poses.arm_fraction * (upper + fore))
    forearm2world = distal_frames(arm2world, elbows, wrists)
    hands = wrists + _to_world(forearm2world, poses.hand_dir) * seg[..., SIDE_LENGTHS["hand"]][..., None]
    out[..., SIDE_JOINTS["shoulder"], :] = shoulders
    out[..., SIDE_JOINTS["elbow"], :] = elbows
    out[..., SIDE_JOINTS["wrist"], :] = wrists
    out[..., SIDE_JOINTS["hand"], :] = hands
    return DecodedPose(out, pelvis2world, thorax2world, head2world, leg2world, arm2world)
