"""Outputs (issue 11, items 6-8): no output of a command is one of its inputs, a run's export
folder is replaced as one set or not at all (also when the process is killed), nothing
temporary outlives a write, and an unwritable place is found before any work."""

from __future__ import annotations

import contextlib
import errno
import json
import multiprocessing
import os
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from conftest import MOTIONS_DIR
from ecs_anim.apps.cli.args import MAX_ERROR_CHARS
from ecs_anim.apps.cli.main import main
from ecs_anim.core import files
from ecs_anim.core.errors import EcsAnimError
from ecs_anim.core.files import MANIFEST_NAME, atomic_output, output_set

#: The first line of the scenarios written here (named, so no assert reads like a timing).
LENGTH_LINE = "duration_s: 0.5"
SET = ["kick.bvh", "kick.glb", "kick.npz", "other.bvh", "other.glb", "other.npz"]


def write_scenario(folder: Path, kick: Path, names: tuple[str, ...] = ("kick", "other"),
                   file_name: str = "s.yaml") -> Path:
    """A short scenario whose characters ``names`` play the clip ``kick``, side by side 2 m
    apart (not in each other, which CollisionSeparate would report on stderr)."""
    path = folder / file_name
    people = "".join(f"  - {{name: {n}, morphology: adult_male, motion: kick, "
                     f"position_m: [0.0, {2.0 * i}]}}\n" for i, n in enumerate(names))
    path.write_text(f"{LENGTH_LINE}\nmotions:\n  kick: {kick}\ncharacters:\n{people}")
    return path


def error_of(capsys: pytest.CaptureFixture[str]) -> str:
    """The one error line the last command printed."""
    captured = capsys.readouterr()
    lines = captured.err.splitlines()
    assert len(lines) == 1 and "Traceback" not in captured.err, captured.err
    return lines[0]


def snapshot(folder: Path) -> dict[str, bytes] | None:
    """Every entry of ``folder`` (hidden ones too) with its bytes, or None if it is missing."""
    if not folder.exists():
        return None
    return {p.name: p.read_bytes() for p in sorted(folder.iterdir())}


# --- item 6: an output is never an input --------------------------------------------------


def test_a_report_must_be_json_and_never_the_scenario(tmp_path, capsys, monkeypatch):
    scenario = write_scenario(tmp_path, MOTIONS_DIR / "kick.bvh")
    before = scenario.read_bytes()
    assert main(["run", str(scenario), "--report", str(scenario), "--force"]) == 1
    assert error_of(capsys) == f"error: --report {scenario}: a report is JSON: name it .json"
    # A scenario may be JSON (JSON is YAML): ./s.json and s.json are one file.
    as_json = write_scenario(tmp_path, MOTIONS_DIR / "kick.bvh", file_name="s.json")
    monkeypatch.chdir(tmp_path)
    assert main(["run", "s.json", "--report", "./s.json", "--force"]) == 1
    assert error_of(capsys) == ("error: --report ./s.json: is s.json, an input of this command; "
                                "give another output")
    link = tmp_path / "link.json"
    link.symlink_to(scenario)
    assert main(["run", str(scenario), "--report", str(link), "--force"]) == 1
    assert error_of(capsys) == (f"error: --report {link}: is {scenario}, an input of this "
                                "command; give another output")
    assert scenario.read_bytes() == before and as_json.read_text().startswith(LENGTH_LINE)


def test_export_into_the_motions_folder_is_refused(tmp_path, capsys):
    """The issue's case: a character named ``kick`` exported into the folder of ``kick.bvh``."""
    motions = tmp_path / "motions"
    shutil.copytree(MOTIONS_DIR, motions)
    before = snapshot(motions)
    scenario = write_scenario(tmp_path, motions / "kick.bvh")
    through_link = tmp_path / "out"
    through_link.symlink_to(motions)
    for folder in (motions, through_link):
        assert main(["run", str(scenario), "--export", str(folder), "--force"]) == 1
        assert error_of(capsys) == (f"error: --export {folder}: holds {motions / 'kick.bvh'}, an "
                                    "input of this command, and an export replaces its whole "
                                    "folder; give another folder")
    assert snapshot(motions) == before


