"""A normalized motion: poses, timing, source body, constraints; and the ``.nmo`` file.

The ``.nmo`` container is documented in ``docs/format.md``: a zip of numpy arrays (``np.savez``)
with a JSON header. It is written through a temporary file and renamed, so an interrupted write
never leaves a damaged file behind.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from ecs_anim.core.errors import InputError, listed
from ecs_anim.core.files import atomic_output
from ecs_anim.core.morphology import MAX_STATURE_M, MIN_STATURE_M, Morphology, leg_length
from ecs_anim.core.normalized import (
    DIRECTION_FIELDS,
    QUATERNION_FIELDS,
    TRAILING_SHAPES,
    NormalizedPoses,
)
from ecs_anim.core.skeleton import LENGTHS
from ecs_anim.motion.constraint_table import check_stored
from ecs_anim.motion.constraints import ConstraintSpec, contacts_from_constraints

FORMAT_NAME = "ecs_anim.nmo"
FORMAT_VERSION = 2
#: Versions this ecs_anim reads: 1 (no planted arrays: the foot contacts stand for every part)
#: and 2 (``planted/heel``, ``planted/ball``, ``planted/foot``, ``planted/on_ground``).
READ_VERSIONS = (1, 2)
#: The foot parts whose planted frames a motion stores (:attr:`NormalizedMotion.planted`).
PLANTED_PARTS = ("heel", "ball", "foot", "on_ground")
HEADER_KEY = "header_json"
#: The heaviest source body a header may hold (import writes 22 kg/m² x stature², at most 198 kg).
MAX_MASS_KG = 1000.0
#: Frame rates a motion may have (frames per second).
MIN_FPS, MAX_FPS = 0.1, 10000.0


@dataclass
class NormalizedMotion:
    """A clip in normalized form.

    poses : per-frame :class:`NormalizedPoses` (leading axis = frames).
    fps : frames per second.
    source_morphology : the captured subject's body (decoding on it gives the source back).
    constraints : foot contacts and user constraints, times in seconds from the first frame.
    info : provenance (source file, joint map, unit assumed, joints filled in, ...).
    planted : part -> bool (n_frames, 2), left/right, as import found them: ``"heel"`` (the
        ankle joint still on the ground), ``"ball"`` (the toe joint), ``"foot"`` (either: the
        foot contacts, as the constraints hold them), ``"on_ground"`` (touch-down to lift-off,
        the span gait events mark: the foot rolling in and off as well). None: not known (a
        version-1 file, a motion made by code); :meth:`planted_part` then answers with the
        foot contacts. The tick plants the whole foot from the contact constraints; these say
        which part is down, for a pipeline that pins the ball through toe-off.
    capture_ground : (n_frames,) the height of the ground the capture stood on under the body
        (import's estimate from its contacts), in the source's leg lengths like the root; the
        poses keep it (decoding on the source body gives the source back) and playback takes
        it out, so the motion stands on each character's own ground. None: level at 0.
    """

    poses: NormalizedPoses
    fps: float
    source_morphology: Morphology
    constraints: list[ConstraintSpec] = field(default_factory=list)
    info: dict[str, Any] = field(default_factory=dict)
    planted: dict[str, NDArray[np.bool_]] | None = None
    capture_ground: NDArray[np.float64] | None = None

    @property
    def n_frames(self) -> int:
        """Frames in the clip."""
        return int(self.poses.root_heading.shape[0])

    @property
    def duration_s(self) -> float:
        """Seconds from the first frame to the last: (n_frames - 1) / fps."""
        return (self.n_frames - 1) / self.fps

    def contacts(self) -> np.ndarray:
        """Bool (n_frames, 2): left/right foot in full contact."""
        return contacts_from_constraints(self.constraints, self.n_frames, self.fps)

    def ground_under(self) -> NDArray[np.float64]:
        """(n_frames,) :attr:`capture_ground`, zero where it is not known."""
        if self.capture_ground is None:
            return np.zeros(self.n_frames)
        return self.capture_ground

    def planted_part(self, part: str) -> NDArray[np.bool_]:
        """Bool (n_frames, 2): frames where ``part`` (``"heel"``, ``"ball"``, ``"foot"``) of the
        left/right foot is planted; the foot contacts where the motion does not know."""
        if part not in PLANTED_PARTS:
            raise ValueError(f"planted part {part!r}: expected one of {', '.join(PLANTED_PARTS)}")
        if self.planted is not None and part in self.planted:
            return self.planted[part]
        return self.contacts()


def facing_and_travel(motion: NormalizedMotion) -> dict[str, float]:
    """Which way the clip faces at its first frame (degrees anticlockwise from +x, the pelvis's
    forward axis) and how far its root travels on the source body: first to last frame
    (``straight_m``, horizontal) and along its path (``path_m``), with the direction of travel."""
    leg = float(leg_length(motion.source_morphology.lengths))
    root_xy = motion.poses.root_position[:, :2] * leg
    travel = root_xy[-1] - root_xy[0]
    heading = float(motion.poses.root_heading[0])
    return {  # + 0.0: no "-0" in a table
        "facing_deg": round(math.degrees(math.atan2(math.sin(heading), math.cos(heading))), 1) + 0.0,
        "straight_m": round(float(np.linalg.norm(travel)), 3),
        "path_m": round(float(np.linalg.norm(np.diff(root_xy, axis=0), axis=1).sum()), 3),
        "direction_deg": round(math.degrees(math.atan2(travel[1], travel[0])), 1) + 0.0,
    }


#: ``import --face``: the directions a clip can be turned to face at its first frame (radians).
FACINGS = {"+x": 0.0, "+y": math.pi / 2, "-x": math.pi, "-y": -math.pi / 2}


def turned_to_face(motion: NormalizedMotion, heading_rad: float) -> NormalizedMotion:
    """The clip turned about the vertical through its origin so that it faces ``heading_rad``
    (anticlockwise from +x) at its first frame, as :func:`facing_and_travel` measures it: the
    root path turns with it; everything below the root is relative to it and stays."""
    start = float(motion.poses.root_heading[0])
    turn = math.atan2(math.sin(heading_rad - start), math.cos(heading_rad - start))
    c, s = math.cos(turn), math.sin(turn)
    root = motion.poses.root_position.copy()
    root[:, :2] = root[:, :2] @ np.array([[c, s], [-s, c]])  # each row (x, y) turned by +turn
    poses = replace(motion.poses, root_position=root, root_heading=motion.poses.root_heading + turn)
    return replace(motion, poses=poses, info=dict(motion.info, turned_deg=round(math.degrees(turn), 3)))


def save_nmo(motion: NormalizedMotion, path: str | Path, force: bool = False) -> None:
    """Write ``motion`` to ``path``; refuses to overwrite unless ``force``."""
    arrays: dict[str, Any] = {f"poses/{k}": np.ascontiguousarray(v, dtype=np.float64)
                              for k, v in motion.poses.arrays().items()}
    for part, flags in (motion.planted or {}).items():
        arrays[f"planted/{part}"] = np.ascontiguousarray(flags, dtype=bool)
    if motion.capture_ground is not None:
        arrays["capture_ground"] = np.ascontiguousarray(motion.capture_ground, dtype=np.float64)
    header = {
        "format": FORMAT_NAME,
        "version": FORMAT_VERSION,
        "fps": motion.fps,
        "n_frames": motion.n_frames,
        "source_morphology": motion.source_morphology.to_dict(),
        "constraints": [c.to_dict() for c in motion.constraints],
        "info": motion.info,
    }
    with atomic_output(path, force) as f:
        # Any: numpy's stubs would match a dict of arrays against savez's allow_pickle: bool.
        payload: dict[str, Any] = {HEADER_KEY: np.array(json.dumps(header)), **arrays}
        np.savez_compressed(f, **payload)


def load_nmo(path: str | Path) -> NormalizedMotion:
    """Read a ``.nmo`` file; a damaged file or an unknown version gives :class:`InputError`."""
    path = str(path)
    if not Path(path).exists():
        raise InputError(path, "no such file")
    if not Path(path).is_file():
        raise InputError(path, "a folder (or device), not an .nmo file")
    with open(path, "rb") as head:
        if head.read(4) != b"PK\x03\x04":  # an .nmo is a zip archive (numpy's .npz)
            if Path(path).suffix.lower() == ".nmo":
                raise InputError(path, "not a readable .nmo file (damaged or truncated?): not a "
                                       "zip archive")
            hint = " (import it first: ecs-anim import FILE -o DIR)" \
                if Path(path).suffix.lower() in (".bvh", ".c3d", ".fbx") else ""
            raise InputError(path, f"not an .nmo file{hint}")
    try:
        loaded = np.load(path, allow_pickle=False)
        if not isinstance(loaded, np.lib.npyio.NpzFile):
            raise InputError(path, "not a readable .nmo file (a single numpy array, not an .nmo archive)")
        with loaded as data:
            if HEADER_KEY not in data.files:
                raise InputError(path, f"not an .nmo file (no {HEADER_KEY} entry)")
            header = json.loads(str(data[HEADER_KEY]))
            _check_header(path, header)
            arrays = {}
            for name in TRAILING_SHAPES:
                key = f"poses/{name}"
                if key not in data.files:
                    raise InputError(path, f"damaged .nmo file: array {name!r} is missing")
                arrays[name] = np.asarray(data[key], dtype=np.float64)
            planted = {part: np.asarray(data[f"planted/{part}"]) for part in PLANTED_PARTS
                       if f"planted/{part}" in data.files}
            ground = np.asarray(data["capture_ground"]) if "capture_ground" in data.files \
                else None
    except InputError:
        raise
    except Exception as exc:  # zip, zlib, json, numpy: any failure to read means a damaged file
        reason = f"{type(exc).__name__}: {exc}" if str(exc) else type(exc).__name__
        raise InputError(path, f"not a readable .nmo file (damaged or truncated?): {reason}") from None
    n = int(header["n_frames"])
    problem = pose_arrays_problem(arrays, n)
    if problem:
        raise InputError(path, f"damaged .nmo file: {problem}")
    for part, flags in planted.items():
        if flags.dtype != np.bool_ or flags.shape != (n, 2):
            raise InputError(path, f"damaged .nmo file: planted/{part} must be bool ({n}, 2), "
                                   f"found {flags.dtype} {flags.shape}")
    problem = capture_ground_problem(ground, n)
    if problem:
        raise InputError(path, f"damaged .nmo file: {problem}")
    try:
        morph = Morphology.from_dict(header["source_morphology"])
        constraints = [ConstraintSpec.from_dict(c) for c in header.get("constraints", [])]
        check_stored(constraints, (n - 1) / float(header["fps"]))
    except (KeyError, TypeError, ValueError) as exc:
        raise InputError(path, f"damaged .nmo header: {exc}") from None
    return NormalizedMotion(NormalizedPoses(**arrays), float(header["fps"]), morph, constraints,
                            dict(header.get("info", {})), planted or None, ground)


def pose_arrays_problem(arrays: dict[str, np.ndarray], n_frames: int) -> str | None:
    """What is wrong with a motion's normalized pose arrays (``NormalizedPoses.arrays()``,
    each (n_frames, *TRAILING_SHAPES[name])), or None: shapes, finite values, limb fractions
    0-1, positive stretch, unit quaternions and directions. Import guarantees all of it; a file
    or a motion made by code is checked against it."""
    for name, trailing in TRAILING_SHAPES.items():
        if name not in arrays:
            return f"array {name!r} is missing"
        value = arrays[name]
        if value.shape != (n_frames,) + trailing:
            return f"{name} has shape {value.shape}, expected {(n_frames,) + trailing}"
        if not np.all(np.isfinite(value)):
            return f"{name} holds non-finite values"
        if np.any(np.abs(value) > 1e6):  # leg lengths, fractions, unit vectors: never
            return f"{name} holds values beyond 1e6"
    # A limb's length fraction is 0 (folded) to 1 (straight); a bone's stretch is positive.
    for name, lo, hi in (("leg_fraction", 0.0, 1.0 + 1e-6), ("arm_fraction", 0.0, 1.0 + 1e-6),
                         ("stretch", 1e-3, 1e3)):
        if np.any((arrays[name] < lo) | (arrays[name] > hi)):
            return f"{name} holds values outside {lo:g}-{hi:g}"
    for name in QUATERNION_FIELDS + DIRECTION_FIELDS:
        if np.any(np.abs(np.linalg.norm(arrays[name], axis=-1) - 1.0) > 1e-6):
            what = "quaternions" if name in QUATERNION_FIELDS else "directions"
            return f"{name} holds non-unit {what}"
    return None


def capture_ground_problem(ground: object, n_frames: int) -> str | None:
    """What is wrong with a motion's :attr:`~NormalizedMotion.capture_ground`, or None (None
    itself is fine: level at 0)."""
    if ground is None:
        return None
    if not (isinstance(ground, np.ndarray) and ground.dtype == np.float64
            and ground.shape == (n_frames,)):
        found = f"{ground.dtype} {ground.shape}" if isinstance(ground, np.ndarray) \
            else type(ground).__name__
        return f"capture_ground must be float64 ({n_frames},), found {found}"
    if not np.all(np.isfinite(ground)):
        return "capture_ground has non-finite values"
    return None


def motion_problem(motion: object) -> str | None:
    """What is wrong with a motion handed over by code (not read from a file), or None: a
    :class:`NormalizedMotion` with at least one frame, a frame rate of 0.1-10,000 fps, pose
    arrays as :func:`pose_arrays_problem` checks them and a source body of positive lengths."""
    if not isinstance(motion, NormalizedMotion):
        return f"expected a NormalizedMotion, got {type(motion).__name__}"
    if not (_is_number(motion.fps) and MIN_FPS <= motion.fps <= MAX_FPS):
        return f"fps must be a number from {MIN_FPS:g} to {MAX_FPS:g}, got {motion.fps!r}"
    if motion.n_frames < 1:
        return "no frames"
    problem = pose_arrays_problem(motion.poses.arrays(), motion.n_frames) \
        or capture_ground_problem(motion.capture_ground, motion.n_frames)
    if problem:
        return problem
    body = _source_body_problem(motion.source_morphology.to_dict())
    return None if body is None else f"source body: {body}"


def _check_header(path: str, header: Any) -> None:
    if not isinstance(header, dict) or header.get("format") != FORMAT_NAME:
        raise InputError(path, "not an .nmo file (wrong format name in header)")
    version = header.get("version")
    if type(version) is not int or version not in READ_VERSIONS:  # JSON true is not version 1
        raise InputError(path, f".nmo format version {version!r} is not supported by this "
                               f"ecs_anim (reads versions {READ_VERSIONS[0]}-{READ_VERSIONS[-1]}); "
                               "re-import the source clip or upgrade ecs_anim")
    for key in ("fps", "n_frames", "source_morphology"):
        if key not in header:
            raise InputError(path, f"damaged .nmo header: {key!r} is missing")
    fps, n = header["fps"], header["n_frames"]
    if not (_is_number(fps) and MIN_FPS <= fps <= MAX_FPS) \
            or isinstance(n, bool) or not isinstance(n, int) or n <= 0:
        raise InputError(path, f"damaged .nmo header: fps={fps!r}, n_frames={n!r}")
    if not isinstance(header.get("info", {}), dict) or not isinstance(header.get("constraints", []), list):
        raise InputError(path, "damaged .nmo header: 'info' must be an object and 'constraints' a list")
    problem = _source_body_problem(header["source_morphology"])
    if problem:
        raise InputError(path, f"damaged .nmo header: source_morphology: {problem}")


def _is_number(value: Any) -> bool:
    return isinstance(value, (int, float)) and not isinstance(value, bool) and math.isfinite(value)


def _source_body_problem(body: Any) -> str | None:
    """What is wrong with a header's source body, or None: what import guarantees, checked again
    (every segment of :data:`LENGTHS` a number 0-3 m, a stature of 0.3-3 m, a positive mass, a
    sex of de Leva's table)."""
    if not isinstance(body, dict) or not isinstance(body.get("lengths_m"), dict):
        return "expected an object with lengths_m: {segment: metres}"
    lengths = body["lengths_m"]
    missing = [name for name in LENGTHS if name not in lengths]
    if missing:
        return f"lengths_m lacks {listed(missing)}"
    bad = [f"{name}={lengths[name]!r}" for name in LENGTHS
           if not (_is_number(lengths[name]) and 0.0 < lengths[name] <= MAX_STATURE_M)]
    if bad:
        return f"segment lengths must be numbers above 0 and at most {MAX_STATURE_M:g} m, found {listed(bad, 3)}"
    mass: Any = body.get("mass_kg")
    if not (_is_number(mass) and 0.0 < mass <= MAX_MASS_KG):
        return f"mass_kg must be a number above 0 and at most {MAX_MASS_KG:g}, found {mass!r}"
    if body.get("sex") not in ("male", "female"):
        return f"sex must be 'male' or 'female', found {body.get('sex')!r}"
    stature = Morphology(np.array([lengths[name] for name in LENGTHS], dtype=np.float64)).stature
    if not MIN_STATURE_M <= stature <= MAX_STATURE_M:
        return (f"the body is {stature:.3g} m tall; import only writes bodies of "
                f"{MIN_STATURE_M:g}-{MAX_STATURE_M:g} m")
    return None
