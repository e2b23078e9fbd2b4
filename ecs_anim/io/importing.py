"""From a captured BVH clip to a :class:`~ecs_anim.motion.clip.NormalizedMotion` (the off-line step).

parse -> map joints -> detect units -> forward kinematics (all frames at once) -> Y-up to Z-up
-> canonical joint positions and part orientations -> source morphology -> encode -> contacts.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, replace
from itertools import pairwise
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from ecs_anim.core.errors import EcsAnimError, InputError, listed
from ecs_anim.core.morphology import (
    ADULT_PROPORTIONS,
    MAX_STATURE_M,
    MIN_STATURE_M,
    Morphology,
    bone_lengths_of,
)
from ecs_anim.core.normalized import encode
from ecs_anim.core.rotations import frame_from_axes, normalize
from ecs_anim.core.skeleton import JOINT_INDEX as J
from ecs_anim.core.skeleton import JOINTS, LENGTH_INDEX, N_JOINTS
from ecs_anim.io.bvh import BvhMotion, BvhSkeleton, forward_kinematics, read_bvh, rest_positions
from ecs_anim.io.capture_ground import capture_ground
from ecs_anim.io.contacts import (
    ContactThresholds,
    contact_constraints,
    contacts_from_events,
    detect_foot_contacts,
    leg_of,
    rigid_legs,
    treadmill_belt,
)
from ecs_anim.io.joint_map import JointMap, map_skeleton, unused_joints
from ecs_anim.motion.clip import NormalizedMotion

F64 = NDArray[np.float64]

#: DESIGN §2: a Y-up source becomes Z-up by +90° about X: (x, y, z) -> (x, -z, y).
YUP_TO_ZUP = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, 1.0, 0.0]])
#: An X-up source (some labs' C3D, rare BVH) turns its axes round: (x, y, z) -> (y, z, x).
XUP_TO_ZUP = np.array([[0.0, 1.0, 0.0], [0.0, 0.0, 1.0], [1.0, 0.0, 0.0]])

#: Length units a BVH may be written in, as metres per unit.
UNITS: dict[str, float] = {
    "m": 1.0,
    "cm": 0.01,
    "mm": 0.001,
    "inch": 0.0254,
    "cmu": 0.0254 / 0.45,  # CMU ASF length unit: 1/0.45 inch
}
#: Thigh + shank of an adult, the yardstick for telling units apart (m).
TYPICAL_LEG_M = 0.80
PLAUSIBLE_LEG_M = (0.25, 1.4)

# Lengths of parts a skeleton may lack, as fractions of its thigh + shank.
_LEG = ADULT_PROPORTIONS["thigh"] + ADULT_PROPORTIONS["shank"]
FILL_FRACTION = {
    "toe": ADULT_PROPORTIONS["foot"] / _LEG,
    "hand": ADULT_PROPORTIONS["hand"] / _LEG,
    "head_top": ADULT_PROPORTIONS["head"] / _LEG,
    "ankle_height": ADULT_PROPORTIONS["ankle_height"] / _LEG,
}


@dataclass
class CanonicalClip:
    """A source clip resampled onto the canonical skeleton, in metres, world Z up.

    positions : (n_frames, N_JOINTS, 3).
    pelvis2world, thorax2world, head2world : (n_frames, 3, 3).
    measured : (N_JOINTS,) bool, True where the joint comes straight from the source (False where
        it was filled in: interpolated spine joints, toes/hands/head top from orientations).
    """

    positions: F64
    pelvis2world: F64
    thorax2world: F64
    head2world: F64
    measured: NDArray[np.bool_]
    fps: float
    unit: str
    unit_reason: str
    joint_map: JointMap
    up_axis: str = "y"
    up_reason: str = ""
    warnings: tuple[str, ...] = ()
    #: Source joints no canonical part uses (:func:`~ecs_anim.io.joint_map.unused_joints`).
    ignored: tuple[str, ...] = ()
    #: The toe joints were filled in rigidly with the ankles (a joint-positions layout without
    #: toes): contact detection finds touch-downs by the ankle
    #: (:func:`~ecs_anim.io.contacts.detect_foot_contacts`).
    toes_follow_ankle: bool = False


#: The largest frame number or seconds ``--trim`` takes (a day at 10,000 fps is under 1e9).
MAX_TRIM = 1e9


@dataclass(frozen=True)
class FrameRange:
    """``import --trim START:END``: the frames kept, from ``start`` up to (not including) ``stop``;
    each a frame number of the file (seconds from its first frame when ``seconds``), negative
    from the clip's end, None for the clip's own start or end (Python slice rules)."""

    start: float | None
    stop: float | None
    seconds: bool = False

    @classmethod
    def parse(cls, text: str) -> FrameRange:
        """``"1:"`` (drop a T-pose frame), ``":-30"``, ``"0.5s:12s"``; raises ValueError."""
        if text.count(":") != 1:
            raise ValueError(f"--trim {text!r}: expected START:END (frames, or seconds with s)")
        ends = [part.strip() for part in text.split(":")]
        in_seconds = {part.endswith("s") for part in ends if part}
        if len(in_seconds) > 1:
            raise ValueError(f"--trim {text!r}: give both ends in frames or both in seconds")
        seconds = in_seconds == {True}
        values: list[float | None] = []
        for part in ends:
            number = part[:-1] if seconds and part else part
            if not part:
                values.append(None)
                continue
            if not number:
                raise ValueError(f"--trim {text!r}: {part!r} has no number")
            try:
                value = float(number) if seconds else int(number)
            except ValueError:
                raise ValueError(f"--trim {text!r}: {part!r} is not a "
                                 f"{'number of seconds' if seconds else 'frame number'}") from None
            if not math.isfinite(value) or abs(value) > MAX_TRIM:
                raise ValueError(f"--trim {text!r}: {part!r} is beyond {MAX_TRIM:g}")
            values.append(value)
        return cls(values[0], values[1], seconds)

    def frames(self, n_frames: int, fps: float, first_frame: int = 0) -> slice:
        """The kept frames of a clip of ``n_frames`` whose frame 0 is the file's ``first_frame``
        (a C3D import may have trimmed some); raises :class:`EcsAnimError` when nothing is left."""
        def index(value: float | None, default: int) -> int:
            if value is None:
                return default
            frame = round(value * fps) if self.seconds else int(value)
            return frame + n_frames if frame < 0 else frame - first_frame

        start = min(max(index(self.start, 0), 0), n_frames)
        stop = min(max(index(self.stop, n_frames), 0), n_frames)
        if stop - start < 1:
            raise EcsAnimError(f"--trim keeps no frame of the {n_frames} "
                             f"(frames {first_frame}-{first_frame + n_frames - 1} of the file)")
        return slice(start, stop)


def trim_clip(clip: CanonicalClip, frames: slice) -> CanonicalClip:
    """The clip's frames ``frames`` only (everything per frame sliced alike)."""
    return replace(clip, positions=clip.positions[frames], pelvis2world=clip.pelvis2world[frames],
                   thorax2world=clip.thorax2world[frames], head2world=clip.head2world[frames])


