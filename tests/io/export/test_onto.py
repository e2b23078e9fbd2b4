"""``export --onto RIG``: the shipped walk written onto rigs of each convention (Rigify with twist
halves, HumanIK with a helper leaf at the neck, Mixamo, the UE4 and UE5 mannequins, Unity
Humanoid, VRM as VRoid names it, Daz Genesis 8; ``onto_rigs.py``), each in a T and an A rest
pose, as a BVH and as a skinned GLB with its own bone axes, written out as BVH and GLB.

Every output is read back here through the rig's own hierarchy by a forward kinematics of this
file (glTF) or of ``support/bvh_reference.py`` (BVH), not the exporter's: each rig joint that is
one of our body parts must be where ``export --morphology RIG.bvh`` (the same rig's lengths)
puts that part, within 1 mm on every frame. The names are the rig's, the bones we do not drive
keep their rest pose, the twist bones their share of the twist, the GLB rig its own mesh and
skin, and every GLB passes the Khronos validator with no error and no warning.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pygltflib
import pytest

from ecs_anim.apps.cli.main import main
from ecs_anim.core.skeleton import JOINT_INDEX
from ecs_anim.io.export import export_motion
from ecs_anim.io.export.rig import load_rig, twist_shares
from ecs_anim.motion.clip import save_nmo
from support import onto_rigs as rigs
from support.bvh_reference import reference_world
from support.export_readback import GLTF_TO_OURS, glb_world, quat_matrix
from support.gltf_validator import assert_valid

MM = 1e-3
#: The rigs' body: the walk's proportions at 1.1 times its stature.
STATURE_SCALE = 1.1
CASES = [(c, pose) for c in rigs.CONVENTIONS for pose in "TA"]
IDS = [f"{c.name}-{pose}" for c, pose in CASES]
#: (rig file, output file): every rig format onto every output format.
FORMATS = [(".bvh", ".bvh"), (".glb", ".glb"), (".bvh", ".glb"), (".glb", ".bvh")]


# --- an independent reading of the outputs -------------------------------------------------------


def read_back(path: Path, convention: rigs.Convention) -> tuple[list[str], np.ndarray]:
    """(joint names, (frames, joints, 3) positions in metres, our Z-up world) of an output."""
    if path.suffix == ".glb":
        names, world = glb_world(path)
        return names, world[..., :3, 3] @ GLTF_TO_OURS.T
    rig_unit_up = (convention.unit, convention.up) if path.name.startswith("bvh") else (1.0, "y")
    return reference_world(path, *rig_unit_up)


# --- the exports ---------------------------------------------------------------------------------


@pytest.fixture(scope="module")
def exports(walk, tmp_path_factory) -> dict:
    """Every rig written and the walk exported onto it in both formats, with the reference:
    the walk on the same rig's lengths (``--morphology RIG.bvh``)."""
    folder = tmp_path_factory.mktemp("onto")
    out: dict = {}
    for convention, pose in CASES:
        body = rigs.body_points(walk, STATURE_SCALE, pose)
        stem = f"{convention.name}_{pose}"
        rig_files = {suffix: rigs.write_rig(convention, body, folder / f"{stem}{suffix}")
                     for suffix in (".bvh", ".glb")}
        _, reference = export_motion(walk, str(rig_files[".bvh"]), folder / f"{stem}.npz")
        files = {}
        for rig_suffix, out_suffix in FORMATS:
            path = folder / f"{rig_suffix[1:]}_{stem}_onto{out_suffix}"
            export_motion(walk, "source", path, onto=rig_files[rig_suffix])
            files[rig_suffix, out_suffix] = path
        out[stem] = {"rigs": rig_files, "reference": reference.positions, "files": files}
    return out


