"""Issue 31, import classes 1 and 3, fixed by structure and physics:

- Up axis: a C3D's up comes from its markers, whether or not the parts they mark can be
  computed (a Z-up standing trial with only the pelvis computable was refused as "tallest along
  z, downwards"); a BVH upside down (an image's convention, Y down) is detected as -Y up (it
  was "Y up (assumed)"), and ``--up`` takes a negative axis.
- Glitch frames: frames whose root jumps further than a body moves and back are repaired from
  the frames around them (or cut at the clip's ends) and said, and the rest-pose rule no longer
  takes their jump for a T-pose's (frames 0-3 were dropped "as a rest pose" and the glitches
  kept: the root "travels 2065 m").
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from conftest import MOCAP_DIR, MOTIONS_DIR, require_mocap
from ecs_anim.apps.cli.main import main
from ecs_anim.core.skeleton import JOINT_INDEX
from ecs_anim.io.bvh import read_bvh
from ecs_anim.io.c3d.importing import canonical_clip_c3d
from ecs_anim.io.c3d.reading import read_c3d
from ecs_anim.io.importing import (
    UP_AXES,
    canonical_clip,
    glitch_frames,
    import_bvh,
    leading_rest_frames,
    repair_glitches,
)
from support.c3d_files import write_c3d

WALK = MOTIONS_DIR / "walk.bvh"
STANDING = MOCAP_DIR / "varied2" / "c3dorg_qualisys_standing_knjntln_240hz_2400f.c3d"
JUMPS = MOCAP_DIR / "varied2" / "sfu_0005_2feetjump_cm_xyz_120hz.bvh"
#: A BVH channel whose value changes sign when the clip is turned 180 degrees about X.
TURNED_BY_X = {"Yposition", "Zposition", "Yrotation", "Zrotation"}


def _upside_down(src: Path, dst: Path) -> Path:
    """``src`` turned 180 degrees about X, rest pose and frames alike (Y and Z of every OFFSET
    and root position negated, and the rotations about Y and Z): an image's convention, Y down."""
    head, motion = src.read_text().split("MOTION", 1)
    lines, columns = [], []
    for line in head.splitlines():
        words = line.split()
        if words[:1] == ["OFFSET"]:
            x, y, z = (float(w) for w in words[1:4])
            line = f"{line[:line.index('OFFSET')]}OFFSET {x:.6f} {-y:.6f} {-z:.6f}"
        elif words[:1] == ["CHANNELS"]:
            columns += words[2:]
        lines.append(line)
    rows = motion.strip().splitlines()
    frames = [" ".join(f"{-float(v):.6f}" if c in TURNED_BY_X else v
                       for v, c in zip(row.split(), columns, strict=True)) for row in rows[2:]]
    dst.write_text("\n".join(lines) + "\nMOTION\n" + "\n".join(rows[:2] + frames) + "\n")
    return dst


def _with_glitches(src: Path, dst: Path, frames: range, metres: float) -> Path:
    """``src`` with its root put ``metres`` out along X and Z, the sign alternating, in
    ``frames`` (a capture's glitch: the root's first and third channels, X and Z position)."""
    head, motion = src.read_text().split("MOTION", 1)
    rows = motion.strip().splitlines()
    frame_rows = [row.split() for row in rows[2:]]
    for k in frames:
        sign = 1.0 if k % 2 == 0 else -1.0
        frame_rows[k][0], frame_rows[k][2] = f"{sign * metres:.4f}", f"{-sign * metres:.4f}"
    dst.write_text(head + "MOTION\n" + "\n".join(rows[:2] + [" ".join(r) for r in frame_rows])
                   + "\n")
    return dst


# --- class 3: the up axis -------------------------------------------------------------------


