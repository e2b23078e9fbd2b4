"""BVH variants as other tools write them, made from dev files by editing a copy in ``tmp_path``.

Each variant keeps the pose of every frame (a helper root's motion is taken out of the hips'
channels, a joint's new channel order gets angles converted with numpy Euler code), so
the import with no flags must give back the original file's joints within 0.1 mm on every
frame, against the independent forward kinematics of ``support/bvh_reference.py`` on the
original file.
Variants: helper bones above the hips (a Blender-style ``Armature``, MotionBuilder's
``Reference``, a ``root`` carrying the translation), extra bones the canonical body has no part
for (ignored and named in the import report), every End Site removed, and text rewrites (tabs,
CRLF, blank lines, trailing spaces, scientific notation, mixed channel orders, six channels on
every joint, lower-case keywords).
"""

from __future__ import annotations

import copy
import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pytest

from conftest import MOCAP_DIR
from ecs_anim.core.errors import listed
from ecs_anim.core.skeleton import JOINT_INDEX, JOINTS
from ecs_anim.io.bvh import read_bvh
from ecs_anim.motion.clip import load_nmo
from support.bvh_reference import (
    DOCUMENTED,
    euler_angles,
    euler_matrix,
    import_and_export,
    lookup,
    reference_world,
)

MM = 1e-3
#: Frames of each dev file kept in a variant (the round trip is checked on every one of them).
FRAMES = 240
#: Dev files with three naming conventions, units and up axes (Bandai: a joint_Root above Hips,
#: 6 channels on every joint; CMU: ZYX, a LowerBack chain; FAIR: Z up, inches, XYZ).
DEV_FILES = ["bandai_walk.bvh", "cmu_01_01_playground_jumps.bvh",
             "varied/fair_zup_walk_inch_120hz.bvh"]
#: Files whose toes are the ankle's End Site (varied/README.md), for the no-End-Site variant.
TOE_END_SITE_FILES = ["varied/optitrack_notoes_bike_100hz.bvh",
                      "varied/neuron_notoes_stand_125hz.bvh"]
POSITIONS = ["Xposition", "Yposition", "Zposition"]


@dataclass
class EditJoint:
    """A joint being edited: ``values`` (n_frames, len(channels)) in file units and degrees."""

    name: str
    parent: int
    offset: np.ndarray
    channels: list[str]
    values: np.ndarray
    is_end_site: bool = False

    def rotation_order(self) -> str:
        return "".join(c[0].upper() for c in self.channels if c.lower().endswith("rotation"))

    def columns(self, kind: str) -> list[int]:
        return [k for k, c in enumerate(self.channels) if c.lower().endswith(kind)]


@dataclass
class EditClip:
    """A BVH file as joints in file (topological) order, for editing and writing back."""

    joints: list[EditJoint]
    frame_time_s: float

    @property
    def n_frames(self) -> int:
        return len(self.joints[0].values)

    def index(self, name: str) -> int:
        return [j.name for j in self.joints].index(name)

    def children(self, index: int) -> list[int]:
        return [i for i, j in enumerate(self.joints) if j.parent == index]

    def insert(self, joint: EditJoint) -> None:
        """Add ``joint`` as the last child of its parent (after the parent's whole subtree)."""
        at = joint.parent + 1
        while at < len(self.joints) and self._below(at, joint.parent):
            at += 1
        for j in self.joints:
            j.parent += j.parent >= at
        self.joints.insert(at, joint)

    def _below(self, index: int, ancestor: int) -> bool:
        while index >= 0:
            index = self.joints[index].parent
            if index == ancestor:
                return True
        return False

    def text(self, indent: str = "\t", newline: str = "\n", number: str = "{:.9f}",
             keyword=str, blank_lines: bool = False, trailing: str = "") -> str:
        """BVH text, laid out as asked (``keyword`` rewrites HIERARCHY, JOINT, ... e.g. to lower
        case; ``blank_lines`` puts one after each CHANNELS line, MOTION and frame line)."""
        out = [keyword("HIERARCHY")]

        def numbers(values) -> str:
            return " ".join(number.format(float(v)) for v in values) + trailing

        def emit(i: int, depth: int) -> None:
            joint, pad = self.joints[i], indent * depth
            head = keyword("End Site") if joint.is_end_site else \
                f"{keyword('ROOT' if joint.parent < 0 else 'JOINT')} {joint.name}"
            out.extend([pad + head + trailing, pad + "{" + trailing,
                        f"{pad}{indent}{keyword('OFFSET')} {numbers(joint.offset)}"])
            if not joint.is_end_site:
                out.append(f"{pad}{indent}{keyword('CHANNELS')} {len(joint.channels)} "
                           f"{' '.join(joint.channels)}{trailing}")
                out.extend([""] * blank_lines)
            for child in self.children(i):
                emit(child, depth + 1)
            out.append(pad + "}" + trailing)

        emit(0, 0)
        out.append(keyword("MOTION"))
        out.extend([""] * blank_lines)
        out += [f"{keyword('Frames:')} {self.n_frames}",
                f"{keyword('Frame')} {keyword('Time:')} {self.frame_time_s:.10g}"]
        values = np.concatenate([j.values for j in self.joints], axis=1)
        for row in values:
            out.append(numbers(row))
            out.extend([""] * blank_lines)
        return newline.join(out) + newline