def test_import_and_export_never_write_over_an_input(tmp_path, capsys):
    walk = tmp_path / "walk.bvh"
    shutil.copy(MOTIONS_DIR / "walk.bvh", walk)
    out = tmp_path / "out"
    out.mkdir()
    (out / "walk.nmo").symlink_to(walk)  # writing out/walk.nmo would replace walk.bvh
    assert main(["import", str(walk), "-o", str(out), "--force"]) == 1
    assert error_of(capsys) == (f"error: -o {out / 'walk.nmo'}: is {walk}, an input of this "
                                "command; give another output")
    assert walk.read_bytes() == (MOTIONS_DIR / "walk.bvh").read_bytes()

    nmo = tmp_path / "walk.nmo"
    assert main(["import", str(walk), "-o", str(tmp_path)]) == 0
    skeleton = tmp_path / "skeleton.bvh"
    shutil.copy(MOTIONS_DIR / "kick.bvh", skeleton)
    capsys.readouterr()
    assert main(["export", str(nmo), "--morphology", str(skeleton), "-o", str(skeleton),
                 "--force"]) == 1
    assert error_of(capsys) == (f"error: {skeleton}: is {skeleton}, an input of this command; "
                                "give another output")
    played = tmp_path / "played.npz"
    played.symlink_to(nmo)
    assert main(["export", str(nmo), "-o", str(played), "--force"]) == 1
    assert error_of(capsys) == (f"error: {played}: is {nmo}, an input of this command; give "
                                "another output")
    assert skeleton.read_bytes() == (MOTIONS_DIR / "kick.bvh").read_bytes()
    assert nmo.read_bytes()[:4] == b"PK\x03\x04"


def test_a_screenshot_never_replaces_the_scenario(tmp_path, capsys):
    scenario = write_scenario(tmp_path, MOTIONS_DIR / "kick.bvh")
    shot = tmp_path / "shot.png"
    shot.symlink_to(scenario)
    assert main(["view", str(scenario), "--screenshot", str(shot), "--force"]) == 1
    assert error_of(capsys) == (f"error: --screenshot {shot}: is {scenario}, an input of this "
                                "command; give another output")
    assert scenario.read_text().startswith(LENGTH_LINE)


# --- item 7: a run's outputs appear together or not at all ------------------------------


def test_export_folder_is_replaced_as_a_set_and_a_users_files_are_kept(tmp_path, capsys):
    scenario = write_scenario(tmp_path, MOTIONS_DIR / "kick.bvh")
    out = tmp_path / "out"
    assert main(["run", str(scenario), "--seconds", "0.2", "--export", str(out)]) == 0
    assert sorted(os.listdir(out)) == [MANIFEST_NAME, *SET]
    assert sorted(json.loads((out / MANIFEST_NAME).read_text())["files"]) == SET
    # The next scenario has other characters: the earlier set (in the manifest) goes as a whole.
    renamed = write_scenario(tmp_path, MOTIONS_DIR / "kick.bvh", ("kick", "third"), "t.yaml")
    assert main(["run", str(renamed), "--seconds", "0.2", "--export", str(out)]) == 1
    assert error_of(capsys) == (f"error: --export {out}: holds an earlier export (use --force "
                                "to replace it)")
    assert main(["run", str(renamed), "--seconds", "0.2", "--export", str(out), "--force"]) == 0
    assert sorted(os.listdir(out)) == [MANIFEST_NAME, "kick.bvh", "kick.glb", "kick.npz",
                                       "third.bvh", "third.glb", "third.npz"]
    assert np.load(out / "third.npz")["positions"].shape == (6, 22, 3)
    # A file ecs-anim did not write is never deleted, --force or not.
    (out / "notes.txt").write_text("mine")
    capsys.readouterr()
    assert main(["run", str(renamed), "--export", str(out), "--force"]) == 1
    assert error_of(capsys) == (f"error: --export {out}: holds files ecs-anim did not write "
                                "('notes.txt'); an export replaces its whole folder, so give a new "
                                "or empty folder")
    assert (out / "notes.txt").read_text() == "mine"
    report = out / "r.json"
    assert main(["run", str(renamed), "--export", str(tmp_path / "new"), "--report",
                 str(tmp_path / "new" / "r.json")]) == 1
    assert error_of(capsys) == (f"error: --report {tmp_path / 'new' / 'r.json'}: inside the "
                                "--export folder, which an export replaces as a whole; write it "
                                "elsewhere")
    assert not report.exists() and not (tmp_path / "new").exists()


