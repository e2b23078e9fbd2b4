"""Content hashes: a job's inputs (:func:`job_digest`, what its stamp holds) and the code
that runs it (the project version and :func:`source_digest`). Equal hashes mean equal outputs.
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from ecs_anim.apps.batch.plan import Job


def project_version() -> str:
    """The installed ecs_anim version (written into metrics.json and the batch marker)."""
    from importlib.metadata import PackageNotFoundError, version

    try:
        return version("ecs_anim")
    except PackageNotFoundError:
        return "0+unknown"


_SOURCE_DIGEST: str | None = None


def source_digest() -> str:
    """A hash of the package's own source files (every ``.py`` of ``ecs_anim`` and of the
    ``ecs_anim.components`` and ``ecs_anim.systems`` packages, wherever they are installed
    from), computed once per process: part of every job's hash, so a code change redoes jobs
    even when the version string stays."""
    global _SOURCE_DIGEST
    if _SOURCE_DIGEST is None:
        import importlib

        digest = hashlib.sha256()
        for name in ("ecs_anim", "ecs_anim.components", "ecs_anim.systems"):
            module = importlib.import_module(name)
            folder = Path(module.__file__ or "").resolve().parent
            files = sorted(folder.rglob("*.py"))
            for path in files:
                digest.update(f"{name}/{path.relative_to(folder)}".encode() + b"\0")
                digest.update(hashlib.sha256(path.read_bytes()).digest())
        _SOURCE_DIGEST = digest.hexdigest()
    return _SOURCE_DIGEST


def _canonical(value: Any) -> Any:
    """``value`` as JSON-able data that two equal inputs map to identically: dataclasses by
    type and fields, arrays by dtype, shape and a hash of their bytes, floats exactly."""
    if dataclasses.is_dataclass(value) and not isinstance(value, type):
        return [type(value).__name__, {f.name: _canonical(getattr(value, f.name))
                                       for f in dataclasses.fields(value)}]
    if isinstance(value, np.ndarray):
        data = np.ascontiguousarray(value)
        return ["array", str(data.dtype), list(data.shape), hashlib.sha256(data.tobytes()).hexdigest()]
    if isinstance(value, dict):
        return {str(k): _canonical(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_canonical(v) for v in value]
    if isinstance(value, (float, np.floating)):
        return float(value).hex()
    if isinstance(value, (np.integer, np.bool_)):
        return value.item()
    return value


def files_digest(paths: Sequence[str | Path]) -> str:
    digest = hashlib.sha256()
    for path in paths:
        digest.update(hashlib.sha256(Path(path).read_bytes()).digest())
    return digest.hexdigest()


def job_digest(job: Job, clip_digest: str, version: str) -> str:
    """The hash a job's stamp holds: its clip's bytes, body, ground, template, formats, length,
    rig and ``version`` (the project version and :func:`source_digest`). Equal hashes mean
    equal outputs."""
    data = {"version": version, "clip": clip_digest, "body": _canonical(job.body),
            "ground": _canonical(job.ground), "formats": list(job.formats),
            "seconds": _canonical(job.seconds),
            "template": None if job.template is None else job.template.digest,
            "onto": None if job.onto is None else job.onto.digest}
    return hashlib.sha256(json.dumps(data, sort_keys=True).encode("utf-8")).hexdigest()