def load_clip(path: Path, frames: int = FRAMES) -> EditClip:
    motion = read_bvh(path)
    joints, column = [], 0
    for j in motion.skeleton.joints:
        width = len(j.channels)
        joints.append(EditJoint(j.name, j.parent, j.offset.copy(), list(j.channels),
                                motion.channels[:frames, column:column + width].copy(),
                                j.is_end_site))
        column += width
    return EditClip(joints, motion.frame_time_s)


def _dev_file(name: str) -> Path:
    path = MOCAP_DIR / name
    if not path.exists():
        pytest.skip(f"{path} not found (the dev captures live in ../shared/mocap)")
    return path


def _round_trip(source: Path, variant: Path, tmp_path: Path) -> tuple[dict, dict]:
    """Import ``variant`` with no flags, export it on the source body; (info, worst error (m) per
    mapped canonical joint against the original ``source`` file's joint)."""
    info, exported = import_and_export(variant, tmp_path / "out")
    scale, up = lookup(DOCUMENTED, source.name)
    names, ref = reference_world(source, scale, up)
    start = info.get("first_file_frame", 0)  # a leading rest pose is dropped on import
    ref = ref[start: start + len(exported)]
    errors = {}
    for joint, name in info["joints"].items():
        if name is None or joint in info["filled_in"]:
            continue
        assert name in names, f"{joint} is {name}, which the original file does not have"
        errors[joint] = float(np.linalg.norm(exported[:, JOINT_INDEX[joint]]
                                             - ref[:, names.index(name)], axis=-1).max())
    assert {"pelvis", "hip_l", "knee_l", "ankle_l", "neck", "head", "wrist_r"} <= set(errors)
    worst = max(errors, key=lambda j: errors[j])
    assert errors[worst] < 0.1 * MM, f"{worst} off by {errors[worst] * 1e3:.4f} mm"
    return info, errors


def _plain_import(source: Path, tmp_path: Path) -> dict:
    """The import report (``info``) of the dev file's first :data:`FRAMES` frames, unedited."""
    path = tmp_path / "plain.bvh"
    path.write_text(load_clip(source).text())
    return import_and_export(path, tmp_path / "plain")[0]


# --- helper bones above the hips ---------------------------------------------------------------

def _with_helper_root(clip: EditClip, name: str, offset, channels: int, rotation_deg=None,
                      translation=None, carries_translation: bool = False) -> EditClip:
    """``clip`` under a new root ``name``: with no channels at ``offset``, or with six channels
    holding ``translation`` (n, 3) and ZXY ``rotation_deg`` (n, 3); the old root's channels are
    rewritten so that every joint stays where it was. ``carries_translation``: the new root has
    the old root's translation (minus its OFFSET) and the old root keeps only its rotations."""
    clip = copy.deepcopy(clip)
    n = clip.n_frames
    old = clip.joints[0]
    position_cols, rotation_cols = old.columns("position"), old.columns("rotation")
    old_place, old_rotation = old.values[:, position_cols], old.values[:, rotation_cols]
    turn = np.broadcast_to(np.eye(3), (n, 3, 3)) if rotation_deg is None else \
        euler_matrix(rotation_deg, "ZXY")
    if channels == 0:
        values, place = np.zeros((n, 0)), np.broadcast_to(np.asarray(offset, float), (n, 3))
    else:
        place = np.zeros((n, 3)) if translation is None else translation
        values = np.concatenate([place, np.zeros((n, 3)) if rotation_deg is None
                                 else rotation_deg], axis=1)
    if carries_translation:
        values[:, :3] = old_place - old.offset
        old.channels = [old.channels[k] for k in rotation_cols]
        old.values = old_rotation
    else:
        old.values = old.values.copy()
        old.values[:, position_cols] = np.einsum("fji,fj->fi", turn, old_place - place)
        old.values[:, rotation_cols] = euler_angles(
            np.swapaxes(turn, -1, -2) @ euler_matrix(old_rotation, old.rotation_order()),
            old.rotation_order())
    for j in clip.joints:
        j.parent += 1
    names = POSITIONS + ["Zrotation", "Xrotation", "Yrotation"]
    clip.joints.insert(0, EditJoint(name, -1, np.asarray(offset, float), names[:channels],
                                    values))
    return clip