def killed_at(step: int, argv: list[str], no_exchange: bool = False) -> int | None:
    """Run ``ecs-anim argv`` in a forked process that SIGKILLs itself just before its
    ``step``-th call of anything that writes to disk or renames (fsync, rename, replace, the
    atomic exchange, rmtree; 0: never); ``no_exchange`` takes the exchange away (the
    two-rename fallback). Returns the exit code (-9 when killed)."""
    def child() -> None:
        calls = [0]

        def counted(action):
            def wrapper(*args, **kwargs):
                calls[0] += 1
                if calls[0] == step:
                    os.kill(os.getpid(), signal.SIGKILL)
                return action(*args, **kwargs)
            return wrapper

        os.fsync, os.rename, os.replace = counted(os.fsync), counted(os.rename), counted(os.replace)
        shutil.rmtree = counted(shutil.rmtree)
        files._exchange = (lambda a, b: False) if no_exchange else counted(files._exchange)
        with open(os.devnull, "w") as sink, contextlib.redirect_stdout(sink):
            raise SystemExit(main(argv))

    process = multiprocessing.get_context("fork").Process(target=child)
    process.start()
    process.join()
    return process.exitcode


def run_args(scenario: Path, work: Path, seconds: str) -> list[str]:
    return ["run", str(scenario), "--seconds", seconds, "--export", str(work / "out"),
            "--report", str(work / "r.json"), "--force"]


def check_killed_run(work: Path, old: dict[str, bytes] | None, new: dict[str, bytes] | None,
                     new_args: list[str]) -> None:
    """After a killed run: the export folder holds the old set or the new one (or, only in the
    fallback's window between its two renames, is missing while the old set waits aside), the
    report is whole; the next run puts back or removes whatever was left and writes the set."""
    now = snapshot(work / "out")
    if now is None:
        (aside,) = [p for p in work.iterdir() if p.name.startswith(".out.old-")]
        assert snapshot(aside) == old
    else:
        assert now in (old, new), sorted(now)
    assert json.loads((work / "r.json").read_text())["ticks"] in (3, 6)
    assert main(new_args) == 0
    assert snapshot(work / "out") == new
    assert sorted(os.listdir(work)) == ["out", "r.json"]
    assert json.loads((work / "r.json").read_text())["ticks"] == 6


@pytest.fixture
def old_and_new(tmp_path):
    """A scenario, and the export folder and report of a 0.1 s run (the old set) and of a 0.2 s
    run (the new one) of it: (scenario, old folder, its report, new folder's snapshot)."""
    scenario = write_scenario(tmp_path, MOTIONS_DIR / "kick.bvh")
    assert main(run_args(scenario, tmp_path / "old", "0.1")) == 0
    assert main(run_args(scenario, tmp_path / "new", "0.2")) == 0
    return scenario, tmp_path / "old", snapshot(tmp_path / "new" / "out")


def with_old_set(work: Path, old: Path) -> dict[str, bytes] | None:
    """``work`` holding a copy of the old export folder and report; the folder's snapshot."""
    shutil.copytree(old / "out", work / "out")
    shutil.copy(old / "r.json", work / "r.json")
    return snapshot(work / "out")


@pytest.mark.parametrize("no_exchange", [False, True], ids=["exchange", "two_renames"])
def test_a_killed_export_leaves_the_old_set_or_the_new_one(no_exchange, old_and_new, tmp_path,
                                                            capsys):
    scenario, old_folder, new = old_and_new
    step, status = 0, None
    while status != 0:  # kill before every step in turn, until a run gets through
        step += 1
        work = tmp_path / f"killed_at_{step}"
        old = with_old_set(work, old_folder)
        status = killed_at(step, run_args(scenario, work, "0.2"), no_exchange)
        assert status in (0, -signal.SIGKILL)
        check_killed_run(work, old, new, run_args(scenario, work, "0.2"))
    # 6 files (a .bvh, .npz and .glb for each of 2 characters) and the manifest, the folder, the
    # swap (one or two renames), the old set's removal, the parent folder, the report's data and
    # its rename
    assert step == (14 if no_exchange else 13) + 1
    capsys.readouterr()


