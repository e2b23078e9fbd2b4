"""``ecs-anim batch``: plans and their errors, metrics equal to ``ecs-anim run``'s, resumption after
a kill, a bad clip failing only its jobs, and Ray (a real local Ray with 2 CPUs) writing the
same bytes as the local pool."""

from __future__ import annotations

import argparse
import csv
import json
import os
import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import numpy as np
import pytest

from conftest import MOCAP_DIR, MOTIONS_DIR, REPO, mocap_files, require_mocap
from ecs_anim.apps.batch import driver, job_hash
from ecs_anim.apps.batch import jobs as batch_jobs
from ecs_anim.apps.batch.command import add_parser, cmd_batch, plan_from_args
from ecs_anim.apps.batch.job_hash import job_digest
from ecs_anim.apps.batch.jobs import foot_skate_ratio, import_clip
from ecs_anim.apps.batch.local_engine import WORKER_DIED
from ecs_anim.apps.batch.metrics_files import CSV_FIELDS
from ecs_anim.apps.batch.plan import BATCH_MARKER, STAMP_SUFFIX, Job, NamedGround
from ecs_anim.apps.batch.plan_parts import body_from_text, expand_clips
from ecs_anim.apps.cli.main import main as cli_main
from ecs_anim.core.errors import EcsAnimError
from ecs_anim.core.ground import Plane

GROUNDS_YAML = """\
grounds:
  flat: {type: plane}
  bumps: {type: bumps, amplitude_m: 0.04, wavelength_x_m: 1.5, wavelength_y_m: 2.0}
"""
GROUND_SPECS = {"flat": {"type": "plane"},
                "bumps": {"type": "bumps", "amplitude_m": 0.04, "wavelength_x_m": 1.5,
                          "wavelength_y_m": 2.0}}
#: The command as the CLI registers it (the lead adds it to ecs_anim/cli.py's parser).
RUNNER = """\
import argparse, sys
from ecs_anim.apps.batch.command import add_parser, cmd_batch
from ecs_anim.apps.cli.args import error_line
from ecs_anim.core.errors import EcsAnimError
parser = argparse.ArgumentParser(prog="ecs-anim")
add_parser(parser.add_subparsers(dest="command", required=True))
try:
    sys.exit(cmd_batch(parser.parse_args(["batch", *sys.argv[1:]])))
except (EcsAnimError, FileExistsError) as exc:
    print("error: " + error_line(exc), file=sys.stderr)
    sys.exit(1)
"""


def parse(*argv: str) -> argparse.Namespace:
    parser = argparse.ArgumentParser(prog="ecs-anim")
    add_parser(parser.add_subparsers(dest="command", required=True))
    return parser.parse_args(["batch", *argv])


def run_batch_cli(*argv: str) -> int:
    return cmd_batch(parse(*argv))


def job_files(folder: Path) -> dict[str, bytes]:
    """Every job output under ``folder`` (not the metrics, report or stamps) by relative path."""
    return {str(p.relative_to(folder)): p.read_bytes() for p in sorted(folder.glob("*/*"))
            if p.suffix in (".bvh", ".npz", ".glb")}


def records(folder: Path) -> list[dict]:
    return json.loads((folder / "metrics.json").read_text())["jobs"]


def without_time(record: dict) -> dict:
    return {k: v for k, v in record.items() if k not in ("seconds", "status")}


@pytest.fixture
def grounds_file(tmp_path: Path) -> Path:
    path = tmp_path / "grounds.yaml"
    path.write_text(GROUNDS_YAML)
    return path


# ---------------------------------------------------------------------------------------------
# Kernels and plans


def test_foot_skate_counts_low_toes_moving_fast() -> None:
    """A toe joint 3 cm up sliding 3 cm per 1/30 s skates (frames 1..9 of 10); at 2 cm per frame
    it does not; at 60 Hz, 1.5 cm a frame is 3 cm per 1/30 s. (Floating is MetricsRecorder's.)"""
    frames, fps = 10, 30.0
    positions = np.zeros((frames, 22, 3))
    from ecs_anim.runtime.metrics import TOES

    positions[:, TOES, 2] = 0.03  # under 5 cm
    positions[:, TOES[0], 0] = 0.03 * np.arange(frames)  # left toe: 3 cm a frame
    assert foot_skate_ratio(positions, Plane(), fps) == pytest.approx(9 / 10)
    positions[:, TOES[0], 0] = 0.02 * np.arange(frames)
    assert foot_skate_ratio(positions, Plane(), fps) == 0.0
    positions[:, TOES[0], 0] = 0.015 * np.arange(frames)
    assert foot_skate_ratio(positions, Plane(), 60.0) == pytest.approx(0.9)
    positions[:, TOES, 2] = 0.06  # above 5 cm: a swing, not a skate
    assert foot_skate_ratio(positions, Plane(), 60.0) == 0.0