def _helper_roots(clip: EditClip) -> dict[str, EditClip]:
    t = np.linspace(0.0, 1.0, clip.n_frames)[:, None]
    turning = np.concatenate([10 * t, 90 + 0 * t, -5 * t], axis=1)  # a Z-up armature, yawing
    return {
        "armature_no_channels_at_origin": _with_helper_root(clip, "Armature", (0, 0, 0), 0),
        "armature_no_channels_offset": _with_helper_root(clip, "Armature", (12.0, -3.0, 7.0), 0),
        "armature_turning_and_moving": _with_helper_root(
            clip, "Armature", (0, 0, 0), 6, turning, np.concatenate([10 * t, 20 * t, 0 * t], 1)),
        "reference_at_rest": _with_helper_root(clip, "Reference", (0, 0, 0), 6),
        "root_carries_translation": _with_helper_root(clip, "root", (0, 0, 0), 6,
                                                      carries_translation=True),
    }


@pytest.mark.parametrize("name", DEV_FILES)
def test_helper_bones_above_the_hips_keep_the_round_trip(name, tmp_path):
    source = _dev_file(name)
    plain = _plain_import(source, tmp_path)
    for variant, clip in _helper_roots(load_clip(source)).items():
        path = tmp_path / f"{variant}.bvh"
        path.write_text(clip.text())
        info, _ = _round_trip(source, path, tmp_path / variant)
        assert info["joints"] == plain["joints"], variant
        assert info.get("ignored_joints") == plain.get("ignored_joints"), variant


def test_an_armature_turning_a_z_up_rest_pose_to_y_up_is_read_y_up(tmp_path, capsys):
    """Blender's exporter writes the armature object's turn (-90 degrees about X) in a root
    above the hips, unlike the helper roots above: the rest pose stands along Z, every frame
    along Y. The frames decide, and the body comes out as the Z-up original."""
    source = _dev_file("varied/fair_zup_walk_inch_120hz.bvh")
    clip = load_clip(source)
    turned = np.tile([0.0, -90.0, 0.0], (clip.n_frames, 1))
    for joint in clip.joints:
        joint.parent += 1
    clip.joints.insert(0, EditJoint("Armature", -1, np.zeros(3), POSITIONS + [
        "Zrotation", "Xrotation", "Yrotation"], np.concatenate([0 * turned, turned], axis=1)))
    path = tmp_path / "blender.bvh"
    path.write_text(clip.text())
    info, _ = _round_trip(source, path, tmp_path)
    assert info["up_axis"] == "y"
    assert ("Y up (detected: the head is above the feet along +Y in 100% of frames, which decide "
            "over the rest pose's spine pointing +1.00 along Z)") in capsys.readouterr().out


# --- extra bones ---------------------------------------------------------------------------------

def _leaf(clip: EditClip, parent: str, name: str, offset, end_site: bool = True) -> None:
    """A joint under ``parent`` with three rotation channels that turn it about, and an End Site
    beyond it unless ``end_site`` is False (as written by tools that drop them)."""
    rng = np.random.default_rng(len(clip.joints))
    clip.insert(EditJoint(name, clip.index(parent), np.asarray(offset, float),
                          ["Zrotation", "Xrotation", "Yrotation"],
                          rng.normal(0.0, 20.0, (clip.n_frames, 3))))
    if end_site:
        clip.insert(EditJoint(f"{name}.end", clip.index(name), 0.5 * np.asarray(offset, float),
                              [], np.zeros((clip.n_frames, 0)), is_end_site=True))