#: A leading rest pose (a converter's T-pose frame) is told from the motion by the jump to the
#: first captured frame: within the first second, the frame-to-frame move of the joints,
#: averaged over them (m; the mean, so one joint's glitch later in a clip does not hide the
#: jump), must be at least this many times the 99th percentile of the same move over the frames
#: after it (measured on ../shared/mocap and varied/: 3.0-19.4 with a rest pose, at most 1.5
#: without),
REST_JUMP_RATIO = 2.2
#: and at least this fraction of the leg (thigh + shank), so a clip that starts after a still
#: moment is not cut for a small move (0.13-0.31 with a rest pose; 0.04 at most where the ratio
#: passes 1.2 without one; fast motion reaches 0.18 at a ratio of 1.0).
REST_JUMP_LEG_FRACTION = 0.08


@dataclass(frozen=True)
class RestFrames:
    """Frames 0 to ``count - 1`` of a clip come before its motion (a rest pose): the joints move
    ``jump_m`` metres on average from frame ``count - 1`` to frame ``count``."""

    count: int
    jump_m: float

    def report(self, first_file_frame: int = 0) -> str:
        """The import's line saying what was dropped, frames numbered as in the file (the clip's
        frame 0 is the file's ``first_file_frame``) and how to keep them."""
        first, last = first_file_frame, first_file_frame + self.count - 1
        frames = f"frame {first}" if first == last else f"frames {first}-{last}"
        return (f"dropped {frames}: a rest pose (T-pose) before the motion, the joints jump "
                f"{self.jump_m:.2f} m on average to frame {last + 1}; --trim {first}: keeps it")


#: A glitch: the root further than this many leg lengths (thigh + shank) from where the frames
#: around it put it (the running median of its position), or a joint this far from the root: no
#: body moves so far in a few frames (on every dev file the pelvis keeps within 0.41 legs of that
#: median, a run's, and a joint within 1.5 legs of the pelvis), so such frames are a capture's or
#: converter's error.
GLITCH_LEGS = 4.0
#: Runs of glitch frames up to this long are found and repaired between the frames around
#: them (seconds; at least :data:`GLITCH_MIN_FRAMES`): a longer jump that stays is motion cut
#: together, not a glitch.
GLITCH_MAX_S = 0.2
GLITCH_MIN_FRAMES = 5


@dataclass(frozen=True)
class GlitchFrames:
    """Frames where the clip jumps further than a body moves and back
    (:func:`glitch_frames`): ``repaired`` runs (first, last) between good frames, replaced from
    them; ``dropped_start`` / ``dropped_end`` frames at the clip's ends, with no good frame on
    one side, cut; ``farthest_m`` the farthest a joint was put from its place."""

    repaired: tuple[tuple[int, int], ...]
    dropped_start: int
    dropped_end: int
    farthest_m: float

    def report(self, n_frames: int, first_file_frame: int = 0) -> str:
        """The import's line saying what was repaired or cut, frames numbered as in the file (the
        clip's frame 0, before the cut, is the file's ``first_file_frame``)."""
        def span(a: int, b: int) -> str:
            a, b = a + first_file_frame, b + first_file_frame
            return f"frame {a}" if a == b else f"frames {a}-{b}"
        parts = []
        if self.repaired:
            parts.append("repaired " + ", ".join(
                f"{span(a, b)} (from frames {a - 1 + first_file_frame} and "
                f"{b + 1 + first_file_frame})" for a, b in self.repaired))
        if self.dropped_start:
            parts.append(f"dropped {span(0, self.dropped_start - 1)}")
        if self.dropped_end:
            parts.append(f"dropped {span(n_frames - self.dropped_end, n_frames - 1)}")
        return (f"{' and '.join(parts)}: glitches, the body put up to {self.farthest_m:.4g} m "
                f"from the frames around them (over {GLITCH_LEGS:g} leg lengths, which no body "
                "moves in a few frames)")


def glitch_frames(positions: F64, fps: float
                  ) -> tuple[NDArray[np.bool_], NDArray[np.bool_], float]:
    """Which frames are glitches, which of them tear the body apart, and how far (m) the worst
    puts a joint from its place: the pelvis further than :data:`GLITCH_LEGS` legs from the
    running median of its position over the :data:`GLITCH_MAX_S` on each side (a run up to that
    long is outvoted by the frames around it; a jump that stays is not), or a joint that far
    from the pelvis (the body torn apart).

    ``positions`` (n_frames, N_JOINTS, 3): canonical joint positions, metres. Returns
    ((n_frames,) bool glitch, (n_frames,) bool torn, metres)."""
    n = len(positions)
    leg = leg_of(positions) if n >= 3 else 0.0
    if not leg > 0:  # too short to tell, or legs of no length (said by the import's checks)
        return np.zeros(n, dtype=bool), np.zeros(n, dtype=bool), 0.0
    half = max(GLITCH_MIN_FRAMES, math.ceil(GLITCH_MAX_S * fps))
    pelvis = positions[:, J["pelvis"]]
    padded = np.pad(pelvis, ((half, half), (0, 0)), mode="reflect" if n > half else "edge")
    windows = np.lib.stride_tricks.sliding_window_view(padded, 2 * half + 1, axis=0)  # (n, 3, w)
    off_root = np.linalg.norm(pelvis - np.median(windows, axis=-1), axis=-1)  # (n,)
    off_body = np.max(np.linalg.norm(positions - pelvis[:, None], axis=-1), axis=1)  # (n,)
    far = np.maximum(off_root, off_body)
    glitch = far > GLITCH_LEGS * leg
    return glitch, off_body > GLITCH_LEGS * leg, float(far[glitch].max()) if glitch.any() else 0.0


