"""Joint-position layouts of research datasets and pose estimators: which of a layout's joints is
which of our body parts (``ecs-anim import X.npy --layout NAME``, ``export --layout NAME``).

Each layout is one table, :class:`PositionLayout`: its joint names in the file's order, which of
them gives each canonical joint (:data:`~ecs_anim.core.skeleton.JOINTS`; two names: their
middle), and how an export places the layout's joints our skeleton has no part for (an SMPL
collar, a MediaPipe heel, a COCO eye): an affine blend of canonical joints, or an offset in the
head's frame. Those placements approximate each layout's rest proportions; they are filled in,
never measured. Sources of the orders are named in each table's ``source``.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from ecs_anim.core.errors import EcsAnimError, did_you_mean

F64 = NDArray[np.float64]


@dataclass(frozen=True)
class PositionLayout:
    """One dataset's joint order and what each joint is.

    ``joints``: the layout's joint names in file order. ``canonical``: canonical joint -> the
    layout joints it is read from (one: that joint; two: their middle). ``blends``: layout
    joint -> weights of canonical joints (summing to 1) that place it on export. ``head_offsets``:
    layout joint -> (forward, left, up) in the head's frame from the canonical head, as fractions
    of the leg (thigh + shank). ``face``: (nose, left ear, right ear), whose frame is the head's
    on import. ``export_up``/``export_unit_m``: the axes (a key of
    :data:`~ecs_anim.io.importing.UP_AXES`) and metres per unit export writes; ``hips_origin``:
    export puts the hips' middle at the origin every frame (as MediaPipe's world landmarks).
    ``fps``: the dataset's own frame rate, used when a file holds none."""

    name: str
    joints: tuple[str, ...]
    canonical: Mapping[str, tuple[str, ...]]
    source: str
    blends: Mapping[str, Mapping[str, float]] = field(default_factory=dict)
    head_offsets: Mapping[str, tuple[float, float, float]] = field(default_factory=dict)
    face: tuple[str, str, str] | None = None
    export_up: str = "y"
    export_unit_m: float = 1.0
    hips_origin: bool = False
    fps: float | None = None

    def index(self, joint: str) -> int:
        """The position of ``joint`` in the file's order."""
        return self.joints.index(joint)


#: SMPL's first 22 joints (HumanML3D's ``new_joints``, SMPL-X's body joints are the same).
SMPL_BODY = ("pelvis", "left_hip", "right_hip", "spine1", "left_knee", "right_knee", "spine2",
             "left_ankle", "right_ankle", "spine3", "left_foot", "right_foot", "neck",
             "left_collar", "right_collar", "head", "left_shoulder", "right_shoulder",
             "left_elbow", "right_elbow", "left_wrist", "right_wrist")

#: Our two intermediate spine joints are SMPL's spine1 and spine3 (spine3 carries the collars, so
#: the thorax frame stands on it); spine2 and the collars have no part of ours.
_SMPL_CANONICAL: dict[str, tuple[str, ...]] = {
    "pelvis": ("pelvis",), "spine_1": ("spine1",), "spine_2": ("spine3",), "neck": ("neck",),
    "head": ("head",),
    **{f"{part}_{s}": (f"{side}_{their}",) for s, side in (("l", "left"), ("r", "right"))
       for part, their in (("hip", "hip"), ("knee", "knee"), ("ankle", "ankle"), ("toe", "foot"),
                           ("shoulder", "shoulder"), ("elbow", "elbow"), ("wrist", "wrist"))},
}
#: SMPL's spine2 halfway up our spine's middle segment; a collar between spine3, the neck and
#: the shoulder, about 40 % of the way out (SMPL's rest pose).
_SMPL_BLENDS: dict[str, dict[str, float]] = {
    "spine2": {"spine_1": 0.5, "spine_2": 0.5},
    "left_collar": {"spine_2": 0.3, "neck": 0.3, "shoulder_l": 0.4},
    "right_collar": {"spine_2": 0.3, "neck": 0.3, "shoulder_r": 0.4},
}
_SMPL_SOURCE = "SMPL joint order (Loper et al. 2015; HumanML3D's paramUtil t2m_kinematic_chain)"

HUMANML3D = PositionLayout(
    "humanml3d", SMPL_BODY, _SMPL_CANONICAL, "HumanML3D new_joints: " + _SMPL_SOURCE,
    blends=_SMPL_BLENDS, export_up="y", fps=20.0)
SMPLX22 = PositionLayout(
    "smplx22", SMPL_BODY, _SMPL_CANONICAL, "SMPL-X body joints 0-21: " + _SMPL_SOURCE,
    blends=_SMPL_BLENDS, export_up="z")
SMPL24 = PositionLayout(
    "smpl24", (*SMPL_BODY, "left_hand", "right_hand"),
    {**_SMPL_CANONICAL, "hand_l": ("left_hand",), "hand_r": ("right_hand",)},
    "SMPL's 24 joints: " + _SMPL_SOURCE, blends=_SMPL_BLENDS, export_up="z")