@pytest.mark.parametrize("formats", FORMATS, ids=[f"{a[1:]}-rig-to-{b[1:]}" for a, b in FORMATS])
@pytest.mark.parametrize(("convention", "pose"), CASES, ids=IDS)
def test_the_rig_read_back_is_the_walk_on_its_lengths(exports, convention, pose, formats):
    case = exports[f"{convention.name}_{pose}"]
    rig = load_rig(case["rigs"][formats[0]])
    names, positions = read_back(case["files"][formats], convention)
    assert len(positions) == len(case["reference"])
    errors = {}
    for part, joint in rig.joint_map.source.items():
        if joint is None:
            continue
        name = rig.names[joint]
        found = positions[:, names.index(name)]
        errors[part] = float(np.linalg.norm(found - case["reference"][:, JOINT_INDEX[part]],
                                            axis=-1).max())
    required = {"pelvis", "hip_l", "knee_l", "ankle_l", "toe_l", "spine_1", "spine_2", "neck",
                "head", "shoulder_r", "elbow_r", "wrist_r", "hand_r"}
    assert required <= set(errors), sorted(required - set(errors))
    worst = max(errors, key=lambda part: errors[part])
    assert errors[worst] < 1.0 * MM, f"{worst} off by {errors[worst] / MM:.3f} mm"


@pytest.mark.parametrize(("convention", "pose"), CASES, ids=IDS)
def test_the_output_is_the_rigs_own_skeleton(exports, convention, pose):
    """The BVH onto a BVH rig has the rig's hierarchy text (names, OFFSETs in its unit,
    channels in its order); the GLB onto a GLB rig its nodes, mesh, skin and inverse binds."""
    case = exports[f"{convention.name}_{pose}"]
    rig_text = case["rigs"][".bvh"].read_text()
    out_text = case["files"][".bvh", ".bvh"].read_text()
    assert out_text.split("MOTION")[0].split() == rig_text.split("MOTION")[0].split()
    rig_doc = pygltflib.GLTF2.load(str(case["rigs"][".glb"]))
    out_doc = pygltflib.GLTF2.load(str(case["files"][".glb", ".glb"]))
    assert [n.name for n in out_doc.nodes] == [n.name for n in rig_doc.nodes]
    assert [(n.translation, n.rotation, n.scale, n.children) for n in out_doc.nodes] == \
        [(n.translation, n.rotation, n.scale, n.children) for n in rig_doc.nodes]
    assert out_doc.skins[0].joints == rig_doc.skins[0].joints
    for attributes in (out_doc.meshes[0].primitives[0].attributes,
                       rig_doc.meshes[0].primitives[0].attributes):
        assert (attributes.POSITION, attributes.JOINTS_0, attributes.WEIGHTS_0) == (1, 2, 3)
    rig_blob, out_blob = rig_doc.binary_blob(), out_doc.binary_blob()
    assert out_blob[:len(rig_blob)] == rig_blob  # the rig's buffers kept, ours after them
    animated = {c.target.node for c in out_doc.animations[0].channels}
    assert animated >= set(rig_doc.skins[0].joints) - {rig_doc.skins[0].joints[0]}


def _bvh_rotations(path: Path) -> dict[str, np.ndarray]:
    """Each joint's rotation channel values (frames, 3), degrees, as written."""
    from ecs_anim.io.bvh import read_bvh

    motion = read_bvh(path)
    out, column = {}, 0
    for joint in motion.skeleton.joints:
        columns = [column + k for k, c in enumerate(joint.channels) if c.lower().endswith("rotation")]
        out[joint.name] = motion.channels[:, columns]
        column += len(joint.channels)
    return out


#: Bones we do not drive, per convention: they keep their rest pose relative to their parent.
UNDRIVEN = {"rigify": ["DEF-pelvis.L", "DEF-f_middle.02.L", "DEF-thumb.01.R", "root"],
            "humanik": ["Neck_RIGMESH", "L_Humerus_RIGMESH", "Character1_Reference"],
            "mixamo": ["mixamorig:LeftEye", "mixamorig:LeftHandIndex1", "mixamorig:RightHandThumb1"],
            "ue4_mannequin": ["ik_foot_root", "ik_foot_l", "ik_hand_gun", "weapon_r", "thumb_01_l"],
            "ue5_mannequin": ["middle_01_l"], "unity_humanoid": ["Jaw", "LeftEye"],
            "vrm": ["J_Sec_Hair1_01", "J_Sec_Hair2_01", "J_Adj_L_FaceEye"],
            "daz_genesis8": ["pelvis", "lMid2"]}