def repair_glitches(clip: CanonicalClip) -> tuple[CanonicalClip, GlitchFrames | None]:
    """The clip with its glitch frames (:func:`glitch_frames`) repaired or cut: a run between
    good frames is moved onto the straight line between them: the whole body with its pelvis
    where only the root jumped (the pose kept), else each joint (each part's orientation from
    the nearer good frame); a run at either end is cut. Returns the clip and what was done
    (None: no glitch, the clip unchanged). Raises :class:`EcsAnimError` when fewer than two
    frames are good."""
    glitch, torn, farthest = glitch_frames(clip.positions, clip.fps)
    if not glitch.any():
        return clip, None
    good = np.flatnonzero(~glitch)
    if len(good) < 2:
        raise EcsAnimError(f"{len(glitch) - len(good)} of {len(glitch)} frames put the body more "
                           f"than {GLITCH_LEGS:g} leg lengths from the frames around them: no "
                           "motion to import; check the file's root positions")
    start, stop = int(good[0]), int(good[-1]) + 1
    inside = np.flatnonzero(glitch[start:stop]) + start
    positions = clip.positions.copy()
    frames = {k: getattr(clip, k).copy() for k in ("pelvis2world", "thorax2world", "head2world")}
    if len(inside):
        after = good[np.searchsorted(good, inside)]  # the next good frame, (k,)
        before = good[np.searchsorted(good, inside) - 1]
        w = ((inside - before) / (after - before))[:, None, None]
        line = (1 - w) * positions[before] + w * positions[after]  # (k, N_JOINTS, 3)
        pelvis = positions[inside, J["pelvis"]][:, None]
        moved = positions[inside] - pelvis + line[:, J["pelvis"]][:, None]
        positions[inside] = np.where(torn[inside, None, None], line, moved)
        nearer = np.where(w[:, 0, 0] <= 0.5, before, after)
        for value in frames.values():
            value[inside] = np.where(torn[inside, None, None], value[nearer], value[inside])
    repaired = tuple((int(a), int(b)) for a, b in _runs(inside))
    fixed = replace(clip, positions=positions, **frames)
    report = GlitchFrames(repaired, start, len(glitch) - stop, farthest)
    return trim_clip(fixed, slice(start, stop)), report


def _runs(frames: NDArray[np.intp]) -> list[tuple[int, int]]:
    """Sorted frame numbers as runs of consecutive ones, (first, last) each."""
    if not len(frames):
        return []
    breaks = np.flatnonzero(np.diff(frames) > 1)
    firsts = np.concatenate([[frames[0]], frames[breaks + 1]])
    lasts = np.concatenate([frames[breaks], [frames[-1]]])
    return list(zip(firsts.tolist(), lasts.tolist(), strict=True))


def leading_rest_frames(positions: F64, fps: float) -> RestFrames | None:
    """The rest pose a converter put before the motion (CMU's T-pose frame 0, with any frames
    it then ramps or holds through), if any: a jump within the first second that is many times
    the clip's own fast frame-to-frame motion after it and a part of the leg
    (:data:`REST_JUMP_RATIO`, :data:`REST_JUMP_LEG_FRACTION`). None when the clip starts with
    its motion.

    ``positions`` (n_frames, N_JOINTS, 3): canonical joint positions, metres.
    """
    if len(positions) < 3:
        return None
    move = np.mean(np.linalg.norm(np.diff(positions, axis=0), axis=-1), axis=1)  # (n_frames - 1,)
    # A glitch's jumps are no rest pose's (:func:`glitch_frames`; repaired before, on import).
    glitch, _, _ = glitch_frames(positions, fps)
    move[glitch[:-1] | glitch[1:]] = 0.0
    jump = int(np.argmax(move[:max(1, min(round(fps), len(move) - 1))]))
    fast_after = float(np.percentile(move[jump + 1:], 99))
    leg = 0.5 * sum(float(np.median(np.linalg.norm(positions[:, J[f"{upper}_{s}"]]
                                                   - positions[:, J[f"{lower}_{s}"]], axis=-1)))
                    for s in "lr" for upper, lower in (("hip", "knee"), ("knee", "ankle")))
    if move[jump] >= REST_JUMP_RATIO * fast_after and move[jump] >= REST_JUMP_LEG_FRACTION * leg:
        return RestFrames(jump + 1, float(move[jump]))
    return None


def detect_unit(leg_in_file_units: float) -> tuple[str, str]:
    """Pick the unit that gives a human leg (thigh + shank) closest to 0.8 m.

    Returns (unit name, a sentence saying why, naming a close runner-up so a child in
    centimetres read as an adult in inches is caught). Raises :class:`EcsAnimError` if no unit
    fits.
    """
    if not (math.isfinite(leg_in_file_units) and leg_in_file_units > 0):
        raise EcsAnimError("cannot tell the length unit: the legs have zero length in the rest pose")
    scored = []
    for name, scale in UNITS.items():
        leg_m = leg_in_file_units * scale
        if PLAUSIBLE_LEG_M[0] <= leg_m <= PLAUSIBLE_LEG_M[1]:
            scored.append((abs(math.log(leg_m / TYPICAL_LEG_M)), name, leg_m))
    if not scored:
        raise EcsAnimError(
            f"cannot tell the length unit: thigh + shank is {leg_in_file_units:g} file units, "
            f"which is no human leg in {', '.join(UNITS)}; give --unit")
    scored.sort()
    _, name, leg_m = scored[0]
    reason = f"thigh + shank = {leg_in_file_units:.4g} units = {leg_m:.3f} m in {name}"
    if len(scored) > 1 and scored[1][0] - scored[0][0] < 0.5:
        _, other, other_m = scored[1]
        reason += f"; {other} ({other_m:.3f} m) is also plausible: give --unit {other} if so"
    return name, reason


def _leg_rest_length(skeleton: BvhSkeleton, jmap: JointMap) -> float:
    rest = rest_positions(skeleton)
    total = 0.0
    for s in "lr":
        hip, knee, ankle = (jmap.source[f"{p}_{s}"] for p in ("hip", "knee", "ankle"))
        total += float(np.linalg.norm(rest[knee] - rest[hip]) + np.linalg.norm(rest[ankle] - rest[knee]))
    return 0.5 * total


#: Two joints closer than this fraction of the leg at rest are at the same place (no bone).
SAME_PLACE_FRACTION = 1e-3