def test_a_floating_planted_foot_is_reported_by_the_metrics(tmp_path) -> None:
    """Floating as the batch records it comes from MetricsRecorder: a planted sole lifted 7 mm
    above the ground in the posture floats 7 mm."""
    from conftest import MOTIONS_DIR
    from ecs_anim.components import MotionPlayer
    from ecs_anim.core.morphology import Morphology
    from ecs_anim.io.importing import import_bvh
    from ecs_anim.runtime.metrics import ANKLES, TOES, MetricsRecorder
    from ecs_anim.runtime.simulation import Simulation

    sim = Simulation({"idle": import_bvh(MOTIONS_DIR / "idle.bvh")})
    sim.spawn("a", Morphology.preset("adult_male"), MotionPlayer("idle"))
    metrics = MetricsRecorder(sim)
    for _ in range(3):
        sim.step()
        sim.store.positions[0, ANKLES + TOES, 2] += 0.007  # heels and balls 7 mm up
        metrics.record()
    assert metrics.report()["characters"][0]["floating_mm_max"] == pytest.approx(7.0, abs=0.01)


def test_contact_intervals_are_first_and_last_planted_frame_times() -> None:
    planted = np.array([1, 1, 0, 0, 1, 1, 1, 0, 1], bool)
    assert batch_jobs._intervals(planted, 10.0) == [[0.0, 0.1], [0.4, 0.6], [0.8, 0.8]]
    assert batch_jobs._intervals(np.zeros(4, bool), 10.0) == []


def test_manifest_plan_bodies_statures_grounds(tmp_path: Path) -> None:
    (tmp_path / "wide.yaml").write_text("stature_m: 1.7\nleg_scale: 0.9\n")
    manifest = tmp_path / "batch.yaml"
    manifest.write_text(textwrap.dedent(f"""\
        clips: ["{MOTIONS_DIR}/walk.bvh", "{MOTIONS_DIR}/k*.bvh"]
        bodies:
          - child
          - wide.yaml
          - statures: {{from_m: 1.2, to_m: 1.8, count: 3}}
          - statures: {{from_m: 1.5, to_m: 1.5, count: 1}}
            proportions: child
            sex: female
        grounds:
          bumps: {{type: bumps, amplitude_m: 0.03}}
        formats: [npz]
        out: results
        """))
    plan = plan_from_args(parse("--manifest", str(manifest)))
    assert [c.name for c in plan.clips] == ["walk.bvh", "kick.bvh"]
    assert [b.name for b in plan.bodies] == ["child", "wide", "stature_1.20", "stature_1.50",
                                             "stature_1.80", "stature_1.50_female_child"]
    assert [round(b.morphology.stature, 3) for b in plan.bodies[2:]] == [1.2, 1.5, 1.8, 1.5]
    assert plan.out == tmp_path / "results" and plan.formats == ("npz",)
    jobs = plan.jobs()
    assert len(jobs) == 12 and jobs[0].stem == "walk/child_bumps"
    assert jobs[0].outputs() == ["walk/child_bumps.npz"]
    # the command line's --out and --formats win over the manifest's
    plan = plan_from_args(parse("--manifest", str(manifest), "--out", "x", "--formats", "bvh,glb"))
    assert plan.out == Path("x") and plan.formats == ("bvh", "glb")


@pytest.mark.parametrize("text, expected", [
    ("clips: [walk.bvh]\nbodys: [child]\n", "batch.yaml:2: bodys: unknown key; did you mean 'bodies'?"),
    ("clips: [nothing*.bvh]\nbodies: [child]\n", "batch.yaml:1: clips: nothing*.bvh: matches no"),
    ("clips: [walk.bvh]\nbodies:\n  - child\n  - chlid\n",
     "batch.yaml:4: bodies[1]: body 'chlid': not a preset (did you mean 'child'?)"),
    ("clips: [walk.bvh]\nbodies: [child, child]\n", "batch.yaml:2: bodies[1]: a body named 'child' is given twice"),
    ("clips: [walk.bvh]\nbodies:\n  - statures: {from_m: 1.2, to_m: 9, count: 3}\n",
     "batch.yaml:3: bodies[0].statures.to_m: expected a number between 0.3 and 3 m, found 9"),
    ("clips: [walk.bvh]\nbodies: [child]\ngrounds:\n  hill: {type: slop}\n",
     "batch.yaml:4: grounds.hill.type: unknown ground 'slop'; did you mean 'slope'?"),
    ("clips: [walk.bvh]\nbodies: [child]\nformats: [bvh, fbx]\n", "batch.yaml:3: formats: unknown format 'fbx'"),
])
def test_manifest_errors_name_file_and_line(tmp_path: Path, text: str, expected: str) -> None:
    (tmp_path / "walk.bvh").write_bytes((MOTIONS_DIR / "walk.bvh").read_bytes())
    manifest = tmp_path / "batch.yaml"
    manifest.write_text(text + "out: out\n")
    with pytest.raises(EcsAnimError) as info:
        plan_from_args(parse("--manifest", str(manifest)))
    message = str(info.value)
    assert "\n" not in message
    assert message.startswith(str(tmp_path / expected.split(":", 1)[0]) + ":" + expected.split(":", 1)[1])


