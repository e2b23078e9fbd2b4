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


@contextmanager
def atomic_output(path: str | Path, force: bool) -> Iterator[IO[bytes]]:
    """A binary file object whose content replaces ``path`` only when the block succeeds.

    Refuses an existing ``path`` unless ``force`` (FileExistsError). The temporary file lives in
    the target folder (so the final rename is atomic) and gets the usual permissions (0666 less
    the umask; ``mkstemp`` alone would leave 0600).
    """
    path = Path(path)
    if path.exists() and not force:
        raise FileExistsError(f"{path}: already exists (use --force to overwrite)")
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
