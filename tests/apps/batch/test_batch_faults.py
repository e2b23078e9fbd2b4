"""``ecs-anim batch`` under faults (issue 35): pool workers SIGKILLed at random moments, the
driver SIGKILLed alone, two batches into one folder, links where outputs go, a folder turned
read-only, ``$`` in clip names, a template's triggers. The fault tests kill real processes
(the driver runs as a subprocess, as the CLI does) and are bounded in time."""

from __future__ import annotations

import errno
import json
import os
import random
import signal
import socket
import subprocess
import sys
import tempfile
import textwrap
import time
from pathlib import Path

import pytest
from apps.batch.test_batch import RUNNER, job_files, parse, records, run_batch_cli

from conftest import MOTIONS_DIR, REPO
from ecs_anim.apps.batch.folder_lock import LOCK_NAME, folder_lock
from ecs_anim.apps.batch.local_engine import WORKER_DIED
from ecs_anim.apps.batch.plan import STAMP_SUFFIX
from ecs_anim.core.errors import EcsAnimError

linux_only = pytest.mark.skipif(not Path("/proc/self/stat").exists(),
                                reason="finds a driver's workers in /proc (Linux)")


def children(pid: int) -> list[int]:
    """The live (not zombie) child processes of ``pid``, from /proc."""
    found = []
    for entry in Path("/proc").iterdir():
        if entry.name.isdigit():
            try:
                fields = (entry / "stat").read_text().rsplit(")", 1)[1].split()
            except OSError:
                continue
            if fields[0] != "Z" and int(fields[1]) == pid:
                found.append(int(entry.name))
    return found


def alive(pid: int) -> bool:
    """Whether ``pid`` runs (a zombie, dead and not yet reaped, does not)."""
    try:
        return Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0] != "Z"
    except OSError:
        return False


def start_driver(tmp_path: Path, *argv: str) -> subprocess.Popen[bytes]:
    """The batch command as a process of its own (its own session, so the test can kill its
    whole group if it must), output to ``tmp_path/driver.log``."""
    runner = tmp_path / "runner.py"
    runner.write_text(RUNNER)
    with open(tmp_path / "driver.log", "wb") as log:  # the child has its own copy
        return subprocess.Popen([sys.executable, str(runner), *argv], cwd=REPO, stdout=log,
                                stderr=subprocess.STDOUT, start_new_session=True)


def wait_for(condition, seconds: float, what: str) -> None:
    deadline = time.monotonic() + seconds
    while not condition():
        assert time.monotonic() < deadline, f"waited {seconds} s for {what}"
        time.sleep(0.01)


def clips(n: int) -> list[str]:
    return [str(p) for p in sorted(MOTIONS_DIR.glob("*.bvh"))[:n]]


@pytest.fixture
def compiled_kernels(tmp_path: Path) -> None:
    """The tick's kernels compiled into numba's disk cache before a driver starts its workers:
    each new worker would compile them again (a minute on loaded cores, after a source change),
    and one killed while compiling leaves nothing cached."""
    assert run_batch_cli(str(MOTIONS_DIR / "walk.bvh"), "--bodies", "child", "--seconds", "0.1",
                         "--formats", "npz", "--jobs", "1", "--out", str(tmp_path / "warm")) == 0


# ---------------------------------------------------------------------------------------------
# Item 3: workers killed at any moment never hang the pool


@linux_only
@pytest.mark.timeout(240)
def test_workers_killed_at_random_moments_never_hang_the_batch(tmp_path: Path,
                                                               compiled_kernels: None) -> None:
    """Real SIGKILLs of real pool workers, at random moments (importing, running, reading a
    task, writing a result) while the driver hands out 6 clips x 3 bodies: the batch ends
    (bounded), each job is ok with its file or failed because its worker died, and a second
    run ends the work. (Whether the second run skips the first's jobs depends on the package's
    source not changing between the two: the job hash holds it.)"""
    rng = random.Random(35)
    out = tmp_path / "out"
    # 30 s simulated a job (0.6 s of CPU on an idle machine: 1 s ones all ended in 1.6 s, after
    # 3 kills), so the killer has time for its kills on any machine
    argv = [*clips(6), "--bodies", "child,adult_male,tall", "--seconds", "30.0", "--formats",
            "npz", "--jobs", "2", "--out", str(out)]
    driver = start_driver(tmp_path, *argv)
    kills, started = 0, time.monotonic()
    try:
        while driver.poll() is None and kills < 12:
            workers = children(driver.pid)
            if workers:
                try:
                    os.kill(rng.choice(workers), signal.SIGKILL)
                    kills += 1
                except ProcessLookupError:  # it ended (the driver stopped it) meanwhile
                    pass
            time.sleep(rng.uniform(0.02, 0.4))
        driver.wait(timeout=180)  # a hang fails here
    finally:
        if driver.poll() is None:
            os.killpg(driver.pid, signal.SIGKILL)
            driver.wait()
    log = (tmp_path / "driver.log").read_text()
    print(f"{kills} workers killed; the batch ended in {time.monotonic() - started:.1f} s")
    assert kills >= 6, f"the batch ended after {kills} kills: give it more jobs\n{log}"
    jobs = records(out)
    assert len(jobs) == 18 and driver.returncode == (0 if all(
        j["status"] == "ok" for j in jobs) else 1), log
    assert all(j["status"] == "ok" or WORKER_DIED in j["error"] for j in jobs), log
    assert sorted(job_files(out)) == sorted(f"{j['clip']}/{j['body']}.npz" for j in jobs
                                            if j["status"] == "ok")
    assert run_batch_cli(*argv) == 0  # the failed ones redone, whole
    assert len(job_files(out)) == 18 and {j["status"] for j in records(out)} <= {"ok", "skipped"}


