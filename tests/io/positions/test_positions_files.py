"""Issue 34: joint-position files as users bring them (MediaPipe JSON and CSV, .npz), the
layout detected or asked for, and malformed files refused in one line naming file and place;
the commands of docs/import.md's and docs/export.md's positions sections run as written."""

from __future__ import annotations

import json
import shlex

import numpy as np
import pytest

from conftest import MOCAP_DIR, REPO, require_mocap
from ecs_anim.apps.cli.main import main
from ecs_anim.core.errors import EcsAnimError
from ecs_anim.io.export import export_motion
from ecs_anim.io.importing import import_bvh
from ecs_anim.io.position_layouts import MEDIAPIPE33
from ecs_anim.io.positions import PositionOptions, import_positions

BAD = {
    "shape.npy": lambda p: np.save(p, np.zeros((10, 22, 2))),
    "empty.npy": lambda p: np.save(p, np.zeros((0, 22, 3))),
    "nan.npy": lambda p: np.save(p, np.full((10, 22, 3), np.nan)),
    "text.npy": lambda p: np.save(p, np.array([["a"] * 3] * 4)),
    "count.npy": lambda p: np.save(p, np.zeros((10, 19, 3))),
    "ambiguous.npy": lambda p: np.save(p, np.random.default_rng(1).normal(size=(10, 22, 3))),
    "smpl.npz": lambda p: np.savez(p, poses=np.zeros((5, 72)), betas=np.zeros(10)),
    "bad.json": lambda p: p.write_text('[[{"x": 1, "y": 2}]]'),
    "broken.json": lambda p: p.write_text('[[{"x": 1,'),
    "word.csv": lambda p: p.write_text("x0,y0,z0\n1,2,oops\n"),
    "ragged.csv": lambda p: p.write_text("x0,y0,z0\n1,2,3\n1,2\n"),
    "truncated.npy": lambda p: p.write_bytes(b"\x93NUMPY\x01\x00v\x00{'descr': '<f8', 'fortran_"),
}
PLACES = {"shape.npy": "shape (10, 22, 2)", "empty.npy": "0 frame", "nan.npy": "NaN everywhere",
          "text.npy": "expected numbers", "count.npy": "19 joints", "ambiguous.npy": "--layout",
          "smpl.npz": "SMPL parameters", "bad.json": "frame 0, landmark 0",
          "broken.json": "not JSON", "word.csv": "word.csv:2", "ragged.csv": "ragged.csv:3",
          "truncated.npy": "truncated.npy"}


@pytest.mark.parametrize("name", list(BAD))
def test_a_malformed_positions_file_is_one_line_naming_it(name, tmp_path, capsys):
    path = tmp_path / name
    BAD[name](path)
    assert main(["import", str(path), "-o", str(tmp_path / "out")]) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 2 and err[0].startswith(f"error: {path}"), err  # and the count line
    assert PLACES[name] in err[0], err[0]
    assert "Traceback" not in err[0]


def mediapipe_frames(tmp_path):
    """A walk's MediaPipe landmarks, as the export writes them (metres, Y down, hips at 0)."""
    require_mocap()
    motion = import_bvh(MOCAP_DIR / "bandai_walk.bvh")
    path = tmp_path / "walk.npy"
    export_motion(motion, "source", path, layout="mediapipe33")
    return motion, np.load(path).astype(np.float64)


def test_mediapipe_json_and_csv_read_like_the_array(tmp_path, capsys):
    motion, frames = mediapipe_frames(tmp_path)
    as_json = [{"timestamp_ms": 1000 * k / motion.fps,
                "pose_world_landmarks": [{"x": x, "y": y, "z": z, "visibility": 0.9}
                                         for x, y, z in frame]} for k, frame in enumerate(frames)]
    as_json[5] = {"timestamp_ms": 1000 * 5 / motion.fps, "pose_world_landmarks": []}  # no pose
    (tmp_path / "walk.json").write_text(json.dumps(as_json))
    header = ",".join(f"{n}_{a}" for n in MEDIAPIPE33.joints for a in "xyz")
    rows = [f"{k / motion.fps:.6f}," + ",".join(f"{v:.6f}" for v in frame.reshape(-1))
            for k, frame in enumerate(frames)]
    (tmp_path / "walk.csv").write_text("time," + header + "\n" + "\n".join(rows) + "\n")
    for name, filled in (("walk.json", "33 missing joint samples interpolated"),
                         ("walk.csv", "")):
        assert main(["import", str(tmp_path / name), "-o", str(tmp_path / name[5:])]) == 0
        line = capsys.readouterr().out
        assert "layout mediapipe33" in line and "-Y up" in line and "fps from the file" in line
        assert filled in line and (filled or "interpolated" not in line)


def test_an_export_npz_names_its_layout(tmp_path, capsys):
    require_mocap()
    motion = import_bvh(MOCAP_DIR / "bandai_walk.bvh")
    export_motion(motion, "source", tmp_path / "walk.npz", layout="smplx22")
    assert main(["import", str(tmp_path / "walk.npz"), "-o", str(tmp_path / "out")]) == 0
    line = capsys.readouterr().out
    assert "layout smplx22 (named in the file)" in line and "fps from the file" in line


