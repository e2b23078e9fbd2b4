"""A job's files in the batch folder, written whole or not at all: the stamp, written last,
marks a job done (with the hash of its inputs), so a job killed half-way is done again. Never
through a link: a link where a file of the batch goes is replaced, not followed, and a clip's
folder that is a link fails its jobs.
"""

from __future__ import annotations

import json
import stat
from pathlib import Path
from typing import Any

from ecs_anim.apps.batch.jobs import Outcome
from ecs_anim.apps.batch.plan import Job
from ecs_anim.core.errors import EcsAnimError


def replace_link(path: Path) -> None:
    """Remove ``path`` when it is a symlink, so that the write that follows replaces the link
    itself (:func:`~ecs_anim.core.files.atomic_output` writes through links) and never the file
    it points to, wherever that is."""
    if path.is_symlink():
        try:
            path.unlink()
        except OSError as exc:
            raise EcsAnimError(f"{path}: a symlink, which cannot be removed to write the file in "
                               f"its place ({exc.strerror or exc})") from None


def _is_regular_file(path: Path) -> bool:
    """Whether ``path`` is a file itself (not a link to one)."""
    try:
        return stat.S_ISREG(path.lstat().st_mode)
    except OSError:
        return False


def _check_clip_folder(out: Path, job: Job) -> None:
    """Refuse a job's folder (``DIR/<clip>``) that is a link: its files would land elsewhere."""
    folder = out / job.clip
    if folder.is_symlink():
        raise EcsAnimError(f"{folder}: a symlink; a batch writes only inside its folder, never "
                           "through a link (remove it)")


def done_record(out: Path, job: Job, digest: str) -> dict[str, Any] | None:
    """The record of an earlier run of ``job`` whose stamp has ``digest`` and whose outputs all
    exist, as files in the batch folder (not links), or None."""
    if (out / job.clip).is_symlink():
        return None
    try:
        stamp = json.loads((out / job.stamp).read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return None
    if not isinstance(stamp, dict) or stamp.get("digest") != digest:
        return None
    record = stamp.get("record")
    if not isinstance(record, dict) or record.get("outputs") != job.outputs():
        return None
    if not all(_is_regular_file(out / rel) for rel in job.outputs()):
        return None
    return record


def clear_outputs(out: Path, job: Job) -> None:
    """Delete a job's stamp, then its files in every format (a failed job leaves none, a job
    redone with other formats none of the others); links among them are removed, not followed."""
    _check_clip_folder(out, job)
    try:
        (out / job.stamp).unlink(missing_ok=True)
        for rel in job.all_outputs():
            (out / rel).unlink(missing_ok=True)
    except OSError as exc:
        raise EcsAnimError(f"{out / job.stem}: cannot delete an earlier run's files "
                           f"({exc.strerror or exc})") from None


def commit_outputs(out: Path, job: Job, outcome: Outcome, digest: str) -> None:
    """Write a finished job whole or not at all: every file goes to a temporary name first
    (:func:`~ecs_anim.core.files.atomic_output`, all open at once); then the stamp and the earlier
    run's files in every format are deleted, the new files renamed in, and the new stamp
    written last. A job counts as done only with its stamp, so a kill at any point leaves it to
    be redone, never with old and new files mixed. A link at one of its paths is replaced, and a
    clip folder that is a link refused (:class:`EcsAnimError`), before anything is written."""
    from contextlib import ExitStack

    from ecs_anim.core.files import atomic_output

    if outcome.record["status"] != "ok":
        clear_outputs(out, job)
        return
    _check_clip_folder(out, job)
    for rel in (*job.all_outputs(), job.stamp):
        replace_link(out / rel)
    with ExitStack() as files:
        for rel, data in outcome.files.items():
            # the batch's own file (the driver checked it is none of the batch's inputs)
            files.enter_context(atomic_output(out / rel, force=True)).write(data)
        clear_outputs(out, job)
    # leaving the block renamed every file in (or, when one failed, removed every temporary)
    with atomic_output(out / job.stamp, force=True) as f:
        f.write(json.dumps({"digest": digest, "record": outcome.record}, allow_nan=False,
                           indent=1).encode("utf-8"))
