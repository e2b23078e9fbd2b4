"""BVH as tools write it, on the real files of ../shared/mocap and ../shared/mocap/varied.

Every file imports with no flags (or the one documented flag of FLAGS) and exporting on the
source body gives back the source joints within 0.1 mm on every frame, toes included, against a
forward kinematics written here from the files' documented units and up axes
(../shared/mocap/README.md, ../shared/mocap/varied/README.md), not from the importer's guesses.
Kinds no real file has (one frame line more than ``Frames:``, a rig scaled x2, generic names)
are made by editing a copy of a dev file in ``tmp_path``.
"""

from __future__ import annotations

import json
import re
from pathlib import Path

import numpy as np
import pytest

from conftest import MOCAP_DIR
from ecs_anim.apps.cli.main import main
from ecs_anim.core.skeleton import JOINT_INDEX, JOINTS
from ecs_anim.motion.clip import load_nmo
from support.bvh_reference import DOCUMENTED, errors_m, import_and_export, lookup, reference_world

MM = 1e-3
VARIED = MOCAP_DIR / "varied"
#: The one flag a file needs, and why: a child's legs are as long in inches as an adult's in
#: CMU units (0.515 m or 1.145 m), which no proportion of the skeleton tells apart.
FLAGS = {"fair_zup_child": ["--unit", "inch"]}
#: Files whose non-root position channels hold the joint's place in the file's frame (read by
#: hand: the ASF-converted karate's thorax and head channels are ~50 inches, its OFFSETs 6-18).
FILE_FRAME_POSITIONS = {"asf_zup_karate_6116f.bvh": {"thorax", "head"}}
#: Files without toe joints, whose ankle End Site is the toe tip (varied/README.md).
TOE_END_SITE = {"optitrack_notoes", "neuron_notoes", "cmudaz"}


def _all_bvh() -> list[object]:
    files = sorted(MOCAP_DIR.glob("*.bvh")) + sorted(VARIED.glob("*.bvh"))
    if not files:
        return [pytest.param(None, marks=pytest.mark.skip(
            reason=f"real captured clips not found at {MOCAP_DIR} (../shared/mocap)"))]
    return [pytest.param(f, id=f.name) for f in files]


@pytest.mark.parametrize("path", _all_bvh())
def test_every_bvh_imports_and_exports_its_source_joints_within_0_1_mm(path, tmp_path):
    scale, up = lookup(DOCUMENTED, path.name)
    info, exported = import_and_export(path, tmp_path, lookup(FLAGS, path.name))
    assert info["up_axis"] == up
    names, ref = reference_world(path, scale, up,
                                 frozenset(FILE_FRAME_POSITIONS.get(path.name, ())))
    # A converter's rest-pose first frame is dropped on import (info.first_file_frame says so).
    errors = errors_m(info, exported, names, ref[info.get("first_file_frame", 0):])
    assert {"pelvis", "hip_l", "knee_l", "ankle_l", "head", "wrist_r"} <= set(errors)
    if lookup({k: True for k in TOE_END_SITE}, path.name):
        ends = [info["joints"][f"toe_{s}"] for s in "lr"]
        assert all(e is not None and e.endswith(".end") for e in ends), ends
    if "cmubiped" not in path.name:  # Biped's ankle End Site is the sole, below the ankle
        assert {"toe_l", "toe_r"} <= set(errors), info["filled_in"]
    worst = max(errors, key=lambda j: errors[j])
    assert errors[worst] < 0.1 * MM, f"{worst} off by {errors[worst] * 1e3:.4f} mm"


@pytest.mark.parametrize("name", ["asf_noneck_walk_speeds_120hz.bvh", "asf_zup_karate_6116f.bvh"])
def test_no_neck_joint_puts_the_neck_base_where_the_clavicles_meet(name, tmp_path):
    path = VARIED / name
    if not path.exists():
        pytest.skip(f"{path} not found")
    scale, up = lookup(DOCUMENTED, name)
    _, exported = import_and_export(path, tmp_path)
    names, ref = reference_world(path, scale, up, frozenset(FILE_FRAME_POSITIONS.get(name, ())))
    meet = 0.5 * (ref[:, names.index("lclavicle")] + ref[:, names.index("rclavicle")])
    neck = exported[:, JOINT_INDEX["neck"]]
    assert np.linalg.norm(neck - meet, axis=-1).max() < 0.1 * MM
    # The thorax joint the neck was put at before sits 0.28 m (ASF walks) / 0.38 m lower.
    thorax = ref[:, names.index("thorax")]
    assert np.linalg.norm(neck - thorax, axis=-1).min() > 0.25


