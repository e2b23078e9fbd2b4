"""FBX import (``ecs_anim/io/fbx.py``, through ufbx) against the BVH path on the same motion.

No FBX file is shipped: ``support/fbx_writer.py`` writes ASCII FBX 7.4 from a real BVH clip
(``../shared/mocap/bandai_walk.bvh``, centimetres, Y up): a LimbNode skeleton with the BVH's
offsets and one take of curves. The rigs vary the way FBX tools differ from a BVH (joints whose
axes are turned away from the BVH's, with and without ``PreRotation``; other rotation orders),
and the import must give the BVH import's joints back within 1 mm on every frame (measured:
0.0002 mm, the FBX curves' float32 values) and the same foot contacts.
"""

from __future__ import annotations

import re
import shlex
import sys
from pathlib import Path

import numpy as np
import pytest

from conftest import MOCAP_DIR, REPO, require_mocap
from ecs_anim.apps.cli.main import main
from ecs_anim.core.errors import EcsAnimError, InputError
from ecs_anim.core.normalized import decode
from ecs_anim.io.bvh import BvhMotion, read_bvh
from ecs_anim.io.importing import import_bvh
from ecs_anim.motion.clip import NormalizedMotion, load_nmo

pytest.importorskip("ufbx", reason="FBX import needs the fbx extra (pip install 'ecs_anim[fbx]')")

from ecs_anim.io.fbx import import_fbx, read_fbx
from support.fbx_writer import Take, turned_joint_frames, write_fbx

MM = 1e-3
WALK, RUN = "bandai_walk.bvh", "bandai_run.bvh"
#: Bandai's joints as Mixamo names them (the root above the hips becomes a Blender-like null).
MIXAMO = {"joint_Root": "Armature", "Hips": "Hips", "Spine": "Spine1", "Chest": "Spine2",
          "Neck": "Neck", "Head": "Head", "Head.end": "HeadTop_End",
          **{f"{bandai}_{s}": f"{side}{mixamo}" for s, side in (("L", "Left"), ("R", "Right"))
             for bandai, mixamo in (("Shoulder", "Shoulder"), ("UpperArm", "Arm"),
                                    ("LowerArm", "ForeArm"), ("Hand", "Hand"),
                                    ("UpperLeg", "UpLeg"),
                                    ("LowerLeg", "Leg"), ("Foot", "Foot"), ("Toes", "ToeBase"))},
          **{f"Hand_{s}.end": f"{side}HandEnd" for s, side in (("L", "Left"), ("R", "Right"))},
          **{f"Toes_{s}.end": f"{side}Toe_End" for s, side in (("L", "Left"), ("R", "Right"))}}


def bvh(name: str) -> BvhMotion:
    require_mocap()
    return read_bvh(MOCAP_DIR / name)


def joints_of(motion: NormalizedMotion) -> np.ndarray:
    """The motion's canonical joints on its own source body, (n_frames, N_JOINTS, 3) m."""
    return decode(motion.poses, motion.source_morphology.lengths).positions


def worst_mm(a: NormalizedMotion, b: NormalizedMotion) -> float:
    assert a.n_frames == b.n_frames
    return float(np.linalg.norm(joints_of(a) - joints_of(b), axis=-1).max() / MM)


RIGS = {
    "as_bvh": {},
    "turned_joints_yxz": {"turned": True, "order": "YXZ"},
    "pre_rotations_zyx": {"turned": True, "pre_rotation": True, "order": "ZYX"},
}


@pytest.mark.parametrize("rig", list(RIGS))
def test_the_fbx_of_a_bvh_clip_imports_to_the_same_joints_and_contacts(rig: str, tmp_path: Path):
    motion = bvh(WALK)
    options = dict(RIGS[rig])
    if options.pop("turned", False):
        options["joint_frames"] = turned_joint_frames(len(motion.skeleton.joints))
    path = write_fbx(tmp_path / "walk.fbx", [Take("Take 001", motion)], **options)
    from_bvh = import_bvh(MOCAP_DIR / WALK)
    from_fbx = import_fbx(path)
    assert worst_mm(from_bvh, from_fbx) < 1.0
    assert np.array_equal(from_bvh.contacts(), from_fbx.contacts())
    assert from_fbx.info["joint_map"] == from_bvh.info["joint_map"] == "preset bandai (detected)"
    assert (from_fbx.info["unit"], from_fbx.info["up_axis"]) == ("cm", "y")
    assert "UnitScaleFactor 1" in from_fbx.info["unit_reason"]
    assert from_fbx.info["fbx"]["take"] == "Take 001"
    assert from_fbx.fps == 30.0