# ---------------------------------------------------------------------------------------------
# Items 5 and 8: one batch per folder; workers die with their driver


def test_a_held_folder_refuses_a_second_lock_naming_its_holder(tmp_path: Path) -> None:
    lines: list[str] = []
    with folder_lock(tmp_path / "out", lines.append):
        with pytest.raises(EcsAnimError) as info, folder_lock(tmp_path / "out", lines.append):
            pass
    message = str(info.value)
    assert f"pid {os.getpid()} on host {socket.gethostname()}, started 20" in message
    assert "another batch is writing into it" in message and "\n" not in message
    assert lines == [] and not (tmp_path / "out" / LOCK_NAME).exists()  # released, removed


def hold_lock_as_orphan(folder: Path, seconds: float) -> subprocess.Popen[bytes]:
    """The lock of ``folder`` named after a driver that has ended and held by another process
    for ``seconds`` (as a killed batch's forked workers hold it until they follow it)."""
    folder.mkdir(parents=True, exist_ok=True)
    ended = subprocess.Popen([sys.executable, "-c", "pass"])
    ended.wait()
    (folder / LOCK_NAME).write_text(json.dumps({"pid": ended.pid, "host": socket.gethostname(),
                                                "started": "2026-12-07 05:00:00 UTC"}))
    holder = subprocess.Popen([sys.executable, "-c", textwrap.dedent(f"""
        import fcntl, os, sys, time
        fd = os.open({str(folder / LOCK_NAME)!r}, os.O_RDWR)
        fcntl.flock(fd, fcntl.LOCK_EX)
        print("held", flush=True)
        time.sleep({seconds})
        """)], stdout=subprocess.PIPE)
    assert holder.stdout is not None and holder.stdout.readline() == b"held\n"
    return holder


def test_a_killed_drivers_workers_are_waited_for_then_its_lock_taken_over(tmp_path: Path
                                                                          ) -> None:
    holder = hold_lock_as_orphan(tmp_path / "out", 0.5)
    lines: list[str] = []
    try:
        started = time.monotonic()
        with folder_lock(tmp_path / "out", lines.append):
            waited = time.monotonic() - started
            assert holder.poll() is not None  # (taken once the last holder had ended)
    finally:
        holder.kill()
        holder.wait()
    assert waited < 8.0
    assert len(lines) == 1 and "took over the lock of a batch that ended" in lines[0]
    assert "started 2026-12-07 05:00:00 UTC" in lines[0]


def test_workers_outliving_their_driver_too_long_are_named_in_one_line(tmp_path: Path,
                                                                       monkeypatch) -> None:
    monkeypatch.setattr("ecs_anim.apps.batch.folder_lock.ORPHANS_WAIT_S", 0.3)
    holder = hold_lock_as_orphan(tmp_path / "out", 30.0)
    try:
        with pytest.raises(EcsAnimError) as info, folder_lock(tmp_path / "out", print):
            pass
    finally:
        holder.kill()
        holder.wait()
    message = str(info.value)
    assert "the workers of a batch that was killed are still writing into it (pid " in message
    assert "wait for it to end, or give another folder" in message and "\n" not in message
    assert (tmp_path / "out" / LOCK_NAME).exists()  # (not ours: left as it was)


