"""Acclaim ASF/AMC import: BVH dev files written as ASF/AMC (here, by a writer of the test's own)
import like the BVH within 1 mm on every frame, joint for joint; CMU's unit section and layout
(``length 0.45``, ``01.asf`` beside ``01_02.amc``), degrees or radians as the ASF says, bone axes
and dof orders of every kind; malformed files are refused in one line naming file and line.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from conftest import MOCAP_DIR, require_mocap
from ecs_anim.apps.cli.main import main
from ecs_anim.core.errors import EcsAnimError, InputError
from ecs_anim.core.normalized import decode
from ecs_anim.io.acclaim import import_amc, read_amc, read_asf
from ecs_anim.io.bvh import BvhMotion, forward_kinematics, read_bvh
from ecs_anim.io.importing import import_bvh
from ecs_anim.scenario import load_scenario
from support.bvh_reference import euler_angles, euler_matrix

MM = 1e-3
#: Fixed-axes rotation orders the writer gives bones in turn (first applied first).
DOF_ORDERS = (("rx", "ry", "rz"), ("rz", "rx", "ry"), ("ry", "rz", "rx"))


def _fixed_axes_matrix(names: tuple[str, ...] | list[str], radians: np.ndarray) -> np.ndarray:
    """R_last @ ... @ R_first (the ASF's fixed axes), as BVH's intrinsic order reversed."""
    order = "".join(n[1].upper() for n in reversed(names))
    return euler_matrix(np.degrees(radians[:, ::-1]), order)


def _fixed_axes_angles(names: tuple[str, ...], matrix: np.ndarray) -> np.ndarray:
    """The inverse of :func:`_fixed_axes_matrix`: radians (n, 3) in the order of ``names``."""
    order = "".join(n[1].upper() for n in reversed(names))
    return np.radians(euler_angles(matrix, order))[:, ::-1]


def write_acclaim(motion: BvhMotion, asf: Path, amc: Path, length_factor: float = 1.0,
                  radians: bool = False, seed: int = 1, scale: float | None = None,
                  names: dict[str, str] | None = None) -> None:
    """``motion`` as an ASF skeleton and AMC motion. A BVH joint whose children all sit at one
    place is a bone of its name (or ``names[name]``) from it to there (turning as the joint
    does), its children's bones hanging at its end, as CMU lays its skeletons out; one whose
    children sit apart is a bone of length 0, with a bone ``<joint>-<child>`` to each child that
    does not turn. Every bone gets a random ``axis`` (its AMC values are about that frame) and a
    dof order from :data:`DOF_ORDERS`; ``length_factor`` is the ASF's ``:units length``, by which
    lengths are multiplied (``scale`` instead, where given: CMU's BVH numbers are its ASF's)."""
    scale = length_factor if scale is None else scale
    rng = np.random.default_rng(seed)
    sk = motion.skeleton
    joint2file, positions = forward_kinematics(motion)
    n_frames = motion.n_frames
    from_rad = np.degrees if not radians else (lambda v: v)
    bones: list[str] = []
    hierarchy: dict[str, list[str]] = {}
    values: dict[str, np.ndarray] = {}

    def add(name: str, parent: str, offset: np.ndarray, joint: int | None) -> None:
        length = float(np.linalg.norm(offset))
        direction = offset / length if length > 0 else np.array([0.0, 1.0, 0.0])
        axis_deg = rng.uniform(-40, 40, 3)
        text = [f"  begin\n    id {len(bones) + 1}\n    name {name}",
                f"    direction {direction[0]:.10f} {direction[1]:.10f} {direction[2]:.10f}",
                f"    length {length * scale:.10f}",
                f"    axis {from_rad(np.radians(axis_deg[0])):.10f} "
                f"{from_rad(np.radians(axis_deg[1])):.10f} {from_rad(np.radians(axis_deg[2])):.10f} XYZ"]
        if joint is not None:
            dof = DOF_ORDERS[len(values) % len(DOF_ORDERS)]
            c = _fixed_axes_matrix(("rx", "ry", "rz"), np.radians(axis_deg)[None])[0]
            parent_turn = joint2file[:, sk.joints[joint].parent]
            local = np.swapaxes(parent_turn, -1, -2) @ joint2file[:, joint]
            values[name] = from_rad(_fixed_axes_angles(dof, c.T @ local @ c))
            text.append(f"    dof {' '.join(dof)}")
        bones.append("\n".join(text) + "\n  end")
        hierarchy.setdefault(parent, []).append(name)

    def bone_for(joint: int, parent: str) -> None:
        kids = sk.children(joint)
        name = (names or {}).get(sk.joints[joint].name, sk.joints[joint].name)
        ends = {tuple(sk.joints[k].offset) for k in kids}
        if len(ends) == 1:
            add(name, parent, sk.joints[kids[0]].offset, joint)
            for kid in kids:
                if not sk.joints[kid].is_end_site:
                    bone_for(kid, name)
            return
        add(name, parent, np.zeros(3), joint)
        for kid in kids:
            link = f"{name}-{sk.joints[kid].name}"
            add(link, name, sk.joints[kid].offset, None)
            if not sk.joints[kid].is_end_site:
                bone_for(kid, link)

    for kid in sk.children(0):
        offset = sk.joints[kid].offset
        if np.linalg.norm(offset) == 0:
            bone_for(kid, "root")
        else:
            link = f"root-{sk.joints[kid].name}"
            add(link, "root", offset, None)
            bone_for(kid, link)
    root_deg = np.array([10.0, -25.0, 40.0])
    c_root = _fixed_axes_matrix(("rx", "ry", "rz"), np.radians(root_deg)[None])[0]
    root_order = ("rz", "ry", "rx")
    root_turn = from_rad(_fixed_axes_angles(root_order, c_root.T @ joint2file[:, 0] @ c_root))
    angle = "rad" if radians else "deg"
    asf.write_text(
        "# written by tests/io/formats/test_acclaim.py\n:version 1.10\n:name test\n"
        f":units\n  mass 1.0\n  length {length_factor}\n  angle {angle}\n"
        ":documentation\n  a BVH dev file as ASF\n"
        ":root\n  order TX TY TZ RZ RY RX\n  axis XYZ\n  position 0 0 0\n"
        f"  orientation {' '.join(f'{v:.10f}' for v in from_rad(np.radians(root_deg)))}\n"
        ":bonedata\n" + "\n".join(bones) + "\n:hierarchy\n  begin\n"
        + "".join(f"    {p} {' '.join(c)}\n" for p, c in hierarchy.items()) + "  end\n")
    lines = ["#!OML:ASF " + asf.name, ":FULLY-SPECIFIED", ":RADIANS" if radians else ":DEGREES"]
    root = np.concatenate([positions[:, 0] * scale, root_turn], axis=1)
    for f in range(n_frames):
        lines.append(str(f + 1))
        lines.append("root " + " ".join(f"{v:.10f}" for v in root[f]))
        lines += [f"{name} " + " ".join(f"{v:.10f}" for v in v_[f]) for name, v_ in values.items()]
    amc.write_text("\n".join(lines) + "\n")


#: CMU's own ASF bone names of the joints of its MotionBuilder conversions (the bone that starts
#: at each: ``lfemur`` at the hip), so the written ASF is laid out and named as CMU's 01.asf.
CMU_BONES = {
    "LowerBack": "lowerback", "Spine": "upperback", "Spine1": "thorax", "Neck": "lowerneck",
    "Neck1": "upperneck", "Head": "head",
    **{f"{s}{mb}": f"{s.lower()}{cmu}" for s, side in (("L", "Left"), ("R", "Right"))
       for mb, cmu in (("HipJoint", "hipjoint"), ("Thumb", "thumb"), ("Fingers", "fingers"))},
    **{f"{side}{mb}": f"{side[0].lower()}{cmu}" for side in ("Left", "Right")
       for mb, cmu in (("UpLeg", "femur"), ("Leg", "tibia"), ("Foot", "foot"), ("ToeBase", "toes"),
                       ("Shoulder", "clavicle"), ("Arm", "humerus"), ("ForeArm", "radius"),
                       ("Hand", "wrist"), ("FingerBase", "hand"))},
}


def test_cmu_s_own_layout_and_names_import_with_no_flag_like_its_bvh(tmp_path):
    require_mocap()
    bvh = MOCAP_DIR / "cmu_01_01_playground_jumps.bvh"
    source = read_bvh(bvh)
    asf, amc = tmp_path / "01.asf", tmp_path / "01_01.amc"
    write_acclaim(source, asf, amc, 0.45, scale=1.0, names=CMU_BONES)
    assert "name lfemur" in asf.read_text() and "lhipjoint lfemur" in asf.read_text()
    from_bvh, from_amc = import_bvh(bvh), import_amc(amc)
    assert from_amc.info["joint_map"] == "structure (no preset matched)"
    assert from_amc.info["joints"]["hip_l"] == "lfemur" and from_amc.info["joints"]["wrist_r"] == "rwrist"
    assert from_amc.info["filled_in"] == from_bvh.info["filled_in"]
    error = np.linalg.norm(_joints(from_amc) - _joints(from_bvh), axis=-1)
    assert error.max() < 1 * MM, f"{error.max() * 1e3:.4f} mm"


def _joints(motion) -> np.ndarray:
    """The motion's joints on its source body (F, J, 3), metres."""
    return decode(motion.poses, motion.source_morphology.lengths, use_stretch=True).positions


#: BVH dev files with rotations only below the root (an ASF bone has a fixed length) and joint
#: names of a preset (the writer's link bones at branches sit where their joint is, and a
#: structural match may take one for the neck): the ASF's length factor, what the BVH's numbers
#: are multiplied by, the angle unit and the unit import finds for the lengths divided by the
#: factor. CMU's BVH numbers are its ASF's (``length 0.45``: inches times 0.45); the spec's
#: example 2.54 is data in cm of local units in inches (here metres times 2.54).
CASES = [("cmu_01_01_playground_jumps.bvh", 0.45, 1.0, True, "inch"),
         ("varied/cmu_walk_120hz_adelaide.bvh", 0.45, 1.0, False, "inch"),
         ("cmumax_131_02_start_walk_stop_m.bvh", 2.54, 2.54, False, "m")]


@pytest.mark.parametrize(("name", "factor", "scale", "radians", "unit"), CASES)
def test_a_bvh_written_as_asf_amc_imports_like_the_bvh_within_1_mm(name, factor, scale, radians,
                                                                   unit, tmp_path):
    require_mocap()
    bvh = MOCAP_DIR / name
    source = read_bvh(bvh)
    asf, amc = tmp_path / "01.asf", tmp_path / "01_02.amc"
    write_acclaim(source, asf, amc, factor, radians, scale=scale)
    from_bvh = import_bvh(bvh)
    from_amc = import_amc(amc, fps=source.fps)  # 01.asf found beside it, as CMU lays them out
    assert from_amc.info["acclaim"]["skeleton"] == str(asf)
    assert from_amc.n_frames == from_bvh.n_frames
    assert from_amc.info["filled_in"] == from_bvh.info["filled_in"]
    error = np.linalg.norm(_joints(from_amc) - _joints(from_bvh), axis=-1)
    assert error.max() < 1 * MM, f"{error.max() * 1e3:.4f} mm"
    assert from_amc.info["unit"] == unit and f"length {factor:g}" in from_amc.info["unit_reason"]


def test_the_cli_imports_an_amc_with_its_skeleton_given_and_says_the_assumed_rate(tmp_path, capsys):
    require_mocap()
    asf, amc = tmp_path / "skeleton.asf", tmp_path / "walk.amc"
    write_acclaim(read_bvh(MOCAP_DIR / "cmubiped_10_01_kick_30fps.bvh"), asf, amc)
    (tmp_path / "other.asf").write_text(asf.read_text())  # two skeletons: none is guessed
    assert main(["import", str(amc), "-o", str(tmp_path / "out")]) == 1
    assert "no skeleton for this motion" in capsys.readouterr().err
    assert main(["import", str(amc), "--body-model", str(asf), "-o", str(tmp_path / "out")]) == 0
    said = capsys.readouterr()
    assert "walk.nmo: 200 frames at 120 fps" in said.out
    assert "an AMC stores no frame rate: 120 fps assumed" in said.err


def _small_pair(tmp_path: Path) -> tuple[Path, Path]:
    asf, amc = tmp_path / "s.asf", tmp_path / "s.amc"
    write_acclaim(read_bvh(MOCAP_DIR / "cmubiped_10_01_kick_30fps.bvh"), asf, amc)
    return asf, amc


@pytest.mark.parametrize(("edit", "expected"), [
    (lambda t: t[: t.rindex("\n", 0, len(t) - 300)], "lacks"),  # truncated mid-frame
    (lambda t: "\n".join(t.splitlines()[:3]) + "\n", "holds no frame"),  # zero frames
    (lambda t: t.replace("root ", "root nan ", 1), "values must be finite"),
    (lambda t: t.replace("\nroot ", "\nrooot ", 1), "'rooot' is not one"),
    (lambda t: t.replace("\n1\nroot", "\n1\nroot 1 2", 1), "expected 6 numbers|expected 6 values"),
])
def test_a_malformed_amc_is_refused_naming_file_and_line(edit, expected, tmp_path):
    require_mocap()
    asf, amc = _small_pair(tmp_path)
    amc.write_text(edit(amc.read_text()))
    with pytest.raises(InputError, match=rf"s\.amc(:\d+)?: .*({expected})"):
        read_amc(amc, read_asf(asf))


@pytest.mark.parametrize(("edit", "expected"), [
    (lambda t: t.replace("  angle deg", "  angle grad"), "angle: expected deg or rad"),
    (lambda t: t.replace("length 1.0\n", "length x\n", 1), "length: expected numbers"),
    (lambda t: t.replace("dof rx ry rz", "dof rx ry l", 1), "only rotations"),
    (lambda t: t.replace("    length 0", "    lenxth 0", 1), "has no length"),
    (lambda t: t.replace(":hierarchy\n  begin\n    root", ":hierarchy\n  begin\n    root ghost"),
     "'ghost'"),
    (lambda t: t.split(":bonedata")[0], "no bone"),
])
def test_a_malformed_asf_is_refused_naming_file_and_place(edit, expected, tmp_path):
    require_mocap()
    asf, _ = _small_pair(tmp_path)
    asf.write_text(edit(asf.read_text()))
    with pytest.raises(InputError, match=rf"s\.asf(:\d+)?: .*{expected}"):
        read_asf(asf)


def test_a_folder_with_no_skeleton_is_one_line_naming_the_flag(tmp_path):
    amc = tmp_path / "07_01.amc"
    amc.write_text(":FULLY-SPECIFIED\n:DEGREES\n1\nroot 0 0 0 0 0 0\n")
    with pytest.raises(EcsAnimError, match=r"looked for 07_01\.asf and 07\.asf .*--body-model"):
        import_amc(amc)


def test_a_scenario_plays_an_amc_named_under_motions(tmp_path):
    require_mocap()
    write_acclaim(read_bvh(MOCAP_DIR / "cmu_01_01_playground_jumps.bvh"), tmp_path / "01.asf",
                  tmp_path / "01_02.amc", 0.45, scale=1.0)
    (tmp_path / "s.yaml").write_text(
        "duration_s: 1\nmotions:\n  jumps: 01_02.amc\ncharacters:\n"
        "  - {name: b, morphology: {stature_m: 1.8}, motion: jumps}\n")
    jumps = load_scenario(tmp_path / "s.yaml").motions["jumps"]
    assert jumps.info["acclaim"]["skeleton"] == str(tmp_path / "01.asf") and jumps.fps == 120.0


def test_an_asf_alone_and_a_body_model_with_nothing_to_take_it_are_one_line_each(tmp_path, capsys):
    asf = tmp_path / "01.asf"
    asf.write_text(":version 1.10\n")
    assert main(["import", str(asf), "-o", str(tmp_path / "out")]) == 1
    assert "an ASF holds a skeleton only; import its .amc motions" in capsys.readouterr().err
    bvh = tmp_path / "x.bvh"
    bvh.write_text("HIERARCHY\n")
    assert main(["import", str(bvh), "--body-model", str(asf), "-o", str(tmp_path / "out")]) == 1
    assert "--body-model is for AMASS .npz motions" in capsys.readouterr().err
