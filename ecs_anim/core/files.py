"""Writing outputs safely: never over an existing file without ``force``, never over an input of
the same command, never half-written, and a set of files (a run's export folder) replaced as a
whole or not at all.

Temporary names carry the writer's process id, ``.NAME.<random>.ecs-anim-<pid>.tmp`` beside a
file and ``.DIR.partial-<pid>`` / ``.DIR.old-<pid>`` beside a folder, so that a later write
recognizes what a killed one left (its process is gone) and removes it, and touches nothing else.
"""

from __future__ import annotations

import ctypes
import errno
import json
import os
import re
import shutil
import stat
import sys
import tempfile
from collections.abc import Iterable, Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import IO

from ecs_anim.core.errors import EcsAnimError, InputError, listed, quoted

#: Written last into every export folder: the names of the files of the set, so that a later
#: ``--force`` knows which files it may replace (and refuses a folder holding anything else).
MANIFEST_NAME = ".ecs-anim-export.json"
#: Names that name files (characters, motions, bodies, grounds): no path separators, no leading
#: dot, at most :data:`MAX_NAME_LENGTH` characters.
NAME_PATTERN = re.compile(r"[A-Za-z0-9_\-][A-Za-z0-9_.\-]*")
MAX_NAME_LENGTH = 64


def read_text(path: str | Path) -> str:
    """The text of the input file at ``path`` (UTF-8, undecodable bytes replaced, a leading
    byte-order mark dropped), or :class:`InputError` saying why it cannot be read."""
    try:
        with open(path, encoding="utf-8", errors="replace") as f:
            return f.read().lstrip("\ufeff")
    except OSError as exc:
        raise InputError(str(path), f"cannot read file: {exc.strerror or exc}") from None


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


def _cannot_write(path: str | Path, exc: OSError) -> EcsAnimError:
    """The one-line error of a failed write, naming the output (never a temporary file)."""
    return EcsAnimError(f"{path}: cannot write: {exc.strerror or exc}")


def _loop_problem(path: str | Path) -> str | None:
    """``path: a symlink loop`` when following ``path`` (or a folder on the way) comes back to a
    link already followed, or None. ``Path.resolve()`` raises ``RuntimeError`` on a loop and
    ``exists()`` says False, so a loop would pass for a missing file until the write."""
    try:
        os.stat(path)
    except OSError as exc:
        if exc.errno == errno.ELOOP:
            return f"{path}: a symlink loop"
    except ValueError:  # a NUL in the name: the write says so
        pass
    return None


def _nearest_existing(folder: str | Path) -> Path:
    existing = Path(folder)
    while not existing.exists() and existing != existing.parent:
        existing = existing.parent
    return existing


#: The random part ``tempfile.mkstemp`` puts in a name (its ``_RandomNameSequence``).
_RANDOM_CHARS = 8


def _tmp_prefix(name: str) -> str:
    """The start of the temporary file's name beside the output file ``name``."""
    return f".{name}."


def _tmp_suffix() -> str:
    """The end of the temporary file's name beside an output file: it names this process."""
    return f".ecs-anim-{os.getpid()}.tmp"


def _aside(target: Path, kind: str) -> Path:
    """The hidden sibling of the export folder ``target`` (``partial`` or ``old``) this process
    uses."""
    return target.parent / f".{target.name}.{kind}-{os.getpid()}"


def _name_max(folder: Path) -> int:
    """The longest file name (in bytes) the file system of ``folder`` (or of the nearest folder
    above it that exists) allows; 255 where the system does not say."""
    try:
        limit = os.pathconf(_nearest_existing(folder), "PC_NAME_MAX")
    except (OSError, ValueError, AttributeError):  # AttributeError: no pathconf (Windows)
        return 255
    return limit if limit > 0 else 255


def _shown(path: str | Path) -> str:
    """``path`` as an error names it, the middle cut from a very long one so the reason fits
    in the line."""
    text = str(path)
    return text if len(text) <= 120 else f"{text[:80]}...{text[-30:]}"


def _name_length_problem(path: str | Path, longest: str, folder: Path) -> str | None:
    """Why the temporary name ``longest`` (the longest name a write of ``path`` makes in
    ``folder``) is too long for the file system there, or None. Found before any work: else a
    run ends in "File name too long" on a name the user never gave."""
    need, limit = len(os.fsencode(longest)), _name_max(folder)
    if need <= limit:
        return None
    return (f"{_shown(path)}: name too long: writing it takes a temporary name of {need} bytes "
            f"beside it, and this file system allows {limit}; shorten the name by {need - limit}")


