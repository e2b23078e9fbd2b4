"""Import classes of issue 31 found on files nobody here had seen: the arm's joints by structure
(class 5) and a degenerate ankle End Site taken for the toe (class 8).

Each class is checked on a dev file where there is one and on hierarchies written here by hand:
Y up, facing +Z, left at +X, T-pose, a short walk (the hips move forward, the thighs swing in
antiphase, the knees and elbows bend).
"""

from __future__ import annotations

import re

import numpy as np
import pytest

from conftest import MOCAP_DIR, require_mocap
from ecs_anim.core.skeleton import LENGTH_INDEX
from ecs_anim.io.importing import import_bvh

N_FRAMES = 40
FRAME_TIME_S = 1.0 / 30.0

#: A joint: (name, parent or None, OFFSET, End Site OFFSET or None).
Joint = tuple[str, str | None, tuple[float, ...], tuple[float, ...] | None]

#: What each driven joint does over the walk: (kind of joint, axis its channel turns about).
_DRIVE = {"hip": "X", "knee": "X", "shoulder": "Y", "elbow": "Y"}


def _right(name: str) -> str:
    """The right side's name for a left joint's: ``Left``/``L_`` renamed ``Right``/``R_``."""
    return name.replace("Left", "Right").replace("L_", "R_")


def _mirrored(left: list[Joint]) -> list[Joint]:
    """``left`` and its mirror image: names through :func:`_right`, X negated."""
    def flip(v: tuple[float, ...] | None) -> tuple[float, ...] | None:
        return None if v is None else (-v[0], *v[1:])

    return left + [(_right(n), None if p is None else _right(p), (-o[0], *o[1:]), flip(e))
                   for n, p, o, e in left]


def _bvh(joints: list[Joint], drive: dict[str, str], unit: float) -> str:
    """BVH text for ``joints`` (OFFSETs in metres, written in file units of ``unit`` m), rotations
    Z X Y; ``drive``: joint name -> kind of joint (:data:`_DRIVE`) for the walk's rotations."""
    t = np.arange(N_FRAMES) * FRAME_TIME_S
    phase = 2.0 * np.pi * t + 0.9  # frame 0 is no rest pose (which the import would drop)
    children: dict[str | None, list[Joint]] = {}
    for j in joints:
        children.setdefault(j[1], []).append(j)
    lines, columns = ["HIERARCHY"], []

    def angles(name: str) -> np.ndarray:
        kind = drive.get(name)
        out = np.zeros((N_FRAMES, 3))  # Z, X, Y
        if kind is None:
            return out
        shift = 0.0 if "Left" in name or name.startswith("L_") else np.pi
        degrees = {"hip": -25.0 * np.sin(phase + shift),
                   "knee": 20.0 * (1.0 - np.cos(phase + shift)),
                   "shoulder": 15.0 * np.sin(phase + shift),
                   "elbow": (15.0 + 5.0 * np.sin(phase)) * (1.0 if shift else -1.0)}[kind]
        out[:, "ZXY".index(_DRIVE[kind])] = degrees
        return out

    def vec(v: tuple[float, ...]) -> str:
        return " ".join(f"{x / unit:.6f}" for x in v)

    def emit(joint: Joint, depth: int) -> None:
        name, parent, offset, end = joint
        pad = "\t" * depth
        lines.extend([f"{pad}{'ROOT' if parent is None else 'JOINT'} {name}", pad + "{",
                      f"{pad}\tOFFSET {vec(offset)}"])
        if parent is None:
            lines.append(f"{pad}\tCHANNELS 6 Xposition Yposition Zposition Zrotation Xrotation "
                         "Yrotation")
            place = np.stack([np.zeros(N_FRAMES), np.full(N_FRAMES, offset[1]), 1.2 * t], -1)
            columns.append(place / unit)
        else:
            lines.append(f"{pad}\tCHANNELS 3 Zrotation Xrotation Yrotation")
        columns.append(angles(name))
        for child in children.get(name, []):
            emit(child, depth + 1)
        if end is not None:
            lines.extend([f"{pad}\tEnd Site", f"{pad}\t{{", f"{pad}\t\tOFFSET {vec(end)}",
                          f"{pad}\t}}"])
        lines.append(pad + "}")

    emit(joints[0], 0)
    values = np.concatenate(columns, axis=1)
    lines += ["MOTION", f"Frames: {N_FRAMES}", f"Frame Time: {FRAME_TIME_S:.8f}"]
    lines += [" ".join(f"{v:.6f}" for v in row) for row in values]
    return "\n".join(lines) + "\n"