def test_a_cli_run_killed_at_random_moments(old_and_new, tmp_path, capsys):
    """The real command in its own process, killed after random delays."""
    scenario, old_folder, new = old_and_new
    rng = np.random.default_rng(7)
    for k, delay in enumerate(rng.uniform(0.2, 0.6, size=3)):
        work = tmp_path / f"try_{k}"
        old = with_old_set(work, old_folder)
        process = subprocess.Popen([sys.executable, "-m", "ecs_anim.apps.cli.main",
                                    *run_args(scenario, work, "0.2")],
                                   stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        time.sleep(delay)
        process.kill()
        process.wait()
        check_killed_run(work, old, new, run_args(scenario, work, "0.2"))
    capsys.readouterr()


def test_a_set_put_aside_by_a_killed_export_comes_back(tmp_path):
    """The fallback's window: the old folder renamed aside, the new one not yet in place."""
    dead = subprocess.run([sys.executable, "-c", "import os; print(os.getpid())"],
                          capture_output=True, text=True, check=True).stdout.strip()
    aside = tmp_path / f".out.old-{dead}"
    aside.mkdir()
    (aside / "kick.bvh").write_text("old")
    (aside / MANIFEST_NAME).write_text(json.dumps({"files": ["kick.bvh"]}))
    (tmp_path / f".out.partial-{dead}").mkdir()
    with pytest.raises(RuntimeError), output_set(tmp_path / "out", ["kick.bvh"], True) as export:
        with export.file("kick.bvh") as f:
            f.write(b"new")
        raise RuntimeError("the run failed before its set was complete")
    assert sorted(os.listdir(tmp_path)) == ["out"]
    assert (tmp_path / "out" / "kick.bvh").read_text() == "old"


def test_a_killed_single_file_write_leaves_nothing_after_the_next(tmp_path):
    nmo = tmp_path / "walk.nmo"
    assert main(["import", str(MOTIONS_DIR / "walk.bvh"), "-o", str(tmp_path)]) == 0
    args = ["export", str(nmo), "-o", str(tmp_path / "played.npz"), "--force"]
    assert killed_at(1, args) == -signal.SIGKILL  # killed before its data reached the disk
    (leftover,) = [p.name for p in tmp_path.iterdir() if p.name.startswith(".played.npz.")]
    assert leftover.endswith(".tmp") and ".ecs-anim-" in leftover
    assert main(args) == 0
    assert sorted(os.listdir(tmp_path)) == ["played.npz", "walk.nmo"]
    assert np.load(tmp_path / "played.npz")["positions"].shape[1:] == (22, 3)


def test_a_failed_write_names_the_output_and_leaves_no_temporary_file(tmp_path):
    target = tmp_path / "x.bvh"
    with pytest.raises(ValueError), atomic_output(target, force=False) as f:
        f.write(b"half")
        raise ValueError("the writer failed")
    with pytest.raises(EcsAnimError) as error, atomic_output(target, force=False) as f:
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))
    assert str(error.value) == f"{target}: cannot write: No space left on device"
    with pytest.raises(EcsAnimError) as error, output_set(tmp_path / "out", SET, False) as export, \
            export.file("kick.bvh"):
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))
    assert str(error.value) == f"{tmp_path / 'out' / 'kick.bvh'}: cannot write: No space left on device"
    assert os.listdir(tmp_path) == []


# --- item 8: an unwritable place is found before any work ---------------------------------


@pytest.fixture
def immutable_folder(tmp_path):
    """A folder nobody can create files in, not even root (``chattr +i``)."""
    folder = tmp_path / "locked"
    folder.mkdir()
    if shutil.which("chattr") is None or subprocess.run(
            ["chattr", "+i", str(folder)], capture_output=True, check=False).returncode != 0:
        pytest.skip("chattr +i is not available here (needs ext2/3/4 and CAP_LINUX_IMMUTABLE)")
    yield folder
    subprocess.run(["chattr", "-i", str(folder)], check=True)


