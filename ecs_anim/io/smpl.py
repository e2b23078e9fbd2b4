"""SMPL, SMPL-H and SMPL-X motions (AMASS ``.npz``) with the user's own body-model file.

An AMASS file holds pose parameters, not joints: ``poses`` (n_frames, 3 x n_joints), each
joint's axis-angle rotation in its parent's frame (the root's in the world), ``trans``
(n_frames, 3) the root's translation, ``betas`` the body's shape, and ``mocap_framerate``
(``mocap_frame_rate`` in AMASS's SMPL-X files). The joints come from the body model (Loper et
al. 2015): ``J_regressor @ (v_template + shapedirs @ betas)``, its kinematic tree from
``kintree_table``. The model files are licensed (smpl.is.tue.mpg.de, mano.is.tue.mpg.de,
smpl-x.is.tue.mpg.de) and are never shipped: the user gives theirs (``--body-model``), as
``.npz`` (AMASS's SMPL+H models, SMPL-X's downloads; an official SMPL ``.pkl`` holds chumpy and
scipy objects, which are not read).

:func:`smpl_motion` turns model and motion into the BVH reader's structure (joints named as
SMPL names them, the rest pose the model's with no rotation), so the ``smpl`` joint-name preset,
the up axis and contacts are found as for BVH; no vertex is posed (joints only: ``weights`` and
``posedirs`` are not needed).
"""

from __future__ import annotations

import math
import zipfile
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from ecs_anim.core.errors import InputError
from ecs_anim.core.rotations import axis_angle, quat_from_matrix
from ecs_anim.io.bvh import BvhMotion
from ecs_anim.io.contacts import ContactThresholds
from ecs_anim.io.fbx import bvh_motion_from_transforms
from ecs_anim.io.importing import FrameRange, canonical_clip, import_canonical
from ecs_anim.io.position_layouts import SMPL_BODY
from ecs_anim.motion.clip import NormalizedMotion

F64 = NDArray[np.float64]

#: The keys of a body-model file the joints need.
MODEL_KEYS = ("v_template", "shapedirs", "J_regressor", "kintree_table")
_FINGERS = tuple(f"{finger}{k}" for finger in ("index", "middle", "pinky", "ring", "thumb")
                 for k in (1, 2, 3))
#: Joint names by the model's joint count: SMPL 24, SMPL-H 52, SMPL-X 55.
JOINT_NAMES: dict[int, tuple[str, ...]] = {
    24: (*SMPL_BODY, "left_hand", "right_hand"),
    52: (*SMPL_BODY, *(f"{side}_{f}" for side in ("left", "right") for f in _FINGERS)),
    55: (*SMPL_BODY, "jaw", "left_eye_smplhf", "right_eye_smplhf",
         *(f"{side}_{f}" for side in ("left", "right") for f in _FINGERS)),
}
MODEL_KINDS = {24: "SMPL", 52: "SMPL-H", 55: "SMPL-X"}
#: A body's joints lie within this many metres of its root (a model in millimetres or a
#: corrupted template does not).
MAX_JOINT_REACH_M = 3.0


@dataclass
class BodyModel:
    """The joints of a body model: ``template_joints`` (n_joints, 3) metres for betas 0,
    ``shape_joints`` (n_joints, 3, n_betas) how they move per beta (``J_regressor`` applied to
    ``v_template`` and ``shapedirs``), ``parents`` (n_joints,) -1 for the root."""

    template_joints: F64
    shape_joints: F64
    parents: NDArray[np.intp]
    path: str

    @property
    def kind(self) -> str:
        """``SMPL``, ``SMPL-H``, ``SMPL-X`` or ``n joints``."""
        n = len(self.parents)
        return MODEL_KINDS.get(n, f"{n} joints")

    def joints(self, betas: F64) -> F64:
        """The rest joints (n_joints, 3) of the body ``betas`` shapes (its first ``n_betas``
        used; a model with fewer takes as many as it has)."""
        n = min(len(betas), self.shape_joints.shape[-1])
        joints: F64 = self.template_joints + self.shape_joints[..., :n] @ betas[:n]
        return joints


def _load_npz(path: str, what: str) -> dict[str, NDArray[np.generic]]:
    """The arrays of an ``.npz``, or one :class:`InputError` line. Pickled objects are never
    loaded (a file could run code): an entry holding them is left out (AMASS stores some
    files' ``gender`` so; the joints need none)."""
    try:
        with np.load(path, allow_pickle=False) as data:
            arrays = {}
            for key in data.files:
                try:
                    arrays[key] = data[key]
                except ValueError:  # an object array
                    continue
            return arrays
    except FileNotFoundError:
        raise InputError(path, f"{what} not found") from None
    except (OSError, ValueError, zipfile.BadZipFile, EOFError) as exc:
        raise InputError(path, f"not a readable .npz {what} ({exc})") from None


