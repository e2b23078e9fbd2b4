"""A converter's rest pose before the motion (CMU's T-pose frame 0) is dropped on import with no
flag, said in the import's report and recorded as ``--trim`` is (issue 12, "imports that work on
files nobody here made"); a clip that starts with its motion is never cut, and ``--trim 0:``
keeps the frame."""

from __future__ import annotations

import glob
import re
from pathlib import Path

import numpy as np
import pytest

from conftest import DATA_DIR, MOCAP_DIR, REPO
from ecs_anim.apps.cli.main import main
from ecs_anim.io.bvh import read_bvh
from ecs_anim.io.c3d.importing import canonical_clip_c3d, import_c3d
from ecs_anim.io.c3d.reading import read_c3d
from ecs_anim.io.importing import FrameRange, canonical_clip, import_bvh, leading_rest_frames
from ecs_anim.motion.clip import load_nmo
from support.c3d_files import write_c3d

VARIED = MOCAP_DIR / "varied"
#: Files whose frame 0 is a rest pose (all rotations zero but the root's: the folders' READMEs
#: and the files' first lines), the frames dropped: 03_02's converter then ramps from the rest
#: pose (frames 1-11), holds still (12-23) and jumps into the capture at frame 25.
REST_FRAME = {"cmu_01_01_playground_jumps.bvh": 1, "cmu_walk_120hz_adelaide.bvh": 1,
              "cmubiped_10_01_kick_30fps.bvh": 1, "cmudaz_03_01_uneven_terrain.bvh": 1,
              "cmudaz_03_02_uneven_terrain.bvh": 25}
#: The --map a file needs (docs/import.md's tables): labels no convention uses.
MAPS = {"qualisys_lowercase_underscore_240hz.c3d":
        str(DATA_DIR / "maps" / "qualisys_knee_joint_line.yaml"),
        "rancho_wheelchair_rightarm_50hz.c3d":
        str(DATA_DIR / "maps" / "rancho_wheelchair_rightarm.yaml")}


def _dev_files() -> list[object]:
    files = [Path(f) for pattern in ("*.bvh", "*.c3d") for folder in (MOCAP_DIR, VARIED)
             for f in sorted(glob.glob(str(folder / pattern)))]
    files += sorted((REPO / "scenarios" / "motions").glob("*.bvh"))
    if not any(f.is_relative_to(MOCAP_DIR) for f in files):
        files.append(Path("mocap-not-found"))
    return [pytest.param(f, id=f.name) for f in files]


@pytest.mark.parametrize("path", _dev_files())
def test_a_rest_frame_is_found_in_the_files_that_have_one_and_in_no_other(path):
    """The thresholds hold with a margin on every file here (the joints' largest mean jump within
    the first second / the 99th percentile of it after, and / leg): 3.0-19.4 and 0.13-0.31 with
    a rest pose; without, at most 1.5 (at 0.04 leg)."""
    if not path.exists():
        pytest.skip(f"real captured clips not found at {MOCAP_DIR} (../shared/mocap)")
    if path.suffix == ".bvh":
        clip = canonical_clip(read_bvh(path))  # the unit does not matter: both tests are ratios
    else:
        clip, _ = canonical_clip_c3d(read_c3d(path), MAPS.get(path.name))
    rest = leading_rest_frames(clip.positions, clip.fps)
    expected = REST_FRAME.get(path.name)
    assert (rest.count if rest else None) == expected, rest


@pytest.mark.parametrize("name", ["cmu_01_01_playground_jumps.bvh",
                                  "varied/cmu_walk_120hz_adelaide.bvh"])
def test_a_cmu_t_pose_frame_0_is_dropped_with_no_flag_and_said(name, tmp_path, capsys):
    path = MOCAP_DIR / name
    if not path.exists():
        pytest.skip(f"{path} not available")
    assert main(["import", str(path), "-o", str(tmp_path)]) == 0
    out = capsys.readouterr().out
    assert re.search(r"; dropped frame 0: a rest pose \(T-pose\) before the motion, the joints jump "
                     r"0\.[12]\d m on average to frame 1; --trim 0: keeps it", out), out
    motion = load_nmo(tmp_path / f"{path.stem}.nmo")
    assert motion.info["first_file_frame"] == 1
    assert motion.n_frames == read_bvh(path).n_frames - 1
    assert main(["info", str(tmp_path / f"{path.stem}.nmo")]) == 0
    out = capsys.readouterr().out
    assert "  starts at  frame 1 of the file" in out and "  dropped frame 0: a rest pose" in out


@pytest.mark.parametrize("name", ["bandai_run.bvh", "cmumax_131_02_start_walk_stop_m.bvh",
                                  "varied/optitrack_notoes_bike_100hz.bvh",
                                  "varied/asf_zup_karate_6116f.bvh"])
def test_a_clip_that_starts_with_its_motion_is_not_cut(name):
    """A fast run at 30 fps, a stand-walk-stop, a first frame with two joints at rest (8 cm
    off) and a long kata: every frame kept."""
    path = MOCAP_DIR / name
    if not path.exists():
        pytest.skip(f"{path} not available")
    motion = import_bvh(path)
    assert motion.n_frames == read_bvh(path).n_frames
    assert "first_file_frame" not in motion.info and "rest_frames_dropped" not in motion.info