@pytest.mark.parametrize(("convention", "pose"), CASES, ids=IDS)
def test_bones_we_do_not_drive_keep_their_rest_pose(exports, convention, pose):
    rotations = _bvh_rotations(exports[f"{convention.name}_{pose}"]["files"][".bvh", ".bvh"])
    for name in UNDRIVEN[convention.name]:
        np.testing.assert_allclose(rotations[name], 0.0, atol=1e-5, err_msg=name)
    # and the driven ones do move
    rig = load_rig(exports[f"{convention.name}_{pose}"]["rigs"][".bvh"])
    knee_joint = rig.joint_map.source["knee_l"]
    assert knee_joint is not None
    knee = rig.names[knee_joint]
    assert np.ptp(rotations[knee], axis=0).max() > 20.0


def _twist_degrees(relative: np.ndarray, axis: np.ndarray) -> np.ndarray:
    """The twist (degrees) of rotations (frames, 3, 3) about ``axis`` (3,): swing-twist split."""
    w = 0.5 * np.sqrt(np.maximum(1.0 + np.trace(relative, axis1=-2, axis2=-1), 1e-12))
    vector = np.stack([relative[:, 2, 1] - relative[:, 1, 2], relative[:, 0, 2] - relative[:, 2, 0],
                       relative[:, 1, 0] - relative[:, 0, 1]], -1) / (4.0 * w[:, None])
    return np.degrees(2.0 * np.arctan2(vector @ axis, w))


@pytest.mark.parametrize(("name", "upper", "twist", "lower", "share"), [
    ("rigify", "DEF-forearm.L", "DEF-forearm.L.001", "DEF-hand.L", 0.5),
    ("daz_genesis8", "lForearmBend", "lForearmTwist", "lHand", 0.5),
    ("ue4_mannequin", "lowerarm_l", "lowerarm_twist_01_l", "hand_l", 0.5),
])
def test_twist_bones_take_their_share_of_the_twist(exports, name, upper, twist, lower, share):
    """Read from the GLB onto the GLB rig: the twist bone's turn about the forearm, relative to
    the forearm, is its share of the hand's (each a change from the rest pose, whose bone axes
    are the rig's own)."""
    path = exports[f"{name}_T"]["files"][".glb", ".glb"]
    names, world = glb_world(path)
    rest = _rest_matrices(pygltflib.GLTF2.load(str(path)))

    def change(joint: str) -> np.ndarray:
        k = names.index(joint)
        now = world[:, k, :3, :3] / np.linalg.norm(world[:, k, :3, 0], axis=-1)[:, None, None]
        return now @ (rest[k][:3, :3] / np.linalg.norm(rest[k][:3, 0])).T

    a, b = rest[names.index(upper)][:3, 3], rest[names.index(lower)][:3, 3]
    axis = (b - a) / np.linalg.norm(b - a)
    base = np.swapaxes(change(upper), -1, -2)
    hand = _twist_degrees(base @ change(lower), axis)
    part = _twist_degrees(base @ change(twist), axis)
    # Our hands carry a direction and no roll of their own, so on the walk the hand's twist
    # about the forearm is nil (2.5e-7 degrees) and so is the twist bone's.
    np.testing.assert_allclose(part, share * hand, atol=1e-3)
    assert twist_shares(load_rig(exports[f"{name}_T"]["rigs"][".glb"]))[twist] == share


def test_twist_shares_along_a_bone(walk, tmp_path):
    """The k-th of n twist joints on a bone takes k / (n + 1) of the twist; leaves named
    ``*twist*`` half; the upper arm's and thigh's too."""
    rigify = next(c for c in rigs.CONVENTIONS if c.name == "rigify")
    ue5 = next(c for c in rigs.CONVENTIONS if c.name == "ue5_mannequin")
    body = rigs.body_points(walk, 1.0, "T")
    shares = twist_shares(load_rig(rigs.write_rig(rigify, body, tmp_path / "rigify.bvh")))
    assert shares == {f"DEF-{bone}.{s}.001": 0.5 for bone in ("thigh", "shin", "upper_arm",
                                                              "forearm") for s in "LR"}
    shares = twist_shares(load_rig(rigs.write_rig(ue5, body, tmp_path / "ue5.bvh")))
    assert shares == {f"{bone}_twist_0{k}_{s}": 0.5 for bone, ks in (
        ("upperarm", (1, 2)), ("lowerarm", (1, 2)), ("thigh", (1,)), ("calf", (1,)))
        for k in ks for s in "lr"}
    daz = next(c for c in rigs.CONVENTIONS if c.name == "daz_genesis8")
    chained = rigs.Convention("chain", "", [
        (n, p, place) for n, p, place in daz.joints] + [], order="ZYX")
    # Two twist joints on one forearm: a third and two thirds.
    chained.joints = [j if j[0] != "lHand" else ("lForearmTwist2", "lForearmTwist",
                                                 ("elbow_l", "wrist_l", 0.75))
                      for j in chained.joints] + [("lHand", "lForearmTwist2", "wrist_l")]
    shares = twist_shares(load_rig(rigs.write_rig(chained, body, tmp_path / "daz2.bvh")))
    assert shares["lForearmTwist"] == pytest.approx(1 / 3)
    assert shares["lForearmTwist2"] == pytest.approx(2 / 3)


