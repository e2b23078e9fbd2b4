"""One batch at a time in a batch folder: a lock file in it, held (``flock``) for the whole run
and naming its holder, so a second batch into the same folder refuses in one line instead of
mixing its files with the first's.

The kernel releases the lock when its holder's process ends, however it ends, so a lock left
by a killed batch is free: the next batch takes it over and says whose it was. (A killed
driver's pool workers, forked with its descriptor, hold the lock until they follow it, within
seconds: a batch that finds the named driver gone waits for them.)
"""

from __future__ import annotations

import errno
import fcntl
import json
import os
import socket
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager, suppress
from pathlib import Path

from ecs_anim.core.errors import EcsAnimError

#: The lock file in a batch folder (hidden; removed when its batch ends).
LOCK_NAME = ".ecs-anim-batch.lock"
#: How long a holder that has just taken the lock may take to write its name into it.
NAMING_WAIT_S = 1.0
#: How long the pool workers of a driver that is gone may take to follow it (they are told to
#: end when it dies: ``PR_SET_PDEATHSIG``) and so free the lock they inherited.
ORPHANS_WAIT_S = 10.0


def _holder(fd: int) -> tuple[int, str, str] | None:
    """The holder the lock file ``fd`` names: (pid, host, start time), or None."""
    try:
        holder = json.loads(os.pread(fd, 4096, 0).decode("utf-8"))
        return int(holder["pid"]), str(holder["host"]), str(holder["started"])
    except (OSError, ValueError, KeyError, TypeError):
        return None


def _holder_text(fd: int) -> str:
    """The holder the lock file ``fd`` names (``pid 12 on host h, started 2026-...``), or ""."""
    holder = _holder(fd)
    return f"pid {holder[0]} on host {holder[1]}, started {holder[2]}" if holder else ""


def _gone(holder: tuple[int, str, str] | None) -> bool:
    """Whether ``holder`` is a process of this host that has ended."""
    if holder is None or holder[1] != socket.gethostname():
        return False
    try:
        os.kill(holder[0], 0)
    except ProcessLookupError:
        return True
    except OSError:  # (alive, another user's)
        return False
    return False


def _lock_when_orphans_end(fd: int) -> bool:
    """Lock ``fd``, whose named holder has ended, once its pool workers have followed it
    (within :data:`ORPHANS_WAIT_S`); False if they still hold it then."""
    deadline = time.monotonic() + ORPHANS_WAIT_S
    while time.monotonic() < deadline:
        time.sleep(0.05)
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
            return True
        except BlockingIOError:
            continue
    return False


def _write_holder(fd: int) -> None:
    """Name this process in the lock file ``fd``: pid, host and start time (UTC)."""
    holder = {"pid": os.getpid(), "host": socket.gethostname(),
              "started": time.strftime("%Y-%m-%d %H:%M:%S UTC", time.gmtime())}
    os.ftruncate(fd, 0)
    os.pwrite(fd, json.dumps(holder).encode("utf-8"), 0)
    os.fsync(fd)


def _open_locked(path: Path) -> tuple[int, str] | None:
    """The lock file ``path`` opened (never through a link) and locked, with the holder it
    named before (a batch that ended without removing it); None when it was removed or
    replaced before it was locked (its holder ended: try again). Refuses a held lock."""
    flags = os.O_RDWR | os.O_CREAT | os.O_NOFOLLOW | getattr(os, "O_CLOEXEC", 0)
    try:
        fd = os.open(path, flags, 0o644)
    except OSError as exc:
        reason = "a symlink" if exc.errno == errno.ELOOP else exc.strerror or str(exc)
        raise EcsAnimError(f"{path}: cannot open the batch folder's lock ({reason})") from None
    try:
        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except BlockingIOError:
        deadline = time.monotonic() + NAMING_WAIT_S
        while not (holder := _holder_text(fd)) and time.monotonic() < deadline:
            time.sleep(0.05)
        orphans = _gone(_holder(fd))
        if not (orphans and _lock_when_orphans_end(fd)):
            os.close(fd)
            who = ("the workers of a batch that was killed are still writing into it "
                   f"({holder})" if orphans else
                   f"another batch is writing into it ({holder or 'a batch starting now'})")
            raise EcsAnimError(f"--out {path.parent}: {who}; wait for it to end, or give "
                               "another folder") from None
    except OSError as exc:
        os.close(fd)
        raise EcsAnimError(f"{path}: cannot lock the batch folder ({exc.strerror or exc})") from None
    try:
        same = os.stat(path, follow_symlinks=False).st_ino == os.fstat(fd).st_ino
    except FileNotFoundError:
        same = False
    if not same:
        os.close(fd)
        return None
    return fd, _holder_text(fd)


@contextmanager
def folder_lock(out: Path, say: Callable[[str], None]) -> Iterator[None]:
    """Hold the batch folder ``out`` (made if missing) for the block: refuses in one line,
    naming the holder (pid, host, start time), when another batch holds it; takes over,
    saying so through ``say``, a lock whose batch was killed. The lock file is removed when
    the block ends."""
    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise EcsAnimError(f"--out {out}: cannot make the folder ({exc.strerror or exc})") from None
    path = out / LOCK_NAME
    while (opened := _open_locked(path)) is None:
        pass
    fd, earlier = opened
    try:
        if earlier:
            say(f"--out {out}: took over the lock of a batch that ended without releasing it "
                f"({earlier})")
        _write_holder(fd)
        yield
    finally:
        # removed before the lock goes, so a batch waiting on this file opens a new one; in a
        # folder turned read-only the file stays, and the next batch takes it over
        with suppress(OSError):
            path.unlink(missing_ok=True)
        os.close(fd)
