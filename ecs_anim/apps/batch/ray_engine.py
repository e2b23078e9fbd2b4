"""The Ray engine (``--engine ray``): jobs as Ray tasks on a cluster or a local Ray, and
the quick check of ``--address`` before anything starts. Yields (job, outcome) as jobs finish.
"""

from __future__ import annotations

import logging
from collections.abc import Iterator
from typing import Any

from ecs_anim.apps.batch.jobs import Outcome, WorkList, failed_record, import_task, job_task
from ecs_anim.apps.batch.plan import Job
from ecs_anim.core.errors import EcsAnimError
from ecs_anim.motion.clip import NormalizedMotion
from ecs_anim.runtime import kernels


def _ray_job_task(job: Job, imported: tuple[NormalizedMotion | None, str]) -> Outcome:
    """:func:`~ecs_anim.apps.batch.jobs.job_task` in a Ray worker, which has one CPU: its
    kernels tick on one thread."""
    kernels.set_threads(1)
    return job_task(job, imported)


#: How long ``--address HOST:PORT`` may take to accept a TCP connection before it is unreachable.
RAY_CONNECT_TIMEOUT_S = 3.0


def check_ray_address(address: str | None) -> None:
    """Refuse, in one line and quickly, what ``ray.init`` would wait minutes on: Ray is not
    installed, ``ray://`` (Ray Client: the clips are imported on the driver's node, which with
    Ray Client is the head, not this machine), or a ``HOST:PORT`` that does not accept a TCP
    connection within :data:`RAY_CONNECT_TIMEOUT_S`. ``auto`` is left to Ray."""
    import importlib.util
    import socket

    if importlib.util.find_spec("ray") is None:
        raise EcsAnimError("--engine ray needs Ray: pip install 'ecs_anim[ray]'")
    if not address or address == "auto":
        return
    if "://" in address:
        raise EcsAnimError(f"--address {address}: Ray Client (ray://) is not supported; run the "
                           "command on a cluster node (--address auto) or give the head's "
                           "HOST:PORT (e.g. head:6379) from a machine in the cluster")
    host, sep, port = address.rpartition(":")
    if not sep or not host or not port.isdigit() or not 0 < int(port) < 65536:
        raise EcsAnimError(f"--address {address}: expected HOST:PORT (e.g. head:6379) or auto")
    try:
        with socket.create_connection((host.strip("[]"), int(port)), timeout=RAY_CONNECT_TIMEOUT_S):
            pass
    except OSError as exc:
        reason = "timed out" if isinstance(exc, TimeoutError) else (exc.strerror or str(exc))
        raise EcsAnimError(f"--address {address}: no Ray cluster reachable there ({reason} "
                           f"within {RAY_CONNECT_TIMEOUT_S:g} s)") from None


def run_on_ray(work: WorkList, workers: int, address: str | None) -> Iterator[tuple[Job, Outcome]]:
    """The jobs as Ray tasks on the cluster at ``address``, or on a local one of ``workers``
    CPUs started here (a Ray already initialized in this process is used as it is). Clips are
    imported on this machine's node (where the files are), once each; jobs run anywhere and
    return their bytes, which this process writes."""
    try:
        import ray
    except ImportError:
        raise EcsAnimError("--engine ray needs Ray: pip install 'ecs_anim[ray]'") from None
    started = not ray.is_initialized()
    if started:
        try:
            if address:
                ray.init(address=address, logging_level=logging.WARNING, log_to_driver=False)
            else:
                ray.init(num_cpus=workers, include_dashboard=False, logging_level=logging.WARNING,
                         log_to_driver=False)
        except (ConnectionError, RuntimeError, ValueError) as exc:
            where = f"at {address}" if address else "locally"
            raise EcsAnimError(f"--engine ray: cannot start or reach a Ray cluster {where}: "
                               f"{' '.join(str(exc).split())[:200]}") from None
    try:
        from ray.util.scheduling_strategies import NodeAffinitySchedulingStrategy

        here = NodeAffinitySchedulingStrategy(ray.get_runtime_context().get_node_id(), soft=False)
        import_remote = ray.remote(import_task).options(num_cpus=1, scheduling_strategy=here)
        job_remote = ray.remote(_ray_job_task).options(num_cpus=1)
        refs: dict[Any, Job] = {}
        for clip, jobs in work.items():
            imported = import_remote.remote(clip)  # one object, shared by the clip's jobs
            for job in jobs:
                refs[job_remote.remote(job, imported)] = job
        pending = list(refs)
        while pending:
            done, pending = ray.wait(pending, num_returns=1)
            for ref in done:
                job = refs.pop(ref)
                try:
                    yield job, ray.get(ref)
                except Exception as exc:
                    yield job, Outcome(failed_record(job, f"ray task failed: "
                                                          f"{' '.join(str(exc).split())[:200]}"))
    finally:
        if started:
            ray.shutdown()