# --- class 5: the arm's joints by structure --------------------------------------------------

def test_max_biped_arms_are_upper_arm_forearm_hand():
    """3ds Max Biped names with underscores (no preset), the hand's End Site repeating the
    forearm's OFFSET: the arm is UpperArm / Forearm / Hand, not Forearm / Hand / the hand's End
    Site (before: the shoulder on Left_Forearm), and both hands alike."""
    require_mocap()
    path = MOCAP_DIR / "varied2" / "max_biped_underscore_zup_6ch_30fps.bvh"
    joints = import_bvh(path).info["joints"]
    for side, name in (("l", "Left"), ("r", "Right")):
        assert (joints[f"shoulder_{side}"], joints[f"elbow_{side}"], joints[f"wrist_{side}"]) \
            == (f"{name}_UpperArm", f"{name}_Forearm", f"{name}_Hand"), joints
    assert (joints["hand_l"] is None) == (joints["hand_r"] is None), joints


def _arm_body(collar: tuple[float, ...], clavicle: float, humerus: float, forearm: float,
              hand_end: float) -> list[Joint]:
    """A body in metres with names no preset knows: a collar joint ``collar`` off the chest, then
    the collar bone, upper arm and forearm along +X, and the hand as the wrist's End Site."""
    return [("Pelvis", None, (0.0, 0.95, 0.0), None), ("Spine", "Pelvis", (0.0, 0.12, 0.0), None),
            ("Chest", "Spine", (0.0, 0.24, 0.0), None), ("Neck", "Chest", (0.0, 0.2, 0.0), None),
            ("Head", "Neck", (0.0, 0.1, 0.0), (0.0, 0.18, 0.0))] + _mirrored([
        ("L_Hip", "Pelvis", (0.09, -0.05, 0.0), None), ("L_Knee", "L_Hip", (0.0, -0.44, 0.0), None),
        ("L_Ankle", "L_Knee", (0.0, -0.42, 0.0), None),
        ("L_Toe", "L_Ankle", (0.0, -0.08, 0.13), (0.0, -0.01, 0.06)),
        ("L_Collar", "Chest", collar, None), ("L_Shoulder", "L_Collar", (clavicle, 0.0, 0.0), None),
        ("L_Elbow", "L_Shoulder", (humerus, 0.0, 0.0), None),
        ("L_Wrist", "L_Elbow", (forearm, 0.0, 0.0), (hand_end, 0.0, 0.0))])


_ARM_DRIVE = {f"{s}_{j}": kind for s in "LR" for j, kind in
              (("Hip", "hip"), ("Knee", "knee"), ("Shoulder", "shoulder"), ("Elbow", "elbow"))}


@pytest.mark.parametrize(("collar", "clavicle", "humerus", "forearm", "hand_end"), [
    # CMU's proportions (clavicle 3.58, humerus 4.98, forearm 3.48 units) with the collar joint
    # at the sternum, 16 cm up the chest: before, the shoulder was L_Collar.
    ((0.02, 0.16, 0.0), 0.2, 0.28, 0.195, 0.08),
    # 3ds Max Biped's: the hand's End Site as long as the forearm: before, the shoulder was
    # L_Elbow and the wrist the End Site.
    ((0.034, 0.18, 0.0), 0.13, 0.235, 0.25, 0.255),
], ids=["collar_longer_than_forearm", "hand_end_as_long_as_forearm"])
def test_the_shoulder_is_where_the_arm_leaves_the_collar_bone(collar, clavicle, humerus, forearm,
                                                              hand_end, tmp_path):
    """Arms matched by structure: the shoulders are the first joints along the arms farther apart
    than the hips, and the hand's End Site ends the chain, so the long bones are the upper arm and
    the forearm however long the collar bone or the hand's End Site."""
    path = tmp_path / "arms.bvh"
    path.write_text(_bvh(_arm_body(collar, clavicle, humerus, forearm, hand_end), _ARM_DRIVE,
                         0.01))
    info = import_bvh(path).info
    assert info["joint_map"].startswith("structure"), info["joint_map"]
    joints = info["joints"]
    for side, s in (("l", "L"), ("r", "R")):
        assert (joints[f"shoulder_{side}"], joints[f"elbow_{side}"], joints[f"wrist_{side}"]) \
            == (f"{s}_Shoulder", f"{s}_Elbow", f"{s}_Wrist"), joints
        assert (joints[f"hip_{side}"], joints[f"knee_{side}"], joints[f"ankle_{side}"],
                joints[f"toe_{side}"]) == (f"{s}_Hip", f"{s}_Knee", f"{s}_Ankle", f"{s}_Toe")


