"""The batch's driver (:func:`run_batch`): many clips played on many bodies over many grounds.

A batch is the product clips x bodies x grounds (:mod:`.plan`). Each job plays one clip on one
body over one ground (:mod:`.jobs`) and writes ``DIR/<clip>/<body>[_<ground>].<format>``.

Who does what:

* the driver (this process) holds the batch folder's lock (:mod:`.folder_lock`: one batch at
  a time in a folder), plans the jobs, skips those already done (a stamp beside the
  outputs holds a content hash of clip, body, ground, template, formats and project version:
  :mod:`.job_hash`), and writes every file, each atomically
  (:func:`~ecs_anim.core.files.atomic_output`), the stamp last (:mod:`.job_outputs`): a job
  killed half-way has no stamp and is done again, so its outputs end whole; a job whose
  files cannot be written (a full disk, a folder turned read-only, a clip folder that is a
  link) fails alone;
* the workers (a local process pool, :mod:`.local_engine`, or Ray tasks, :mod:`.ray_engine`)
  import each clip once and run jobs; they return the files' bytes, so workers on other
  machines need no shared file system, and the local and Ray engines produce the same bytes
  from the same function.

Finally ``DIR/metrics.json``, ``DIR/metrics.csv`` (one row per job, the scalar fields of
:data:`~ecs_anim.apps.batch.metrics_files.CSV_FIELDS` then one ``constraint:<name>_mm`` column
per stored constraint: :mod:`.metrics_files`) and ``DIR/report.html``
(:func:`ecs_anim.apps.batch.report.write_report`).
"""

from __future__ import annotations

import hashlib
import json
import os
import sys
import time
from contextlib import suppress
from pathlib import Path
from typing import Any

from ecs_anim.apps.batch.folder_lock import LOCK_NAME, folder_lock
from ecs_anim.apps.batch.job_hash import job_digest, project_version, source_digest
from ecs_anim.apps.batch.job_outputs import (
    clear_outputs,
    commit_outputs,
    done_record,
    replace_link,
)
from ecs_anim.apps.batch.jobs import Outcome, WorkList, failed_record
from ecs_anim.apps.batch.local_engine import run_in_pool, run_in_process
from ecs_anim.apps.batch.metrics_files import write_metrics
from ecs_anim.apps.batch.plan import BATCH_MARKER, RESERVED, Job, Plan
from ecs_anim.apps.batch.progress import Progress
from ecs_anim.apps.batch.ray_engine import check_ray_address, run_on_ray
from ecs_anim.core.errors import EcsAnimError


def _check_folder(out: Path) -> None:
    """Refuse a batch folder that cannot be written or holds files no batch wrote."""
    from ecs_anim.core.files import folder_problem

    problem = folder_problem(out)
    if problem is not None:
        raise EcsAnimError(f"--out {problem}")
    # (a lock file alone: a batch just starting there, or killed before its marker)
    if out.is_dir() and not (out / BATCH_MARKER).is_file() and \
            any(entry.name != LOCK_NAME for entry in out.iterdir()):
        raise EcsAnimError(f"--out {out}: holds files ecs-anim batch did not write (no "
                           f"{BATCH_MARKER}); give a new or empty folder")


def _check_outputs(plan: Plan, jobs: list[Job]) -> None:
    """Refuse outputs (every format a job may write or delete, its stamp, the metrics and the
    report) that are one of the batch's inputs (by real path or, hard links, by inode)."""
    from ecs_anim.core.files import input_problem

    names = [rel for job in jobs for rel in (*job.all_outputs(), job.stamp)] + list(RESERVED)
    for rel in names:
        problem = input_problem(plan.out / rel, plan.inputs)
        if problem is not None:
            raise EcsAnimError(f"--out {problem.replace(' command', ' batch')}")


def _committed(out: Path, job: Job, outcome: Outcome, digest: str) -> Outcome:
    """Write a finished job's files, or clear a failed job's earlier ones; when that fails (a
    full disk, a folder turned read-only, a link), the job fails with the reason, alone."""
    try:
        commit_outputs(out, job, outcome, digest)
        return outcome
    except (EcsAnimError, OSError) as exc:
        problem = str(exc)
    record = outcome.record
    error = problem if record["status"] == "ok" else f"{record['error']} ({problem})"
    # where nothing can be deleted (read-only), the earlier files stay whole with their stamp
    with suppress(EcsAnimError):
        clear_outputs(out, job)
    return Outcome(failed_record(job, error, record["seconds"]))


def run_batch(plan: Plan, engine: str = "local", workers: int | None = None,
              address: str | None = None, force: bool = False,
              stream: Any = None) -> list[dict[str, Any]]:
    """Run a plan: hold its folder (:func:`~.folder_lock.folder_lock`: a second batch into it
    refuses), skip jobs done with the same inputs (unless ``force``), run the rest on
    ``engine`` (``local`` or ``ray``) with ``workers`` processes (default: every core), write
    each job's files, then the metrics and the report. Returns the records in plan order."""
    start = time.perf_counter()
    jobs = plan.jobs()
    _check_folder(plan.out)
    _check_outputs(plan, jobs)
    if engine == "ray":
        check_ray_address(address)
    with folder_lock(plan.out, lambda line: print(line, file=stream or sys.stderr, flush=True)):
        ordered = _run_jobs(plan, jobs, engine, workers, address, force, stream)
        write_metrics(plan.out, ordered, time.perf_counter() - start)
        from ecs_anim.apps.batch.report import write_report

        write_report(plan.out / "report.html", ordered)
    return ordered


def _run_jobs(plan: Plan, jobs: list[Job], engine: str, workers: int | None,
              address: str | None, force: bool, stream: Any) -> list[dict[str, Any]]:
    """The jobs of a held batch folder: each skipped or run and written; their records."""
    from ecs_anim.core.files import atomic_output

    version = f"{project_version()}+{source_digest()}"
    clip_digests = {str(c): hashlib.sha256(c.read_bytes()).hexdigest() for c in plan.clips}
    digests = {job.stem: job_digest(job, clip_digests[job.clip_path], version) for job in jobs}
    records: dict[str, dict[str, Any]] = {}
    work: WorkList = {}
    for job in jobs:
        earlier = None if force else done_record(plan.out, job, digests[job.stem])
        if earlier is not None:
            records[job.stem] = earlier | {"status": "skipped"}
        else:
            work.setdefault(job.clip_path, []).append(job)
    for name in (BATCH_MARKER, *RESERVED):  # the batch's own files, never written through links
        replace_link(plan.out / name)
    if not (plan.out / BATCH_MARKER).is_file():
        with atomic_output(plan.out / BATCH_MARKER, force=True) as f:
            f.write(json.dumps({"written_by": "ecs-anim batch",
                                "version": project_version()}).encode("utf-8"))
    n_work = sum(len(j) for j in work.values())
    workers = max(1, min(workers or os.cpu_count() or 1, max(n_work, 1)))
    progress = Progress(n_work, stream)
    if len(records):
        progress.write(f"{len(records)} of {len(jobs)} job(s) already done with the same inputs: "
                       "skipped (--force redoes them)")
    try:
        if engine == "ray":
            outcomes = run_on_ray(work, workers, address)
        elif workers == 1:
            outcomes = run_in_process(work)
        else:
            outcomes = run_in_pool(work, workers)
        for job, outcome in outcomes:
            outcome = _committed(plan.out, job, outcome, digests[job.stem])
            records[job.stem] = outcome.record
            progress.update(job.stem, outcome.record)
    finally:
        progress.close()
    return [records[job.stem] for job in jobs]