def _with_extra_bones(clip: EditClip, names: dict[str, str], at_the_hands: bool = True
                      ) -> tuple[EditClip, list[str]]:
    """``clip`` with twist bones, IK leaves and, ``at_the_hands``, a helper leaf, a prop and
    finger chains; ``names``: canonical joint -> source joint of the original file. Returns the
    clip and the added joints' names."""
    clip = copy.deepcopy(clip)
    rest = {j.name: j.offset for j in clip.joints}
    added = []
    hand = rest[names["wrist_l"]]
    if at_the_hands:
        _leaf(clip, names["wrist_l"], "Bone.001", 0.3 * hand)
        _leaf(clip, names["wrist_r"], "Sword", 4.0 * rest[names["wrist_r"]])
        added += ["Bone.001", "Sword"]
    for side in "lr":
        parent = names[f"wrist_{side}"]
        for k in range(1, 4) if at_the_hands else ():
            _leaf(clip, parent, f"Finger{side.upper()}{k}", 0.15 * hand, end_site=k == 3)
            parent = f"Finger{side.upper()}{k}"
            added.append(parent)
        _leaf(clip, names[f"shoulder_{side}"], f"UpperArmTwist_{side}",
              0.5 * rest[names[f"elbow_{side}"]], end_site=False)
        added.append(f"UpperArmTwist_{side}")
    # IK targets (Unreal's ik_foot_l): leaves under the root at the feet, with six channels.
    for side in "lr":
        chain, joint = [], clip.index(names[f"ankle_{side}"])
        while joint > 0:
            chain.append(clip.joints[joint].offset)
            joint = clip.joints[joint].parent
        _leaf(clip, clip.joints[0].name, f"ik_foot_{side}", np.sum(chain, axis=0), end_site=False)
        ik = clip.joints[clip.index(f"ik_foot_{side}")]
        ik.channels = POSITIONS + ik.channels
        ik.values = np.concatenate([np.tile(ik.offset, (clip.n_frames, 1)), ik.values], axis=1)
        added.append(f"ik_foot_{side}")
    return clip, added


@pytest.mark.parametrize("name", DEV_FILES)
def test_extra_bones_are_ignored_and_named_in_the_import_report(name, tmp_path, capsys):
    source = _dev_file(name)
    plain_info = _plain_import(source, tmp_path)
    clip, added = _with_extra_bones(load_clip(source), plain_info["joints"])
    path = tmp_path / "extra.bvh"
    path.write_text(clip.text())
    capsys.readouterr()
    info, _ = _round_trip(source, path, tmp_path)
    assert info["joints"] == plain_info["joints"]
    assert set(added) <= set(info["ignored_joints"])
    assert set(info["ignored_joints"]) - set(added) == set(plain_info.get("ignored_joints", []))
    line = capsys.readouterr().out.splitlines()[0]
    assert f", ignored (no body part): {listed(info['ignored_joints'])}" in line, line


def _generic_names(clip: EditClip) -> tuple[EditClip, dict[str, str]]:
    """``clip`` with every joint renamed ``Bone_NNN`` (no preset fits: structural matching),
    and the new names' old ones (End Sites included, as ``<joint>.end``)."""
    clip = copy.deepcopy(clip)
    old_names = {}
    for k, joint in enumerate(clip.joints):
        if not joint.is_end_site:
            old_names[f"Bone_{k:03d}"], joint.name = joint.name, f"Bone_{k:03d}"
            old_names[f"Bone_{k:03d}.end"] = f"{old_names[joint.name]}.end"
    return clip, old_names


def _structural_joints(clip: EditClip, tmp_path: Path, label: str) -> dict[str, str | None]:
    """The joints found by structure alone in ``clip`` renamed ``Bone_NNN``, by original name."""
    generic, old_names = _generic_names(clip)
    path = tmp_path / f"{label}.bvh"
    path.write_text(generic.text())
    info = import_and_export(path, tmp_path / label)[0]
    assert info["joint_map"].startswith("structure")
    return {j: None if n is None else old_names[n] for j, n in info["joints"].items()}