def test_command_line_errors(tmp_path: Path, grounds_file: Path) -> None:
    walk = str(MOTIONS_DIR / "walk.bvh")
    cases = [
        ((walk, "--out", str(tmp_path / "o")), "give --bodies"),
        ((walk, "--bodies", "child,talll", "--out", str(tmp_path / "o")), "did you mean 'tall'?"),
        ((walk, "--bodies", "child", "--out", str(tmp_path / "o"), "--formats", "bvh,bvh"),
         "at most once"),
        (("--manifest", str(grounds_file), "--bodies", "child"), "not also --bodies"),
        ((walk, walk.replace("walk", "../motions/walk"), "--bodies", "child", "--out", "o"), None),
    ]
    for argv, expected in cases:
        if expected is None:  # the same file twice counts once
            assert len(plan_from_args(parse(*argv)).clips) == 1
            continue
        with pytest.raises(EcsAnimError, match=expected.replace("(", r"\(").replace(")", r"\)")):
            plan_from_args(parse(*argv))
    # a folder holding someone else's files is refused, never written into
    foreign = tmp_path / "mine"
    foreign.mkdir()
    (foreign / "notes.txt").write_text("keep")
    with pytest.raises(EcsAnimError, match="did not write"):
        run_batch_cli(walk, "--bodies", "child", "--out", str(foreign), "--seconds", "0.1")
    assert sorted(os.listdir(foreign)) == ["notes.txt"]


def test_digest_follows_every_input() -> None:
    walk = MOTIONS_DIR / "walk.bvh"
    job = Job(str(walk), "walk", body_from_text("child"), NamedGround("", Plane()),
                    ("bvh",))
    base = job_digest(job, "clip", "1.0")
    from dataclasses import replace
    changed = [replace(job, body=body_from_text("tall")),
               replace(job, ground=NamedGround("", Plane(0.01))),
               replace(job, formats=("bvh", "npz")), replace(job, seconds=2.0)]
    digests = {job_digest(j, "clip", "1.0") for j in changed}
    digests |= {job_digest(job, "other clip", "1.0"), job_digest(job, "clip", "1.1")}
    assert base not in digests and len(digests) == 6
    assert job_digest(replace(job, body=body_from_text("child")), "clip", "1.0") == base


# ---------------------------------------------------------------------------------------------
# The pipeline: every job's figures are ``ecs-anim run``'s


def _scenario_for(record: dict, clip: Path, fps: float, tmp: Path) -> Path:
    """The scenario ``ecs-anim run`` plays for the batch job ``record``."""
    import yaml

    doc = {"duration_s": record["frames"] / fps, "fps": fps, "motions": {record["clip"]: str(clip)},
           "characters": [{"name": record["body"], "morphology": record["body"],
                           "motion": record["clip"], "loop": False}]}
    if record["ground"]:
        doc["ground"] = GROUND_SPECS[record["ground"]]
    path = tmp / f"{record['clip']}_{record['body']}_{record['ground']}.yaml"
    path.write_text(yaml.safe_dump(doc))
    return path


@pytest.mark.slow
def test_mocap_batch_metrics_equal_ecs_anim_run(tmp_path: Path, grounds_file: Path) -> None:
    """The dev clips (BVH and C3D) x 3 bodies x 2 grounds: every job is ok, metrics.csv and
    metrics.json hold the same rows, every job's figures (every scalar column and each
    constraint's error) and files equal what ``ecs-anim run`` reports and exports for the same
    case, every .glb passes the Khronos validator, and the report's plots are drawn."""
    from support.gltf_validator import assert_valid
    from support.images import decode_png, embedded_pngs, ink

    require_mocap()
    clips = mocap_files("*.bvh") + mocap_files("*.c3d")
    out = tmp_path / "out"
    formats = "bvh,npz,glb"
    status = run_batch_cli(*map(str, clips), "--bodies", "child,adult_female,tall", "--grounds",
                           str(grounds_file), "--out", str(out), "--seconds", "0.2",
                           "--formats", formats, "--jobs", "2")
    assert status == 0
    jobs = records(out)
    assert len(jobs) == len(clips) * 6
    assert all(j["status"] == "ok" and j["error"] == "" for j in jobs)
    for j in jobs:  # every file listed exists
        assert j["outputs"] == [f"{j['clip']}/{j['body']}_{j['ground']}.{f}" for f in formats.split(",")]
        assert all((out / rel).stat().st_size > 0 for rel in j["outputs"])
    with open(out / "metrics.csv", newline="") as f:
        rows = list(csv.DictReader(f))
    assert list(rows[0])[:len(CSV_FIELDS)] == list(CSV_FIELDS)
    assert [(r["clip"], r["body"], r["ground"]) for r in rows] == \
        [(j["clip"], j["body"], j["ground"]) for j in jobs]
    numbers = [k for k in CSV_FIELDS if k.endswith(("_mm", "_m", "_ratio"))]
    for row, j in zip(rows, jobs, strict=False):
        assert [float(row[k]) if row[k] else None for k in numbers] == [j[k] for k in numbers]
    by_clip = {c.stem: c for c in clips}
    fps_of = {c.stem: import_clip(c).fps for c in clips}
    for job in jobs:
        clip = by_clip[job["clip"]]
        scenario = _scenario_for(job, clip, fps_of[job["clip"]], tmp_path)
        report = tmp_path / f"{scenario.stem}.json"
        assert cli_main(["run", str(scenario), "--report", str(report),
                         "--export", str(tmp_path / scenario.stem)]) == 0
        run = json.loads(report.read_text())
        character = run["characters"][0]
        case = f"{job['clip']}/{job['body']}_{job['ground']}"
        assert run["ticks"] == job["frames"], case
        simulated_s = job["duration_s"]  # simulated, not wall-clock, seconds
        assert simulated_s == pytest.approx(run["ticks"] / fps_of[job["clip"]]), case
        assert [job["slide_max_mm"], job["slide_mean_mm"], job["penetration_max_mm"],
                job["floating_max_mm"], job["bone_error_m"], job["com_error_mm"]] == \
            [character["foot_sliding_mm_per_frame"]["max"],
             character["foot_sliding_mm_per_frame"]["mean"],
             character["ground_penetration_mm_max"], character["floating_mm_max"],
             character["bone_length_error_m_max"], character["com_error_mm_max"]], case
        assert job["constraint_errors_mm"] == {c["name"]: c["error_mm_max_fully_active"]
                                               for c in run["constraints"]}, case
        # the same motion comes out: run's export equals the batch's files
        ours = np.load(out / f"{case}.npz")["positions"]
        theirs = np.load(tmp_path / scenario.stem / f"{job['body']}.npz")["positions"]
        np.testing.assert_array_equal(ours, theirs)
        assert (out / f"{case}.bvh").read_bytes() == \
            (tmp_path / scenario.stem / f"{job['body']}.bvh").read_bytes(), case
    assert_valid(sorted(out.glob("*/*.glb")))  # Khronos: 0 errors, 0 warnings
    pngs = embedded_pngs((out / "report.html").read_text("utf-8"))
    assert len(pngs) == 4
    for png in pngs:  # not blank: drawn, with coloured dots and bars
        amount = ink(decode_png(png))
        assert 0.02 < amount["drawn"] < 0.6 and amount["coloured"] > 0.001, amount