def test_an_upside_down_bvh_is_detected_minus_y_up_and_imports_as_the_upright_one(tmp_path):
    """Before: "Y up (assumed (the BVH convention): neither Y nor Z shows the head clearly
    above the feet)", the body imported head down."""
    flipped = _upside_down(WALK, tmp_path / "walk_upside_down.bvh")
    clip = canonical_clip(read_bvh(flipped))
    assert clip.up_axis == "-y", clip.up_reason
    assert clip.up_reason.startswith("detected: the head is above the feet along -Y in 100% "
                                     "of frames")
    upright = canonical_clip(read_bvh(WALK))
    np.testing.assert_allclose(clip.positions, upright.positions, atol=1e-5)
    np.testing.assert_allclose(clip.pelvis2world, upright.pelvis2world, atol=1e-5)
    head, ankle = clip.positions[:, JOINT_INDEX["head"], 2], clip.positions[:, JOINT_INDEX["ankle_l"], 2]
    assert np.all(head > ankle + 1.0)


def test_up_takes_a_negative_axis_on_the_command_line(tmp_path, capsys):
    flipped = _upside_down(WALK, tmp_path / "walk_upside_down.bvh")
    assert main(["import", str(flipped), "-o", str(tmp_path / "a"), "--up", "-y"]) == 0
    assert "-Y up (given with --up)" in capsys.readouterr().out
    assert main(["import", str(WALK), "-o", str(tmp_path / "b"), "--up", "+y",
                 "--face", "-x"]) == 0
    assert "Y up (given with --up)" in capsys.readouterr().out
    with pytest.raises(SystemExit):
        main(["import", str(WALK), "-o", str(tmp_path / "c"), "--up", "w"])
    assert "--up: expected x, y, z, -x, -y, -z" in capsys.readouterr().err


def test_every_up_axis_is_a_rotation_taking_that_axis_to_z():
    for name, rotation in UP_AXES.items():
        axis = np.zeros(3)
        axis["xyz".index(name[-1])] = -1.0 if name.startswith("-") else 1.0
        np.testing.assert_allclose(rotation @ axis, [0.0, 0.0, 1.0], atol=1e-12)
        np.testing.assert_allclose(rotation @ rotation.T, np.eye(3), atol=1e-12)
        assert np.linalg.det(rotation) == pytest.approx(1.0)


def test_a_z_up_c3d_whose_legs_cannot_be_computed_is_z_up_from_its_markers():
    """varied2's Qualisys standing trial: its legs lack a knee marker the preset knows, so only
    the pelvis is computed; its ankle, heel and toe markers still stand below the pelvis's.
    Before: "cannot tell the up axis (the body is tallest along z, downwards); give --up"."""
    require_mocap()
    if not STANDING.exists():
        pytest.skip(f"{STANDING} not available")
    clip, extra = canonical_clip_c3d(read_c3d(STANDING))
    assert clip.up_axis == "z" and extra["up_reason"] == "detected from the markers"
    assert {"leg_l", "leg_r"} <= set(extra["absent"])  # the case: no leg computed


def test_a_c3d_upside_down_is_minus_z_up_and_imports_as_the_upright_one(tmp_path):
    """The same markers turned 180 degrees about X (Z pointing down): -Z up, the same clip
    (before: refused as "downwards")."""
    require_mocap()
    if not STANDING.exists():
        pytest.skip(f"{STANDING} not available")
    raw = read_c3d(STANDING)
    every = slice(None, None, 8)  # 30 Hz is plenty for a standing trial, and quicker to write

    def written(name: str, positions: np.ndarray) -> Path:
        return write_c3d(tmp_path / name, list(raw.labels), positions[every], raw.valid[every],
                         rate=raw.rate / 8, units=raw.units)

    clip, _ = canonical_clip_c3d(read_c3d(written("upside_down.c3d",
                                                  raw.positions * np.array([1.0, -1.0, -1.0]))))
    upright, _ = canonical_clip_c3d(read_c3d(written("upright.c3d", raw.positions)))
    assert clip.up_axis == "-z" and upright.up_axis == "z"
    np.testing.assert_allclose(clip.positions, upright.positions, atol=1e-5)