def write_problem(folder: str | Path) -> str | None:
    """Why files cannot be made in ``folder`` (or, while it does not exist, in the nearest folder
    above it, where it would be made), or None. A real probe (a nameless temporary file made
    and dropped there): ``os.access`` says yes to root even on an immutable folder."""
    existing = _nearest_existing(folder)
    if not existing.is_dir():
        return f"{existing} is a file, not a folder"
    try:
        with tempfile.TemporaryFile(dir=existing):
            pass
    except OSError as exc:
        return f"cannot write in {os.path.realpath(existing)} ({exc.strerror or exc})"
    return None


def output_problem(path: str | Path, force: bool) -> str | None:
    """Why ``path`` cannot be written as an output file, or None: it is a folder or a device
    rather than a file, it exists and ``force`` is not given, it is a symlink loop, its folder
    cannot be written, or the temporary file's name would be too long there. A link counts as
    what it points to (outputs are written through links)."""
    path = Path(path)
    problem = _loop_problem(path)
    if problem is not None:
        return problem
    if path.exists() and not path.is_file():
        return f"{path}: not a file (a folder or a device); give a file path"
    if path.exists() and not force:
        return f"{path}: already exists (use --force to overwrite)"
    real = Path(os.path.realpath(path))
    problem = write_problem(real.parent)
    if problem is not None:
        return f"{path}: {problem}"
    longest = _tmp_prefix(real.name) + "x" * _RANDOM_CHARS + _tmp_suffix()
    return _name_length_problem(path, longest, real.parent)


def folder_problem(path: str | Path) -> str | None:
    """Why files cannot be written into the folder ``path``, or None."""
    path = Path(path)
    problem = _loop_problem(path)
    if problem is not None:
        return problem
    if path.exists() and not path.is_dir():
        return f"{path}: not a folder"
    problem = write_problem(path)
    return None if problem is None else f"{path}: {problem}"


def input_problem(output: str | Path, inputs: Iterable[str | Path],
                  folder: bool = False) -> str | None:
    """Why writing ``output`` would destroy one of the command's ``inputs``, or None: it is the
    same file by real path (links, ``./x`` against ``x``) or by inode (hard links), or, with
    ``folder`` (an output folder replaced as a whole), an input lies inside it."""
    real_output = os.path.realpath(output)
    inside = real_output.rstrip(os.sep) + os.sep
    for given in inputs:
        real = os.path.realpath(given)
        if folder and real.startswith(inside):
            return (f"{output}: holds {given}, an input of this command, and an export replaces "
                    "its whole folder; give another folder")
        if real == real_output or (os.path.exists(output) and os.path.exists(given)
                                   and os.path.samefile(output, given)):
            return f"{output}: is {given}, an input of this command; give another output"
    return None


def _process_alive(pid: int) -> bool:
    """Whether process ``pid`` runs (another user's counts). Our own id counts as gone: this
    process has not started the write whose leftovers are looked for, so an entry with its id
    was left by an earlier process that had the same id."""
    if pid == os.getpid():
        return False
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:  # another user's process
        pass
    return True


def _left_by_killed_writers(folder: Path, pattern: str) -> list[tuple[Path, re.Match[str]]]:
    """Entries of ``folder`` whose names match ``pattern`` (a regex with a group ``pid``) and
    whose writer process is gone, with the match."""
    try:
        names = os.listdir(folder)
    except OSError:
        return []
    found = []
    for name in names:
        match = re.fullmatch(pattern, name)
        if match and not _process_alive(int(match["pid"])):
            found.append((folder / name, match))
    return found


def _fsync(fd_or_file: int | IO[bytes]) -> None:
    if not isinstance(fd_or_file, int):
        fd_or_file.flush()
        fd_or_file = fd_or_file.fileno()
    os.fsync(fd_or_file)


def _fsync_folder(folder: Path) -> None:
    """Make the folder's renames durable (where the system allows opening a folder)."""
    try:
        fd = os.open(folder, os.O_RDONLY)
    except OSError:
        return
    try:
        _fsync(fd)
    finally:
        os.close(fd)