def test_template_gives_constraints_their_csv_columns(tmp_path: Path) -> None:
    """A template's world constraint is every job's, with its own ``constraint:<name>_mm``
    column; the template's fps and duration hold."""
    template = tmp_path / "template.yaml"
    template.write_text(textwrap.dedent(f"""\
        duration_s: 0.5
        fps: 30
        motions: {{idle: {MOTIONS_DIR}/idle.bvh}}
        characters:
          - name: anyone
            morphology: adult_male
            motion: idle
            com_control: false
            constraints:
              - {{name: reach, point: wrist_r, priority: 1, target: {{world_m: [0.45, -0.25, 1.1]}}}}
        """))
    out = tmp_path / "out"
    assert run_batch_cli(str(MOTIONS_DIR / "idle.bvh"), "--bodies", "child,tall", "--template",
                         str(template), "--out", str(out), "--formats", "npz", "--jobs", "1") == 0
    jobs = records(out)
    assert [j["frames"] for j in jobs] == [15, 15]
    errors = [j["constraint_errors_mm"]["reach"] for j in jobs]
    assert errors[1] < 1.0 < errors[0]  # the tall body reaches the target, the child cannot
    header = (out / "metrics.csv").read_text().splitlines()[0].split(",")
    assert header[len(CSV_FIELDS):] == ["constraint:reach_mm"]


def test_bad_clip_fails_its_jobs_only(tmp_path: Path) -> None:
    bad = tmp_path / "broken.bvh"
    bad.write_text("HIERARCHY\nROOT Hips\n{\n  OFFSET 0 0 zero\n")
    out = tmp_path / "out"
    status = run_batch_cli(str(bad), str(MOTIONS_DIR / "kick.bvh"), "--bodies", "child,tall",
                           "--out", str(out), "--seconds", "0.2", "--jobs", "2")
    assert status == 1
    jobs = records(out)
    failed = [j for j in jobs if j["status"] == "failed"]
    assert [(j["clip"], j["body"]) for j in failed] == [("broken", "child"), ("broken", "tall")]
    assert all(str(bad) in j["error"] and "\n" not in j["error"] and j["outputs"] == []
               for j in failed)
    assert all(j["status"] == "ok" for j in jobs if j["clip"] == "kick")
    assert not (out / "broken").exists()
    rows = (out / "metrics.csv").read_text().splitlines()
    assert len(rows) == 5 and rows[1].startswith("broken,child,,1.2,0,failed,")


# ---------------------------------------------------------------------------------------------
# Resumption


def test_second_run_skips_changed_inputs_redo_force_redoes(tmp_path: Path, grounds_file: Path) -> None:
    walk, kick = str(MOTIONS_DIR / "walk.bvh"), str(MOTIONS_DIR / "kick.bvh")
    out = tmp_path / "out"
    argv = (walk, kick, "--bodies", "child,tall", "--grounds", str(grounds_file), "--out",
            str(out), "--seconds", "0.1", "--jobs", "1", "--formats", "npz")
    assert run_batch_cli(*argv) == 0
    first = job_files(out)
    times = {p: (out / p).stat().st_mtime_ns for p in first}
    assert run_batch_cli(*argv) == 0
    assert {j["status"] for j in records(out)} == {"skipped"}
    assert {p: (out / p).stat().st_mtime_ns for p in first} == times  # nothing rewritten
    # the bumps get higher: only the jobs on them are redone
    grounds_file.write_text(GROUNDS_YAML.replace("0.04", "0.05"))
    assert run_batch_cli(*argv) == 0
    assert [(j["ground"], j["status"]) for j in records(out)] == \
        [(g, "ok" if g == "bumps" else "skipped") for _ in range(4) for g in ("flat", "bumps")]
    assert run_batch_cli(*argv, "--force") == 0
    assert {j["status"] for j in records(out)} == {"ok"}
    # a job whose output went missing is redone, the others not
    (out / "kick/tall_flat.npz").unlink()
    assert run_batch_cli(*argv) == 0
    assert [j["body"] + "_" + j["ground"] for j in records(out) if j["status"] == "ok"] == \
        ["tall_flat"]