def test_the_fbx_reader_gives_the_bvh_readers_structure(tmp_path: Path):
    """Joints in topological order, End Sites where a leaf named as an end does not move, and
    the same forward kinematics as the BVH file (in the file's own units and axes)."""
    from ecs_anim.io.bvh import forward_kinematics

    motion = bvh(WALK)
    path = write_fbx(tmp_path / "walk.fbx", [Take("Walk", motion)],
                     joint_frames=turned_joint_frames(len(motion.skeleton.joints)))
    fbx = read_fbx(path)
    skeleton = fbx.motion.skeleton
    assert skeleton.names == motion.skeleton.names
    assert [j.parent for j in skeleton.joints] == [j.parent for j in motion.skeleton.joints]
    assert [j.name for j in skeleton.joints if j.is_end_site] == \
        [j.name for j in motion.skeleton.joints if j.is_end_site]
    _, ours = forward_kinematics(fbx.motion)
    _, theirs = forward_kinematics(motion)
    assert np.abs(ours - theirs).max() < 1e-3  # cm: float32 curves
    assert (fbx.take, fbx.takes, fbx.unit_m, fbx.up) == ("Walk", ["Walk"], 0.01, "y")


def test_mixamo_names_map_through_the_mixamo_preset(tmp_path: Path):
    motion = bvh(WALK)
    names = ["mixamorig:" + MIXAMO[n] if n != "joint_Root" else MIXAMO[n]
             for n in motion.skeleton.names]
    path = write_fbx(tmp_path / "mixamo_walk.fbx", [Take("mixamo.com", motion)], names=names,
                     joint_frames=turned_joint_frames(len(names)), pre_rotation=True)
    from_fbx = import_fbx(path)
    from_bvh = import_bvh(MOCAP_DIR / WALK)
    assert from_fbx.info["joint_map"] == "preset mixamo (detected)"
    assert from_fbx.info["joints"]["hip_l"] == "mixamorig:LeftUpLeg"
    assert from_fbx.info["joints"]["toe_r"] == "mixamorig:RightToeBase"
    assert worst_mm(from_bvh, from_fbx) < 1.0
    assert np.array_equal(from_bvh.contacts(), from_fbx.contacts())


def two_takes(tmp_path: Path) -> Path:
    return write_fbx(tmp_path / "moves.fbx", [Take("Walk", bvh(WALK)), Take("Run", bvh(RUN))])


def test_two_takes_the_first_by_default_and_take_picks_one(tmp_path: Path, capsys):
    path = two_takes(tmp_path)
    assert main(["import", str(path), "-o", str(tmp_path / "a")]) == 0
    out, err = capsys.readouterr()
    assert "take 'Walk' (the file has 1 other: --take NAME)" in out
    assert "2 takes ('Walk', 'Run'); read the first, 'Walk'" in err
    assert load_nmo(tmp_path / "a" / "moves.nmo").n_frames == import_bvh(MOCAP_DIR / WALK).n_frames

    assert main(["import", str(path), "-o", str(tmp_path / "b"), "--take", "Run"]) == 0
    out, err = capsys.readouterr()
    run = load_nmo(tmp_path / "b" / "moves.nmo")
    from_bvh = import_bvh(MOCAP_DIR / RUN)
    assert "take 'Run'" in out and not err
    assert run.info["fbx"] == {"take": "Run", "takes": ["Walk", "Run"], "stated_unit_m": 0.01,
                               "stated_up": "y", "joints": 27}
    assert worst_mm(from_bvh, run) < 1.0
    assert np.array_equal(from_bvh.contacts(), run.contacts())