#: A file's up axis -> the rotation taking its axes to ours (Z up). A negative axis is a file
#: upside down along the positive one (an image convention, Y down): first turned 180° about an
#: axis across it, then as the positive one, so it is a rotation, never a mirror.
UP_AXES = {"x": XUP_TO_ZUP, "y": YUP_TO_ZUP, "z": np.eye(3),
           "-x": XUP_TO_ZUP @ np.diag([-1.0, -1.0, 1.0]),
           "-y": YUP_TO_ZUP @ np.diag([1.0, -1.0, -1.0]),
           "-z": np.diag([1.0, -1.0, -1.0])}


def up_axis(text: str) -> str:
    """``--up``'s value as a key of :data:`UP_AXES` (``+y`` -> ``y``, ``-Y`` -> ``-y``); raises
    :class:`EcsAnimError` for anything else."""
    key = text.strip().lower().removeprefix("+")
    if key not in UP_AXES:
        raise EcsAnimError(f"--up {text}: expected {', '.join(UP_AXES)} (the axis the head points "
                           "along from the feet; -y for a file upside down, Y pointing down)")
    return key


def unit_scale(unit: str) -> float:
    """Metres per file unit for ``--unit``: a name of :data:`UNITS` or a positive number
    (``0.0254``); raises :class:`EcsAnimError` otherwise."""
    if unit in UNITS:
        return UNITS[unit]
    try:
        scale = float(unit)
    except ValueError:
        scale = math.nan
    if not (math.isfinite(scale) and scale > 0):
        raise EcsAnimError(f"--unit {unit}: expected one of {', '.join(UNITS)} or a positive "
                           "number of metres per file unit (0.0254 for inches)")
    return scale


#: A person's legs hang below the spine: hips-to-ankles against pelvis-to-neck at a cosine under
#: this, in the rest pose or in most frames (a seated rider: -0.6; standing, walking: -0.99). A
#: skeleton whose legs stand square to its spine in both (cosine about 0) is built on all fours.
HUMAN_LEGS_TO_SPINE_COS = -0.3


def legs_to_spine_cos(positions: F64, src: dict[str, int | None]) -> F64:
    """Cosine between the legs (hips' middle to ankles' middle) and the spine (pelvis to neck)
    of joint positions (..., n_joints, 3), ``src`` our joints' indices in them; NaN where either
    has no length (a degenerate pose shows nothing) or a joint is not in them. -> (...)."""
    ends = [src[j] for j in ("neck", "pelvis", "ankle_l", "ankle_r", "hip_l", "hip_r")]
    if any(i is None for i in ends):
        return np.full(positions.shape[:-2], np.nan)
    spine = positions[..., src["neck"], :] - positions[..., src["pelvis"], :]
    legs = 0.5 * (positions[..., src["ankle_l"], :] + positions[..., src["ankle_r"], :]
                  - positions[..., src["hip_l"], :] - positions[..., src["hip_r"], :])
    norms = np.linalg.norm(spine, axis=-1) * np.linalg.norm(legs, axis=-1)
    shown = norms > 1e-12 * max(float(np.abs(positions).max(initial=0.0)), 1.0) ** 2
    cos: F64 = np.where(shown, np.sum(spine * legs, axis=-1) / np.where(shown, norms, 1.0), np.nan)
    return cos


def check_human_build(skeleton: BvhSkeleton, jmap: JointMap, pos_file: F64) -> None:
    """Refuse a skeleton that is not a person's (issue 31, class 4: a quadruped with
    human-looking names): its legs stand square to its spine (:data:`HUMAN_LEGS_TO_SPINE_COS`)
    both in the rest pose and in most frames. A person crawling has an upright rest pose; a
    converter's degenerate rest pose still has upright frames."""
    src = jmap.source
    rest = float(legs_to_spine_cos(rest_positions(skeleton), src))
    per_frame = legs_to_spine_cos(pos_file, src)
    frames = float(np.median(per_frame[np.isfinite(per_frame)])) if np.isfinite(per_frame).any() \
        else math.nan
    # NaN compares False: a degenerate pose (every joint on one point) refuses nothing here.
    if rest > HUMAN_LEGS_TO_SPINE_COS and frames > HUMAN_LEGS_TO_SPINE_COS:
        angle = math.degrees(math.acos(min(max(frames, -1.0), 1.0)))
        raise EcsAnimError(f"not a human skeleton: its legs stand at {angle:.0f} degrees to its "
                           "spine in the rest pose and the frames, not below it (a four-legged "
                           "animal?); ecs_anim animates people, nothing imported")


