"""``ecs-anim info`` on many files or a folder (a table), facing and travel, ``import --trim``
(issue 15, item 6)."""

from __future__ import annotations

import glob
import json

import numpy as np
import pytest

from conftest import MOCAP_DIR, MOTIONS_DIR, REPO, require_mocap
from ecs_anim.apps.cli.main import main
from ecs_anim.core.errors import EcsAnimError
from ecs_anim.io.importing import FrameRange, import_bvh
from ecs_anim.motion.clip import facing_and_travel, load_nmo


@pytest.fixture(scope="module")
def library(tmp_path_factory):
    out = tmp_path_factory.mktemp("lib")
    assert main(["import", *(str(MOTIONS_DIR / f"{n}.bvh") for n in ("walk", "idle", "kick")),
                 "-o", str(out)]) == 0
    return out


def test_info_on_a_folder_is_a_table_and_a_bad_file_is_a_row(library, capsys):
    (library / "broken.nmo").write_bytes(b"junk")
    capsys.readouterr()
    assert main(["info", str(library)]) == 1
    out, err = capsys.readouterr()
    lines = out.splitlines()
    assert lines[0].split()[:4] == ["file", "frames", "fps", "s"]
    assert lines[1].startswith("broken.nmo") and "not a readable .nmo file" in lines[1]
    walk = next(line for line in lines if line.startswith("walk.nmo")).split()
    assert walk[1:3] == ["132", "30"]  # frames, fps
    assert float(walk[5]) == pytest.approx(5.44, abs=0.01)  # root travel, m
    assert "1 of 4 file(s) could not be read" in err
    (library / "broken.nmo").unlink()
    assert main(["info", str(library / "walk.nmo"), str(library / "idle.nmo"), "--json"]) == 0
    rows = json.loads(capsys.readouterr().out)
    assert [r["frames"] for r in rows] == [132, 240]


def test_facing_and_travel_of_our_walk_and_a_turned_copy():
    walk = import_bvh(MOTIONS_DIR / "walk.bvh")
    root = facing_and_travel(walk)
    assert abs(root["facing_deg"]) < 2.0 and abs(root["direction_deg"]) < 1.0  # faces and walks +x
    assert root["straight_m"] == pytest.approx(5.44, abs=0.01)
    assert root["path_m"] >= root["straight_m"]


def test_info_on_one_file_says_facing_and_travel(library, capsys):
    assert main(["info", str(library / "walk.nmo")]) == 0
    line = next(x for x in capsys.readouterr().out.splitlines() if x.strip().startswith("facing"))
    assert "deg from +x at the first frame; the root travels 5.439 m towards" in line


def test_trim_parses_frames_and_seconds():
    assert FrameRange.parse("1:").frames(100, 30.0) == slice(1, 100)
    assert FrameRange.parse(":-30").frames(100, 30.0) == slice(0, 70)
    assert FrameRange.parse("0.5s:2s").frames(100, 30.0) == slice(15, 60)
    assert FrameRange.parse("10:20").frames(100, 30.0, first_frame=5) == slice(5, 15)
    for bad, message in (("x", "expected START:END"), ("a:b", "'a' is not a frame number"),
                         ("1s:20", "both ends in frames or both in seconds")):
        with pytest.raises(ValueError, match=message):
            FrameRange.parse(bad)
    with pytest.raises(EcsAnimError, match="--trim keeps no frame of the 100"):
        FrameRange.parse("200:300").frames(100, 30.0)


def test_import_trim_drops_frames_and_says_where_the_clip_starts(tmp_path, capsys):
    require_mocap()
    cmu = MOCAP_DIR / "cmu_01_01_playground_jumps.bvh"
    # --trim 0: keeps the T-pose frame that an import without --trim drops (test_rest_frames).
    assert main(["import", str(cmu), "-o", str(tmp_path / "all"), "--trim", "0:"]) == 0
    assert main(["import", str(cmu), "-o", str(tmp_path / "cut"), "--trim", "1:"]) == 0
    full, cut = load_nmo(tmp_path / "all" / f"{cmu.stem}.nmo"), load_nmo(tmp_path / "cut" / f"{cmu.stem}.nmo")
    assert cut.n_frames == full.n_frames - 1 and cut.info["first_file_frame"] == 1
    # The same frames, encoded on a body measured without the T-pose frame: bones within 1 %.
    assert np.abs(cut.source_morphology.lengths / full.source_morphology.lengths - 1.0).max() < 0.01
    capsys.readouterr()
    assert main(["import", str(cmu), "-o", str(tmp_path / "none"), "--trim", "99999:"]) == 1
    assert "--trim keeps no frame of the" in capsys.readouterr().err