def test_unwritable_outputs_are_refused_before_any_work(immutable_folder, tmp_path, capsys):
    scenario = write_scenario(tmp_path, MOTIONS_DIR / "kick.bvh")
    nmo = tmp_path / "walk.nmo"
    assert main(["import", str(MOTIONS_DIR / "walk.bvh"), "-o", str(tmp_path)]) == 0
    capsys.readouterr()
    locked = immutable_folder
    why = f"cannot write in {locked} (Operation not permitted)"
    cases = [
        (["run", str(scenario), "--export", str(locked / "out")], f"--export {locked / 'out'}: {why}"),
        (["run", str(scenario), "--report", str(locked / "r.json")], f"--report {locked / 'r.json'}: {why}"),
        (["import", str(MOTIONS_DIR / "walk.bvh"), "-o", str(locked)], f"-o {locked}: {why}"),
        (["import", str(MOTIONS_DIR / "walk.bvh"), "-o", str(locked / "a" / "b")],
         f"-o {locked / 'a' / 'b'}: {why}"),
        (["export", str(nmo), "-o", str(locked / "x.bvh")], f"{locked / 'x.bvh'}: {why}"),
        (["view", str(scenario), "--screenshot", str(locked / "x.png")],
         f"--screenshot {locked / 'x.png'}: {why}"),
    ]
    for argv, message in cases:
        assert main(argv) == 1, argv
        captured = capsys.readouterr()
        assert captured.err == f"error: {message}\n" and captured.out == "", argv
    assert os.listdir(locked) == []


def test_error_lines_are_capped(tmp_path, capsys):
    deep = tmp_path / ("a" * 200) / ("b" * 200) / ("c" * 200) / "s.yaml"
    assert main(["run", str(deep)]) == 1
    line = error_of(capsys)
    assert len(line) == len("error: ") + MAX_ERROR_CHARS and line.endswith("...")
    assert line.startswith(f"error: {tmp_path}/aaa")


# --- review of the output checks: loops, long names, a set put aside, one check -----------


def dead_pid() -> str:
    """The id of a process that has ended."""
    return subprocess.run([sys.executable, "-c", "import os; print(os.getpid())"],
                          capture_output=True, text=True, check=True).stdout.strip()


def test_a_symlink_loop_as_an_output_is_refused_before_any_work(tmp_path, capsys):
    scenario = write_scenario(tmp_path, MOTIONS_DIR / "kick.bvh")
    nmo = tmp_path / "walk.nmo"
    assert main(["import", str(MOTIONS_DIR / "walk.bvh"), "-o", str(tmp_path)]) == 0
    capsys.readouterr()
    loops = {}
    for name in ("loop.bvh", "loop.json", "loopA", "loop.png", "loopdir"):
        loops[name] = tmp_path / name
        loops[name].symlink_to(name)  # the link points to itself
    (tmp_path / "ping").symlink_to("pong")
    (tmp_path / "pong").symlink_to("ping")
    cases = [
        (["export", str(nmo), "--morphology", "child", "-o", str(loops["loop.bvh"])],
         f"{loops['loop.bvh']}: a symlink loop"),
        (["export", str(nmo), "-o", str(tmp_path / "ping" / "x.npz")],
         f"{tmp_path / 'ping' / 'x.npz'}: a symlink loop"),
        (["run", str(scenario), "--report", str(loops["loop.json"])],
         f"--report {loops['loop.json']}: a symlink loop"),
        (["run", str(scenario), "--export", str(loops["loopA"]), "--force"],
         f"--export {loops['loopA']}: a symlink loop"),
        (["run", str(scenario), "--export", str(tmp_path / "ping")],
         f"--export {tmp_path / 'ping'}: a symlink loop"),
        (["view", str(scenario), "--screenshot", str(loops["loop.png"]), "--force"],
         f"--screenshot {loops['loop.png']}: a symlink loop"),
        (["import", str(MOTIONS_DIR / "walk.bvh"), "-o", str(loops["loopdir"])],
         f"-o {loops['loopdir']}: a symlink loop"),
    ]
    before = sorted(os.listdir(tmp_path))
    for argv, message in cases:
        assert main(argv) == 1, argv
        captured = capsys.readouterr()
        assert captured.err == f"error: {message}\n" and captured.out == "", argv
    assert sorted(os.listdir(tmp_path)) == before
    with pytest.raises(FileExistsError) as error, atomic_output(loops["loop.bvh"], force=True):
        pass
    assert str(error.value) == f"{loops['loop.bvh']}: a symlink loop"


