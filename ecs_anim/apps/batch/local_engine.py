"""The local engines: every job in this process (``--jobs 1``), or a process pool that
survives a worker killed under it. Each yields (job, outcome) as jobs finish, in any order.
"""

from __future__ import annotations

import multiprocessing
import pickle
from collections.abc import Iterator
from concurrent.futures import FIRST_COMPLETED, Future, ProcessPoolExecutor, wait
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
_started: Any = None  # in a pool worker: the queue it tells which task it starts


def _set_started(queue: Any) -> None:
    """A pool worker's start: the queue it tells which task it starts; its kernels tick on one
    thread (the pool's processes share the cores, and a kernel thread spins between chunks)."""
    global _started
    _started = queue
    kernels.set_threads(1)


def _pool_task(key: str, function: Any, *args: Any) -> Any:
    """``function(*args)`` in a pool worker, saying first that task ``key`` started, so a worker
    that dies is matched with the task it ran."""
    _started.put(key)
    return function(*args)


def run_in_pool(work: WorkList, workers: int) -> Iterator[tuple[Job, Outcome]]:
    """A process pool of ``workers``: each clip imported once (a task), then its jobs as tasks
    given the motion. A worker that dies (SIGKILL, out of memory) breaks the pool: a new pool
    takes the unfinished tasks, those that were running each run alone first; one that kills
    its worker again, alone, fails (for an import, its clip's jobs) and the others go on."""
    from concurrent.futures.process import BrokenProcessPool

    methods = multiprocessing.get_all_start_methods()
    context = multiprocessing.get_context("fork" if "fork" in methods else "spawn")
    jobs = {job.stem: job for clip_jobs in work.values() for job in clip_jobs}
    imported: dict[str, Any] = {}
    todo: list[str] = [f"import:{clip}" for clip in work]  # task keys: import:<clip>, job:<stem>
    suspects: list[str] = []  # running when a pool broke: each runs alone next
    blind = 0  # pools that broke with no task running
    while todo or suspects:
        alone = suspects.pop(0) if suspects else None
        started = context.SimpleQueue()
        pool = ProcessPoolExecutor(max_workers=1 if alone else workers, mp_context=context,
                                   initializer=_set_started, initargs=(started,))
        tasks: dict[Future[Any], str] = {}
        began: list[str] = []  # keys the workers said they started, read as they come (a full
        broken = False         # pipe would block the workers)

        def read_started(started: Any = started, began: list[str] = began) -> None:
            try:
                while not started.empty():
                    began.append(started.get())
            except (OSError, EOFError, ValueError, pickle.UnpicklingError):
                pass  # a worker killed while it said so: what was read is what is known

        def submit(key: str, pool: ProcessPoolExecutor = pool,
                   tasks: dict[Future[Any], str] = tasks) -> None:
            nonlocal broken
            if broken:
                return
            name = key.split(":", 1)[1]
            try:
                if key.startswith("import:"):
                    future = pool.submit(_pool_task, key, import_task, name)
                else:
                    job = jobs[name]
                    future = pool.submit(_pool_task, key, job_task, job, imported[job.clip_path])
            except BrokenProcessPool:
                broken = True
                return
            tasks[future] = key

        try:
            for key in [alone] if alone else list(todo):
                submit(key)
            pending = set(tasks)
            while pending and not broken:
                done, pending = wait(pending, return_when=FIRST_COMPLETED)
                read_started()
                for future in done:
                    key = tasks[future]
                    name = key.split(":", 1)[1]
                    try:
                        result = future.result()
                    except BrokenProcessPool:
                        broken = True
                        continue
                    except Exception as exc:
                        result = (None, error_text(exc)) if key.startswith("import:") else \
                            Outcome(failed_record(jobs[name], error_text(exc)))
                    if key in todo:
                        todo.remove(key)
                    if key.startswith("job:"):
                        yield jobs[name], result
                        continue
                    imported[name] = result
                    for job in work[name]:
                        if result[0] is None:
                            yield job, Outcome(failed_record(job, result[1]))
                            continue
                        todo.append(f"job:{job.stem}")
                        if alone is None:  # a task run alone runs with nothing else
                            submit(todo[-1])
                            if not broken:
                                pending.add(next(reversed(tasks)))
        finally:
            pool.shutdown(wait=True, cancel_futures=True)
        if not broken:
            continue
        if alone is not None:  # it killed its worker again, running alone: it fails
            name = alone.split(":", 1)[1]
            if alone.startswith("import:"):
                for job in work[name]:
                    yield job, Outcome(failed_record(job, f"{name}: the import's {WORKER_DIED}"))
            else:
                yield jobs[name], Outcome(failed_record(jobs[name], WORKER_DIED))
            continue
        read_started()
        running = [key for key in dict.fromkeys(began) if key in todo]
        if not running:  # a worker died before its task began: the pool itself cannot work
            blind += 1
            if blind >= 3:
                for key in todo:
                    name = key.split(":", 1)[1]
                    for job in work[name] if key.startswith("import:") else [jobs[name]]:
                        yield job, Outcome(failed_record(job, f"{WORKER_DIED} before its task began"))
                return
        for key in running:
            todo.remove(key)
        suspects += running