def detect_up(skeleton: BvhSkeleton, jmap: JointMap, pos_file: F64) -> tuple[str, str]:
    """The file's up axis, ``"y"``, ``"z"``, ``"-y"`` or ``"-z"``, with a sentence saying why: the
    way along which the head stands above the feet, in the rest pose (the spine from pelvis to
    neck) and over the clip's frames (the head above the lower ankle), each as a fraction of its
    length, summed per way (a negative axis is a file upside down, as in an image's convention,
    Y down: the head below the feet along the positive one). When the best way leads the other
    axis's by under 0.2 (the rest pose and the frames disagree), the frames decide if they show
    it along one way only (median over 0.5); and the head must stand above the feet in most
    frames along the way chosen where another way has it so in two thirds of them.

    ``pos_file`` (n_frames, n_joints, 3): joint positions in file axes. A tie or no way showing
    the head above the feet keeps the BVH convention, Y up, and says so.
    """
    src = jmap.source
    rest = rest_positions(skeleton)
    spine = normalize(rest[src["neck"]] - rest[src["pelvis"]])
    head = pos_file[:, src["head"]]
    # Per way: (the rest pose's spine along it, the frames' median rise of the head over the
    # feet, the share of frames where the head is clearly above the feet along it).
    rise: dict[str, tuple[float, float, float]] = {}
    for axis, k in (("y", 1), ("z", 2)):
        feet_low = np.minimum(pos_file[:, src["ankle_l"], k], pos_file[:, src["ankle_r"], k])
        feet_high = np.maximum(pos_file[:, src["ankle_l"], k], pos_file[:, src["ankle_r"], k])
        reach = np.maximum(np.linalg.norm(
            head - 0.5 * (pos_file[:, src["ankle_l"]] + pos_file[:, src["ankle_r"]]), axis=-1), 1e-12)
        above = (head[:, k] - feet_low) / reach
        below = (feet_high - head[:, k]) / reach  # the head's rise along -axis
        rise[axis] = (float(spine[k]), float(np.median(above)), float(np.mean(above > 0.5)))
        rise[f"-{axis}"] = (-float(spine[k]), float(np.median(below)), float(np.mean(below > 0.5)))
    score = {way: r[0] + r[1] for way, r in rise.items()}

    def rival(way: str) -> float:  # the best way along the other axis
        return max(v for w, v in score.items() if w[-1] != way[-1])

    up = max(score, key=lambda w: score[w])
    if score[up] <= 0.5 or score[up] - rival(up) < 0.2:
        # The rest pose and the frames disagree (a Blender armature turns a Z-up rest pose to
        # Y up in its channels; a converter turns only the frames upside down): the frames are
        # what is imported, so they decide if clear.
        clear = [way for way, r in rise.items() if r[1] > 0.5]
        if len(clear) != 1:
            return "y", ("assumed (the BVH convention): no axis shows the head clearly above the "
                         "feet; give --up (y, z, -y or -z) if wrong")
        up = clear[0]
        spine_way = max(rise, key=lambda w: rise[w][0])
        if spine_way != up and rise[spine_way][0] > 0.5:
            return up, (f"detected: the head is above the feet along {_way(up)} in "
                        f"{rise[up][2]:.0%} of frames, which decide over the rest pose's spine "
                        f"pointing {rise[spine_way][0]:+.2f} along {spine_way.upper()}")
    # The head above the feet in most frames is what up means: a way the frames clearly show it
    # along (two thirds of them) overrides a rest pose that points elsewhere.
    majority = [way for way, r in rise.items() if r[2] >= 2 / 3]
    if rise[up][2] <= 0.5 and len(majority) == 1:
        up = majority[0]
    spine_k, _, share = rise[up]
    rest_text = (f"the rest pose's spine points {spine_k:+.2f} along {up.upper()}"
                 if abs(spine_k) > 0.5 else "the rest pose shows no stance")
    if share <= 0.5:
        return up, (f"from the rest pose's spine ({spine_k:+.2f} along {up.upper()}): the head is "
                    f"above the feet along it in only {share:.0%} of frames, and along no axis in "
                    "two thirds of them (does the body tumble or lie?); give --up if wrong")
    return up, (f"detected: the head is above the feet along {_way(up)} in {share:.0%} of "
                f"frames and {rest_text}")


def _way(up: str) -> str:
    """``"y"`` -> ``"+Y"``, ``"-z"`` -> ``"-Z"``: an up axis as the reasons write it."""
    return up.upper() if up.startswith("-") else f"+{up.upper()}"


def canonical_clip(motion: BvhMotion, map_spec: str | None = None,
                   unit: str | None = None, up: str | None = None,
                   stature_m: float | None = None) -> CanonicalClip:
    """Map, scale and rotate a BVH clip onto the canonical skeleton (see module docstring).

    ``up`` is the file's up axis, ``"x"``, ``"y"`` or ``"z"``; None detects it (:func:`detect_up`).
    ``unit``: a unit name or metres per file unit as text (:func:`unit_scale`); None detects it.
    ``stature_m``: scale the source so that its body is this tall (m) instead.
    """
    if up is not None:
        up = up_axis(up)
    skeleton = motion.skeleton
    joint2file, pos_file = forward_kinematics(motion)
    jmap = map_skeleton(skeleton, map_spec, pos_file)
    check_human_build(skeleton, jmap, pos_file)
    if up is None:
        up, up_reason = detect_up(skeleton, jmap, pos_file)
    else:
        up_reason = "given with --up"
    leg_units = _leg_rest_length(skeleton, jmap)
    if unit is None and stature_m is not None:
        unit, reason = "m", ""  # the stature sets the scale below
    elif unit is None:
        unit, reason = detect_unit(leg_units)
    else:
        reason = f"given with --unit (thigh + shank = {leg_units * unit_scale(unit):.3f} m)"
    scale = unit_scale(unit)
    rest = rest_positions(skeleton)
    src = jmap.source
    # Body axes of the rest (all-zero-rotation) pose, in file axes: forward, left, up as columns.
    # A joint's orientation in the rest pose is the identity, so these are also the body axes in
    # each joint's local frame; joint2file @ rest_body gives a part's frame in any frame.
    left0 = rest[src["hip_l"]] - rest[src["hip_r"]]
    up0 = rest[src["neck"]] - rest[src["pelvis"]]
    rest_body = frame_from_axes(left0, up0, 1, 2)

    to_world = UP_AXES[up]
    n_frames = motion.n_frames
    positions = np.empty((n_frames, N_JOINTS, 3))
    measured = np.zeros(N_JOINTS, dtype=bool)
    for name, i in src.items():
        if i is not None:
            positions[:, J[name]] = pos_file[:, i] @ to_world.T * scale
            measured[J[name]] = True
    leg_m = leg_units * scale

    def world_frame(i: int) -> F64:
        return to_world @ joint2file[:, i] @ rest_body

    # No neck joint (the head and both clavicles hang straight off the thorax, as in Acclaim
    # ASF): the neck base is where the clavicles meet, the middle of the arms' first joints.
    neck_at_clavicles = False
    if src["neck"] == jmap.thorax:
        roots = [_child_towards(skeleton, jmap.thorax, src[f"shoulder_{s}"]) for s in "lr"]  # type: ignore[arg-type]
        meet = 0.5 * (pos_file[:, roots[0]] + pos_file[:, roots[1]]) @ to_world.T * scale
        if np.linalg.norm(meet[0] - positions[0, J["neck"]]) > 1e-3 * leg_units * scale:
            positions[:, J["neck"]] = meet
            neck_at_clavicles = True
    # Spine joints a skeleton lacks: evenly between their neighbours on the pelvis-neck line. A
    # mapped spine joint at the place of the next one up at rest (a Neck with a zero OFFSET under
    # Spine2) measures no bone: it is placed so too.
    chain = ["pelvis", "spine_1", "spine_2", "neck"]
    for name, above in pairwise(chain[1:]):
        i, j = src[name], src[above]
        if i is not None and j is not None and \
                np.linalg.norm(rest[i] - rest[j]) <= SAME_PLACE_FRACTION * leg_units:
            measured[J[name]] = False
    known = [k for k, name in enumerate(chain) if measured[J[name]]]
    for k, name in enumerate(chain):
        if not measured[J[name]]:
            lo = max(a for a in known if a < k)
            hi = min(b for b in known if b > k)
            w = (k - lo) / (hi - lo)
            positions[:, J[name]] = (1 - w) * positions[:, J[chain[lo]]] + w * positions[:, J[chain[hi]]]
    # End parts a skeleton lacks: from the orientation of the joint they hang from.
    forward0 = rest_body[:, 0]
    for side in "lr":
        fills = (
            (f"toe_{side}", f"ankle_{side}", forward0, FILL_FRACTION["toe"]),
            (f"hand_{side}", f"wrist_{side}",
             normalize(rest[src[f"wrist_{side}"]] - rest[src[f"elbow_{side}"]]),
             FILL_FRACTION["hand"]),
        )
        for name, parent, dir_rest, frac in fills:
            if not measured[J[name]]:
                i = src[parent]
                d = (to_world @ joint2file[:, i] @ dir_rest)
                positions[:, J[name]] = positions[:, J[parent]] + d * frac * leg_m
    if not measured[J["head_top"]]:
        up_head = normalize(rest[src["head"]] - rest[src["neck"]])
        if np.linalg.norm(up_head) < 0.5:
            up_head = up0 / np.linalg.norm(up0)
        d = to_world @ joint2file[:, src["head"]] @ up_head
        positions[:, J["head_top"]] = positions[:, J["head"]] + d * FILL_FRACTION["head_top"] * leg_m
    if neck_at_clavicles:
        measured[J["neck"]] = False
    if stature_m is not None:
        if not MIN_STATURE_M <= stature_m <= MAX_STATURE_M:
            raise EcsAnimError(f"--stature {stature_m:g}: expected {MIN_STATURE_M:g}-"
                               f"{MAX_STATURE_M:g} m")
        factor = stature_m / source_morphology(positions, "source").stature
        positions *= factor
        scale *= factor
        unit = f"{scale:.6g}"
        reason = (f"--stature {stature_m:g} m: {scale:.6g} m per file unit (thigh + shank = "
                  f"{leg_units * scale:.3f} m)")
    return CanonicalClip(
        positions=positions,
        pelvis2world=world_frame(src["pelvis"]),  # type: ignore[arg-type]
        thorax2world=world_frame(jmap.thorax),
        head2world=world_frame(src["head"]),  # type: ignore[arg-type]
        measured=measured, fps=motion.fps, unit=unit, unit_reason=reason, joint_map=jmap,
        up_axis=up, up_reason=up_reason, warnings=tuple(motion.warnings),
        ignored=tuple(unused_joints(skeleton, jmap)),
    )


