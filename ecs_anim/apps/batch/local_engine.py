"""The local engines: every job in this process (``--jobs 1``), or a pool of worker processes
that survives a worker killed under it and dies with its driver. Each yields (job, outcome) as
jobs finish, in any order.

The pool shares nothing a dying process could leave locked: each worker has its own pipe, on
which the driver sends it one task at a time and reads its result, so a worker killed at any
moment (even half-way through reading a task, or writing its result) breaks only its own pipe,
and the driver knows which task it held. Workers die with the driver: on Linux the kernel kills
them when it goes (``PR_SET_PDEATHSIG``), elsewhere a thread in each watches the driver's id.
"""

from __future__ import annotations

import multiprocessing
import os
import signal
import sys
import threading
import time
from collections import deque
from collections.abc import Callable, Iterator
from multiprocessing.connection import Connection, wait
from typing import Any

from ecs_anim.apps.batch.jobs import (
    Outcome,
    WorkList,
    error_text,
    failed_record,
    import_task,
    job_task,
)
from ecs_anim.apps.batch.plan import Job
from ecs_anim.runtime import kernels


def run_in_process(work: WorkList) -> Iterator[tuple[Job, Outcome]]:
    """``--jobs 1``: everything in this process (no pool, nothing pickled)."""
    for clip, jobs in work.items():
        imported = import_task(clip)
        for job in jobs:
            yield job, job_task(job, imported)


#: Why a job failed whose worker process died under it (and again when it ran alone).
WORKER_DIED = "its worker process died (killed by a signal, or out of memory)"
#: Where the kernel cannot kill a worker with its driver, how often a worker looks for it.
DRIVER_WATCH_S = 0.5


def _die_with_driver(driver_pid: int) -> None:
    """End this worker when the driver ``driver_pid`` ends, however it ends (SIGKILL included):
    on Linux the kernel sends SIGKILL when the parent goes (``prctl(PR_SET_PDEATHSIG)``), else a
    daemon thread checks the parent's id every :data:`DRIVER_WATCH_S`. A driver already gone
    before this ran is caught by the same check, done once first."""
    if os.getppid() != driver_pid:
        os._exit(1)
    if sys.platform.startswith("linux"):
        import ctypes

        pr_set_pdeathsig = 1
        libc = ctypes.CDLL(None, use_errno=True)
        if libc.prctl(pr_set_pdeathsig, signal.SIGKILL, 0, 0, 0) == 0:
            if os.getppid() != driver_pid:  # it went between the check and the prctl
                os._exit(1)
            return

    def watch() -> None:
        while os.getppid() == driver_pid:
            time.sleep(DRIVER_WATCH_S)
        os._exit(1)

    threading.Thread(target=watch, name="driver-watch", daemon=True).start()


def _serve(conn: Connection, driver_pid: int, others: list[Connection]) -> None:
    """A pool worker: runs each ``(function, args)`` it reads on ``conn`` and writes back
    ``(result, "")`` or ``(None, error line)``, until ``None`` or the driver's end closes.
    ``others`` are the driver's ends of earlier workers' pipes, inherited by the fork: closed,
    so only the driver holds them. Ctrl-C is the driver's to handle (it ends the pool); the
    kernels tick on one thread (the pool's processes share the cores, and a kernel thread
    spins between chunks)."""
    for other in others:
        other.close()
    _die_with_driver(driver_pid)
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    kernels.set_threads(1)
    while True:
        try:
            task = conn.recv()
        except (EOFError, OSError):
            return
        if task is None:
            return
        function, args = task
        try:
            reply = (function(*args), "")
        except Exception as exc:
            reply = (None, error_text(exc))
        conn.send(reply)


class _Worker:
    """A pool process, the driver's end of its pipe, and the key of the task it runs (or None)."""

    def __init__(self, context: Any, others: list[Connection]):
        self.conn, child = context.Pipe()
        self.process = context.Process(target=_serve, args=(child, os.getpid(), others),
                                       daemon=True, name="ecs-anim-batch-worker")
        self.process.start()
        child.close()  # the worker's end lives in the worker only: its death closes the pipe
        self.task: str | None = None

    def give(self, key: str, function: Callable[..., Any], *args: Any) -> None:
        """Send it a task. A worker that dies before it has the whole task breaks the pipe:
        that is seen, as any death, when its result is read."""
        self.task = key
        try:
            self.conn.send((function, args))
        except OSError:
            pass

    def stop(self) -> None:
        """End it now (a worker holds nothing of the batch's but its task) and reap it."""
        self.conn.close()
        if self.process.is_alive():
            self.process.kill()
        self.process.join()