# --- class 8: a degenerate ankle End Site is no toe ------------------------------------------

def _toeless_walker(names: dict[str, str], ankle_end: tuple[float, ...]) -> list[Joint]:
    """A body in metres without toe joints, its ankles ending in the End Site ``ankle_end``;
    ``names`` gives the left joints' names (the right ones are mirrored)."""
    n = names
    return [(n["pelvis"], None, (0.0, 0.95, 0.0), None),
            (n["spine"], n["pelvis"], (0.0, 0.12, 0.0), None),
            (n["chest"], n["spine"], (0.0, 0.24, 0.0), None),
            (n["neck"], n["chest"], (0.0, 0.2, 0.0), None),
            (n["head"], n["neck"], (0.0, 0.1, 0.0), (0.0, 0.18, 0.0))] + _mirrored([
        (n["hip"], n["pelvis"], (0.09, -0.05, 0.0), None),
        (n["knee"], n["hip"], (0.0, -0.44, 0.0), None),
        (n["ankle"], n["knee"], (0.0, -0.42, 0.0), ankle_end),
        (n["collar"], n["chest"], (0.03, 0.16, 0.0), None),
        (n["shoulder"], n["collar"], (0.14, 0.0, 0.0), None),
        (n["elbow"], n["shoulder"], (0.29, 0.0, 0.0), None),
        (n["wrist"], n["elbow"], (0.26, 0.0, 0.0), (0.18, 0.0, 0.0))])


#: Mixamo's names (a preset names no toe: the ankle's End Site is looked at) and names no preset
#: knows (structural matching).
NAMINGS = {
    "mixamo": {"pelvis": "Hips", "spine": "Spine1", "chest": "Spine2", "neck": "Neck",
               "head": "Head", "hip": "LeftUpLeg", "knee": "LeftLeg", "ankle": "LeftFoot",
               "collar": "LeftShoulder", "shoulder": "LeftArm", "elbow": "LeftForeArm",
               "wrist": "LeftHand"},
    "generic": {"pelvis": "Root", "spine": "Torso", "chest": "UpperTorso", "neck": "NeckBase",
                "head": "Skull", "hip": "L_Thighbone", "knee": "L_Shinbone",
                "ankle": "L_Heelbone", "collar": "L_Clav", "shoulder": "L_Humerus",
                "elbow": "L_Radius", "wrist": "L_Carpus"},
}


def _drive_for(names: dict[str, str]) -> dict[str, str]:
    out = {}
    for kind in _DRIVE:
        left = names[kind]
        out[left] = kind
        out[_right(left)] = kind
    return out


@pytest.mark.parametrize("naming", list(NAMINGS))
def test_a_tenth_of_a_millimetre_ankle_end_site_is_no_toe(naming, tmp_path):
    """An ankle End Site 0.1 mm ahead of the ankle (a file in metres): the toes are filled in as
    for a file without toes, the foot a plausible length (before: toe_l was the End Site and the
    foot 0.0001 m long)."""
    names = NAMINGS[naming]
    path = tmp_path / f"{naming}_degenerate_toe.bvh"
    path.write_text(_bvh(_toeless_walker(names, (0.0, 0.0, 0.0001)), _drive_for(names), 1.0))
    motion = import_bvh(path)
    info = motion.info
    assert info["unit"] == "m", info["unit"]
    for side in "lr":
        assert info["joints"][f"toe_{side}"] is None, info["joints"]
        assert f"toe_{side}" in info["filled_in"], info["filled_in"]
        foot = float(motion.source_morphology.lengths[LENGTH_INDEX[f"foot_{side}"]])
        assert 0.1 < foot < 0.35, f"foot_{side} {foot:.4f} m"


@pytest.mark.parametrize("naming", list(NAMINGS))
def test_an_ankle_end_site_as_long_as_a_foot_is_still_the_toe(naming, tmp_path):
    """The same body with a 15 cm End Site ahead of and below the ankle: that End Site is the toe
    (measured, not filled in), as for Daz and Perception Neuron files."""
    names = NAMINGS[naming]
    path = tmp_path / f"{naming}_end_site_toe.bvh"
    path.write_text(_bvh(_toeless_walker(names, (0.0, -0.09, 0.13)), _drive_for(names), 1.0))
    motion = import_bvh(path)
    for side, ankle in (("l", names["ankle"]), ("r", _right(names["ankle"]))):
        assert motion.info["joints"][f"toe_{side}"] == f"{ankle}.end", motion.info["joints"]
        foot = float(motion.source_morphology.lengths[LENGTH_INDEX[f"foot_{side}"]])
        assert abs(foot - np.hypot(0.09, 0.13)) < 1e-3, foot