def _child_towards(skeleton: BvhSkeleton, ancestor: int, joint: int) -> int:
    """The child of ``ancestor`` on the path down to ``joint`` (``joint`` itself if a child)."""
    while skeleton.joints[joint].parent not in (ancestor, -1):
        joint = skeleton.joints[joint].parent
    return joint


def ankle_height_or_typical(height_m: float, leg_m: float) -> float:
    """An ankle's height over the floor read as its height over z = 0 (m), or the adult
    proportion for the leg (m) where that is implausible: a capture whose floor is not at
    z = 0 (a lab's origin elsewhere, a BVH root offset) or that never stands."""
    typical = FILL_FRACTION["ankle_height"] * leg_m
    return height_m if 0.4 * typical <= height_m <= 2.5 * typical else typical


def source_morphology(positions: F64, name: str) -> Morphology:
    """The captured subject's body: mean bone lengths over the clip, ankle height from the
    lowest ankle positions, mass from stature at a body-mass index of 22.

    ``positions`` (n_frames, N_JOINTS, 3) in metres, Z up, ground near z = 0.
    """
    per_frame = bone_lengths_of(positions)
    lengths = np.ones(per_frame.shape[-1])
    is_bone = ~np.isnan(per_frame[0])
    lengths[is_bone] = per_frame[:, is_bone].mean(axis=0)
    leg = 0.5 * (lengths[LENGTH_INDEX["thigh_l"]] + lengths[LENGTH_INDEX["shank_l"]]
                 + lengths[LENGTH_INDEX["thigh_r"]] + lengths[LENGTH_INDEX["shank_r"]])
    for side in "lr":
        low = float(np.percentile(positions[:, J[f"ankle_{side}"], 2], 5))
        lengths[LENGTH_INDEX[f"ankle_height_{side}"]] = ankle_height_or_typical(low, leg)
    collapsed = [length for length, i in LENGTH_INDEX.items() if not lengths[i] > 0]
    if collapsed:  # said here: Morphology's own check would list every length, on no line
        raise EcsAnimError(f"bones of zero length over the whole clip: {listed(collapsed)} "
                           "(their joints coincide in every frame)")
    morph = Morphology(lengths, 1.0, "male", name)
    stature = morph.stature
    return Morphology(lengths, 22.0 * stature**2, "male", name)


def measured_stature(positions: F64, measured: NDArray[np.bool_]) -> tuple[float, list[str]] | None:
    """The stature (m) the measured bones alone give, with their names, or None when no bone is
    measured: the median over bones whose both joints come from the source (``measured``,
    (N_JOINTS,) bool) of each bone's mean length over its adult share of the stature
    (:data:`~ecs_anim.core.morphology.ADULT_PROPORTIONS`). Parts filled in (a neutral pose at
    adult proportions, interpolated spine joints) say nothing of the file's unit.

    ``positions`` (n_frames, N_JOINTS, 3) metres."""
    from ecs_anim.core.skeleton import BONE_JOINTS, LENGTHS

    lengths = bone_lengths_of(positions).mean(axis=0)
    implied, names = [], []
    for k, (a, b) in enumerate(BONE_JOINTS):
        share = ADULT_PROPORTIONS.get(LENGTHS[k].removesuffix("_l").removesuffix("_r"))
        if a >= 0 and share and measured[a] and measured[b] and lengths[k] > 0:
            implied.append(float(lengths[k]) / share)
            names.append(LENGTHS[k])
    return (float(np.median(implied)), names) if implied else None