def doc_commands(page: str, heading: str) -> list[list[str]]:
    """The ``.venv/bin/ecs-anim`` command lines under ``heading`` of ``docs/<page>``, as argv,
    up to the next heading of that level."""
    text = (REPO / "docs" / page).read_text(encoding="utf-8")
    start = text.index(f"\n{heading}\n")
    level = heading.split(" ")[0]
    end = text.find(f"\n{level} ", start + 1)
    section = text[start:end if end > 0 else len(text)]
    return [shlex.split(line.strip())[1:] for line in section.splitlines()
            if line.strip().startswith(".venv/bin/ecs-anim ")]


def test_docs_positions_commands_run(tmp_path, capsys, monkeypatch):
    """docs/import.md's joint-positions commands, then docs/export.md's and docs/cli.md's
    export --layout examples on their result, as written (from a scratch folder, with
    ../shared/mocap where the tests find it)."""
    require_mocap()
    monkeypatch.chdir(tmp_path)
    commands = (doc_commands("import.md", "## Joint positions: datasets and pose estimators")
                + doc_commands("export.md", "## Joint positions in a research layout: "
                                            "`export --layout`")
                + [c for c in doc_commands("cli.md", "## export") if "--layout" in c])
    assert len(commands) == 5, commands
    for argv in commands:
        argv = [str(MOCAP_DIR / a.removeprefix("../shared/mocap/"))
                if a.startswith("../shared/mocap/") else a for a in argv]
        assert main([*argv, "--force"]) == 0, argv
    line = capsys.readouterr().out.splitlines()[2]
    assert "layout humanml3d (given with --layout)" in line and "fps from --fps" in line
    assert np.load("out/joints/child_h36m.npy").shape[1:] == (17, 3)


def test_every_positions_flag_is_in_the_cli_docs():
    text = (REPO / "docs" / "cli.md").read_text(encoding="utf-8")
    for flag in ("--layout NAME", "--fps F", "--lowpass HZ"):
        assert f"| `{flag}` |" in text, flag
    assert "-o OUT.bvh|OUT.npz|OUT.glb|OUT.npy [--layout NAME]" in text


def exported(tmp_path, layout):
    """bandai_walk's BVH import as ``layout``'s joints, in a .npy."""
    require_mocap()
    path = tmp_path / f"{layout}.npy"
    export_motion(import_bvh(MOCAP_DIR / "bandai_walk.bvh"), "source", path, layout=layout)
    return path


@pytest.mark.parametrize("layout", ["smpl24", "kit", "h36m", "coco17", "mediapipe33"])
def test_the_layout_is_detected_without_a_flag(layout, tmp_path, capsys):
    path = exported(tmp_path, layout)
    assert main(["import", str(path), "-o", str(tmp_path / "out"), "--fps", "30"]) == 0
    assert f"layout {layout} (detected: " in capsys.readouterr().out


def test_missing_samples_are_interpolated_and_absent_end_parts_filled(tmp_path):
    path = exported(tmp_path, "mediapipe33")
    joints = np.load(path).astype(np.float64)
    whole = import_positions(path, PositionOptions(fps=30))
    gappy = joints.copy()
    gappy[40:44, MEDIAPIPE33.index("left_knee")] = np.nan  # a 4-frame gap
    gappy[:, [MEDIAPIPE33.index("left_foot_index"), MEDIAPIPE33.index("right_foot_index")]] = np.nan
    np.save(tmp_path / "gappy.npy", gappy)
    got = import_positions(tmp_path / "gappy.npy", PositionOptions(fps=30))
    assert got.info["positions"]["samples_filled"] == 4
    assert got.info["positions"]["absent_joints"] == ["toe_l", "toe_r"]
    assert {"toe_l", "toe_r"} <= set(got.info["filled_in"])
    assert got.n_frames == whole.n_frames
    knee_less = joints.copy()
    knee_less[:, MEDIAPIPE33.index("left_knee")] = np.nan
    np.save(tmp_path / "knee_less.npy", knee_less)
    with pytest.raises(EcsAnimError, match=r"knee_less.npy: joint\(s\) left_knee missing \(NaN\) "
                                        r"in every frame: knee_l cannot be placed"):
        import_positions(tmp_path / "knee_less.npy", PositionOptions(fps=30))


@pytest.mark.parametrize("layout", ["mediapipe33", "h36m"])
def test_a_tumbling_body_is_refused_in_one_line_and_imported_with_up(layout, tmp_path, capsys):
    """The video dance of varied2 (MediaPipe's estimate, the body tumbling), as joints."""
    require_mocap()
    motion = import_bvh(MOCAP_DIR / "varied2" / "mediapipe_16joints_notoes_dance_30fps.bvh")
    path = tmp_path / f"dance_{layout}.npy"
    export_motion(motion, "source", path, layout=layout)
    assert main(["import", str(path), "-o", str(tmp_path / "out"), "--fps", "30"]) == 1
    err = capsys.readouterr().err.splitlines()[0]
    assert "the head is above the feet along no axis in most frames" in err and "--up" in err
    up = {"mediapipe33": "-y", "h36m": "z"}[layout]  # the axis the export wrote our Z up along
    assert main(["import", str(path), "-o", str(tmp_path / "out"), "--fps", "30", "--up", up]) == 0
    line = capsys.readouterr().out
    assert "up (given with --up)" in line
    assert "treadmill" not in line  # no root motion invented for a tumbling dance