def test_a_name_too_long_for_the_temporary_file_is_refused_before_any_work(tmp_path, capsys,
                                                                           monkeypatch):
    """A name the file system takes, but not with the hidden sibling's or the temporary file's
    additions around it: found by the checks, not after the run."""
    scenario = write_scenario(tmp_path, MOTIONS_DIR / "kick.bvh")
    monkeypatch.chdir(tmp_path)
    limit = os.pathconf(tmp_path, "PC_NAME_MAX")
    pid = len(str(os.getpid()))
    report = "r" * (limit - 10) + ".json"  # a name the file system allows
    export = "e" * (limit - 5)
    temporary = {report: len(f".{report}.") + 8 + len(f".ecs-anim-{os.getpid()}.tmp"),
                 export: len(f".{export}.partial-") + pid}
    for flag, name in (("--report", report), ("--export", export)):
        assert main(["run", str(scenario), "--seconds", "0.1", flag, name]) == 1
        captured = capsys.readouterr()
        assert captured.out == ""  # nothing ran
        need = temporary[name]
        assert captured.err == (f"error: {flag} {name[:80]}...{name[-30:]}: name too long: "
                                f"writing it takes a temporary name of {need} bytes beside it, "
                                f"and this file system allows {limit}; shorten the name by "
                                f"{need - limit}\n")
        assert len(captured.err) < 300
    assert sorted(os.listdir(tmp_path)) == ["s.yaml"]
    # A name that leaves room for the additions is written.
    fits = "f" * (limit - 10 - pid)
    assert main(["run", str(scenario), "--seconds", "0.1", "--export", fits]) == 0
    assert sorted(os.listdir(fits)) == [MANIFEST_NAME, *SET]
    # Where the system does not say (no pathconf), 255.
    monkeypatch.setattr(os, "pathconf", lambda *args: (_ for _ in ()).throw(OSError(errno.EINVAL, "")))
    assert files._name_max(tmp_path) == 255


def test_a_set_put_aside_by_a_killed_export_needs_force(tmp_path, capsys):
    """Off Linux (no atomic exchange) a killed export may leave the earlier set aside and the
    folder missing: the next run puts it back before checking, so it needs --force."""
    scenario = write_scenario(tmp_path, MOTIONS_DIR / "kick.bvh")
    out = tmp_path / "out"
    assert main(["run", str(scenario), "--seconds", "0.1", "--export", str(out)]) == 0
    old = snapshot(out)
    out.rename(tmp_path / f".out.old-{dead_pid()}")
    (tmp_path / f".out.partial-{dead_pid()}").mkdir()
    capsys.readouterr()
    assert main(["run", str(scenario), "--seconds", "0.2", "--export", str(out)]) == 1
    assert error_of(capsys) == (f"error: --export {out}: holds an earlier export (use --force "
                                "to replace it)")
    assert snapshot(out) == old and sorted(os.listdir(tmp_path)) == ["out", "s.yaml"]
    assert main(["run", str(scenario), "--seconds", "0.2", "--export", str(out), "--force"]) == 0
    assert snapshot(out) != old and sorted(os.listdir(out)) == [MANIFEST_NAME, *SET]


def test_the_screenshot_writer_checks_its_output_with_the_shared_check(tmp_path, monkeypatch):
    """``write_screenshot`` refuses what ``output_problem`` refuses, as a user error, before
    rendering."""
    from ecs_anim.apps.viewer import screenshot as window
    from ecs_anim.scenario import load_scenario

    scenario = load_scenario(write_scenario(tmp_path, MOTIONS_DIR / "kick.bvh"))

    def no_render(*args, **kwargs):
        raise AssertionError("rendered before the output was checked")

    monkeypatch.setattr(window, "render_screenshot", no_render)
    existing = tmp_path / "shot.png"
    existing.write_bytes(b"mine")
    loop = tmp_path / "loop.png"
    loop.symlink_to("loop.png")
    folder = tmp_path / "folder.png"
    folder.mkdir()
    for out, force, message in [
            (existing, False, f"{existing}: already exists (use --force to overwrite)"),
            (loop, True, f"{loop}: a symlink loop"),
            (folder, True, f"{folder}: not a file (a folder or a device); give a file path")]:
        with pytest.raises(EcsAnimError) as error:
            window.write_screenshot(scenario, out, 0.0, 64, 48, force)
        assert str(error.value) == message
    assert existing.read_bytes() == b"mine"