def _rest_matrices(doc) -> list[np.ndarray]:
    nodes = doc.nodes
    parent = {c: p for p, n in enumerate(nodes) for c in (n.children or [])}
    local = []
    for n in nodes:
        m = np.eye(4)
        m[:3, :3] = quat_matrix(np.array(n.rotation or [0.0, 0.0, 0.0, 1.0], float)) * \
            np.array(n.scale or [1.0, 1.0, 1.0], float)
        m[:3, 3] = n.translation or [0.0, 0.0, 0.0]
        local.append(m)
    out: dict[int, np.ndarray] = {}

    def place(k: int) -> np.ndarray:
        if k not in out:
            out[k] = local[k] if k not in parent else place(parent[k]) @ local[k]
        return out[k]

    return [place(k) for k in range(len(nodes))]


def test_every_glb_passes_the_khronos_validator(exports):
    paths = [f for case in exports.values() for key, f in case["files"].items() if key[1] == ".glb"]
    paths += [case["rigs"][".glb"] for case in exports.values()]
    assert_valid(paths)


# --- the command line --------------------------------------------------------------------------


def test_export_onto_from_the_command_line(walk, tmp_path, capsys):
    nmo = tmp_path / "walk.nmo"
    save_nmo(walk, nmo)
    convention = next(c for c in rigs.CONVENTIONS if c.name == "mixamo")
    rig = rigs.write_rig(convention, rigs.body_points(walk, 0.9, "A"), tmp_path / "hero.glb")
    assert main(["export", str(nmo), "--onto", str(rig), "-o", str(tmp_path / "hero_walk.glb")]) == 0
    said = capsys.readouterr().out
    assert "onto" in said and "preset mixamo (detected)" in said
    names, _ = glb_world(tmp_path / "hero_walk.glb")
    assert "mixamorig:LeftUpLeg" in names
    # --onto and --morphology together: the rig is the body.
    assert main(["export", str(nmo), "--onto", str(rig), "--morphology", "tall",
                 "-o", str(tmp_path / "x.bvh")]) != 0
    assert "the rig is the body" in capsys.readouterr().err


def test_a_rig_named_by_a_user_map(walk, tmp_path, capsys):
    """A rig whose legs no preset names (``Bein_L``...): a map YAML with ``base:`` and
    ``joints:`` names them, as for import."""
    convention = next(c for c in rigs.CONVENTIONS if c.name == "mixamo")
    german = {"mixamorig:LeftUpLeg": "Bein_L", "mixamorig:LeftLeg": "Knie_L",
              "mixamorig:RightUpLeg": "Bein_R", "mixamorig:RightLeg": "Knie_R"}
    renamed = rigs.Convention("renamed", "", [
        (german.get(n, n), german.get(p, p) if p else p, place)
        for n, p, place in convention.joints], unit=convention.unit)
    rig = rigs.write_rig(renamed, rigs.body_points(walk, 1.0, "T"), tmp_path / "rig.bvh")
    user_map = tmp_path / "rig_map.yaml"
    user_map.write_text("base: mixamo\njoints:\n  hip_l: Bein_L\n  knee_l: Knie_L\n"
                        "  hip_r: Bein_R\n  knee_r: Knie_R\n")
    nmo = tmp_path / "walk.nmo"
    save_nmo(walk, nmo)
    out = tmp_path / "out.bvh"
    assert main(["export", str(nmo), "--onto", str(rig), "--map", str(user_map), "-o", str(out)]) == 0
    assert "preset mixamo + " in capsys.readouterr().out
    names, positions = reference_world(out, renamed.unit, "y")
    _, reference = export_motion(walk, str(rig), tmp_path / "ref.npz")
    error = np.linalg.norm(positions[:, names.index("Knie_L")]
                           - reference.positions[:, JOINT_INDEX["knee_l"]], axis=-1).max()
    assert error < 1.0 * MM