# --- class 1: glitch frames ----------------------------------------------------------------


def test_glitch_frames_are_repaired_from_the_frames_around_them_and_said(tmp_path):
    """walk.bvh with frames 2-6 at +-1460 m along X and Z. Before: kept, the root travelling
    20652 m along its path; after: repaired (the root within 2 cm of the file's own), said."""
    glitched = _with_glitches(WALK, tmp_path / "walk_glitches.bvh", range(2, 7), 1460.0)
    motion = import_bvh(glitched)
    assert motion.info["glitch_frames"].startswith(
        "repaired frames 2-6 (from frames 1 and 7): glitches, the body put up to 2065 m")
    assert motion.n_frames == read_bvh(WALK).n_frames and "first_file_frame" not in motion.info
    clip, glitches = repair_glitches(canonical_clip(read_bvh(glitched)))
    assert glitches is not None and glitches.repaired == ((2, 6),)
    pelvis = JOINT_INDEX["pelvis"]
    path = np.linalg.norm(np.diff(clip.positions[:, pelvis], axis=0), axis=-1).sum()
    plain = canonical_clip(read_bvh(WALK)).positions
    assert np.linalg.norm(clip.positions[:, pelvis] - plain[:, pelvis], axis=-1).max() < 0.02
    assert path == pytest.approx(
        np.linalg.norm(np.diff(plain[:, pelvis], axis=0), axis=-1).sum(), rel=0.01)
    # The pose is the file's own: only the root was off.
    np.testing.assert_allclose(clip.positions - clip.positions[:, pelvis:pelvis + 1],
                               plain - plain[:, pelvis:pelvis + 1], atol=1e-9)


def test_glitch_frames_at_the_start_are_cut_and_the_file_frames_kept_in_step(tmp_path, capsys):
    glitched = _with_glitches(WALK, tmp_path / "walk_glitch_start.bvh", range(0, 2), 1460.0)
    assert main(["import", str(glitched), "-o", str(tmp_path)]) == 0
    assert "; dropped frames 0-1: glitches, the body put up to 2065 m" in capsys.readouterr().out
    motion = import_bvh(glitched)
    assert motion.info["first_file_frame"] == 2 and motion.n_frames == read_bvh(WALK).n_frames - 2


def test_no_frame_of_a_real_clip_is_a_glitch():
    glitch, torn, _ = glitch_frames(canonical_clip(read_bvh(WALK)).positions, 30.0)
    assert not glitch.any() and not torn.any()


def test_the_rest_pose_rule_does_not_take_a_glitch_for_a_t_pose(tmp_path):
    """SFU's 2,575-frame jumps with frames 2-6 at +-1460 m: before, frames 0-4 were dropped
    "as a rest pose (the joints jump 4129.50 m on average to frame 5)", frame 6's glitch kept
    and the root "travels 2065.91 m"; after, nothing dropped and the root's path is the file's."""
    require_mocap()
    if not JUMPS.exists():
        pytest.skip(f"{JUMPS} not available")
    glitched = _with_glitches(JUMPS, tmp_path / "jumps_glitches.bvh", range(2, 7), 146000.0)
    clip = canonical_clip(read_bvh(glitched))
    assert leading_rest_frames(clip.positions, clip.fps) is None
    motion = import_bvh(glitched)
    assert "rest_frames_dropped" not in motion.info and "first_file_frame" not in motion.info
    assert motion.info["glitch_frames"].startswith("repaired frames 2-6 (from frames 1 and 7)")
    assert motion.n_frames == read_bvh(JUMPS).n_frames
    pelvis = JOINT_INDEX["pelvis"]
    repaired, _ = repair_glitches(clip)
    plain = canonical_clip(read_bvh(JUMPS)).positions[:, pelvis]
    assert np.linalg.norm(repaired.positions[:, pelvis] - plain, axis=-1).max() < 0.02