@linux_only
@pytest.mark.timeout(240)
def test_second_batch_refused_then_killed_driver_takes_its_workers_and_frees_the_folder(
        tmp_path: Path, compiled_kernels: None) -> None:
    """Batch A runs (a subprocess, its pool of 2): batch B into the same folder refuses in one
    line naming A (pid, host, start) and writes nothing. Then A's driver alone is SIGKILLed:
    its workers are gone within 2 s (PR_SET_PDEATHSIG), and batch C takes A's lock over,
    saying whose it was, and ends the work."""
    out = tmp_path / "out"
    # 30 s simulated a job (0.6 s of CPU on an idle machine), so A is still running when B and
    # the kill come, however fast the machine
    argv = [*clips(6), "--bodies", "child,adult_male,tall", "--seconds", "30.0", "--formats",
            "npz", "--out", str(out)]
    driver = start_driver(tmp_path, *argv, "--jobs", "2")
    try:
        wait_for(lambda: len(children(driver.pid)) == 2 and
                 len(list(out.glob(f"*/.*{STAMP_SUFFIX}"))) >= 1, 120, "A's first job")
        holder = json.loads((out / LOCK_NAME).read_text())
        assert holder["pid"] == driver.pid
        before = sorted(p.relative_to(out) for p in out.rglob("*") if not p.name.endswith(".tmp"))
        with pytest.raises(EcsAnimError) as info:
            run_batch_cli(*argv, "--jobs", "1", "--force")
        assert f"another batch is writing into it (pid {driver.pid} on host " \
               f"{socket.gethostname()}, started {holder['started']})" in str(info.value)
        workers = children(driver.pid)
        assert len(workers) == 2
        os.kill(driver.pid, signal.SIGKILL)  # the driver alone, not its group
        killed = time.monotonic()
        driver.wait()
        wait_for(lambda: not any(alive(w) for w in workers), 2.0, "the workers to die")
        print(f"workers gone {time.monotonic() - killed:.3f} s after the driver's SIGKILL")
    finally:
        if driver.poll() is None:
            os.killpg(driver.pid, signal.SIGKILL)
            driver.wait()
    after = sorted(p.relative_to(out) for p in out.rglob("*") if not p.name.endswith(".tmp"))
    assert set(before) <= set(after) | {Path(LOCK_NAME)}  # B wrote (and removed) nothing
    lines: list[str] = []

    class Lines:
        def write(self, text: str) -> None:
            lines.extend(t for t in text.splitlines() if t)

        def flush(self) -> None:
            pass

    from ecs_anim.apps.batch.command import plan_from_args
    from ecs_anim.apps.batch.driver import run_batch

    done = run_batch(plan_from_args(parse(*argv)), workers=2, stream=Lines())
    assert f"took over the lock of a batch that ended without releasing it (pid {driver.pid} " \
           f"on host {socket.gethostname()}, started {holder['started']})" in lines[0]
    assert len(done) == 18 and all(j["status"] in ("ok", "skipped") for j in done)
    assert not (out / LOCK_NAME).exists()


# ---------------------------------------------------------------------------------------------
# Item 6: never through a link


def test_a_redo_replaces_links_and_never_writes_through_them(tmp_path: Path) -> None:
    """Links where a job's file, its stamp or the batch's own files go are replaced by the
    files, the files they point to untouched; a clip folder that is a link fails its jobs in
    one line, the others go on; no job is listed ok with a file missing."""
    out = tmp_path / "out"
    walk, kick = str(MOTIONS_DIR / "walk.bvh"), str(MOTIONS_DIR / "kick.bvh")
    argv = (walk, kick, "--bodies", "child", "--out", str(out), "--seconds", "0.1", "--jobs",
            "1", "--formats", "npz")
    assert run_batch_cli(*argv) == 0
    precious = tmp_path / "precious"
    precious.write_bytes(b"not the batch's")
    for rel in ("walk/child.npz", "metrics.json", "report.html"):
        (out / rel).unlink()
        (out / rel).symlink_to(precious)
    assert run_batch_cli(*argv) == 0  # the link is no output: walk/child is redone
    assert precious.read_bytes() == b"not the batch's"
    assert [(j["clip"], j["status"]) for j in records(out)] == [("walk", "ok"), ("kick", "skipped")]
    assert not any((out / rel).is_symlink() for rel in ("walk/child.npz", "metrics.json",
                                                        "report.html"))
    (out / "walk/child.npz").unlink()
    (out / "walk/child.npz").symlink_to(precious)
    assert run_batch_cli(*argv, "--force") == 0
    assert precious.read_bytes() == b"not the batch's"
    assert not (out / "walk/child.npz").is_symlink() and (out / "walk/child.npz").stat().st_size > 100
    elsewhere = tmp_path / "elsewhere"
    (out / "kick").rename(elsewhere)
    (out / "kick").symlink_to(elsewhere)
    before = {p.name: p.read_bytes() for p in elsewhere.iterdir()}
    assert run_batch_cli(*argv, "--force") == 1
    jobs = records(out)
    assert [j["status"] for j in jobs] == ["ok", "failed"]
    assert jobs[1]["error"] == f"{out / 'kick'}: a symlink; a batch writes only inside its " \
                               "folder, never through a link (remove it)"
    assert {p.name: p.read_bytes() for p in elsewhere.iterdir()} == before
    assert all((out / rel).is_file() for j in jobs for rel in j["outputs"])