def run_in_pool(work: WorkList, workers: int) -> Iterator[tuple[Job, Outcome]]:
    """A pool of ``workers`` processes: each clip imported once (a task), then its jobs as
    tasks given the motion, each task sent to an idle worker. A task whose worker dies (SIGKILL,
    out of memory) runs again alone once the others running have finished (it may have died of
    their memory); when it kills its worker again it fails (an import: its clip's jobs). The
    other tasks go on, a new worker in the dead one's place."""
    methods = multiprocessing.get_all_start_methods()
    context = multiprocessing.get_context("fork" if "fork" in methods else "spawn")
    jobs = {job.stem: job for clip_jobs in work.values() for job in clip_jobs}
    imported: dict[str, Any] = {}
    todo: deque[str] = deque(f"import:{clip}" for clip in work)  # import:<clip>, job:<stem>
    suspects: deque[str] = deque()  # their worker died under them: each runs again alone
    retrying: str | None = None  # the suspect running alone now
    pool: list[_Worker] = []

    def send(key: str) -> None:
        for gone in [w for w in pool if w.task is None and not w.process.is_alive()]:
            gone.stop()  # killed while idle: it held no task
            pool.remove(gone)
        worker = next((w for w in pool if w.task is None), None)
        if worker is None:
            worker = _Worker(context, [w.conn for w in pool])
            pool.append(worker)
        kind, name = key.split(":", 1)
        if kind == "import":
            worker.give(key, import_task, name)
        else:
            worker.give(key, job_task, jobs[name], imported[jobs[name].clip_path])

    try:
        while todo or suspects or any(w.task for w in pool):
            busy = [w for w in pool if w.task]
            if suspects and not busy:
                retrying = suspects.popleft()
                send(retrying)
            elif not suspects and retrying is None:
                for _ in range(min(len(todo), workers - len(busy))):
                    send(todo.popleft())
            busy = [w for w in pool if w.task]
            ready = wait([w.conn for w in busy] + [w.process.sentinel for w in busy])
            for worker in busy:
                if worker.conn not in ready and worker.process.sentinel not in ready:
                    continue
                key = worker.task
                assert key is not None
                try:
                    result, error = worker.conn.recv()
                except (EOFError, OSError):  # it died (a result half-written is no result)
                    worker.stop()
                    pool.remove(worker)
                    if key == retrying:
                        retrying = None
                        yield from _failed(key, work, jobs)
                    else:
                        suspects.append(key)
                    continue
                worker.task = None
                if key == retrying:
                    retrying = None
                yield from _finished(key, result, error, work, jobs, imported, todo)
    finally:
        for worker in pool:
            worker.stop()


def _finished(key: str, result: Any, error: str, work: WorkList, jobs: dict[str, Job],
              imported: dict[str, Any], todo: deque[str]) -> Iterator[tuple[Job, Outcome]]:
    """What a finished task gives: a job's outcome, or an import's motion (its clip's jobs
    queued; or, when the import failed, those jobs failed with its error)."""
    kind, name = key.split(":", 1)
    if kind == "job":
        yield jobs[name], result if error == "" else Outcome(failed_record(jobs[name], error))
        return
    motion, why = result if error == "" else (None, error)
    imported[name] = (motion, why)
    for job in work[name]:
        if motion is None:
            yield job, Outcome(failed_record(job, why))
        else:
            todo.append(f"job:{job.stem}")


def _failed(key: str, work: WorkList, jobs: dict[str, Job]) -> Iterator[tuple[Job, Outcome]]:
    """A task that killed its worker again, running alone: it fails (an import, its clip's
    jobs)."""
    kind, name = key.split(":", 1)
    if kind == "job":
        yield jobs[name], Outcome(failed_record(jobs[name], WORKER_DIED))
        return
    for job in work[name]:
        yield job, Outcome(failed_record(job, f"{name}: its import failed: {WORKER_DIED}"))