@contextmanager
def atomic_output(path: str | Path, force: bool) -> Iterator[IO[bytes]]:
    """A binary file object whose content replaces ``path`` only when the block succeeds.

    Refuses (FileExistsError, saying why) an existing ``path`` unless ``force``, and a folder or
    a device whatever ``force``; a failed write is an :class:`EcsAnimError` naming ``path``. A
    link is written through: the file it points to is replaced, the link stays. The temporary
    file lives in the target folder (so the final rename is atomic), gets the usual permissions
    (0666 less the umask; ``mkstemp`` alone would leave 0600), is removed when the block
    fails, and, when a killed process left one for the same ``path``, is removed by the next
    write.
    """
    problem = output_problem(path, force)
    if problem is not None:
        raise FileExistsError(problem)
    path = Path(path)
    if path.is_symlink():
        path = Path(os.path.realpath(path))
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        leftovers = re.escape(_tmp_prefix(path.name)) + r"\w+\.ecs-anim-(?P<pid>\d+)\.tmp"
        for leftover, _ in _left_by_killed_writers(path.parent, leftovers):
            leftover.unlink(missing_ok=True)
        fd, tmp = tempfile.mkstemp(prefix=_tmp_prefix(path.name), suffix=_tmp_suffix(),
                                   dir=path.parent)
    except OSError as exc:
        raise _cannot_write(path, exc) from None
    try:
        os.fchmod(fd, 0o666 & ~_umask())
        with os.fdopen(fd, "wb") as f:
            yield f
            _fsync(f)
        os.replace(tmp, path)
    except BaseException as exc:
        Path(tmp).unlink(missing_ok=True)
        if isinstance(exc, OSError):
            raise _cannot_write(path, exc) from None
        raise


def _manifest_names(folder: Path) -> set[str]:
    """The files an earlier export listed in ``folder``'s manifest (none if it has none or it is
    damaged: then nothing more is ours)."""
    try:
        names = json.loads((folder / MANIFEST_NAME).read_text(encoding="utf-8"))["files"]
    except (OSError, ValueError, KeyError, TypeError):
        return set()
    return {n for n in names if isinstance(n, str)} if isinstance(names, list) else set()


def output_folder_problem(path: str | Path, names: Iterable[str], force: bool) -> str | None:
    """Why the folder ``path`` cannot be replaced by a set of files called ``names`` (see
    :func:`output_set`), or None. The folder and its siblings are made in its parent, which
    must be writable, and the longest of them named there. An existing folder may be replaced
    only with ``force``, and only when it holds nothing but this set's names and what an
    earlier export's manifest lists (regular files): anything else is the user's, and is never
    deleted.

    What killed exports to the same folder left is dealt with first (see
    :func:`_recover_leftovers`): a set put aside and not yet replaced is back in ``path``
    before it is looked at, so it needs ``force`` like any earlier export."""
    path = Path(path)
    problem = _loop_problem(path)
    if problem is not None:
        return problem
    if path.exists() and not path.is_dir():
        return f"{path}: not a folder"
    real = Path(os.path.realpath(path))
    cwd = Path(os.path.realpath(os.getcwd()))
    if real == cwd or real in cwd.parents:
        return f"{path}: is (or holds) the current folder, and an export replaces its folder"
    problem = write_problem(real.parent)
    if problem is not None:
        return f"{path}: {problem}"
    problem = _name_length_problem(path, _aside(real, "partial").name, real.parent)
    if problem is not None:
        return problem
    try:
        _recover_leftovers(real)
    except OSError as exc:
        return f"{path}: cannot put back what a killed export left ({exc.strerror or exc})"
    if not real.exists():
        return None
    ours = set(names) | _manifest_names(real) | {MANIFEST_NAME}
    entries = sorted(os.listdir(real))
    foreign = [e for e in entries
               if e not in ours or (real / e).is_symlink() or not (real / e).is_file()]
    if foreign:
        return (f"{path}: holds files ecs-anim did not write ({listed(map(quoted, foreign), 4)}); an export "
                "replaces its whole folder, so give a new or empty folder")
    if entries and not force:
        return f"{path}: holds an earlier export (use --force to replace it)"
    return None


