"""Command-line details: unit hints, up axis, argument checks, info output."""

import json

import numpy as np
import pytest

from conftest import MOTIONS_DIR, REPO
from ecs_anim.apps.cli.main import main
from ecs_anim.io.bvh import read_bvh
from ecs_anim.io.importing import canonical_clip, detect_unit


def test_unit_detection_names_a_close_runner_up():
    unit, reason = detect_unit(48.0)  # a small child in cm, or an adult in inches
    assert unit in ("cm", "inch") and "--unit" in reason
    unit, reason = detect_unit(80.0)
    assert unit == "cm" and "--unit" not in reason


def test_up_axis_z_reads_a_z_up_file_as_is():
    motion = read_bvh(MOTIONS_DIR / "walk.bvh")
    y_up = canonical_clip(motion).positions
    z_up = canonical_clip(motion, up="z").positions
    np.testing.assert_allclose(z_up[..., [0, 2]], y_up[..., [0, 1]] * [1, -1], atol=1e-12)


@pytest.mark.parametrize("args", [["--contact-min-duration", "inf"], ["--contact-height", "-1"],
                                  ["--contact-speed", "nan"]])
def test_bad_thresholds_are_usage_errors(args, tmp_path, capsys):
    with pytest.raises(SystemExit) as exit_info:
        main(["import", str(MOTIONS_DIR / "walk.bvh"), "-o", str(tmp_path), *args])
    assert exit_info.value.code == 2
    assert "expected a finite number > 0" in capsys.readouterr().err
    assert not any(tmp_path.iterdir())


def test_info_json_and_text(tmp_path, capsys):
    assert main(["import", str(MOTIONS_DIR / "walk.bvh"), "-o", str(tmp_path)]) == 0
    capsys.readouterr()
    assert main(["info", str(tmp_path / "walk.nmo"), "--json"]) == 0
    info = json.loads(capsys.readouterr().out)
    assert info["frames"] == 132 and info["fps"] == 30.0
    assert 0.4 < info["contacts"]["left_fraction"] < 0.8
    played = info["played_on_own_body"]  # run's figures, on the walk's own body, flat ground
    assert played["floating_mm_max"] <= 1.0 and played["penetration_mm_max"] <= 1.0
    assert played["sliding_mm_per_frame_max"] <= 1.0
    assert main(["info", str(tmp_path / "walk.nmo")]) == 0
    out = capsys.readouterr().out
    assert "contacts   left" in out
    assert "planted feet floating 0.0 mm, penetration 0.0 mm, sliding 0.0 mm per frame" in out


def test_bench_rejects_missing_files(capsys):
    assert main(["bench", "import", "nope.bvh"]) == 1
    assert "no such file: nope.bvh" in capsys.readouterr().err


def test_bench_import_times_c3d_files_too(capsys):
    from conftest import mocap_files, require_mocap

    require_mocap()
    c3d = mocap_files("*.c3d")[:1]
    assert main(["bench", "import", str(c3d[0]), "--json", "--repeat", "1"]) == 0
    result = json.loads(capsys.readouterr().out)
    (one,) = result["c3d"]
    assert one["frames"] > 100 and one["frames_per_second"] > 0
    assert set(one["seconds"]) == {"read", "centres_encode", "total"}
    assert main(["bench", "import", "README.md"]) == 1
    assert "not a .bvh or .c3d file" in capsys.readouterr().err


def test_outputs_that_are_not_files_limits_and_links(tmp_path, capsys):
    """Bad output paths and out-of-range runs are one-line errors before any work; an output
    that is a link is written through it (the link stays)."""

    scenario = str(REPO / "scenarios" / "reach_and_touch.yaml")
    folder, plain = tmp_path / "a_folder.json", tmp_path / "a_file"
    folder.mkdir()
    plain.write_text("keep")
    cases = [
        (["run", scenario, "--report", str(folder), "--force"], "not a file (a folder or a device)"),
        (["run", scenario, "--export", str(plain)], "--export " + str(plain) + ": not a folder"),
        (["import", "x.bvh", "-o", str(plain)], "-o " + str(plain) + ": not a folder"),
        (["run", scenario, "--seconds", "1e9"], "at most 86400 s"),
        (["bench", "--characters", "200000"], "at most 100,000"),
    ]
    for argv, message in cases:
        assert main(argv) == 1, argv
        err = capsys.readouterr().err
        assert message in err and "Traceback" not in err, (argv, err)
    assert plain.read_text() == "keep"
    real = tmp_path / "real.json"
    real.write_text("{}")
    link = tmp_path / "link.json"
    link.symlink_to(real)
    assert main(["run", scenario, "--seconds", "0.1", "--report", str(link), "--force"]) == 0
    assert link.is_symlink() and json.loads(real.read_text())["ticks"] == 3


