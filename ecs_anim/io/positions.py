"""From joint positions (research datasets, pose estimators) to a
:class:`~ecs_anim.motion.clip.NormalizedMotion`: ``ecs-anim import X.npy|X.npz|X.json|X.csv``.

read (:mod:`.position_files`) -> the layout (:mod:`.position_layouts`, detected or given) ->
missing samples filled -> metres (unit detected from the legs) -> Z up (the head above the
feet) -> canonical joints, the parts a layout lacks filled in from proportions -> optionally (``--lowpass``,
for noisy data) a zero-lag low-pass and each bone at its robust length (the motion
keeping its directions) -> the canonical clip that BVH and C3D import end in, encoded and its contacts
found by the same :func:`~ecs_anim.io.importing.import_canonical`.
No joint angle is computed: the representation is built from positions.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from ecs_anim.core.errors import EcsAnimError, listed
from ecs_anim.core.normalized import frames_from_positions
from ecs_anim.core.rotations import frame_from_axes, normalize
from ecs_anim.core.skeleton import JOINT_INDEX as J
from ecs_anim.core.skeleton import JOINTS, N_JOINTS, PARENTS
from ecs_anim.io.contacts import ContactThresholds
from ecs_anim.io.importing import (
    FILL_FRACTION,
    UP_AXES,
    CanonicalClip,
    FrameRange,
    detect_unit,
    import_canonical,
    unit_scale,
    up_axis,
)
from ecs_anim.io.joint_map import JointMap
from ecs_anim.io.position_files import PositionFile, read_positions
from ecs_anim.io.position_layouts import PositionLayout, detect_layout, layout_named
from ecs_anim.motion.clip import NormalizedMotion

F64 = NDArray[np.float64]

#: Canonical joints a layout may lack, filled in (as BVH import fills them): the ends from
#: proportions (after any low-pass, so their lengths stay the proportions'), the spine between
#: its neighbours.
FILLABLE = ("toe_l", "toe_r", "hand_l", "hand_r", "head_top", "spine_1", "spine_2")
#: A foot filled in lies flat the way the pelvis faces, tipped down by the ankle's height over
#: the foot's length (an adult's foot, the ball on the floor): planted where the ankle stands
#: still, as a stance foot is (a foot turning with the shank moved its ball through the stance).
FOOT_DROP = FILL_FRACTION["ankle_height"] / FILL_FRACTION["toe"]
#: The head is above the feet along the up axis when their offset points at least this much
#: along it (cos 60°): in most frames, or the body tumbles.
HEAD_ABOVE_FEET = 0.5
#: Jitter over this (mm, the joints' motion above :data:`JITTER_PROBE_HZ`, a robust standard
#: deviation) is said on the import line with the ``--lowpass`` that smooths it: a mocap's joint
#: centres keep under 1 mm there; a video estimator's jitter by centimetres.
JITTER_WARN_MM = 5.0
JITTER_PROBE_HZ = 6.0


@dataclass(frozen=True)
class PositionOptions:
    """``import``'s choices for a positions file: ``layout`` (a name of
    :data:`~ecs_anim.io.position_layouts.LAYOUTS`, None: detected), ``fps`` (None: the file's,
    else the layout's dataset rate), ``up`` and ``unit`` (None: detected), ``lowpass_hz`` (the
    zero-lag low-pass's cut-off, None: no filter, for mocap-grade data)."""

    layout: str | None = None
    fps: float | None = None
    up: str | None = None
    unit: str | None = None
    lowpass_hz: float | None = None


def import_positions(path: str | Path, options: PositionOptions = PositionOptions(),
                     thresholds: ContactThresholds = ContactThresholds(),
                     trim: FrameRange | None = None, treadmill: bool = True) -> NormalizedMotion:
    """Read a joint-positions file and normalize it; ``trim``, ``treadmill`` and the contacts
    as for BVH (:func:`~ecs_anim.io.importing.import_canonical`). ``info.positions`` says how
    the file was read. Raises :class:`~ecs_anim.core.errors.InputError` naming the file on
    bad input."""
    path = Path(path)
    read = read_positions(path)
    details: dict[str, object] = {}

    def make_clip() -> CanonicalClip:
        clip, found = canonical_clip_positions(read, options)
        details.update(found)
        return clip

    motion = import_canonical(path, make_clip, trim, thresholds, treadmill)
    motion.info["format_in"] = "positions"
    motion.info["positions"] = details
    return motion


def canonical_clip_positions(read: PositionFile, options: PositionOptions
                             ) -> tuple[CanonicalClip, dict[str, object]]:
    """A positions file's canonical clip (metres, Z up) and how it was read (for ``info``).
    Raises :class:`EcsAnimError` where the file cannot be a body's motion."""
    raw = read.positions
    if options.layout is not None or read.layout is not None:
        layout = layout_named(options.layout or read.layout or "")
        layout_how = "given with --layout" if options.layout else "named in the file"
        if raw.shape[1] != len(layout.joints):
            raise EcsAnimError(f"{raw.shape[1]} joints per frame, where layout {layout.name} "
                               f"has {len(layout.joints)}")
    else:
        layout, layout_how = detect_layout(raw, read.names)
    fps = options.fps or read.fps or layout.fps
    if fps is None:
        raise EcsAnimError(f"the file gives no frame rate and {layout.name} has none of its "
                           "own; give --fps")
    filled, n_filled, absent = fill_missing(raw, layout)
    in_file = canonical_from_layout(filled, layout, absent)  # file unit and axes
    leg_units = leg_length(in_file)
    if options.unit is None:
        unit, unit_reason = detect_unit(leg_units)
    else:
        unit = options.unit
        unit_reason = f"given with --unit (thigh + shank = {leg_units * unit_scale(unit):.3f} m)"
    if options.up is None:
        up, up_reason = detect_up_axis(in_file)
    else:
        up, up_reason = up_axis(options.up), "given with --up"
    to_world = UP_AXES[up] * unit_scale(unit)
    world = in_file @ to_world.T
    face = filled[:, [layout.index(j) for j in layout.face]] @ to_world.T if layout.face else None
    measured = np.array([j in layout.canonical and len(layout.canonical[j]) == 1
                         and j not in absent for j in JOINTS])
    provided = {j for j in layout.canonical if j not in absent}
    world = fill_spine(world, provided)
    warnings: list[str] = []
    probe_hz = min(JITTER_PROBE_HZ, fps / 4)
    jitter_mm = 1000.0 * float(np.nanmedian(np.sqrt(residual_variance(world[:, measured], fps,
                                                                       probe_hz)[0] / 3)))
    if options.lowpass_hz is not None:
        # Mocap-grade data (no --lowpass) keeps its own bones, whose mean import takes as BVH's.
        world, face = denoised(world, face, fps, options.lowpass_hz)
    elif jitter_mm > JITTER_WARN_MM:
        warnings.append(f"the joints jitter by about {jitter_mm:.0f} mm (their motion above "
                        f"{probe_hz:g} Hz, median over joints and axes): a pose estimator's noise? "
                        f"--lowpass {probe_hz:g} smooths it")
    world = fill_ends(world, provided, face)
    pelvis2world, thorax2world, head2world = frames_from_positions(world)
    if face is not None:
        head2world = face_frame(face)
    names = {j: " and ".join(layout.canonical[j]) if j in provided else None for j in JOINTS}
    names.update({j: f"middle of {names[j]}" for j in provided if len(layout.canonical[j]) == 2})
    details: dict[str, object] = {
        "layout": layout.name, "layout_reason": layout_how, "read_as": read.form,
        "fps_from": ("--fps" if options.fps else "the file" if read.fps else
                     f"{layout.name}'s own rate"),
        "samples_filled": n_filled, "absent_joints": sorted(absent),
        "lowpass_hz": options.lowpass_hz, "jitter_mm": round(jitter_mm, 1),
    }
    clip = CanonicalClip(
        positions=world, pelvis2world=pelvis2world, thorax2world=thorax2world,
        head2world=head2world, measured=measured, fps=float(fps), unit=unit,
        unit_reason=unit_reason,
        joint_map=JointMap(source={}, thorax=-1, how=f"layout {layout.name} ({layout_how})",
                           names=names),
        up_axis=up, up_reason=up_reason, warnings=tuple(warnings),
        toes_follow_ankle=not {"toe_l", "toe_r"} <= provided)
    return clip, details


def denoised(world: F64, face: F64 | None, fps: float, lowpass_hz: float
             ) -> tuple[F64, F64 | None]:
    """Noisy joints (``--lowpass``) smoothed by :func:`zero_lag_lowpass` and each bone set to
    its robust length (:func:`robust_bone_lengths`, the noise the filter leaves taken out), the
    motion keeping its directions; the face's points smoothed alike. ``world`` (n_frames,
    N_JOINTS, 3) metres, NaN for the end parts filled in after; ``face`` (n_frames, 3, 3) or
    None. Raises :class:`EcsAnimError` for a cut-off at or over half the frame rate."""
    if not lowpass_hz < fps / 2:
        raise EcsAnimError(f"--lowpass {lowpass_hz:g}: the cut-off must be under half the frame "
                           f"rate ({fps / 2:g} Hz)")
    noise = bone_noise_variance(world, fps, lowpass_hz)
    smooth = zero_lag_lowpass(world, fps, lowpass_hz)[0]
    smooth_face = None if face is None else zero_lag_lowpass(face, fps, lowpass_hz)[0]
    return bones_to_lengths(smooth, robust_bone_lengths(smooth, noise)), smooth_face


def fill_missing(raw: F64, layout: PositionLayout) -> tuple[F64, int, set[str]]:
    """Missing samples (NaN) of each joint interpolated linearly between its frames, held at
    the clip's ends; returns (positions, samples filled, canonical joints whose layout joints
    are missing in every frame). Raises :class:`EcsAnimError` where such a joint cannot be
    filled in from proportions (:data:`FILLABLE`).

    ``raw`` (n_frames, n_joints, 3)."""
    seen: NDArray[np.bool_] = np.asarray(np.isfinite(raw).all(axis=-1))  # (n_frames, n_joints)
    never = {layout.joints[k] for k in np.flatnonzero(~seen.any(axis=0))}
    absent = {j for j, sources in layout.canonical.items() if never & set(sources)}
    lost = [j for j in absent if j not in FILLABLE]
    if lost:
        joints = [s for j in lost for s in layout.canonical[j] if s in never]
        raise EcsAnimError(f"joint(s) {listed(joints)} missing (NaN) in every frame: "
                           f"{listed(lost)} cannot be placed")
    out = raw.copy()
    frames = np.arange(len(raw))
    for k in np.flatnonzero(seen.any(axis=0) & ~seen.all(axis=0)):
        good = seen[:, k]
        for a in range(3):
            out[:, k, a] = np.interp(frames, frames[good], raw[good, k, a])
    present = [k for k, joint in enumerate(layout.joints) if joint not in never]
    return out, int((~seen[:, present]).sum()), absent


def canonical_from_layout(positions: F64, layout: PositionLayout, absent: set[str]) -> F64:
    """Canonical joints (n_frames, N_JOINTS, 3) read from the layout's (``positions``
    (n_frames, n_joints, 3)): each the layout joint it is, or the middle of two; NaN for the
    joints the layout lacks or are ``absent``."""
    out = np.full((len(positions), N_JOINTS, 3), np.nan)
    for joint, sources in layout.canonical.items():
        if joint not in absent:
            out[:, J[joint]] = positions[:, [layout.index(s) for s in sources]].mean(axis=1)
    return out


def leg_length(positions: F64) -> float:
    """Thigh + shank (median over frames, mean of the sides) of canonical positions, in their
    unit."""
    legs = [np.linalg.norm(positions[:, J[f"knee_{s}"]] - positions[:, J[f"hip_{s}"]], axis=-1)
            + np.linalg.norm(positions[:, J[f"ankle_{s}"]] - positions[:, J[f"knee_{s}"]], axis=-1)
            for s in "lr"]
    return float(np.median(np.mean(legs, axis=0)))


def detect_up_axis(positions: F64) -> tuple[str, str]:
    """The file's up axis (a key of :data:`~ecs_anim.io.importing.UP_AXES`) with a sentence
    saying why: the way along which the head stands above the ankles' middle in most frames
    (:data:`HEAD_ABOVE_FEET`). Raises :class:`EcsAnimError` where no way has it so in half the
    frames (a body that tumbles or lies).

    ``positions`` (n_frames, N_JOINTS, 3) in the file's axes."""
    rise = normalize(positions[:, J["head"]]
                     - 0.5 * (positions[:, J["ankle_l"]] + positions[:, J["ankle_r"]]))
    share = {f"{sign}{axis}": float(np.mean(s * rise[:, k] > HEAD_ABOVE_FEET))
             for k, axis in enumerate("xyz") for sign, s in (("", 1.0), ("-", -1.0))}
    up = max(share, key=lambda way: share[way])
    way = up.upper() if up.startswith("-") else f"+{up.upper()}"
    if share[up] <= 0.5:
        raise EcsAnimError(f"the head is above the feet along no axis in most frames (along "
                           f"{way} in {share[up]:.0%}): the body tumbles or lies; give --up")
    return up, f"detected: the head is above the feet along {way} in {share[up]:.0%} of frames"


def fill_spine(positions: F64, provided: set[str]) -> F64:
    """The spine's joints a layout lacks evenly on the line between its neighbours (as BVH
    import places them); ``positions`` (n_frames, N_JOINTS, 3), NaN where lacking."""
    p = positions.copy()
    chain = ["pelvis", "spine_1", "spine_2", "neck"]
    known = [k for k, name in enumerate(chain) if name in provided]
    for k, name in enumerate(chain):
        if name not in provided:
            lo = max(a for a in known if a < k)
            hi = min(b for b in known if b > k)
            w = (k - lo) / (hi - lo)
            p[:, J[name]] = (1 - w) * p[:, J[chain[lo]]] + w * p[:, J[chain[hi]]]
    return p


def fill_ends(positions: F64, provided: set[str], face: F64 | None) -> F64:
    """The end parts a layout lacks, filled in from proportions of the leg: a hand along the
    forearm, a toe ahead of the ankle (:data:`FOOT_DROP`), the head top above the head (along
    the face's up, else the neck-head line). ``positions`` (n_frames, N_JOINTS, 3) metres, NaN
    where lacking; ``face`` (n_frames, 3, 3): nose, left ear, right ear, or None."""
    p = positions.copy()
    leg = leg_length(p)
    pelvis2world = frame_from_axes(p[:, J["hip_l"]] - p[:, J["hip_r"]],
                                   p[:, J["neck"]] - p[:, J["pelvis"]], 1, 2)
    heading = normalize(pelvis2world[:, :, 0] * [1.0, 1.0, 0.0])
    flat_foot = normalize(heading - [0.0, 0.0, FOOT_DROP])
    for s in "lr":
        if f"hand_{s}" not in provided:
            forearm = normalize(p[:, J[f"wrist_{s}"]] - p[:, J[f"elbow_{s}"]])
            p[:, J[f"hand_{s}"]] = p[:, J[f"wrist_{s}"]] + forearm * FILL_FRACTION["hand"] * leg
        if f"toe_{s}" not in provided:
            p[:, J[f"toe_{s}"]] = p[:, J[f"ankle_{s}"]] + flat_foot * FILL_FRACTION["toe"] * leg
    if "head_top" not in provided:
        up = face_frame(face)[:, :, 2] if face is not None else \
            normalize(p[:, J["head"]] - p[:, J["neck"]])
        p[:, J["head_top"]] = p[:, J["head"]] + up * FILL_FRACTION["head_top"] * leg
    return p


def face_frame(face: F64) -> F64:
    """The head's frame (n_frames, 3, 3) from the face: left from the right ear to the left,
    forward towards the nose; ``face`` (n_frames, 3, 3) nose, left ear, right ear."""
    nose, ear_l, ear_r = face[:, 0], face[:, 1], face[:, 2]
    return frame_from_axes(ear_l - ear_r, nose - 0.5 * (ear_l + ear_r), 1, 0)


def zero_lag_lowpass(x: F64, fps: float, cutoff_hz: float) -> tuple[F64, F64]:
    """``x`` (n_frames, ...) low-passed along frames with no lag: its spectrum times the
    response of a second-order Butterworth filter run forwards and back (scipy's ``filtfilt``
    magnitude, 1 / (1 + (f / cutoff)^4)), the ends padded by odd reflection so they do not
    ring. Returns (the filtered signal, the gain (n_padded,) at each of the two-sided FFT's
    frequencies, for :func:`residual_variance`)."""
    n = len(x)
    pad = min(n - 1, math.ceil(2.0 * fps / cutoff_hz))
    head = 2.0 * x[:1] - x[pad:0:-1]
    tail = 2.0 * x[-1:] - x[-2:-pad - 2:-1]
    padded = np.concatenate([head, x, tail])
    gain = 1.0 / (1.0 + (np.fft.rfftfreq(len(padded), 1.0 / fps) / cutoff_hz) ** 4)
    spectrum = np.fft.rfft(padded, axis=0) * gain.reshape((-1,) + (1,) * (x.ndim - 1))
    filtered: F64 = np.fft.irfft(spectrum, n=len(padded), axis=0)[pad:pad + n]
    full_gain = 1.0 / (1.0 + (np.abs(np.fft.fftfreq(len(padded), 1.0 / fps)) / cutoff_hz) ** 4)
    return filtered, full_gain


def residual_variance(x: F64, fps: float, cutoff_hz: float) -> tuple[F64, F64]:
    """White noise in ``x`` (n_frames, k, 3) estimated from its motion above ``cutoff_hz``:
    per row k, the variance (summed over the axes, unit²) of the raw noise, and of what a
    :func:`zero_lag_lowpass` at that cut-off leaves of it. A robust spread (1.4826 x the median
    absolute deviation), so a few fast moves do not count as noise; the residual keeps
    mean((1 - H)²) of white noise's variance, the filtered signal mean(H²)."""
    filtered, gain = zero_lag_lowpass(x, fps, cutoff_hz)
    residual = x - filtered
    spread = 1.4826 * np.median(np.abs(residual - np.median(residual, axis=0)), axis=0)
    raw = np.sum(spread**2, axis=-1) / max(float(np.mean((1.0 - gain) ** 2)), 1e-12)
    return raw, raw * float(np.mean(gain**2))


def bone_noise_variance(positions: F64, fps: float, cutoff_hz: float) -> F64:
    """The noise variance (m², summed over the axes) a :func:`zero_lag_lowpass` leaves in each
    canonical bone vector (parent -> joint), (N_JOINTS,), 0 for the root: estimated on the bone
    vectors themselves, so joints filled in from others (correlated noise) count right."""
    return residual_variance(bone_vectors(positions), fps, cutoff_hz)[1]


def robust_bone_lengths(positions: F64, noise: F64) -> F64:
    """Each canonical bone's length (N_JOINTS,), 0 for the root: the mean over frames of its
    squared length, outliers (beyond 5 median absolute deviations of the median: a glitch)
    clipped, less the noise's share ``noise`` (N_JOINTS,) m², as a root. A noisy bone
    vector's squared length exceeds the bone's by the noise's variance on average (its median
    by less: the excess is skewed, which made a 7 cm bone 1.6 % short); a breathing bone's
    mean is its length. ``positions`` (n_frames, N_JOINTS, 3)."""
    squared = np.sum(bone_vectors(positions) ** 2, axis=-1)  # (n_frames, N_JOINTS)
    median = np.median(squared, axis=0)
    spread = 5.0 * np.median(np.abs(squared - median), axis=0)
    mean = np.clip(squared, median - spread, median + spread).mean(axis=0)
    lengths: F64 = np.sqrt(np.maximum(mean - noise, 0.25 * mean))
    return lengths


def bone_vectors(positions: F64) -> F64:
    """Parent -> joint vectors (..., N_JOINTS, 3) of canonical positions, zero for the root."""
    parents = np.array([max(k, 0) for k in PARENTS])
    bones: F64 = positions - positions[..., parents, :]
    return bones


def bones_to_lengths(positions: F64, lengths: F64) -> F64:
    """The joints rebuilt from the root down, each bone along its own direction, scaled so that
    its mean length over the frames is ``lengths`` (N_JOINTS,) (:func:`robust_bone_lengths`):
    the source body the import measures (each bone's mean) is the robust one, the motion keeps
    its directions, and what a bone breathes around that stays only in the source's per-frame
    stretch, which no other body plays. Loops over the chain, not the frames."""
    bones = bone_vectors(positions)
    mean = np.linalg.norm(bones, axis=-1).mean(axis=0)
    scale = lengths / np.maximum(mean, 1e-12)
    out = positions.copy()
    for k, parent in enumerate(PARENTS):
        if parent >= 0:
            out[:, k] = out[:, parent] + bones[:, k] * scale[k]
    return out


__all__ = ["PositionOptions", "canonical_clip_positions", "import_positions"]