def read_body_model(path: str | Path) -> BodyModel:
    """Read a SMPL/SMPL-H/SMPL-X body model ``.npz``. Raises :class:`InputError` naming the
    file and the key: a key missing, a wrong shape, a non-finite value, a tree that is not
    parents-first."""
    path = str(path)
    if path.lower().endswith(".pkl"):
        raise InputError(path, "a .pkl body model (its pickled chumpy and scipy objects are not "
                               "read): give the model as .npz (AMASS's SMPL+H models, SMPL-X's "
                               "downloads are .npz)")
    data = _load_npz(path, "body model")
    missing = [k for k in MODEL_KEYS if k not in data]
    if missing:
        raise InputError(path, f"a body model needs {', '.join(MODEL_KEYS)}; lacks "
                               f"{', '.join(missing)} (keys: {', '.join(sorted(data)) or 'none'})")
    arrays = {k: np.asarray(data[k], dtype=np.float64) for k in MODEL_KEYS}
    template, shapedirs, regressor = arrays["v_template"], arrays["shapedirs"], arrays["J_regressor"]
    n_vertices = len(template)
    tree = arrays["kintree_table"]
    n_joints = len(regressor)
    expected = {"v_template": (n_vertices, 3), "shapedirs": (n_vertices, 3, None),
                "J_regressor": (n_joints, n_vertices), "kintree_table": (2, n_joints)}
    for key, shape in expected.items():
        found = arrays[key].shape
        if len(found) != len(shape) or any(s is not None and s != f for s, f in zip(shape, found, strict=True)):
            want = "(" + ", ".join("n_betas" if s is None else str(s) for s in shape) + ")"
            raise InputError(path, f"{key}: shape {found} where the model's {n_vertices} vertices "
                                   f"and {n_joints} joints make {want}")
        if not np.all(np.isfinite(arrays[key])):
            raise InputError(path, f"{key}: holds non-finite values")
    if n_joints < len(SMPL_BODY):
        raise InputError(path, f"J_regressor: {n_joints} joints; a SMPL body has at least "
                               f"{len(SMPL_BODY)}")
    # kintree_table row 0: parents, the root's written as -1 or 2**32 - 1.
    parents = np.where(tree[0] >= n_joints, -1, tree[0]).astype(np.intp)
    if parents[0] != -1 or np.any(parents[1:] < 0) or np.any(parents[1:] >= np.arange(1, n_joints)):
        raise InputError(path, "kintree_table: expected joint 0 the root and every other joint's "
                               "parent before it")
    template_joints = regressor @ template
    reach = float(np.max(np.linalg.norm(template_joints - template_joints[0], axis=-1)))
    if reach > MAX_JOINT_REACH_M:
        raise InputError(path, f"v_template: the joints reach {reach:.3g} from the root; a body "
                               "model is in metres")
    return BodyModel(template_joints, np.einsum("jv,vab->jab", regressor, shapedirs), parents, path)


@dataclass
class AmassMotion:
    """An AMASS file: ``poses`` (n_frames, 3 x n) axis-angle radians, ``trans`` (n_frames, 3)
    metres, ``betas`` (n_betas,), ``fps`` (None where the file gives no rate)."""

    poses: F64
    trans: F64
    betas: F64
    fps: float | None
    gender: str
    path: str


def read_amass(path: str | Path) -> AmassMotion:
    """Read an AMASS ``.npz``. Raises :class:`InputError` naming the file and key: ``poses``
    or ``trans`` missing or of the wrong shape, no frame, a non-finite value."""
    path = str(path)
    data = _load_npz(path, "motion")
    missing = [k for k in ("poses", "trans") if k not in data]
    if missing:
        raise InputError(path, f"an AMASS motion needs poses and trans; lacks {', '.join(missing)} "
                               f"(keys: {', '.join(sorted(data)) or 'none'})")
    poses = np.asarray(data["poses"], dtype=np.float64)
    trans = np.asarray(data["trans"], dtype=np.float64)
    if poses.ndim != 2 or poses.shape[1] % 3 or poses.shape[1] < 3 * len(SMPL_BODY):
        raise InputError(path, f"poses: shape {poses.shape}; expected (n_frames, 3 x n_joints) "
                               f"with at least the {len(SMPL_BODY)} body joints (66 columns)")
    if len(poses) == 0:
        raise InputError(path, "poses: no frame (shape (0, ...))")
    if trans.shape != (len(poses), 3):
        raise InputError(path, f"trans: shape {trans.shape} where poses' {len(poses)} frames "
                               f"make ({len(poses)}, 3)")
    for key, values in (("poses", poses), ("trans", trans)):
        bad = ~np.all(np.isfinite(values), axis=-1)
        if bad.any():
            frames = np.flatnonzero(bad)
            raise InputError(path, f"{key}: non-finite values in {len(frames)} of {len(poses)} "
                                   f"frames (first: frame {frames[0]})")
    betas = np.asarray(data.get("betas", np.zeros(0)), dtype=np.float64).reshape(-1)
    if not np.all(np.isfinite(betas)):
        raise InputError(path, "betas: holds non-finite values")
    rate = next((float(data[k]) for k in ("mocap_framerate", "mocap_frame_rate") if k in data), None)
    if rate is not None and not (math.isfinite(rate) and rate > 0):
        raise InputError(path, f"mocap_framerate: {rate:g}; expected a positive rate")
    gender = str(data["gender"]) if "gender" in data else ""
    return AmassMotion(poses, trans, betas, rate, gender, path)