#: KIT-ML (the MMM model's joints as HumanML3D's KIT release orders them): R before L.
KIT = PositionLayout(
    "kit", ("root", "BP", "BT", "BLN", "BUN", "RS", "RE", "RW", "LS", "LE", "LW",
            "RH", "RK", "RA", "RMrot", "RF", "LH", "LK", "LA", "LMrot", "LF"),
    {"pelvis": ("root",), "spine_1": ("BP",), "spine_2": ("BT",), "neck": ("BLN",),
     "head": ("BUN",),
     **{f"{part}_{s}": (f"{s.upper()}{their}",) for s in "lr"
        for part, their in (("shoulder", "S"), ("elbow", "E"), ("wrist", "W"), ("hip", "H"),
                            ("knee", "K"), ("ankle", "A"), ("toe", "Mrot"))}},
    "KIT-ML (Plappert et al. 2016) as HumanML3D's paramUtil kit_kinematic_chain orders it: "
    "right leg 11-15, left leg 16-20, right arm 5-7, left arm 8-10",
    # The toe tip 40 % of the ankle-to-ball length beyond the ball.
    blends={f"{s.upper()}F": {f"toe_{s}": 1.4, f"ankle_{s}": -0.4} for s in "lr"},
    export_up="y", export_unit_m=0.001, fps=12.5)

H36M = PositionLayout(
    "h36m", ("hip", "right_hip", "right_knee", "right_ankle", "left_hip", "left_knee",
             "left_ankle", "spine", "thorax", "neck_nose", "head", "left_shoulder", "left_elbow",
             "left_wrist", "right_shoulder", "right_elbow", "right_wrist"),
    {"pelvis": ("hip",), "spine_1": ("spine",), "neck": ("thorax",), "head": ("neck_nose",),
     "head_top": ("head",),
     **{f"{part}_{s}": (f"{side}_{part}",) for s, side in (("l", "left"), ("r", "right"))
        for part in ("hip", "knee", "ankle", "shoulder", "elbow", "wrist")}},
    "Human3.6M's 17 joints as VideoPose3D and MotionBERT order them (Ionescu et al. 2014)",
    export_up="z")

#: Face points in the head's frame, from the ears' middle, as fractions of the leg (an adult's
#: face: nose 10 cm ahead, ears 15 cm apart, eyes 3 cm above the ear line).
_NOSE = (0.12, 0.0, 0.0)
_EAR = 0.095


def _sided(x: float, y: float, z: float) -> dict[str, tuple[float, float, float]]:
    return {"left": (x, y, z), "right": (x, -y, z)}


COCO17 = PositionLayout(
    "coco17", ("nose", "left_eye", "right_eye", "left_ear", "right_ear", "left_shoulder",
               "right_shoulder", "left_elbow", "right_elbow", "left_wrist", "right_wrist",
               "left_hip", "right_hip", "left_knee", "right_knee", "left_ankle", "right_ankle"),
    {"pelvis": ("left_hip", "right_hip"), "neck": ("left_shoulder", "right_shoulder"),
     "head": ("left_ear", "right_ear"),
     **{f"{part}_{s}": (f"{side}_{part}",) for s, side in (("l", "left"), ("r", "right"))
        for part in ("hip", "knee", "ankle", "shoulder", "elbow", "wrist")}},
    "COCO keypoints' 17 (Lin et al. 2014), lifted to 3D", face=("nose", "left_ear", "right_ear"),
    head_offsets={"nose": _NOSE,
                  **{f"{side}_eye": xyz for side, xyz in _sided(0.1, 0.04, 0.04).items()},
                  **{f"{side}_ear": xyz for side, xyz in _sided(0.0, _EAR, 0.0).items()}},
    export_up="y")