def check_measured_stature(clip: CanonicalClip, morph: Morphology) -> CanonicalClip:
    """The clip, its filled-in legs resized where they alone make the body no human's size;
    raises :class:`EcsAnimError` where the measured parts are no human's size, asking in one
    line whether the unit is right (issue 31, class 7: only what was measured questions it).

    With a leg measured (hip, knee and ankle from the source) the body's stature decides, as its
    other parts are measured or filled in proportion to it. With no leg measured (absent legs,
    filled in a neutral pose at adult proportions of another part) the measured bones alone
    decide (:func:`measured_stature`); where they are plausible but the filled-in legs make the
    body too tall or too short, those legs are resized about their hips to the legs of the
    measured bones' stature (``info.filled_legs_resized`` says so)."""
    legs = any(all(clip.measured[J[f"{p}_{s}"]] for p in ("hip", "knee", "ankle")) for s in "lr")
    plausible = MIN_STATURE_M <= morph.stature <= MAX_STATURE_M
    expected = f"expected {MIN_STATURE_M:g}-{MAX_STATURE_M:g} m: is the unit right? (--unit)"
    if legs:
        if not plausible:
            raise EcsAnimError(f"the captured body comes out {morph.stature:.3g} m tall with the "
                               f"length unit {clip.unit!r} ({clip.unit_reason}); {expected}")
        return clip
    found = measured_stature(clip.positions, clip.measured)
    if found is not None and not MIN_STATURE_M <= found[0] <= MAX_STATURE_M:
        raise EcsAnimError(f"the measured parts ({listed(found[1], 3)}) make a body "
                           f"{found[0]:.3g} m tall with the length unit {clip.unit!r} "
                           f"({clip.unit_reason}); {expected}")
    if plausible or found is None:
        return clip
    # The filled legs hang straight from their hips: scale knee, ankle and toe about the hip.
    target = found[0] * (ADULT_PROPORTIONS["thigh"] + ADULT_PROPORTIONS["shank"])
    factor = target / leg_of(clip.positions)
    positions = clip.positions.copy()
    for s in "lr":
        hip = positions[:, J[f"hip_{s}"]]
        for part in ("knee", "ankle", "toe"):
            if not clip.measured[J[f"{part}_{s}"]]:
                positions[:, J[f"{part}_{s}"]] = hip + (positions[:, J[f"{part}_{s}"]] - hip) * factor
    return replace(clip, positions=positions)


def import_bvh(path: str | Path, map_spec: str | None = None, unit: str | None = None,
               thresholds: ContactThresholds = ContactThresholds(),
               up: str | None = None, trim: FrameRange | None = None,
               stature_m: float | None = None, treadmill: bool = True,
               contacts: str = "detect") -> NormalizedMotion:
    """Read a BVH file and normalize it (``trim``: only those frames, else a leading rest pose
    is dropped, :func:`leading_rest_frames`, and ``info.rest_frames_dropped`` says so; glitch
    frames are repaired or cut either way, :func:`repair_glitches`, ``info.glitch_frames``; ``up``,
    ``unit``, ``stature_m`` as in :func:`canonical_clip`; ``treadmill``, ``contacts`` as in
    :func:`normalize_clip`: a BVH has no gait events). Raises :class:`EcsAnimError` subclasses
    on bad input."""
    path = Path(path)
    motion = read_bvh(path)
    return import_canonical(path, lambda: canonical_clip(motion, map_spec, unit, up, stature_m),
                            trim, thresholds, treadmill, contacts)


def import_canonical(path: Path, make_clip: Callable[[], CanonicalClip],
                     trim: FrameRange | None, thresholds: ContactThresholds, treadmill: bool,
                     contacts: str = "detect") -> NormalizedMotion:
    """The import of a file read as a skeleton (BVH, FBX) from its canonical clip on
    (``make_clip``: maps, scales and turns it): ``trim``, or a leading rest pose dropped
    (:func:`leading_rest_frames`), glitch frames repaired or cut (:func:`repair_glitches`), then
    :func:`normalize_clip`; ``info`` says what was dropped. A user's mistake anywhere in it is
    one :class:`InputError` naming ``path``; a non-finite result is refused."""
    try:
        clip = make_clip()
        first_file_frame, rest = 0, None
        if trim is not None:
            kept = trim.frames(len(clip.positions), clip.fps)
            clip, first_file_frame = trim_clip(clip, kept), kept.start
        n_before = len(clip.positions)
        clip, glitches = repair_glitches(clip)
        glitch_line = glitches.report(n_before, first_file_frame) if glitches else None
        first_file_frame += glitches.dropped_start if glitches else 0
        if trim is None:
            rest = leading_rest_frames(clip.positions, clip.fps)
            if rest is not None:
                clip = trim_clip(clip, slice(rest.count, None))
                rest_line = rest.report(first_file_frame)
                first_file_frame += rest.count
        normalized = normalize_clip(clip, path.stem, str(path), thresholds, treadmill,
                                    contacts=contacts)
        if first_file_frame:
            normalized.info["first_file_frame"] = first_file_frame
        if glitch_line is not None:
            normalized.info["glitch_frames"] = glitch_line
        if rest is not None:
            normalized.info["rest_frames_dropped"] = rest_line
    except InputError:
        raise
    except EcsAnimError as exc:
        raise InputError(path, str(exc)) from None
    except ValueError as exc:  # e.g. a mapped bone of zero length
        raise InputError(path, f"cannot normalize this skeleton: {exc}") from None
    bad = [k for k, v in normalized.poses.arrays().items() if not np.all(np.isfinite(v))]
    if bad:
        raise InputError(path, f"normalizing gave non-finite values in {', '.join(bad)} "
                               "(degenerate skeleton or motion?); nothing written")
    return normalized