@pytest.mark.parametrize("name", ["fair_zup_walk_inch_120hz.bvh", "asf_zup_karate_6116f.bvh"])
def test_z_up_is_detected_with_its_reason_and_up_overrides(name, tmp_path, capsys):
    path = VARIED / name
    if not path.exists():
        pytest.skip(f"{path} not found")
    assert main(["import", str(path), "-o", str(tmp_path)]) == 0
    out = capsys.readouterr().out
    assert "Z up (detected: the head is above the feet along +Z in 100% of frames" in out
    info, _ = import_and_export(path, tmp_path / "forced", ["--up", "y"])
    assert info["up_axis"] == "y"
    assert "Y up (given with --up)" in capsys.readouterr().out


def _dev_copy(tmp_path, name: str, edit) -> Path:
    src = VARIED / name
    if not src.exists():
        pytest.skip(f"{src} not found")
    text = src.read_text()
    dst = tmp_path / f"edited_{name}"
    dst.write_text(edit(text))
    return dst


def _set_frames(text: str, delta: int) -> str:
    return re.sub(r"Frames:\s*(\d+)", lambda m: f"Frames: {int(m.group(1)) + delta}", text, count=1)


def test_one_frame_line_more_than_frames_imports_with_one_warning(tmp_path, capsys):
    path = _dev_copy(tmp_path, "cmudaz_03_02_uneven_terrain.bvh", lambda t: _set_frames(t, -1))
    assert main(["import", str(path), "-o", str(tmp_path / "out")]) == 0
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1
    assert re.fullmatch(rf"warning: {re.escape(str(path))}:\d+: 'Frames:' says 365 but there "
                        r"are 366 frame lines; read all 366", err[0]), err[0]
    header = json.loads(str(np.load(tmp_path / "out" / f"{path.stem}.nmo")["header_json"]))
    # all 366 read; the converter's 25 frames before the motion dropped (test_rest_frames.py)
    assert header["n_frames"] + header["info"]["first_file_frame"] == 366


@pytest.mark.parametrize("delta, message", [(1, "file ends after 366 of 367 frames (truncated?"),
                                            (-2, "found 366 frame lines but 'Frames:' says 364")])
def test_fewer_frame_lines_or_two_more_are_errors(tmp_path, capsys, delta, message):
    path = _dev_copy(tmp_path, "cmudaz_03_02_uneven_terrain.bvh", lambda t: _set_frames(t, delta))
    assert main(["import", str(path), "-o", str(tmp_path / "out")]) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert message in err[0] and err[0].startswith(f"error: {path}:")
    assert "Traceback" not in "".join(err)


def _scale_rig(text: str, factor: float) -> str:
    """Every OFFSET and the root's position channels times ``factor`` (rotations kept)."""
    head, motion = text.split("MOTION", 1)
    head = re.sub(r"(OFFSET)\s+(\S+)\s+(\S+)\s+(\S+)",
                  lambda m: f"{m.group(1)} " + " ".join(f"{float(v) * factor:.6f}"
                                                       for v in m.groups()[1:]), head)
    lines = motion.splitlines()
    out = []
    for line in lines:
        values = line.split()
        if len(values) > 6:  # a frame line: the root's first three channels are its position
            values[:3] = [f"{float(v) * factor:.6f}" for v in values[:3]]
            line = " ".join(values)
        out.append(line)
    return head + "MOTION" + "\n".join(out) + "\n"