MEDIAPIPE33 = PositionLayout(
    "mediapipe33", ("nose", "left_eye_inner", "left_eye", "left_eye_outer", "right_eye_inner",
                    "right_eye", "right_eye_outer", "left_ear", "right_ear", "mouth_left",
                    "mouth_right", "left_shoulder", "right_shoulder", "left_elbow", "right_elbow",
                    "left_wrist", "right_wrist", "left_pinky", "right_pinky", "left_index",
                    "right_index", "left_thumb", "right_thumb", "left_hip", "right_hip",
                    "left_knee", "right_knee", "left_ankle", "right_ankle", "left_heel",
                    "right_heel", "left_foot_index", "right_foot_index"),
    {"pelvis": ("left_hip", "right_hip"), "neck": ("left_shoulder", "right_shoulder"),
     "head": ("left_ear", "right_ear"),
     **{f"{part}_{s}": (f"{side}_{part}",) for s, side in (("l", "left"), ("r", "right"))
        for part in ("hip", "knee", "ankle", "shoulder", "elbow", "wrist")},
     **{f"toe_{s}": (f"{side}_foot_index",) for s, side in (("l", "left"), ("r", "right"))},
     # The pinky and index landmarks are their knuckles: the hand ends between them.
     **{f"hand_{s}": (f"{side}_pinky", f"{side}_index") for s, side in (("l", "left"), ("r", "right"))}},
    "MediaPipe Pose's 33 landmarks (BlazePose; Google AI Edge, Pose landmarker guide); "
    "world landmarks in metres, origin at the hips' middle, Y down",
    face=("nose", "left_ear", "right_ear"),
    blends={**{f"{side}_heel": {f"ankle_{s}": 1.35, f"toe_{s}": -0.2, f"knee_{s}": -0.15}
               for s, side in (("l", "left"), ("r", "right"))},
            **{f"{side}_{finger}": {f"hand_{s}": 1.0} for s, side in (("l", "left"), ("r", "right"))
               for finger in ("pinky", "index")},
            **{f"{side}_thumb": {f"hand_{s}": 0.5, f"wrist_{s}": 0.5}
               for s, side in (("l", "left"), ("r", "right"))}},
    head_offsets={"nose": _NOSE,
                  **{f"{side}_eye": xyz for side, xyz in _sided(0.1, 0.04, 0.04).items()},
                  **{f"{side}_eye_inner": xyz for side, xyz in _sided(0.1, 0.025, 0.04).items()},
                  **{f"{side}_eye_outer": xyz for side, xyz in _sided(0.09, 0.055, 0.04).items()},
                  **{f"{side}_ear": xyz for side, xyz in _sided(0.0, _EAR, 0.0).items()},
                  **{f"mouth_{side}": xyz for side, xyz in _sided(0.1, 0.03, -0.05).items()}},
    export_up="-y", hips_origin=True)

LAYOUTS: dict[str, PositionLayout] = {
    layout.name: layout for layout in (HUMANML3D, SMPLX22, SMPL24, KIT, H36M, COCO17, MEDIAPIPE33)}


def layout_named(name: str) -> PositionLayout:
    """The layout called ``name``; raises :class:`EcsAnimError` naming the choices."""
    key = name.strip().lower()
    if key not in LAYOUTS:
        raise EcsAnimError(f"--layout {name}: unknown layout; choose one of {', '.join(LAYOUTS)}"
                           + did_you_mean(key, LAYOUTS))
    return LAYOUTS[key]


#: Of two 17-joint layouts, COCO's joints 1 and 2 are the eyes, a few centimetres apart, where
#: Human3.6M's are the right hip and knee, a thigh apart: their distance over that of joints 0
#: and 16 (nose to right ankle, or pelvis to right wrist) is about 0.04 in COCO and 0.4-1 in
#: Human3.6M; this threshold parts them.
COCO_EYES_RATIO = 0.2


def detect_layout(positions: F64, names: tuple[str, ...] | None = None) -> tuple[PositionLayout, str]:
    """The layout of ``positions`` (n_frames, n_joints, 3) with a sentence saying why: from the
    file's joint names where it gives them (``names``: they must be the layout's, in order),
    else from the joint count where only one layout has it, and for 17 joints from the
    structure (:data:`COCO_EYES_RATIO`). Raises :class:`EcsAnimError` where the count is
    ambiguous (22: HumanML3D or SMPL-X's body) or no layout has it."""
    count = positions.shape[1]
    if names is not None:
        for layout in LAYOUTS.values():
            if [n.lower() for n in names] == [n.lower() for n in layout.joints]:
                return layout, f"detected: the file's joint names are {layout.name}'s"
    have = [layout for layout in LAYOUTS.values() if len(layout.joints) == count]
    if not have:
        counts = ", ".join(f"{layout.name} {len(layout.joints)}" for layout in LAYOUTS.values())
        raise EcsAnimError(f"{count} joints per frame: no layout has that many ({counts}); "
                           "give --layout if the array holds extra columns")
    if len(have) == 1:
        return have[0], f"detected: {count} joints"
    if count == 17:
        with np.errstate(invalid="ignore", divide="ignore"):
            ratio = float(np.nanmedian(np.linalg.norm(positions[:, 1] - positions[:, 2], axis=-1)
                                       / np.linalg.norm(positions[:, 0] - positions[:, 16], axis=-1)))
        if np.isfinite(ratio):
            layout = COCO17 if ratio < COCO_EYES_RATIO else H36M
            what = "the eyes" if layout is COCO17 else "a thigh"
            return layout, (f"detected: 17 joints, joints 1 and 2 apart {ratio:.2f} times joints "
                            f"0 and 16 ({what})")
    choices = " or ".join(layout.name for layout in have)
    raise EcsAnimError(f"{count} joints per frame could be {choices} (the same count"
                       + (", the same joints in the same order" if count == 22 else "")
                       + f"); give --layout {have[0].name} or the other")


__all__ = ["LAYOUTS", "PositionLayout", "detect_layout", "layout_named"]