def _with_rest_frame_0(text: str) -> str:
    """The clip with its skeleton's rest pose put before it: frame 0 is the first frame with
    every channel but the root's zero (the root keeps its place and heading)."""
    head, motion = text.split("MOTION", 1)
    channels = re.search(r"CHANNELS\s+(\d+)", head)
    assert channels is not None
    root_channels = int(channels.group(1))
    lines = motion.splitlines()
    first = next(i for i, line in enumerate(lines) if line.startswith("Frame Time"))
    values = lines[first + 1].split()
    rest = values[:root_channels] + ["0"] * (len(values) - root_channels)
    lines.insert(first + 1, " ".join(rest))
    out = head + "MOTION" + "\n".join(lines) + "\n"
    return re.sub(r"Frames:\s*(\d+)", lambda m: f"Frames: {int(m.group(1)) + 1}", out, count=1)


@pytest.mark.parametrize("name", ["cmumax_131_02_start_walk_stop_m.bvh",
                                  "varied/asf_noneck_walk_speeds_120hz.bvh"])
def test_a_rest_pose_put_before_a_dev_clip_is_dropped_and_trim_0_keeps_it(name, tmp_path, capsys):
    src = MOCAP_DIR / name
    if not src.exists():
        pytest.skip(f"{src} not available")
    path = tmp_path / src.name
    path.write_text(_with_rest_frame_0(src.read_text()))
    n_file = read_bvh(src).n_frames + 1
    assert main(["import", str(path), "-o", str(tmp_path / "auto")]) == 0
    assert "; dropped frame 0: a rest pose (T-pose) before the motion" in capsys.readouterr().out
    dropped = load_nmo(tmp_path / "auto" / f"{path.stem}.nmo")
    assert dropped.n_frames == n_file - 1 and dropped.info["first_file_frame"] == 1
    # The clip as it was before the edit.
    original = import_bvh(src).poses.arrays()
    for key, value in dropped.poses.arrays().items():
        np.testing.assert_allclose(value, original[key], atol=1e-6, err_msg=key)
    assert main(["import", str(path), "-o", str(tmp_path / "kept"), "--trim", "0:"]) == 0
    assert "dropped frame" not in capsys.readouterr().out
    kept = load_nmo(tmp_path / "kept" / f"{path.stem}.nmo")
    assert kept.n_frames == n_file and "rest_frames_dropped" not in kept.info


def test_a_c3d_frame_0_from_another_moment_is_dropped_numbered_as_in_the_file(tmp_path):
    """The canonical clip is shared: a C3D trial whose frame 0 is a pose from a second later
    (a jump of about a step) loses it; the report numbers frames as the file does."""
    src = VARIED / "vicon_cgm24_events_jc_100hz.c3d"
    if not src.exists():
        pytest.skip(f"{src} not available")
    raw = read_c3d(src)
    later = int(raw.rate)
    path = write_c3d(tmp_path / "jump.c3d", raw.labels,
                     np.concatenate([raw.positions[later:later + 1], raw.positions]),
                     np.concatenate([raw.valid[later:later + 1], raw.valid]), raw.rate, raw.units)
    motion = import_c3d(path)
    assert motion.info["first_file_frame"] == 1
    assert motion.info["rest_frames_dropped"].startswith("dropped frame 0: a rest pose")
    assert import_c3d(path, trim=FrameRange.parse("0:")).n_frames == motion.n_frames + 1


def test_the_readme_rest_frame_example_runs_and_prints_what_it_says(tmp_path, monkeypatch, capsys):
    """docs/cli.md's rest-pose example (under ``## import``), as a shell runs it from the
    repository (out/ becomes a temporary folder): the line it quotes is printed, and
    ``--trim 0:`` keeps the frame."""
    repo = REPO
    text = (repo / "docs" / "cli.md").read_text(encoding="utf-8")
    block = text.split("Without `--trim`, a rest pose", 1)[1].split("\n## ", 1)[0]
    lines = [line.strip() for line in block.splitlines()]
    commands = [line.replace(".venv/bin/ecs-anim ", "") for line in lines
                if line.startswith(".venv/bin/ecs-anim")]
    quoted = [line.removeprefix("# ...; ") for line in lines if line.startswith("# ...; ")]
    assert len(commands) == 2 and len(quoted) == 1
    if not (repo / "../shared/mocap").is_dir():
        pytest.skip("../shared/mocap not available")
    monkeypatch.chdir(repo)
    assert main(commands[0].replace("out/", f"{tmp_path}/").split()) == 0
    assert capsys.readouterr().out.rstrip().endswith(f"; {quoted[0]}")
    assert main(commands[1].replace("out/", f"{tmp_path}/").split()) == 0
    assert "dropped frame" not in capsys.readouterr().out
    kept = load_nmo(tmp_path / "jumps_all" / "cmu_01_01_playground_jumps.nmo")
    assert kept.n_frames == read_bvh(MOCAP_DIR / "cmu_01_01_playground_jumps.bvh").n_frames
