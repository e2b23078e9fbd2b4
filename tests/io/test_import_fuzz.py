"""Importer fuzzing: corrupted copies of dev files (made in tmp_path) give one short error line
naming the file, or import sanely; never a traceback, a NaN pose or a silently wrong body.

Each case here once imported wrong or said too much: the rest of the fuzz pass (truncations,
NaN/inf values, bad Frame Time or Frames, CRLF/BOM/tabs, bad C3D headers, ...) was already
refused cleanly and is covered by test_bad_input.py and test_hardening_import.py.
"""

from __future__ import annotations

import re
import struct
from pathlib import Path

import numpy as np
import pytest

from conftest import MOCAP_DIR, require_mocap
from ecs_anim.core.errors import InputError
from ecs_anim.io.c3d.importing import import_c3d
from ecs_anim.io.c3d.reading import read_c3d
from ecs_anim.io.importing import import_bvh
from support.c3d_files import parameter_offset, write_c3d

WALK = MOCAP_DIR / "bandai_walk.bvh"  # 6 channels on every joint
PIG = MOCAP_DIR / "varied" / "qualisys_pig_yup_events_100hz.c3d"  # Intel floats


def _bvh_error(path: Path) -> str:
    with pytest.raises(InputError) as exc:
        import_bvh(path)
    message = str(exc.value)
    assert "\n" not in message and len(message) < 300
    return message.replace(str(path), path.name)


def test_a_joint_name_used_twice_is_read_renamed_with_a_warning(tmp_path):
    # Before: imported without a word; the joint map took one of the two, a 1.97 m body
    # instead of 1.81 m for fair_zup_walk_inch. Rigs with extra bones do repeat names, so the
    # file is read, the later joint renamed, and the body is the original's.
    require_mocap()
    text = WALK.read_text()
    names = re.findall(r"JOINT (\S+)\n", text)
    path = tmp_path / "dup.bvh"
    path.write_text(text.replace(f"JOINT {names[2]}\n", f"JOINT {names[0]}\n", 1))
    first = text.splitlines().index(f"  JOINT {names[0]}") + 1
    second = next(i for i, ln in enumerate(text.splitlines(), 1) if ln.strip() == f"JOINT {names[2]}")
    motion = import_bvh(path)
    assert motion.info["warnings"] == [f"{path}:{second}: joint name {names[0]!r} is used again "
                                       f"(first at line {first}); read as '{names[0]}#2'"]
    original = import_bvh(WALK).source_morphology.stature
    assert abs(motion.source_morphology.stature - original) < 1e-3  # metres


def test_a_motion_that_puts_every_joint_on_one_point_names_a_few_bones(tmp_path):
    # Before: "cannot normalize this skeleton: Morphology '... (source)': lengths must be
    # positive, not [all 20 names]", a 400-character line.
    require_mocap()
    text = WALK.read_text()
    head, motion = text.split("MOTION\n")
    n_channels = len(motion.splitlines()[2].split())
    path = tmp_path / "collapsed.bvh"
    path.write_text(head + "MOTION\nFrames: 30\nFrame Time: 0.0333333\n"
                    + (" ".join(["0"] * n_channels) + "\n") * 30)
    assert _bvh_error(path).startswith(
        "collapsed.bvh: bones of zero length over the whole clip: pelvis_l, pelvis_r, thigh_l, "
        "thigh_r, shank_l, shank_r (+")


@pytest.mark.parametrize("variant", ["single_frame", "crlf_bom"])
def test_odd_but_valid_bvh_imports_sanely(tmp_path, variant):
    require_mocap()
    text = WALK.read_text()
    if variant == "single_frame":
        head, frames = text.split("MOTION\n")
        lines = frames.splitlines()
        text = head + "MOTION\nFrames: 1\n" + lines[1] + "\n" + lines[2] + "\n"
    else:
        text = "\ufeff" + text.replace("\n", "\r\n")
    path = tmp_path / f"{variant}.bvh"
    path.write_text(text, newline="")
    imported = import_bvh(path)
    assert all(np.all(np.isfinite(v)) for v in imported.poses.arrays().values())
    assert 0.5 <= imported.source_morphology.stature <= 2.5