class OutputSet:
    """The files of one export, written into a hidden sibling of the target folder (see
    :func:`output_set`)."""

    def __init__(self, target: Path, partial: Path):
        self.target = target
        self.partial = partial
        self.names: list[str] = []

    @contextmanager
    def file(self, name: str) -> Iterator[IO[bytes]]:
        """A new binary file ``name`` of the set, flushed to disk when the block ends."""
        try:
            with open(self.partial / name, "xb") as f:
                yield f
                _fsync(f)
        except OSError as exc:
            raise _cannot_write(self.target / name, exc) from None
        self.names.append(name)


def _exchange(a: Path, b: Path) -> bool:
    """Swap two paths in one atomic step (Linux ``renameat2(RENAME_EXCHANGE)``); False where the
    system or the file system cannot."""
    renameat2 = getattr(ctypes.CDLL(None, use_errno=True), "renameat2", None) \
        if sys.platform.startswith("linux") else None
    if renameat2 is None:
        return False
    at_cwd, rename_exchange = -100, 2
    if renameat2(at_cwd, os.fsencode(a), at_cwd, os.fsencode(b), rename_exchange) == 0:
        return True
    code = ctypes.get_errno()
    if code in (errno.EINVAL, errno.ENOSYS, errno.EOPNOTSUPP):
        return False
    raise OSError(code, os.strerror(code), str(b))


def _put_back_or_remove(leftover: Path, kind: str, target: Path) -> None:
    """A killed or failed export's leftover: an ``old`` folder is the previous set, moved aside
    just before the new one was renamed in; it goes back when the target is missing (the
    process stopped between the two renames). Anything else is removed."""
    if not leftover.is_dir() or leftover.is_symlink():
        return
    if kind == "old" and not target.exists():
        os.rename(leftover, target)
    else:
        shutil.rmtree(leftover)


def _recover_leftovers(target: Path) -> None:
    """Put back or remove what killed exports to the folder ``target`` (a real path) left
    beside it: an earlier set put aside while the folder is missing goes back (see
    :func:`_put_back_or_remove`), the rest is removed. Leftovers of running exports stay."""
    leftovers = re.escape(f".{target.name}.") + r"(?P<kind>partial|old)-(?P<pid>\d+)"
    for leftover, match in _left_by_killed_writers(target.parent, leftovers):
        _put_back_or_remove(leftover, match["kind"], target)


@contextmanager
def output_set(path: str | Path, names: Iterable[str], force: bool) -> Iterator[OutputSet]:
    """A set of files called ``names`` that replaces the folder ``path`` as a whole when the
    block succeeds, and leaves it untouched otherwise. Refuses (:class:`EcsAnimError`) what
    :func:`output_folder_problem` refuses.

    The files go into ``.NAME.partial-<pid>`` beside the folder, each flushed to disk; then the
    manifest (:data:`MANIFEST_NAME`); then the new folder and the old one are exchanged in one
    atomic rename (on Linux; elsewhere the old one is first renamed ``.NAME.old-<pid>``, and put
    back by the next export if the process stopped in between), and the old one is deleted. A
    link to a folder stays and points to the new set. Leftovers of killed exports to the same
    folder are put back or removed first, by the check (:func:`output_folder_problem`), so a
    set put back is checked like any other; a failed write removes its own. Yields an
    :class:`OutputSet`.
    """
    problem = output_folder_problem(path, names, force)
    if problem is not None:
        raise EcsAnimError(problem)
    target = Path(os.path.realpath(path))
    partial, old = _aside(target, "partial"), _aside(target, "old")
    try:
        target.parent.mkdir(parents=True, exist_ok=True)
        partial.mkdir()
        if target.is_dir():
            os.chmod(partial, stat.S_IMODE(target.stat().st_mode))
    except OSError as exc:
        raise _cannot_write(path, exc) from None
    try:
        files = OutputSet(target, partial)
        yield files
        manifest = {"written_by": "ecs-anim", "files": files.names}
        with files.file(MANIFEST_NAME) as f:
            f.write(json.dumps(manifest, indent=2).encode("utf-8"))
        _fsync_folder(partial)
        if not target.exists():
            os.rename(partial, target)
        elif _exchange(partial, target):
            shutil.rmtree(partial)
        else:
            os.rename(target, old)
            os.rename(partial, target)
            shutil.rmtree(old)
        _fsync_folder(target.parent)
    except BaseException as exc:
        for leftover, kind in ((old, "old"), (partial, "partial")):
            if leftover.exists():
                _put_back_or_remove(leftover, kind, target)
        if isinstance(exc, OSError):
            raise _cannot_write(path, exc) from None
        raise
