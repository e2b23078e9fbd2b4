"""Writing outputs safely: never over an existing file without ``force``, never half-written."""

from __future__ import annotations

import os
import tempfile
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import IO


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


def output_problem(path: str | Path, force: bool) -> str | None:
    """Why ``path`` cannot be written as an output file, or None: it is a folder or a device
    rather than a file, or it exists and ``force`` is not given. A link counts as what it
    points to (outputs are written through links)."""
    path = Path(path)
    if path.exists() and not path.is_file():
        return f"{path}: not a file (a folder or a device); give a file path"
    if path.exists() and not force:
        return f"{path}: already exists (use --force to overwrite)"
    for parent in path.parents:
        if parent.exists():
            if not parent.is_dir():
                return f"{path}: {parent} is a file, not a folder"
            break
    return None


def folder_problem(path: str | Path) -> str | None:
    """Why ``path`` cannot be used as an output folder, or None."""
    path = Path(path)
    if path.exists() and not path.is_dir():
        return f"{path}: not a folder"
    return None


@contextmanager
def atomic_output(path: str | Path, force: bool) -> Iterator[IO[bytes]]:
    """A binary file object whose content replaces ``path`` only when the block succeeds.

    Refuses (FileExistsError, saying why) an existing ``path`` unless ``force``, and a folder or
    a device whatever ``force``. A link is written through: the file it points to is
    replaced, the link stays. The temporary file lives in the target folder (so the final
    rename is atomic) and gets the usual permissions (0666 less the umask; ``mkstemp`` alone
    would leave 0600).
    """
    path = Path(path)
    if path.is_symlink():
        path = path.resolve()
    problem = output_problem(path, force)
    if problem is not None:
        raise FileExistsError(problem)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    try:
        os.fchmod(fd, 0o666 & ~_umask())
        with os.fdopen(fd, "wb") as f:
            yield f
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


def write_atomic(path: str | Path, force: bool, write: Callable[[IO[bytes]], object]) -> None:
    """Call ``write(file)`` inside :func:`atomic_output`."""
    with atomic_output(path, force) as f:
        write(f)