def test_rig_scaled_x2_imports_at_its_real_size_with_unit_number_or_stature(tmp_path, capsys):
    name = "cmudaz_03_02_uneven_terrain.bvh"
    src = VARIED / name
    if not src.exists():
        pytest.skip(f"{src} not found")
    doubled = _dev_copy(tmp_path, name, lambda t: _scale_rig(t, 2.0))
    _, plain_pos = import_and_export(src, tmp_path / "plain")
    by_unit, unit_pos = import_and_export(doubled, tmp_path / "unit", ["--unit", "0.005"])
    assert by_unit["unit"] == "0.005"
    assert np.abs(unit_pos - plain_pos).max() < 0.1 * MM
    stature = 1.60
    by_stature, stature_pos = import_and_export(doubled, tmp_path / "stature",
                                                 ["--stature", f"{stature}"])
    scaled_body = load_nmo(tmp_path / "stature" / f"{doubled.stem}.nmo").source_morphology
    # the scale is set on the file's frames, the body measured on those kept (the converter's
    # ramp dropped): 1.5 um apart, and the two imports' scales 1e-6 apart
    assert abs(scaled_body.stature - stature) < 1e-5
    factor = stature / load_nmo(tmp_path / "plain" / f"{src.stem}.nmo").source_morphology.stature
    assert abs(float(by_stature["unit"]) / 0.005 - factor) < 1e-5  # the unit is printed to 6 digits
    ratio = np.linalg.norm(stature_pos[:, JOINT_INDEX["head"]] - stature_pos[:, JOINT_INDEX["ankle_l"]],
                           axis=-1) / np.linalg.norm(plain_pos[:, JOINT_INDEX["head"]]
                                                     - plain_pos[:, JOINT_INDEX["ankle_l"]], axis=-1)
    assert np.abs(ratio - factor).max() < 1e-5


@pytest.mark.parametrize("bad", ["0", "-1", "inches", "nan"])
def test_a_bad_unit_is_one_line(bad, capsys):
    with pytest.raises(SystemExit):
        main(["import", "x.bvh", "-o", "out", "--unit", bad])
    err = capsys.readouterr().err.strip().splitlines()
    assert err[-1].endswith("expected one of m, cm, mm, inch, cmu or a positive number of metres "
                            "per file unit (0.0254 for inches)"), err[-1]


def test_generic_names_keep_the_end_site_toe_and_the_round_trip(tmp_path):
    name = "neuron_notoes_stand_125hz.bvh"
    src = VARIED / name
    if not src.exists():
        pytest.skip(f"{src} not found")
    counter = iter(range(10_000))
    generic = _dev_copy(tmp_path, name, lambda t: re.sub(
        r"^(\s*(?:ROOT|JOINT))\s+\S+", lambda m: f"{m.group(1)} Bone_{next(counter):03d}", t,
        flags=re.MULTILINE))
    info, exported = import_and_export(generic, tmp_path)
    assert info["joint_map"].startswith("structure")
    names, ref = reference_world(generic, 0.01, "y")
    errors = errors_m(info, exported, names, ref)
    assert {"toe_l", "toe_r", "neck", "head", "ankle_l"} <= set(errors)
    assert all(info["joints"][f"toe_{s}"].endswith(".end") for s in "lr")
    assert max(errors.values()) < 0.1 * MM
    assert list(np.load(tmp_path / "source.npz")["joints"]) == list(JOINTS)


def _x_up(text: str) -> str:
    """The same clip with X up: axes turned (x, y, z) -> (z, x, y) by renaming, so old Y is new X
    (OFFSETs' components rotated, each channel renamed to the axis it now turns about)."""
    head, motion = text.split("MOTION", 1)
    head = re.sub(r"(OFFSET)\s+(\S+)\s+(\S+)\s+(\S+)",
                  lambda m: f"{m.group(1)} {m.group(3)} {m.group(4)} {m.group(2)}", head)
    renamed = {"X": "Z", "Y": "X", "Z": "Y"}
    head = re.sub(r"\b([XYZ])(rotation|position)\b",
                  lambda m: renamed[m.group(1)] + m.group(2), head)
    return head + "MOTION" + motion


def test_x_up_file_imports_with_up_x(tmp_path):
    """A BVH with X up (no real dev file has one) is read with ``--up x``: the same joints
    within 0.1 mm, turned about the vertical as X up -> Z up turns them ((x, y, z) -> (y, z, x))."""
    name = "cmudaz_03_02_uneven_terrain.bvh"
    x_up = _dev_copy(tmp_path, name, _x_up)  # skips when the dev file is not there
    _, plain = import_and_export(VARIED / name, tmp_path / "plain")
    info, turned = import_and_export(x_up, tmp_path / "x_up", ["--up", "x"])
    assert info["up_axis"] == "x"
    back = np.stack([turned[..., 1], -turned[..., 0], turned[..., 2]], axis=-1)
    assert np.abs(back - plain).max() < 0.1 * MM