@pytest.mark.parametrize("name", DEV_FILES)
def test_structure_alone_skips_ik_leaves_and_twist_bones(name, tmp_path):
    """With names no preset knows, IK targets at the feet under the root (single bones reaching
    as far as the legs) and twist bones are no limbs: the same joints are found as without them."""
    source = _dev_file(name)
    plain = load_clip(source)
    extra, _ = _with_extra_bones(plain, _plain_import(source, tmp_path)["joints"],
                                 at_the_hands=False)
    assert _structural_joints(extra, tmp_path, "extra") == \
        _structural_joints(plain, tmp_path, "plain_generic")


@pytest.mark.parametrize("name", DEV_FILES)
def test_structure_alone_takes_no_prop_for_a_forearm_or_a_hand(name, tmp_path):
    """A sword under the right hand, four forearms long: the arms' long bones are those alike on
    both sides, and the sword is no hand end (filled in instead)."""
    source = _dev_file(name)
    plain = load_clip(source)
    wrist = _plain_import(source, tmp_path)["joints"]["wrist_r"]
    armed = copy.deepcopy(plain)
    _leaf(armed, wrist, "Sword", 4.0 * armed.joints[armed.index(wrist)].offset)
    found = _structural_joints(armed, tmp_path, "armed")
    expected = _structural_joints(plain, tmp_path, "plain_generic")
    assert found.pop("hand_r") in (None, expected.pop("hand_r"))
    assert found == expected


# --- no End Sites ----------------------------------------------------------------------------------

def _without_end_sites(clip: EditClip) -> EditClip:
    clip = copy.deepcopy(clip)
    while any(j.is_end_site for j in clip.joints):
        index = max(i for i, j in enumerate(clip.joints) if j.is_end_site)
        del clip.joints[index]
        for j in clip.joints:
            j.parent -= j.parent > index
    return clip


@pytest.mark.parametrize("name", DEV_FILES + TOE_END_SITE_FILES)
def test_no_end_sites_fills_toes_and_head_top_and_keeps_the_joints(name, tmp_path):
    source = _dev_file(name)
    path = tmp_path / "no_end_sites.bvh"
    path.write_text(_without_end_sites(load_clip(source)).text())
    info, _ = _round_trip(source, path, tmp_path)
    original = _plain_import(source, tmp_path)["joints"]
    # The same joints as with End Sites, on the same sides; the ends are filled in instead.
    assert info["joints"] == {j: None if n is None or n.endswith(".end") else n
                              for j, n in original.items()}
    assert "head_top" in info["filled_in"]
    nmo = load_nmo(tmp_path / "out" / f"{path.stem}.nmo")
    assert np.all(nmo.source_morphology.lengths > 0)
    exported = np.load(tmp_path / "out" / "source.npz")["positions"]
    assert np.all(np.isfinite(exported))
    # The filled ends sit where the original's End Sites (or toe joints) put them, roughly: the
    # toe within 45 degrees of the foot's direction, the head top above the head.
    scale, up = lookup(DOCUMENTED, source.name)
    names, ref = reference_world(source, scale, up)
    start = info.get("first_file_frame", 0)  # a leading rest pose is dropped on import
    ref = ref[start: start + len(exported)]
    for side in "lr":
        ankle = exported[:, JOINT_INDEX[f"ankle_{side}"]]
        got = exported[:, JOINT_INDEX[f"toe_{side}"]] - ankle
        want = ref[:, names.index(original[f"toe_{side}"])] - ankle
        cos = np.sum(got * want, axis=-1) / np.linalg.norm(got, axis=-1) / np.linalg.norm(want, axis=-1)
        assert np.degrees(np.arccos(np.clip(cos, -1, 1))).max() < 45.0
    head_up = exported[:, JOINT_INDEX["head_top"], 2] - exported[:, JOINT_INDEX["head"], 2]
    assert np.median(head_up) > 0.05
    assert list(np.load(tmp_path / "out" / "source.npz")["joints"]) == list(JOINTS)


#: Dev files whose head End Site lies above the head (Bandai's is at the head itself).
HEAD_TOP_FILES = [n for n in DEV_FILES if not n.startswith("bandai")]