def smpl_motion(model: BodyModel, motion: AmassMotion, fps: float) -> tuple[BvhMotion, list[str]]:
    """The BVH reader's structure for ``motion`` posed on ``model``: each joint at its rest
    place less its parent's, turning by its axis-angle; the root at its rest place plus
    ``trans``. Where the file's pose has other joints than the model (SMPL-H poses on a SMPL
    model), the 22 body joints both share are posed and the others keep their rest; the
    returned notes say so."""
    notes: list[str] = []
    n_joints = len(model.parents)
    posed = motion.poses.shape[1] // 3
    rotations = np.zeros((len(motion.poses), n_joints, 3))
    if posed == n_joints:
        rotations[:] = motion.poses.reshape(len(motion.poses), n_joints, 3)
    else:
        body = len(SMPL_BODY)
        rotations[:, :body] = motion.poses[:, :3 * body].reshape(-1, body, 3)
        notes.append(f"the poses give {posed} joints and the {model.kind} model {n_joints}: the "
                     f"{body} body joints are posed, the others keep their rest")
    if len(motion.betas) > model.shape_joints.shape[-1]:
        notes.append(f"the file's {len(motion.betas)} betas, the model's "
                     f"{model.shape_joints.shape[-1]}: the first {model.shape_joints.shape[-1]} are used")
    rest = model.joints(motion.betas)
    parent_rest = np.where(model.parents[:, None] >= 0, rest[np.maximum(model.parents, 0)], 0.0)
    n_frames = len(motion.poses)
    translation = np.tile(rest - parent_rest, (n_frames, 1, 1))
    translation[:, 0] += motion.trans
    angle = np.linalg.norm(rotations, axis=-1)
    turn = axis_angle(rotations / np.maximum(angle, 1e-12)[..., None], angle)
    names = list(JOINT_NAMES.get(n_joints, (*SMPL_BODY, *(f"joint_{k}" for k in range(len(SMPL_BODY),
                                                                                         n_joints)))))
    identity = np.tile([0.0, 0.0, 0.0, 1.0], (1, n_joints, 1))
    bvh = bvh_motion_from_transforms(
        names, model.parents, ((rest - parent_rest)[None], identity, np.ones((1, n_joints, 3))),
        (translation, quat_from_matrix(turn), np.ones((n_frames, n_joints, 3))), 1.0 / fps,
        motion.path, list(notes))
    return bvh, notes


def import_amass(path: str | Path, body_model: str | Path,
                 thresholds: ContactThresholds = ContactThresholds(), up: str | None = None,
                 trim: FrameRange | None = None, treadmill: bool = True,
                 fps: float | None = None) -> NormalizedMotion:
    """Read an AMASS ``.npz`` and pose it on ``body_model`` (the user's SMPL/SMPL-H/SMPL-X
    ``.npz``), then normalize it as :func:`~ecs_anim.io.importing.import_bvh` does a BVH file
    (the ``smpl`` joint-name preset; metres; the up axis detected, AMASS's is Z, unless
    ``up``). ``fps`` overrides the file's ``mocap_framerate`` (needed where it has none).
    ``info.smpl`` records the model, its kind and the notes. Raises :class:`EcsAnimError`
    subclasses on bad input."""
    path = Path(path)
    model = read_body_model(body_model)
    motion = read_amass(path)
    rate = fps if fps is not None else motion.fps
    if rate is None:
        raise InputError(path, "no frame rate (mocap_framerate or mocap_frame_rate): give --fps F")
    bvh, notes = smpl_motion(model, motion, rate)
    normalized = import_canonical(path, lambda: canonical_clip(bvh, "smpl", "m", up), trim,
                                  thresholds, treadmill)
    normalized.info["unit_reason"] = f"a {model.kind} body model is in metres"
    normalized.info["smpl"] = {"body_model": str(body_model), "model": model.kind,
                               "gender": motion.gender, "betas": len(motion.betas),
                               "fps_from": "--fps" if fps is not None else "mocap_framerate",
                               "notes": notes}
    return normalized


def is_amass(path: str | Path) -> bool:
    """Whether an ``.npz`` holds an AMASS motion (``poses`` and ``trans``), which needs a body
    model, rather than joint positions."""
    try:
        with np.load(path, allow_pickle=False) as data:
            return {"poses", "trans"} <= set(data.files)
    except (OSError, ValueError, zipfile.BadZipFile, EOFError):
        return False


__all__ = ["AmassMotion", "BodyModel", "import_amass", "is_amass", "read_amass",
           "read_body_model", "smpl_motion"]