def test_numbers_written_like_1e3_are_numbers(tmp_path):
    """YAML 1.1 reads 1e3 (no decimal point) as text; the scenario reader takes it as a number."""

    from ecs_anim.scenario import load_scenario

    motions = REPO / "scenarios" / "motions"
    path = tmp_path / "s.yaml"
    path.write_text(f"duration_s: 2e0\nfps: 3e1\nmotions: {{idle: {motions / 'idle.bvh'}}}\n"
                    "characters:\n  - {name: a, morphology: child, motion: idle}\n")
    scenario = load_scenario(path)
    scenario_length_s = scenario.duration_s  # the scenario's own field, not a measured time
    assert scenario.fps == 30.0 and scenario_length_s == 2.0


def test_more_user_mistakes_are_one_line_errors(tmp_path, capsys):
    """A wrong --unit, a BVH given where an .nmo is wanted, a .jpg screenshot, a C3D option
    without a C3D, a BVH number of 1e308, an .nmo whose limb fractions are out of range."""
    from dataclasses import replace
    from pathlib import Path

    from ecs_anim.io.importing import import_bvh
    from ecs_anim.motion.clip import save_nmo

    walk = str(MOTIONS_DIR / "walk.bvh")
    scenario = str(REPO / "scenarios" / "reach_and_touch.yaml")
    huge = tmp_path / "huge.bvh"
    lines = Path(walk).read_text().splitlines()
    first_frame = next(i for i, ln in enumerate(lines) if ln.startswith("Frame Time")) + 1
    values = lines[first_frame].split()
    lines[first_frame] = " ".join(["1e308"] + values[1:])
    huge.write_text("\n".join(lines) + "\n")
    motion = import_bvh(walk)
    poses = motion.poses.arrays()
    poses["leg_fraction"] = poses["leg_fraction"] * 5.0
    save_nmo(replace(motion, poses=type(motion.poses)(**poses)), tmp_path / "bent.nmo")
    cases = [
        (["import", walk, "-o", str(tmp_path / "mm"), "--unit", "mm"], "m tall with the length unit 'mm'"),
        (["info", walk], "not an .nmo file (import it first"),
        (["view", scenario, "--screenshot", str(tmp_path / "v.jpg")], "screenshots are PNG files"),
        (["import", walk, "-o", str(tmp_path / "g"), "--max-gap", "3"], "are for .c3d and .trc files"),
        (["import", str(huge), "-o", str(tmp_path / "h")], f"{huge}:{first_frame + 1}: value beyond 1e+07"),
        (["info", str(tmp_path / "bent.nmo")], "leg_fraction holds values outside 0-1"),
    ]
    for argv, message in cases:
        assert main(argv) == 1, argv
        err = capsys.readouterr().err
        assert message in err and "Traceback" not in err, (argv, err)
    assert not (tmp_path / "v.jpg").exists() and not (tmp_path / "mm").exists()


def test_constrained_bench_runs_and_prints_json(capsys):
    """A smoke run of the constrained benchmark (figures are printed, never asserted)."""
    assert main(["bench", "--constrained", "--characters", "8", "--seconds", "0.1", "--json",
                 "--no-compile-timing"]) == 0
    result = json.loads(capsys.readouterr().out)
    # Figures only: a busy machine may hold no character at 30 Hz (tests never assert speed).
    assert "ConstraintSolve" in result["ms_per_tick"] and result["ms_per_character"] > 0
    capacity = (1000.0 / 30.0 - result["ms_fixed_per_tick"]) / result["ms_per_character"]
    assert abs(result["max_characters_at_30hz"] - max(capacity, 0)) <= 1 + 1e-3 * capacity


def test_reports_are_strict_json():
    """A report never holds NaN or Infinity (strict JSON readers reject them): they become null."""
    from ecs_anim.apps.cli.args import json_safe

    report = {"a": float("inf"), "b": [1.0, float("nan")], "c": {"d": np.float64(2.0)}}
    text = json.dumps(json_safe(report), allow_nan=False)
    assert json.loads(text) == {"a": None, "b": [1.0, None], "c": {"d": 2.0}}