def normalize_clip(clip: CanonicalClip, name: str, source: str,
                   thresholds: ContactThresholds = ContactThresholds(), treadmill: bool = True,
                   events: list[dict[str, Any]] | None = None,
                   contacts: str = "detect") -> NormalizedMotion:
    """Encode a canonical clip, detect its foot contacts, and gather its provenance.

    ``treadmill``: an in-place clip whose stance foot slides back as on a treadmill
    (:func:`~ecs_anim.io.contacts.treadmill_belt`) gets the belt's motion as root motion, so the
    stance foot is planted (``info.treadmill`` says so); False keeps it in place.
    ``events``: gait events in the clip's seconds (``{"side", "kind", "time_s"}``);
    ``contacts="events"`` takes the foot contacts from them instead of detecting them (the
    heel and ball planted frames are still detected, within those contacts).
    """
    if contacts not in ("detect", "events"):
        raise EcsAnimError(f"--contacts {contacts}: expected 'detect' or 'events'")
    treadmill_info: dict[str, Any] | None = None
    belt = treadmill_belt(clip.positions, clip.fps)
    if belt is not None:
        treadmill_info = {"belt_mps": [round(float(b), 4) for b in belt],
                          "speed_mps": round(float(np.linalg.norm(belt)), 3),
                          "converted": treadmill}
        if treadmill:
            shift = np.zeros((len(clip.positions), 3))
            shift[:, :2] = -belt * (np.arange(len(clip.positions)) / clip.fps)[:, None]
            clip = replace(clip, positions=clip.positions + shift[:, None, :])
    morph = source_morphology(clip.positions, f"{name} (source)")
    resized = check_measured_stature(clip, morph)
    filled_stature: float | None = None
    if resized is not clip:
        filled_stature, clip = morph.stature, resized
        morph = source_morphology(clip.positions, f"{name} (source)")
    found = detect_foot_contacts(clip.positions, clip.fps, thresholds,
                                 toes_follow_ankle=clip.toes_follow_ankle)
    foot = found.foot
    contact_info: dict[str, Any] = {
        "method": "detected",
        "speed_threshold_mps": [round(v, 3) for v in found.speed_threshold_mps],
    }
    strikes = [e for e in events or [] if e.get("kind") in ("strike", "off")]
    on_ground = found.on_ground
    if strikes:
        contact_info["events_check"] = event_agreement(on_ground, strikes, clip.fps)
    if contacts == "events":
        if not strikes:
            raise EcsAnimError("--contacts events: the file holds no gait event (EVENT group "
                               "with foot strikes and foot offs)")
        foot = on_ground = contacts_from_events(strikes, len(clip.positions), clip.fps)
        contact_info["method"] = "gait events"
    # No contact on a foot the source does not measure (a leg filled in a neutral pose, by us
    # or by the source: a leg that never moves in the pelvis's frame): its stillness is the
    # fill's, not a stance, and nothing can be checked against it.
    unmeasured = ~clip.measured[[J["ankle_l"], J["ankle_r"]]] \
        | rigid_legs(clip.positions, clip.pelvis2world)
    if unmeasured.any():
        foot, on_ground = foot & ~unmeasured, on_ground & ~unmeasured
        contact_info["not_measured"] = [side for side, gone in zip(("left", "right"), unmeasured,
                                                                   strict=True) if gone]
    constraints = contact_constraints(foot, clip.fps, thresholds)
    heel, ball = found.heel & foot, found.ball & foot
    planted = {"heel": heel, "ball": ball, "foot": foot, "on_ground": on_ground}
    # The ground the capture stood on, which playback takes out (a step in the capture is not
    # a step on every ground); the poses keep it, so the source decodes back as it was.
    ankle_height = np.array([morph["ankle_height_l"], morph["ankle_height_r"]])
    ground, ground_how = capture_ground(clip.positions, clip.fps, foot, heel, ball,
                                        ankle_height, morph.leg_length)
    poses = encode(clip.positions, clip.pelvis2world, clip.thorax2world, clip.head2world,
                   morph.lengths)
    info = {
        "source": source,
        "joint_map": clip.joint_map.how,
        "joints": {j: clip.joint_map.names.get(j) for j in JOINTS},
        "filled_in": [j for j, m in zip(JOINTS, clip.measured, strict=True) if not m],
        "unit": clip.unit,
        "unit_reason": clip.unit_reason,
        "up_axis": clip.up_axis,
        "max_stretch": float(np.max(np.abs(poses.stretch - 1.0))),
        "contacts": contact_info,
        "capture_ground": {"from": ground_how, "lowest_m": round(float(ground.min()), 4),
                           "highest_m": round(float(ground.max()), 4)},
    }
    if treadmill_info is not None:
        info["treadmill"] = treadmill_info
    if filled_stature is not None:
        info["filled_legs_resized"] = (
            f"the absent legs, filled in at adult proportions, made the body {filled_stature:.3g} m "
            f"tall; resized to the measured parts' {morph.stature:.3g} m (if the file has leg "
            "markers, map them with --map FILE.yaml to measure the legs)")
    if clip.up_reason:
        info["up_reason"] = clip.up_reason
    if clip.warnings:
        info["warnings"] = list(clip.warnings)
    if clip.ignored:
        info["ignored_joints"] = list(clip.ignored)
    return NormalizedMotion(poses, clip.fps, morph, constraints, info, planted,
                            ground / morph.leg_length)


def event_agreement(foot: NDArray[np.bool_], events: list[dict[str, Any]], fps: float
                    ) -> dict[str, Any]:
    """How far the detected contacts' edges lie from the file's gait events: for each event
    (``{"side", "kind", "time_s"}``, clip seconds), the nearest touch-down (strike) or lift-off
    (off) of that foot, signed (detected minus event, ms), and the mean and worst of their
    sizes (``mean_ms``, ``worst_ms``; None where an event has no edge of its kind). Events
    within the shortest contact of the clip's ends cannot show an edge and are counted apart
    (``at_clip_ends``)."""
    from ecs_anim.io.contacts import true_runs

    n = len(foot)
    duration = (n - 1) / fps
    errors: list[dict[str, Any]] = []
    at_ends = 0
    for side_i, side in enumerate("lr"):
        runs = true_runs(foot[:, side_i])
        downs = [a / fps for a, _ in runs if a > 0]
        ups = [(b + 1) / fps for _, b in runs if b < n - 1]
        for e in events:
            if e["side"] != side:
                continue
            if e["time_s"] < EVENT_EDGE_S or e["time_s"] > duration - EVENT_EDGE_S:
                at_ends += 1
                continue
            edges = downs if e["kind"] == "strike" else ups
            diff = min((t - e["time_s"] for t in edges), key=abs, default=math.inf)
            errors.append({"side": side, "kind": e["kind"], "time_s": round(e["time_s"], 4),
                           "error_ms": round(1000 * diff, 1) if math.isfinite(diff) else None})
    finite = [abs(x["error_ms"]) for x in errors if x["error_ms"] is not None]
    complete = bool(finite) and len(finite) == len(errors)
    return {"events": errors, "mean_ms": round(sum(finite) / len(finite), 1) if complete else None,
            "worst_ms": max(finite) if complete else None, "at_clip_ends": at_ends}


#: Events closer than this to a clip's ends are not compared (no contact edge can show there).
EVENT_EDGE_S = 0.08