def test_the_written_files_are_what_they_claim():
    """The hand-written walk: the hips move 1.2 m/s forward and the left knee bends 0-40 degrees
    (independent of the importer: positions from the OFFSETs and the X rotations alone)."""
    names = NAMINGS["generic"]
    text = _bvh(_toeless_walker(names, (0.0, 0.0, 0.0001)), _drive_for(names), 1.0)
    rows = np.array([[float(v) for v in line.split()]
                     for line in text.split("Frame Time:")[1].splitlines()[1:]])
    assert rows.shape[0] == N_FRAMES
    assert abs((rows[-1, 2] - rows[0, 2]) / ((N_FRAMES - 1) * FRAME_TIME_S) - 1.2) < 1e-6
    header = text.split("MOTION")[0].split()
    joint_order = [header[k + 1] for k, w in enumerate(header) if w in ("ROOT", "JOINT")]
    knee = joint_order.index(names["knee"])
    knee_x = rows[:, 6 + 3 * (knee - 1) + 1]  # root: 6 channels; then Z X Y per joint
    assert 0.0 <= knee_x.min() < 1.0 and 38.0 < knee_x.max() <= 40.0 + 1e-6


# --- class 4: not a human -----------------------------------------------------------------------

def _four_legged() -> list[Joint]:
    """A dog in metres with human joint names (Mixamo's, no prefix): hips 0.5 m up, the spine
    and neck forward along +Z, hind legs (UpLeg/Leg/Foot) and front legs (Arm/ForeArm/Hand)
    straight down to the ground."""
    return [("Hips", None, (0.0, 0.5, 0.0), None), ("Spine", "Hips", (0.0, 0.0, 0.2), None),
            ("Spine1", "Spine", (0.0, 0.0, 0.2), None), ("Neck", "Spine1", (0.0, 0.05, 0.1), None),
            ("Head", "Neck", (0.0, 0.05, 0.1), (0.0, 0.0, 0.12))] + _mirrored([
        ("LeftUpLeg", "Hips", (0.07, -0.03, 0.0), None),
        ("LeftLeg", "LeftUpLeg", (0.0, -0.22, 0.0), None),
        ("LeftFoot", "LeftLeg", (0.0, -0.22, 0.0), None),
        ("LeftToeBase", "LeftFoot", (0.0, -0.03, 0.05), (0.0, 0.0, 0.03)),
        ("LeftShoulder", "Spine1", (0.06, -0.02, 0.05), None),
        ("LeftArm", "LeftShoulder", (0.02, -0.05, 0.0), None),
        ("LeftForeArm", "LeftArm", (0.0, -0.2, 0.0), None),
        ("LeftHand", "LeftForeArm", (0.0, -0.2, 0.0), (0.0, -0.03, 0.04))])


def test_a_four_legged_skeleton_with_human_names_is_refused(tmp_path, capsys):
    """Issue 31, class 4: a quadruped named like a person (it imported as a person before, its
    spine taken for a short, lying trunk) is refused in one line that says why; nothing is
    written. People pass, whatever they do: every dev BVH imports (the other tests), a seated
    bike rider (legs at 127 degrees to the spine) among them."""
    from ecs_anim.apps.cli.main import main

    path = tmp_path / "dog.bvh"
    drive = {"LeftUpLeg": "hip", "RightUpLeg": "hip", "LeftLeg": "knee", "RightLeg": "knee"}
    path.write_text(_bvh(_four_legged(), drive, 0.01))
    assert main(["import", str(path), "-o", str(tmp_path / "out")]) == 1
    err = capsys.readouterr().err.strip().splitlines()
    said = re.match(rf"error: {re.escape(str(path))}: not a human skeleton: its legs stand at "
                    r"(\d+) degrees to its spine", err[0])
    assert said is not None and 60 < int(said.group(1)) < 120, err
    assert "a four-legged animal?" in err[0] and len(err) == 2  # and the count line
    assert not (tmp_path / "out").exists() or not any((tmp_path / "out").iterdir())