# ---------------------------------------------------------------------------------------------
# Item 12: a folder turned read-only fails only the jobs it hits; a template's triggers


def test_a_read_only_clip_folder_fails_only_its_jobs(tmp_path: Path, monkeypatch) -> None:
    """The folder of one clip turns read-only between two runs (made so by failing what a
    read-only folder fails: the write probe, making and deleting files there; the tests run as
    root, whom chmod does not stop): its jobs fail with the reason, the others are written, the
    metrics and report too; its earlier files stay whole."""
    out = tmp_path / "out"
    argv = (str(MOTIONS_DIR / "walk.bvh"), str(MOTIONS_DIR / "kick.bvh"), "--bodies",
            "child,tall", "--out", str(out), "--seconds", "0.1", "--jobs", "1", "--formats",
            "npz")
    assert run_batch_cli(*argv) == 0
    earlier = job_files(out)
    read_only = str(out / "walk")
    from ecs_anim.core import files

    real_probe, real_mkstemp, real_unlink = files.write_problem, tempfile.mkstemp, Path.unlink

    def refused(path: object) -> bool:
        return os.path.realpath(str(path)).startswith(read_only)

    def probe(folder):
        return "cannot write in it (Read-only file system)" if refused(folder) else real_probe(folder)

    def mkstemp(suffix=None, prefix=None, dir=None, text=False):
        if refused(dir):
            raise OSError(errno.EROFS, "Read-only file system")
        return real_mkstemp(suffix=suffix, prefix=prefix, dir=dir, text=text)

    def unlink(self, missing_ok=False):
        if refused(self.parent):
            raise OSError(errno.EROFS, "Read-only file system", str(self))
        return real_unlink(self, missing_ok=missing_ok)

    monkeypatch.setattr(files, "write_problem", probe)
    monkeypatch.setattr(tempfile, "mkstemp", mkstemp)
    monkeypatch.setattr(Path, "unlink", unlink)
    assert run_batch_cli(*argv, "--force") == 1
    monkeypatch.undo()
    jobs = records(out)
    assert [(j["clip"], j["status"]) for j in jobs] == \
        [("walk", "failed"), ("walk", "failed"), ("kick", "ok"), ("kick", "ok")]
    assert all("Read-only file system" in j["error"] and "\n" not in j["error"]
               for j in jobs[:2])
    now = job_files(out)
    assert {k: v for k, v in now.items() if k.startswith("walk/")} == \
        {k: v for k, v in earlier.items() if k.startswith("walk/")}
    assert (out / "report.html").is_file()


def test_a_template_with_triggers_is_refused_in_one_line(tmp_path: Path) -> None:
    template = tmp_path / "template.yaml"
    template.write_text(textwrap.dedent(f"""\
        duration_s: 0.5
        motions: {{idle: {MOTIONS_DIR}/idle.bvh, kick: {MOTIONS_DIR}/kick.bvh}}
        characters:
          - {{name: anyone, morphology: adult_male, motion: idle}}
        triggers:
          - {{when: {{at_s: 0.2}}, then: [{{play: anyone.kick}}]}}
        """))
    out = tmp_path / "out"
    with pytest.raises(EcsAnimError) as info:
        run_batch_cli(str(MOTIONS_DIR / "idle.bvh"), "--bodies", "child", "--template",
                      str(template), "--out", str(out))
    assert str(info.value) == f"{template}: a batch template's triggers: are not supported (a " \
                              "job plays one clip on one body); remove them"
    assert not out.exists()


# ---------------------------------------------------------------------------------------------
# Item 7: names are text wherever they are rendered


def test_dollar_signs_in_a_clip_name_are_text_in_the_report(tmp_path: Path) -> None:
    """``$...$`` would be math text to matplotlib (and ``$\\foo{$`` a parse error): the batch
    writes its report, the name shown as given and HTML-escaped."""
    name = "walk $\\frac{a<b}$ & $x^$"
    clip = tmp_path / f"{name}.bvh"
    clip.write_bytes((MOTIONS_DIR / "walk.bvh").read_bytes())
    out = tmp_path / "out"
    assert run_batch_cli(str(clip), "--bodies", "child", "--out", str(out), "--seconds", "0.2",
                         "--jobs", "1", "--formats", "npz") == 0
    page = (out / "report.html").read_text("utf-8")
    assert "walk $\\frac{a&lt;b}$ &amp; $x^$" in page and name not in page