def test_import_trim_on_a_c3d_counts_the_files_frames(tmp_path):
    require_mocap()
    from ecs_anim.io.c3d.importing import import_c3d

    gait = MOCAP_DIR / "c3dorg_eb015pi_gait.c3d"
    motion = import_c3d(gait, trim=FrameRange.parse("0:100"))
    # Frames 0-42 were trimmed already (no pelvis in 0-18, two of the three left-foot cluster
    # markers in 19-42): the file's frames 43-99 remain.
    assert motion.n_frames == 57 and motion.info["first_file_frame"] == 43


def test_the_readme_info_example_runs(tmp_path, monkeypatch, capsys):
    """docs/cli.md's info example (import the library into a folder, then info on the folder)."""

    repo = REPO
    text = (repo / "docs" / "cli.md").read_text(encoding="utf-8")
    block = text.split("\n## info\n", 1)[1].split("\n## export\n", 1)[0]
    commands = [line.strip().replace(".venv/bin/ecs-anim ", "") for line in block.splitlines()
                if line.strip().startswith(".venv/bin/ecs-anim")]
    assert len(commands) == 2
    monkeypatch.chdir(repo)
    out = tmp_path / "library"
    for command in commands:  # as a shell runs it: globs expanded
        words = command.replace("out/library", str(out)).split()
        argv = [w for word in words for w in (sorted(glob.glob(word)) if "*" in word else [word])]
        assert main(argv) == 0
    assert "walk.nmo" in capsys.readouterr().out


def test_trim_refuses_hostile_ends_and_info_says_where_the_clip_starts(tmp_path, capsys):
    """A review: ``--trim 1e308s:`` ended in a traceback, ``s:`` meant the whole clip, and info
    did not show where a trimmed clip starts."""
    for bad, message in (("1e308s:", r"is beyond 1e\+09"), ("s:", "'s' has no number"),
                         (":s", "'s' has no number")):
        with pytest.raises(ValueError, match=message):
            FrameRange.parse(bad)
    assert main(["import", str(MOTIONS_DIR / "walk.bvh"), "-o", str(tmp_path), "--trim", "10:"]) == 0
    assert "; --trim kept frames from frame 10 of the file" in capsys.readouterr().out
    assert main(["info", str(tmp_path / "walk.nmo")]) == 0
    assert "  starts at  frame 10 of the file" in capsys.readouterr().out


def test_import_face_turns_the_clip_rigidly_to_start_facing_the_way_asked(tmp_path, capsys):
    """Issue 12, item 5: ``import --face`` turns a clip about its origin; decoded on its own
    body, every joint is the original turned rigidly (within 1e-9 m)."""
    require_mocap()
    import math

    from ecs_anim.core.normalized import decode

    clip = MOCAP_DIR / "bandai_walk_turn_left.bvh"
    assert main(["import", str(clip), "-o", str(tmp_path / "as_is")]) == 0
    assert main(["import", str(clip), "-o", str(tmp_path / "faced"), "--face", "+x"]) == 0
    original = load_nmo(tmp_path / "as_is" / f"{clip.stem}.nmo")
    faced = load_nmo(tmp_path / "faced" / f"{clip.stem}.nmo")
    assert facing_and_travel(faced)["facing_deg"] == 0.0
    turn = float(faced.poses.root_heading[0] - original.poses.root_heading[0])  # info rounds it
    assert abs(faced.info["turned_deg"] + facing_and_travel(original)["facing_deg"]) < 0.1
    body = original.source_morphology.lengths
    before = decode(original.poses, body, use_stretch=True).positions
    after = decode(faced.poses, body, use_stretch=True).positions
    c, s = math.cos(turn), math.sin(turn)
    expected = before @ np.array([[c, s, 0.0], [-s, c, 0.0], [0.0, 0.0, 1.0]])
    np.testing.assert_allclose(after, expected, atol=1e-9)
    capsys.readouterr()
    with pytest.raises(SystemExit) as exit_status:  # argparse's usage error, exit status 2
        main(["import", str(clip), "-o", str(tmp_path / "bad"), "--face", "up"])
    assert exit_status.value.code == 2
    assert "--face 'up': expected +x, -x, +y, -y or degrees" in capsys.readouterr().err