def test_a_rig_built_otherwise_than_the_capture_still_puts_feet_and_hands_where_the_walk_does(
        walk, tmp_path):
    """A Mixamo rig whose hips sit 3 cm lower and 2 cm further forward from its pelvis joint than
    the walk's, and whose clavicles leave the chest 4 cm below and 3 cm beside the neck base:
    no rotation of its rigid pelvis and chest can put every joint where ours are. Its pelvis is
    put where its hips' midpoint is ours and its limbs reach with its own bones, so the ankles,
    toes, wrists and hands are where ``--morphology`` puts them (within 1 mm), the hips' midpoint
    too; the rest is off by the difference of build (printed)."""
    convention = next(c for c in rigs.CONVENTIONS if c.name == "mixamo")
    body = rigs.body_points(walk, 1.0, "T")
    for s in "lr":
        body[f"hip_{s}"] = body[f"hip_{s}"] + np.array([0.02, 0.0, -0.03])
    collars = {"mixamorig:LeftShoulder": ("neck", (0.0, 0.03, -0.04)),
               "mixamorig:RightShoulder": ("neck", (0.0, -0.03, -0.04))}
    other = rigs.Convention("mixamo_other_build", "", [
        (n, p, collars.get(n, place)) for n, p, place in convention.joints], unit=convention.unit)
    rig_path = rigs.write_rig(other, body, tmp_path / "other.bvh")
    _, reference = export_motion(walk, str(rig_path), tmp_path / "ref.npz")
    out = tmp_path / "other_walk.bvh"
    export_motion(walk, "source", out, onto=rig_path)
    rig = load_rig(rig_path)
    names, positions = reference_world(out, other.unit, "y")
    errors = {}
    for part, joint in rig.joint_map.source.items():
        if joint is not None:
            found = positions[:, names.index(rig.names[joint])]
            errors[part] = np.linalg.norm(found - reference.positions[:, JOINT_INDEX[part]], axis=-1)
    print({part: round(float(e.max()) / MM, 1) for part, e in errors.items()})
    for part in ("ankle_l", "ankle_r", "toe_l", "toe_r", "wrist_l", "wrist_r", "hand_l", "hand_r"):
        assert errors[part].max() < 1.0 * MM, (part, errors[part].max() / MM)
    hips = [names.index(rig.names[rig.joint_map.source[f"hip_{s}"]]) for s in "lr"]  # type: ignore[index]
    ours = reference.positions[:, [JOINT_INDEX["hip_l"], JOINT_INDEX["hip_r"]]].mean(axis=1)
    assert np.linalg.norm(positions[:, hips].mean(axis=1) - ours, axis=-1).max() < 1.0 * MM


def test_the_export_page_commands_run_as_written(tmp_path, monkeypatch, capsys):
    """docs/export.md's ``ecs-anim`` lines run as written (its ``out/`` put in a temporary
    folder) and print what the page says; its Python block runs in tests/project/test_docs.py."""
    from conftest import REPO

    page = (REPO / "docs" / "export.md").read_text(encoding="utf-8")
    commands = [line.strip() for line in page.splitlines()
                if line.startswith(("    ecs-anim import ", "    ecs-anim export "))
                and "CLIP.nmo" not in line]
    assert len(commands) == 3
    monkeypatch.chdir(REPO)
    printed = []
    for command in commands:
        args = command.replace("out/", f"{tmp_path}/out/").split()[1:]
        assert main(args) == 0, command
        printed.append(capsys.readouterr().out.replace(f"{tmp_path}/", ""))
    said = " ".join(page.split("The second prints `")[1].split("`")[0].split())
    assert said in printed[1], (said, printed[1])
    names, _ = reference_world(tmp_path / "out" / "onto" / "walk_on_mixamo.bvh", 0.01, "y")
    assert "mixamorig:LeftHandMiddle1" in names
    assert_valid([tmp_path / "out" / "onto" / "walk_on_mixamo.glb"])