@pytest.mark.parametrize("end_sites", [False, True], ids=["no_end_sites", "end_sites"])
@pytest.mark.parametrize("name", HEAD_TOP_FILES)
def test_a_head_top_joint_is_the_head_top_not_the_head(name, end_sites, tmp_path):
    """Names no preset knows, and the head's End Site turned into a joint named as a chain's
    end (Mixamo's ``HeadTop_End``, here after a ``Character1_`` prefix no preset reads), with
    or without End Sites: the head is the original head, the head top that joint, exported
    where the original's End Site is (within 0.1 mm), not 10-20 cm above the head."""
    source = _dev_file(name)
    original = _plain_import(source, tmp_path)["joints"]
    clip, old_names = _generic_names(load_clip(source))
    head = next(new for new, old in old_names.items() if old == original["head"])
    top = next(i for i in clip.children(clip.index(head)) if clip.joints[i].is_end_site)
    joint = clip.joints[top]
    joint.name, joint.is_end_site = "Character1_HeadTop_End", False
    joint.channels, joint.values = ["Zrotation", "Xrotation", "Yrotation"], np.zeros((clip.n_frames, 3))
    if end_sites:
        clip.insert(EditJoint(f"{joint.name}_Site", top, 0.2 * joint.offset, [],
                              np.zeros((clip.n_frames, 0)), is_end_site=True))
    else:
        clip = _without_end_sites(clip)
    path = tmp_path / "head_top.bvh"
    path.write_text(clip.text())
    info, exported = import_and_export(path, tmp_path / "out")
    assert info["joint_map"].startswith("structure")
    assert (info["joints"]["head"], info["joints"]["head_top"]) == (head, joint.name)
    assert "head_top" not in info["filled_in"]
    scale, up = lookup(DOCUMENTED, source.name)
    names, ref = reference_world(source, scale, up)
    start = info.get("first_file_frame", 0)
    ref = ref[start: start + len(exported)]
    for canonical, old in (("head", original["head"]), ("head_top", original["head_top"])):
        off = np.linalg.norm(exported[:, JOINT_INDEX[canonical]] - ref[:, names.index(old)], axis=-1)
        assert off.max() < 0.1 * MM, f"{canonical} off by {off.max() * 1e3:.4f} mm"


# --- text rewrites -------------------------------------------------------------------------------

def _mixed_orders(clip: EditClip) -> EditClip:
    """Every joint's rotation channels in another order (cycling through all six), angles
    converted so that each joint turns the same."""
    clip = copy.deepcopy(clip)
    orders = ["XYZ", "ZXY", "YZX", "XZY", "ZYX", "YXZ"]
    for k, joint in enumerate(j for j in clip.joints if len(j.columns("rotation")) == 3):
        matrix = euler_matrix(joint.values[:, joint.columns("rotation")], joint.rotation_order())
        order = orders[k % 6]
        positions = joint.columns("position")
        joint.channels = [joint.channels[c] for c in positions] + [f"{a}rotation" for a in order]
        joint.values = np.concatenate([joint.values[:, positions], euler_angles(matrix, order)],
                                      axis=1)
    return clip


def _six_channels(clip: EditClip) -> EditClip:
    """Position channels (holding the OFFSET) on every joint that has none."""
    clip = copy.deepcopy(clip)
    for joint in clip.joints:
        if not joint.is_end_site and not joint.columns("position"):
            joint.channels = POSITIONS + joint.channels
            joint.values = np.concatenate([np.tile(joint.offset, (clip.n_frames, 1)),
                                           joint.values], axis=1)
    return clip


REWRITES = {
    "tabs_crlf_blank_lines_trailing_spaces": lambda c: c.text(
        indent="\t", newline="\r\n", blank_lines=True, trailing=" \t "),
    "four_spaces": lambda c: c.text(indent="    "),
    "scientific_notation": lambda c: c.text(number="{:.12e}"),
    "mixed_channel_orders": lambda c: _mixed_orders(c).text(),
    "six_channels_on_every_joint": lambda c: _six_channels(c).text(),
    "lower_case_keywords": lambda c: c.text(keyword=str.lower),
}


@pytest.mark.parametrize("name", DEV_FILES)
@pytest.mark.parametrize("rewrite", list(REWRITES))
def test_text_rewrites_keep_the_round_trip(name, rewrite, tmp_path):
    source = _dev_file(name)
    path = tmp_path / f"{rewrite}.bvh"
    path.write_bytes(REWRITES[rewrite](load_clip(source)).encode())
    info, _ = _round_trip(source, path, tmp_path)
    assert info["joints"] == _plain_import(source, tmp_path)["joints"]
    header = json.loads(str(np.load(tmp_path / "out" / f"{path.stem}.nmo")["header_json"]))
    kept = min(FRAMES, read_bvh(source).n_frames) - info.get("first_file_frame", 0)
    assert header["n_frames"] == kept