def test_a_point_count_below_the_markers_stored_is_refused_not_read_shifted(tmp_path):
    # Before: every frame was read 16 bytes short, so markers slid into one another: a 2.20 m
    # body from a 1.80 m subject (2.89 m for the tennis serve), imported without a word.
    require_mocap()
    data = bytearray(PIG.read_bytes())
    used_at = parameter_offset(bytes(data), "POINT", "USED")
    used = struct.unpack_from("<h", data, used_at)[0]
    struct.pack_into("<h", data, used_at, used - 1)
    struct.pack_into("<H", data, 2, used - 1)  # the header's copy, which the reader checks
    path = tmp_path / "short_used.c3d"
    path.write_bytes(bytes(data))
    with pytest.raises(InputError) as exc:
        import_c3d(path)
    assert str(exc.value) == (
        f"{path}: 3152 bytes of data follow the 197 frames of {used - 1} markers the header "
        "announces: POINT:USED or the frame range is wrong (damaged file?)")


def test_the_dev_c3d_files_end_within_a_block_of_their_frames():
    # The bound the check above uses: writers pad the data to a whole 512-byte block, no more.
    require_mocap()
    paths = sorted([*MOCAP_DIR.glob("*.c3d"), *MOCAP_DIR.glob("varied/*.c3d")])
    assert len(paths) >= 5
    for path in paths:
        markers = read_c3d(path)  # refused (InputError) if more than a block followed the frames
        n_frames, n_markers, _ = markers.positions.shape
        assert n_frames > 0 and n_markers == len(markers.labels) > 0, path
        assert markers.valid.any(axis=0).sum() > n_markers // 2, path  # most markers were seen


@pytest.mark.parametrize(("parameter", "header_at", "value", "message"), [
    # Before: every marker read as "no sample", and the pelvis "lacks LASI (no sample)".
    ("SCALE", 12, 0.0, "POINT:SCALE is 0 (a damaged header): the samples cannot be scaled to "
                       "lengths"),
    # Before: the same words behind "AssertionError: ".
    ("RATE", 20, -50.0, "not a readable C3D file (damaged or truncated?): 'inconsistent analog "
                        "rate! 10 header != 1000.0 analog-fps / -50.0 point-fps'"),
])
def test_a_damaged_scale_or_rate_is_named(tmp_path, parameter, header_at, value, message):
    require_mocap()
    data = bytearray(PIG.read_bytes())
    struct.pack_into("<f", data, parameter_offset(bytes(data), "POINT", parameter), value)
    struct.pack_into("<f", data, header_at, value)  # the header's copy
    path = tmp_path / f"{parameter.lower()}.c3d"
    path.write_bytes(bytes(data))
    with pytest.raises(InputError) as exc:
        import_c3d(path)
    assert str(exc.value) == f"{path}: {message}"


def test_a_marker_seen_in_one_frame_does_not_turn_the_up_axis(tmp_path):
    """c3d.org's cluster-set walk with its first foot-cluster marker seen in one frame only:
    held there while the body walks on, it stretched the markers' spread along the walk, and
    the file was read Y up (the body on its side). Only measured samples give the spread."""
    require_mocap()
    raw = read_c3d(MOCAP_DIR / "c3dorg_eb015pi_gait.c3d")
    valid = raw.valid.copy()
    seen_once = raw.labels.index(next(lab for lab in raw.labels if lab.upper().endswith("FT1")))
    valid[:, seen_once] = False
    valid[50, seen_once] = True  # 1 s in (50 Hz)
    positions = np.where(raw.valid[..., None], raw.positions, 0.0)
    path = write_c3d(tmp_path / "seen_once.c3d", raw.labels, positions, valid, raw.rate, raw.units)
    motion = import_c3d(path)
    assert motion.info["up_axis"] == "z"
    original = import_c3d(write_c3d(tmp_path / "original.c3d", raw.labels, positions, raw.valid,
                                    raw.rate, raw.units))
    assert abs(motion.source_morphology.stature - original.source_morphology.stature) < 0.05