def test_killed_batch_resumes_to_the_same_outputs(tmp_path: Path, grounds_file: Path) -> None:
    """A batch killed (SIGKILL, pool workers included) after a few jobs: the next run skips
    those, does the rest, and the folder ends byte for byte as an uninterrupted run's, with no
    temporary file left."""
    # the job hash holds the package's source as it is now, as the killed process reads it
    # (the digest this process cached earlier predates any edit made since)
    job_hash._SOURCE_DIGEST = None
    clips = [str(MOTIONS_DIR / n) for n in ("walk.bvh", "kick.bvh", "dodge.bvh")]
    argv = [*clips, "--bodies", "child,adult_male,tall", "--grounds", str(grounds_file),
            "--seconds", "0.25", "--formats", "bvh,npz"]
    whole = tmp_path / "whole"
    assert run_batch_cli(*argv, "--out", str(whole), "--jobs", "2") == 0
    runner = tmp_path / "runner.py"
    runner.write_text(RUNNER)
    killed = tmp_path / "killed"
    process = subprocess.Popen([sys.executable, str(runner), *argv, "--out", str(killed),
                                "--jobs", "2"], cwd=REPO, start_new_session=True,
                               stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    try:
        deadline = time.monotonic() + 120
        while len(list(killed.glob(f"*/.*{STAMP_SUFFIX}"))) < 4:
            assert process.poll() is None, "the batch ended before it could be killed"
            assert time.monotonic() < deadline
            time.sleep(0.02)
    finally:
        os.killpg(process.pid, signal.SIGKILL)
        process.wait()
    # (its forked workers may still hold the folder's lock for a moment: the next run waits)
    done_before = len(list(killed.glob(f"*/.*{STAMP_SUFFIX}")))
    assert 4 <= done_before < 18
    assert not (killed / "metrics.json").exists()
    assert run_batch_cli(*argv, "--out", str(killed), "--jobs", "2") == 0
    statuses = [j["status"] for j in records(killed)]
    assert statuses.count("skipped") == done_before and statuses.count("ok") == 18 - done_before
    assert job_files(killed) == job_files(whole)
    assert [without_time(j) for j in records(killed)] == [without_time(j) for j in records(whole)]
    assert not [p for p in killed.rglob("*") if p.name.endswith(".tmp")]


# ---------------------------------------------------------------------------------------------
# Ray: a real local cluster with 2 CPUs: one the command starts and stops, then one started
# once for the module


@pytest.mark.slow
def test_ray_started_by_the_command_writes_the_same_bytes_and_stops(tmp_path: Path,
                                                                    grounds_file: Path,
                                                                    monkeypatch) -> None:
    """No Ray running: ``--engine ray --jobs 2`` starts a local Ray of 2 CPUs, runs the jobs on
    it (glb too, byte for byte the local pool's) and stops it."""
    ray = pytest.importorskip("ray", reason="Ray is not installed (pip install 'ecs_anim[ray]')")
    if ray.is_initialized():
        pytest.skip("a Ray is already running in this process (run this test before the module's)")
    real_init, calls = ray.init, []

    def init(*args, **kwargs):
        calls.append(kwargs)
        return real_init(*args, **kwargs)

    monkeypatch.setattr(ray, "init", init)  # the real Ray, started as the command asks
    bad = tmp_path / "broken.bvh"
    bad.write_text("HIERARCHY\n")
    argv = [str(MOTIONS_DIR / "walk.bvh"), str(bad), "--bodies", "child,tall", "--grounds",
            str(grounds_file), "--seconds", "0.2", "--formats", "bvh,npz,glb", "--jobs", "2"]
    local, on_ray = tmp_path / "local", tmp_path / "ray"
    assert run_batch_cli(*argv, "--out", str(local)) == 1
    assert run_batch_cli(*argv, "--out", str(on_ray), "--engine", "ray") == 1
    assert [c.get("num_cpus") for c in calls] == [2] and "address" not in calls[0]
    assert not ray.is_initialized()  # the command stopped the Ray it started
    assert len(job_files(local)) == 3 * 4 and job_files(on_ray) == job_files(local)
    assert [without_time(j) for j in records(on_ray)] == [without_time(j) for j in records(local)]


@pytest.fixture(scope="module")
def local_ray():
    ray = pytest.importorskip("ray", reason="Ray is not installed (pip install 'ecs_anim[ray]')")
    ray.init(num_cpus=2, include_dashboard=False, logging_level="warning", log_to_driver=False)
    yield ray
    ray.shutdown()


@pytest.mark.slow
def test_ray_writes_the_same_bytes_as_the_local_pool(tmp_path: Path, grounds_file: Path,
                                                      local_ray) -> None:
    bad = tmp_path / "broken.bvh"
    bad.write_text("HIERARCHY\n")
    clips = [str(MOTIONS_DIR / "walk.bvh"), str(MOTIONS_DIR / "guard.bvh"), str(bad)]
    if MOCAP_DIR.is_dir():
        clips.append(str(MOCAP_DIR / "c3dorg_eb015pi_gait.c3d"))
    argv = [*clips, "--bodies", "child,tall", "--grounds", str(grounds_file), "--seconds", "0.3",
            "--formats", "bvh,npz,glb"]
    local, on_ray = tmp_path / "local", tmp_path / "ray"
    assert run_batch_cli(*argv, "--out", str(local), "--jobs", "2") == 1
    assert local_ray.cluster_resources().get("CPU") == 2
    assert run_batch_cli(*argv, "--out", str(on_ray), "--engine", "ray") == 1
    assert job_files(on_ray) == job_files(local)
    assert len(job_files(local)) == 3 * 4 * (len(clips) - 1)
    assert any(rel.endswith(".glb") for rel in job_files(on_ray))
    assert [without_time(j) for j in records(on_ray)] == [without_time(j) for j in records(local)]
    assert [j["status"] for j in records(on_ray)].count("failed") == 4


def test_the_readme_batch_example_runs(tmp_path) -> None:
    """docs/batch.md's batch example (under "The report"), as a shell runs it (out/ becomes a
    temporary folder)."""
    import shlex
    import subprocess

    page = (REPO / "docs" / "batch.md").read_text(encoding="utf-8")
    block = page.split("The report is rewritten on every run. For example", 1)[1]
    lines = [line.strip() for line in block.splitlines()[1:6] if line.strip()][:2]
    assert lines[0].startswith("printf") and lines[1].startswith(".venv/bin/ecs-anim batch")
    ecs_anim = f"{shlex.quote(sys.executable)} -c 'import sys; from ecs_anim.apps.cli.main import main; sys.exit(main())'"
    script = "\n".join(line.replace("out/", f"{tmp_path}/").replace(".venv/bin/ecs-anim", ecs_anim)
                       for line in lines)
    done = subprocess.run(["bash", "-euc", script], cwd=REPO, capture_output=True, text=True,
                          timeout=600, check=False)
    assert done.returncode == 0, done.stderr[-2000:]
    count = len(list((REPO / "scenarios" / "motions").glob("*.bvh"))) * 3 * 2  # bodies, grounds
    output = done.stderr + done.stdout
    assert f"{count} job(s)" in output and f"{count} ok" in output
    jobs = json.loads((tmp_path / "batch" / "metrics.json").read_text())["jobs"]
    assert len(jobs) == count and all(j["status"] == "ok" for j in jobs)
    assert (tmp_path / "batch" / "walk" / "tall_bumps.glb").is_file()
    from support.gltf_validator import assert_valid

    assert_valid(sorted((tmp_path / "batch").glob("*/*.glb")))  # Khronos: 0 errors, 0 warnings
    assert max(j["slide_max_mm"] for j in jobs) < 1.0 and max(j["penetration_max_mm"] for j in jobs) < 1.0


# ---------------------------------------------------------------------------------------------
# Review fixes


def test_a_dead_worker_fails_only_its_job(tmp_path: Path, monkeypatch) -> None:
    """A job whose worker process dies (SIGKILL, as the out-of-memory killer does) fails with a
    one-line reason; the pool is started again and every other job is done."""
    real_run_job = batch_jobs.run_job

    def run_job(job, motion):
        if job.clip == "kick" and job.body.name == "tall":
            os.kill(os.getpid(), signal.SIGKILL)
        return real_run_job(job, motion)

    monkeypatch.setattr(batch_jobs, "run_job", run_job)  # the pool's workers are forked: they see it
    out = tmp_path / "out"
    clips = [str(MOTIONS_DIR / n) for n in ("walk.bvh", "kick.bvh", "idle.bvh")]
    status = run_batch_cli(*clips, "--bodies", "child,tall,adult_male", "--out", str(out),
                           "--seconds", "0.1", "--formats", "npz", "--jobs", "2")
    assert status == 1
    jobs = records(out)
    failed = [(j["clip"], j["body"]) for j in jobs if j["status"] == "failed"]
    assert failed == [("kick", "tall")]
    error = next(j["error"] for j in jobs if j["status"] == "failed")
    assert error == WORKER_DIED and "internal error" not in error
    assert sorted(job_files(out)) == sorted(f"{c}/{b}.npz" for c in ("walk", "kick", "idle")
                                            for b in ("child", "tall", "adult_male")
                                            if (c, b) != ("kick", "tall"))


def test_a_failed_or_reformatted_job_leaves_none_of_its_earlier_files(tmp_path: Path) -> None:
    clip = tmp_path / "walk.bvh"
    clip.write_bytes((MOTIONS_DIR / "walk.bvh").read_bytes())
    out = tmp_path / "out"
    argv = (str(clip), "--bodies", "child", "--out", str(out), "--seconds", "0.1", "--jobs", "1")
    assert run_batch_cli(*argv, "--formats", "bvh,npz") == 0
    assert sorted(job_files(out)) == ["walk/child.bvh", "walk/child.npz"]
    assert run_batch_cli(*argv, "--formats", "npz") == 0  # bvh no longer asked for: gone
    assert sorted(job_files(out)) == ["walk/child.npz"]
    clip.write_text("HIERARCHY\nROOT Hips\n{\n  OFFSET 0 0 zero\n")  # the input breaks
    assert run_batch_cli(*argv, "--formats", "npz") == 1
    assert job_files(out) == {} and not list(out.glob(f"walk/.*{STAMP_SUFFIX}"))


def test_a_job_killed_while_renaming_has_no_old_file_beside_a_new_one(tmp_path: Path,
                                                                       monkeypatch) -> None:
    """Every file of a job is written to a temporary name before any is renamed in, and the
    earlier run's files go first: a kill between two renames leaves new files only, no stamp."""
    out = tmp_path / "out"
    argv = (str(MOTIONS_DIR / "walk.bvh"), "--bodies", "child", "--out", str(out), "--jobs", "1",
            "--formats", "bvh,npz")
    assert run_batch_cli(*argv, "--seconds", "0.1") == 0
    old = job_files(out)
    real_replace = os.replace
    renamed: list[object] = []

    def replace(src, dst):
        if str(dst).endswith((".bvh", ".npz")):
            if renamed:
                raise KeyboardInterrupt  # killed after the job's first rename
            renamed.append(dst)
        return real_replace(src, dst)

    monkeypatch.setattr("ecs_anim.core.files.os.replace", replace)
    with pytest.raises(KeyboardInterrupt):
        run_batch_cli(*argv, "--seconds", "0.2")
    monkeypatch.undo()
    left = job_files(out)
    assert len(left) == 1 and not set(left.items()) & set(old.items())  # only a new file
    assert not list(out.glob(f"walk/.*{STAMP_SUFFIX}"))  # not done: the next run redoes it
    assert not [p for p in out.rglob("*") if p.name.endswith(".tmp")]
    assert run_batch_cli(*argv, "--seconds", "0.2") == 0
    assert [j["status"] for j in records(out)] == ["ok"]


@pytest.mark.parametrize("name", ["metrics.csv", "metrics.json", "report.html", "Report.HTML"])
def test_clips_named_as_the_batch_files_are_refused_up_front(tmp_path: Path, name: str) -> None:
    clip = tmp_path / f"{name}.bvh"
    clip.write_bytes((MOTIONS_DIR / "walk.bvh").read_bytes())
    with pytest.raises(EcsAnimError, match="the batch's own file") as info:
        expand_clips([str(clip)])
    assert "\n" not in str(info.value)
    assert not (tmp_path / "out").exists()


@pytest.mark.parametrize("seconds, expected", [("1e12", "at most 86400 s"),
                                               ("0.0001", "less than one tick at 30 Hz")])
def test_seconds_is_bounded_like_run(tmp_path: Path, seconds: str, expected: str) -> None:
    with pytest.raises(EcsAnimError, match=expected) as info:
        plan_from_args(parse(str(MOTIONS_DIR / "walk.bvh"), "--bodies", "child", "--out",
                                   str(tmp_path / "o"), "--seconds", seconds))
    assert "\n" not in str(info.value)


def test_seconds_under_a_tick_of_an_nmo_clip_fails_its_jobs_not_one_tick(tmp_path: Path) -> None:
    """A clip whose rate is not read up front (.nmo, .c3d): its jobs fail with the same line."""
    nmo = tmp_path / "walk.nmo"
    from ecs_anim.motion.clip import save_nmo

    save_nmo(import_clip(MOTIONS_DIR / "walk.bvh"), nmo)
    out = tmp_path / "out"
    assert run_batch_cli(str(nmo), "--bodies", "child", "--out", str(out), "--seconds", "0.0001",
                         "--jobs", "1") == 1
    assert "less than one tick" in records(out)[0]["error"]


@pytest.mark.parametrize("text, expected", [
    ("bodies: [child, missing.yaml]\n", "batch.yaml:2: bodies[1]: no such morphology file"),
    ("bodies: [child]\ntemplate: nowhere.yaml\n", "batch.yaml:3: template: no such scenario file"),
])
def test_missing_manifest_files_name_the_manifest_line(tmp_path: Path, text: str, expected: str) -> None:
    (tmp_path / "walk.bvh").write_bytes((MOTIONS_DIR / "walk.bvh").read_bytes())
    manifest = tmp_path / "batch.yaml"
    manifest.write_text("clips: [walk.bvh]\n" + text + "out: out\n")
    with pytest.raises(EcsAnimError) as info:
        plan_from_args(parse("--manifest", str(manifest)))
    assert str(info.value).startswith(f"{tmp_path / expected.split(':', 1)[0]}:{expected.split(':', 1)[1]}")
    assert "\n" not in str(info.value)


def test_the_job_hash_follows_the_package_source() -> None:
    """The hash holds a digest of ecs_anim's own .py files (components and systems too): a
    change to any of them changes it."""
    import hashlib
    import importlib

    digest = job_hash.source_digest()
    assert digest == job_hash.source_digest() and len(digest) == 64
    systems = Path(str(importlib.import_module("ecs_anim.systems").__file__)).parent
    original = (systems / "ground_adapt.py").read_bytes()
    real_read = Path.read_bytes

    def read_bytes(path):
        data = real_read(path)
        return data + b"# changed" if path.name == "ground_adapt.py" and path.parent == systems else data

    try:
        job_hash._SOURCE_DIGEST = None
        Path.read_bytes = read_bytes  # type: ignore[method-assign]
        changed = job_hash.source_digest()
    finally:
        Path.read_bytes = real_read  # type: ignore[method-assign]
        job_hash._SOURCE_DIGEST = None
    assert changed != digest and job_hash.source_digest() == digest
    assert (systems / "ground_adapt.py").read_bytes() == original
    assert hashlib.sha256(b"").hexdigest() not in (digest, changed)
    walk = MOTIONS_DIR / "walk.bvh"
    job = Job(str(walk), "walk", body_from_text("child"), NamedGround("", Plane()),
                    ("npz",))
    assert job_digest(job, "clip", f"0.1.0+{digest}") != \
        job_digest(job, "clip", f"0.1.0+{'0' * 64}")


def test_outputs_never_overwrite_body_files_or_template_motions(tmp_path: Path) -> None:
    """Morphology files and the template's motion files are inputs: an output on one of them
    (here a hard link, the same file under another name) is refused before anything is run."""
    out = tmp_path / "out"
    (out / "walk").mkdir(parents=True)
    (out / BATCH_MARKER).write_text("{}")
    body = tmp_path / "wide.yaml"
    body.write_text("stature_m: 1.7\nleg_scale: 0.9\n")
    os.link(body, out / "walk" / "wide.glb")  # a glb the job would delete, being another format
    with pytest.raises(EcsAnimError, match="an input of this batch"):
        run_batch_cli(str(MOTIONS_DIR / "walk.bvh"), "--bodies", str(body), "--out", str(out),
                      "--seconds", "0.1", "--formats", "npz", "--jobs", "1")
    assert body.read_text().startswith("stature_m")
    motion = tmp_path / "idle.bvh"
    motion.write_bytes((MOTIONS_DIR / "idle.bvh").read_bytes())
    template = tmp_path / "template.yaml"
    template.write_text(f"duration_s: 0.2\nfps: 30\nmotions: {{idle: {motion}}}\ncharacters:\n"
                        "  - {name: a, morphology: child, motion: idle}\n")
    os.link(motion, out / "walk" / "child.bvh")
    with pytest.raises(EcsAnimError, match="an input of this batch"):
        run_batch_cli(str(MOTIONS_DIR / "walk.bvh"), "--bodies", "child", "--template",
                      str(template), "--out", str(out), "--jobs", "1")
    assert motion.read_bytes() == (MOTIONS_DIR / "idle.bvh").read_bytes()


def test_unreachable_or_client_ray_addresses_fail_at_once(tmp_path: Path) -> None:
    """A closed port and ray:// fail in one line before the batch folder is touched."""
    pytest.importorskip("ray")
    import socket

    with socket.socket() as s:  # a port nobody listens on
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    out = tmp_path / "out"
    walk = str(MOTIONS_DIR / "walk.bvh")
    for address, expected in ((f"127.0.0.1:{port}", "no Ray cluster reachable there"),
                              ("ray://127.0.0.1:10001", "Ray Client (ray://) is not supported"),
                              ("nonsense", "expected HOST:PORT")):
        with pytest.raises(EcsAnimError, match=expected.replace("(", r"\(").replace(")", r"\)")) as info:
            run_batch_cli(walk, "--bodies", "child", "--out", str(out), "--engine", "ray",
                          "--address", address, "--seconds", "0.1")
        assert "\n" not in str(info.value)
        assert not out.exists()


def test_a_source_change_redoes_the_jobs(tmp_path: Path, monkeypatch) -> None:
    argv = (str(MOTIONS_DIR / "walk.bvh"), "--bodies", "child", "--out", str(tmp_path / "out"),
            "--seconds", "0.1", "--formats", "npz", "--jobs", "1")
    assert run_batch_cli(*argv) == 0
    assert run_batch_cli(*argv) == 0 and records(tmp_path / "out")[0]["status"] == "skipped"
    monkeypatch.setattr(driver, "source_digest", lambda: "another source")
    assert run_batch_cli(*argv) == 0 and records(tmp_path / "out")[0]["status"] == "ok"


def test_pool_workers_tick_on_one_thread():
    """A pool's processes share the cores: each ticks on one thread (a kernel thread spins
    between chunks, so two per process on shared cores would take turns spinning)."""
    import multiprocessing

    from ecs_anim.apps.batch.local_engine import _Worker
    from ecs_anim.runtime import kernels

    worker = _Worker(multiprocessing.get_context("fork"), [])
    try:
        worker.give("threads", kernels.threads)
        assert worker.conn.recv() == (1, "")
    finally:
        worker.stop()


def test_a_folder_gives_its_trc_and_amc_captures_too(tmp_path: Path) -> None:
    for name in ("gait.trc", "walk.amc", "walk.asf", "notes.txt"):
        (tmp_path / name).write_text("")
    assert [p.name for p in expand_clips([str(tmp_path)])] == ["gait.trc", "walk.amc"]