def test_an_unknown_take_is_one_line_naming_the_takes(tmp_path: Path, capsys):
    path = two_takes(tmp_path)
    assert main(["import", str(path), "-o", str(tmp_path / "out"), "--take", "Rnu"]) == 1
    _, err = capsys.readouterr()
    lines = err.strip().splitlines()
    assert lines[0] == (f"error: {path}: no take 'Rnu' (did you mean 'Run'?); the file's "
                        "takes: 'Walk', 'Run'")
    assert "Traceback" not in err
    with pytest.raises(InputError, match="no take 'Jump'; the file's takes: 'Walk', 'Run'"):
        read_fbx(path, "Jump")


def test_take_without_an_fbx_file_is_refused(tmp_path: Path, capsys):
    require_mocap()
    assert main(["import", str(MOCAP_DIR / WALK), "-o", str(tmp_path), "--take", "Walk"]) == 1
    assert "--take is for .fbx files" in capsys.readouterr().err


@pytest.mark.parametrize("cut", ["half", "header", "empty", "garbage", "binary_header"])
def test_a_damaged_file_is_one_line_naming_it(cut: str, tmp_path: Path, capsys):
    text = write_fbx(tmp_path / "whole.fbx", [Take("Walk", bvh(WALK))]).read_bytes()
    data = {"half": text[: len(text) // 2], "header": text[:400], "empty": b"",
            "garbage": b"\x00\x01not an fbx" * 20,
            "binary_header": b"Kaydara FBX Binary  \x00\x1a\x00\xe8\x1c\x00\x00" + bytes(40)}[cut]
    path = tmp_path / f"{cut}.fbx"
    path.write_bytes(data)
    assert main(["import", str(path), "-o", str(tmp_path / "out")]) == 1
    _, err = capsys.readouterr()
    assert len(err.strip().splitlines()) == 2, err  # the error and "1 of 1 file(s) failed"
    assert err.startswith(f"error: {path}: ")
    assert "Traceback" not in err
    assert not (tmp_path / "out" / f"{cut}.nmo").exists()


def test_without_ufbx_the_error_says_what_to_install(tmp_path: Path, capsys,
                                                     monkeypatch: pytest.MonkeyPatch):
    path = write_fbx(tmp_path / "walk.fbx", [Take("Walk", bvh(WALK))])
    monkeypatch.setitem(sys.modules, "ufbx", None)  # import ufbx raises ImportError
    with pytest.raises(EcsAnimError, match=re.escape("pip install 'ecs_anim[fbx]'")):
        read_fbx(path)
    assert main(["import", str(path), "-o", str(tmp_path / "out")]) == 1
    err = capsys.readouterr().err
    assert "reading FBX files needs the ufbx package: pip install 'ecs_anim[fbx]'" in err
    assert "Traceback" not in err


def test_scenarios_and_batches_take_fbx_clips(tmp_path: Path):
    from ecs_anim.apps.batch.jobs import import_clip
    from ecs_anim.apps.batch.plan_parts import expand_clips

    path = write_fbx(tmp_path / "walk.fbx", [Take("Walk", bvh(WALK))])
    assert expand_clips([str(tmp_path)]) == [path]
    assert worst_mm(import_clip(path), import_bvh(MOCAP_DIR / WALK)) < 1.0


def test_the_documented_fbx_example_runs(tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
                                         capsys):
    """docs/import.md's FBX commands, on a file written as the page says (two takes)."""
    text = (REPO / "docs" / "import.md").read_text(encoding="utf-8")
    section = text.split("\n## FBX", 1)[1].split("\n## ", 1)[0]
    commands = [line.strip() for line in section.splitlines()
                if line.strip().startswith(".venv/bin/ecs-anim import")]
    assert len(commands) == 2, commands
    (tmp_path / "mocap").mkdir()
    write_fbx(tmp_path / "mocap" / "moves.fbx", [Take("Walk", bvh(WALK)), Take("Run", bvh(RUN))])
    monkeypatch.chdir(tmp_path)
    for command in commands:
        assert main(shlex.split(command)[1:]) == 0, command
    out = capsys.readouterr().out
    assert "moves.nmo: 195 frames at 30 fps, preset bandai (detected)" in out
    assert "take 'Run'" in out
