"""The tick's compiled kernels (numba, DESIGN §7): one module per system, over the store's arrays.

Each kernel writes its results in place and mirrors a numpy function of the package, which stays
as the reference the tests compare it with (to 1e-9 m). ``vec`` holds the scalar helpers they
share (3-vectors as tuples, frames as tuples of their three axes) and :data:`~.vec.jit`, the
decorator of every kernel: compiled without numba's runtime, so a kernel allocates nothing and
its caller passes every array it writes, scratch included.

The kernels over characters are compiled ``nogil`` and take a range ``lo, hi`` of their loop's
indices; :func:`over_chunks` runs one over all of them, split into contiguous chunks on
:func:`threads` threads of this process (numba's ``parallel=True`` with ``prange``, used before,
made the first compile half as long again).

Compiled code is cached in the user's cache folder (``$XDG_CACHE_HOME/ecs_anim/numba``, else
``~/.cache/ecs_anim/numba``) unless ``NUMBA_CACHE_DIR`` says where. A simulation being built
has every kernel put in memory (:func:`load_kernels`): the first run compiles them there (the
solver in a second process: :func:`compile_solver_aside`; figures in docs/performance.md),
later ones load them in about half a second. numba is imported only then
(:func:`ecs_anim.runtime.kernels.vec.with_numba`, which registers the locator that says where the
cache is, :func:`cache_kernels_in_cache_dir`, before any kernel is compiled).
"""

from __future__ import annotations

import atexit
import logging
import os
import subprocess
import sys
import threading
import time
from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING, Any

from ecs_anim.core.errors import UsageError
from ecs_anim.runtime.kernels.vec import on_numba_import

if TYPE_CHECKING:
    from ecs_anim.runtime.kernels.handover import SpinningThreads


def cache_dir() -> Path:
    """Where numba keeps the compiled kernels."""
    given = os.environ.get("NUMBA_CACHE_DIR")
    if given:
        return Path(given)
    base = Path(os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache")
    return base / "ecs_anim" / "numba"


def cache_kernels_in_cache_dir() -> None:
    """Have numba cache this package's kernels in :func:`cache_dir` (and only them: numba's
    other users keep their own settings, and no environment variable is set). A locator class
    put first in numba's list answers for the functions of this folder alone. Called by
    :func:`ecs_anim.runtime.kernels.vec.with_numba` as numba is imported, before any kernel
    is compiled."""
    from numba.core import caching

    impl = vars(caching).get("CacheImpl") or vars(caching)["_CacheImpl"]  # older numba: _CacheImpl
    if any(getattr(c, "ECS_ANIM_KERNELS", False) for c in impl._locator_classes):
        return

    class KernelCacheLocator(caching._SourceFileBackedLocatorMixin, caching._CacheLocator):
        ECS_ANIM_KERNELS = True

        def __init__(self, py_func: Callable[..., object], py_file: str) -> None:
            self._py_file = py_file
            self._lineno = py_func.__code__.co_firstlineno
            subpath = self.get_suitable_cache_subpath(py_file)  # type: ignore[no-untyped-call]
            self._cache_path = str(cache_dir() / subpath)

        def get_cache_path(self) -> str:
            return self._cache_path

        @classmethod
        def from_function(cls, py_func: Callable[..., object], py_file: str) -> object:
            if Path(py_file).resolve().parent != Path(__file__).resolve().parent:
                return None
            return super().from_function(py_func, py_file)  # type: ignore[no-untyped-call]

    impl._locator_classes.insert(0, KernelCacheLocator)


on_numba_import(cache_kernels_in_cache_dir)


def kernel_sources() -> list[Path]:
    """The modules of this package whose functions numba compiles (``vec.py``, ``decode.py``,
    ...), sorted."""
    here = Path(__file__).resolve().parent
    return sorted(p for p in here.glob("*.py") if p.name not in ("__init__.py", "__main__.py"))


def _cache_subfolder() -> Path:
    """The folder numba writes this package's compiled code into: ``<cache>/kernels_<sha1 of the
    package folder>`` (numba's ``_CacheLocator.get_suitable_cache_subpath``)."""
    import hashlib

    here = str(Path(__file__).resolve().parent)
    return cache_dir() / f"kernels_{hashlib.sha1(here.encode()).hexdigest()}"


def sources_digest() -> str:
    """sha256 of every kernel module's source together (hex)."""
    import hashlib

    digest = hashlib.sha256()
    for source in kernel_sources():
        digest.update(source.name.encode() + b"\0" + source.read_bytes())
    return digest.hexdigest()


#: The file in the cache folder naming the kernel sources its compiled code was made from.
SOURCES_MARKER = "ecs_anim_sources.sha256"


def drop_stale_cache() -> bool:
    """Delete this package's compiled code if any kernel module changed since it was compiled.

    numba checks only the source file of each compiled function, not the helpers of other
    modules compiled into it (a kernel of ``solve.py`` inlines ``vec.py``'s): after an update
    that changed only ``vec.py``, the old code would run. So the cache is kept only for the same
    sources, all of them, as a marker file records. Returns whether anything was dropped."""
    folder = _cache_subfolder()
    marker = folder / SOURCES_MARKER
    digest = sources_digest()
    try:
        if marker.read_text().strip() == digest:
            return False
    except OSError:
        pass
    dropped = False
    try:
        folder.mkdir(parents=True, exist_ok=True)
        for stale in list(folder.glob("*.nbi")) + list(folder.glob("*.nbc")):
            stale.unlink(missing_ok=True)
            dropped = True
        marker.write_text(digest + "\n")
    except OSError:  # a read-only cache: numba then compiles in memory, as without a cache
        pass
    return dropped


drop_stale_cache()


def _compiled_from(index: Path, source_hash: bytes) -> bool:
    """Whether a numba cache index (``.nbi``) was written for the source whose sha256 is
    ``source_hash``: numba 0.68 stamps each index with that hash (``caching._CacheLocator.
    get_source_stamp``) and recompiles when it differs, whatever the file times say."""
    import pickle

    try:
        with open(index, "rb") as f:
            pickle.load(f)  # numba's version
            stamp, _ = pickle.loads(f.read())
    except Exception:
        return False
    return bool(stamp == source_hash)


def uncompiled_kernels() -> list[str]:
    """Names of the kernel modules (those with a kernel over characters, ``nogil=True``) the
    cache holds no compiled code for that matches their current source (not compiled yet, or
    changed since)."""
    import hashlib

    folder = _cache_subfolder()
    missing = []
    for source in kernel_sources():
        if "@jit(nogil=True)" not in source.read_text(encoding="utf-8"):
            continue  # helpers only: compiled into the kernels that call them (often inlined)
        if source.stem == "handover":
            continue  # compiled in a fraction of a second when a tick first uses two threads
        indexes = list(folder.glob(f"{source.stem}.*.nbi")) if folder.is_dir() else []
        source_hash = hashlib.sha256(source.read_bytes()).digest()
        if not any(_compiled_from(index, source_hash) for index in indexes):
            missing.append(source.stem)
    return missing


def compile_notice() -> str | None:
    """The line to show before compiling when the kernels still have to be compiled (the first
    run on a machine, or after an update), else None."""
    if not uncompiled_kernels():
        return None
    return f"compiling the tick's kernels once (1-3 minutes of CPU); cached in {cache_dir()}"


_announcers: list[Callable[[str], None]] = []


def announce_compiling(say: Callable[[str], None] | None) -> None:
    """Have this process's next simulation built (:func:`load_kernels`) call ``say`` with
    :func:`compile_notice` if the kernels still have to be compiled (the CLI prints it on
    stderr); None: no more."""
    _announcers[:] = [] if say is None else [say]


#: What :func:`load_kernels` did in this process: seconds (wall and CPU) and whether it compiled.
load_figures: dict[str, float | bool] = {}
_load_lock = threading.RLock()


def load_kernels() -> bool:
    """Called by :class:`ecs_anim.runtime.simulation.Simulation` when it is built: has every
    kernel a tick calls in memory before the first tick, so that no tick loads one (loading the
    solver's lazily cost the tick its first constraint switched on 95-117 ms of CPU). Says what
    :func:`announce_compiling` asked for. Once per process: where the cache lacks kernels (the
    first run on a machine, or after an update) a child process compiles them all into the
    cache (:func:`compile_in_child`: small scenes using every kernel, the solver in a process
    of its own), then, as on any later run, each kernel's every compiled specialisation is
    loaded from the cache. Its figures: :data:`load_figures` (the child's CPU included).

    After :func:`compile_aside` (``run`` and ``view``) the child is started and not waited for:
    returns False, and the simulation ticks on the numpy references until
    :func:`poll_kernels` finds the child done (between two ticks). Returns whether the kernels
    are in memory."""
    if _announcers:
        say = _announcers.pop()
        notice = compile_notice()
        if notice is not None:
            say(notice + ASIDE_NOTICE if _aside else notice)
    with _load_lock:
        if load_figures or _loading:
            return True  # done, or the warm-up scene's own simulation (it compiles by calling)
        if _background:
            return poll_kernels()
        _loading.append(True)
        try:
            start, cpu = time.perf_counter(), time.process_time()
            compiled = bool(uncompiled_kernels())
            if compiled and _aside and _start_compiling_aside(start):
                return False
            if compiled and compiling_elsewhere() is not None:  # another run's child: wait
                while compiling_elsewhere() is not None:
                    time.sleep(0.2)
                compiled = bool(uncompiled_kernels())
            child_cpu = compile_in_child() if compiled else 0.0
            _load_every_kernel(start, cpu, child_cpu, compiled)
            return True
        finally:
            _loading.clear()


def _load_every_kernel(start: float, cpu: float, child_cpu: float, compiled: bool) -> None:
    """Load every kernel's specialisations from the cache; record :data:`load_figures`: wall
    seconds since ``start``, CPU seconds since ``cpu`` plus ``child_cpu`` (the compiling
    processes')."""
    for kernel in called_kernels():
        load_cached(kernel)
    load_figures.update(seconds=time.perf_counter() - start,
                        cpu_seconds=time.process_time() - cpu + child_cpu,
                        compiled=compiled)


_aside: list[bool] = []
#: The child compiling the kernels aside (:func:`compile_aside`): its process (None: another
#: run's), when it was started (wall seconds) and this process's children's CPU then.
_background: dict[str, Any] = {}


def compile_aside(on: bool = True) -> None:
    """Have this process's simulations, when the kernels still have to be compiled, tick on
    the numpy references while a child process compiles them (``run`` and ``view``: the first
    frame comes in seconds, not after the 1-3 minutes of CPU compiling takes); False: wait for
    the child (the default: the bench, the batch and API users tick on the kernels from the
    first tick)."""
    _aside[:] = [True] if on else []


#: What :func:`announce_compiling` adds to :func:`compile_notice` when they compile aside.
ASIDE_NOTICE = "; meanwhile the ticks run on numpy"


#: The file in the cache folder holding the process id of the child compiling the kernels
#: aside (written as it starts, removed by it as it ends): a run started meanwhile waits for
#: it instead of compiling them again.
COMPILING_MARKER = "ecs_anim_compiling.pid"


def compiling_elsewhere() -> int | None:
    """The process id of the child compiling the kernels aside (this run's or another's) while
    it runs, else None."""
    try:
        pid = int((_cache_subfolder() / COMPILING_MARKER).read_text())
    except (OSError, ValueError):
        return None
    try:
        os.kill(pid, 0)
    except ProcessLookupError:  # ended without removing it (killed)
        return None
    except OSError:  # another user's process: alive
        pass
    try:  # where /proc tells: not ended yet (a zombie), nor its id taken by another program
        with open(f"/proc/{pid}/stat", "rb") as f:
            ended = f.read().rsplit(b")", 1)[1].split()[0] == b"Z"
        with open(f"/proc/{pid}/cmdline", "rb") as f:
            ours = b"ecs_anim.runtime.kernels" in f.read()
    except (OSError, IndexError):
        return pid
    return pid if ours and not ended else None


def compiled_aside() -> None:
    """Called by the child compiling aside as it ends: remove :data:`COMPILING_MARKER` (if it
    still names this process)."""
    if compiling_elsewhere() == os.getpid():
        (_cache_subfolder() / COMPILING_MARKER).unlink(missing_ok=True)


def _start_compiling_aside(start: float) -> bool:
    """Start :data:`COMPILE_COMMAND` in a process of its own session (it goes on compiling into
    the cache if this process ends first, and a Ctrl-C here does not stop it), or follow the
    one another run started; False if no process could be started."""
    import resource

    elsewhere = compiling_elsewhere()
    if elsewhere is not None:
        _background.update(process=None, start=start)
        return True
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    try:
        child = subprocess.Popen(COMPILE_COMMAND, stdout=subprocess.DEVNULL,
                                 stderr=subprocess.DEVNULL, start_new_session=True)
        (_cache_subfolder() / COMPILING_MARKER).write_text(f"{child.pid}\n")
    except OSError:  # cannot start a process (or write the cache): compile where first called
        return False
    _background.update(process=child, start=start, rusage=before)
    return True


def poll_kernels(wait: bool = False) -> bool:
    """Whether the kernels are in memory; called between two ticks by a simulation ticking on
    the numpy references (:func:`compile_aside`). Once the child compiling them is done, a
    thread of this process loads them all from the cache (:func:`_load_aside`) while the ticks
    go on on numpy (loading them in one tick took it 0.5-1 s); True from the first call after
    it finished. With ``wait``: waits for the child and the load, then True."""
    with _load_lock:
        if load_figures or _loading:
            return True
        if not _background:
            return load_kernels()
        loader = _background.get("loader")
        if loader is None:
            child_cpu = _compiled_aside_cpu(wait)
            if child_cpu is None:
                return False
            loader = threading.Thread(target=_load_aside, args=(child_cpu,), daemon=True,
                                      name="ecs_anim kernels loader")
            _background["loader"] = loader
            loader.start()
            atexit.register(loader.join)  # numba loading as the interpreter ends could crash
        if wait:
            loader.join()
        if loader.is_alive():
            return False
        _background.clear()
        return True


def _compiled_aside_cpu(wait: bool) -> float | None:
    """None while the child compiling aside runs (unless ``wait``: then once it ended); then
    the CPU seconds it took (0 for another run's child: not ours to count)."""
    import resource

    child = _background["process"]
    if child is None:
        if compiling_elsewhere() is not None and not wait:
            return None
        while compiling_elsewhere() is not None:
            time.sleep(0.2)
        return 0.0
    if child.poll() is None and not wait:
        return None
    if child.wait() != 0:
        logging.getLogger("ecs_anim").warning(
            "compiling the kernels in a child process failed (exit %d): each compiles where it "
            "is first called", child.returncode)
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    before = _background["rusage"]
    return float((after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime))


def _load_aside(child_cpu: float) -> None:
    """The loader thread of :func:`poll_kernels`: every kernel's specialisations from the
    cache, then :data:`load_figures` (whatever became of the load: a kernel not loaded
    compiles where it is first called): the compile's wall seconds since the child started,
    its CPU seconds and this thread's."""
    compiled_s = time.perf_counter() - _background["start"]
    cpu = time.thread_time()
    try:
        for kernel in called_kernels():
            load_cached(kernel)
    finally:
        load_figures.update(seconds=compiled_s, cpu_seconds=child_cpu + time.thread_time() - cpu,
                            compiled=True, aside=True, ours=_background["process"] is not None)


def kernels_pending() -> bool:
    """Whether a child is compiling the kernels aside and they are not in memory yet."""
    return bool(_background) and not load_figures


_loading: list[bool] = []
_told: list[bool] = []


def compiling_by_calls() -> None:
    """Mark this process as the one compiling the kernels by calling them
    (:data:`COMPILE_COMMAND`): the simulations it builds neither load nor compile ahead."""
    _loading.append(True)


def new_load_figures() -> dict[str, float | bool]:
    """:data:`load_figures` the first time it is asked after :func:`load_kernels` did its work
    in this process, else empty (the kernels were in memory already)."""
    if not load_figures or _told:
        return {}
    _told.append(True)
    return dict(load_figures)


def called_kernels() -> list[Any]:
    """The numba dispatchers of the kernels Python calls (those compiled ``nogil``), in every
    kernel module (imported here)."""
    import importlib

    from ecs_anim.runtime.kernels.vec import with_numba

    modules = [importlib.import_module(f"{__name__}.{source.stem}") for source in kernel_sources()]
    with_numba()
    return [value for module in modules for value in vars(module).values()
            if getattr(value, "targetoptions", {}).get("nogil")
            and value.py_func.__module__ == module.__name__]


def load_cached(kernel: Any) -> None:
    """Load every specialisation of ``kernel`` (a numba dispatcher) its cache index holds for
    this source and machine (numba's ``Cache._index_key``); nothing is compiled."""
    cache = kernel._cache
    codegen = kernel.targetctx.codegen()
    try:
        index = cache._cache_file._load_index()
    except Exception:  # an unreadable index: the kernel compiles on its first call
        return
    for key in index:
        signature = key[0]
        if cache._index_key(signature, codegen) == key:
            kernel.compile(signature)


#: The command of the process compiling every kernel into the cache on a first run
#: (``python -m ecs_anim.runtime.kernels --compile``): the scenes it runs them on sit above this
#: package (a simulation, the shipped walk), so they are run there, not imported here.
COMPILE_COMMAND = (sys.executable, "-m", "ecs_anim.runtime.kernels", "--compile")


def compile_in_child() -> float:
    """Run :data:`COMPILE_COMMAND` and wait for it; returns the CPU seconds it (and its own
    children: the solver compiled aside) took. A child that fails leaves the kernels to
    compile where they are first called."""
    import resource

    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    done = subprocess.run(COMPILE_COMMAND, check=False)
    if done.returncode != 0:
        logging.getLogger("ecs_anim").warning("compiling the kernels in a child process failed (exit %d): each compiles "
                    "where it is first called", done.returncode)
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    return (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)


#: The command of the process compiling the solver's kernel aside (``python -m ecs_anim.runtime.kernels
#: --solver``): it calls :func:`ecs_anim.runtime.kernels.solve.solve` on no character.
SOLVER_COMMAND = (sys.executable, "-m", "ecs_anim.runtime.kernels", "--solver")
_solver_compile: dict[str, subprocess.Popen[bytes] | None] = {}


def compile_solver_aside() -> None:
    """Once per process: when the solver's kernel (about half of the compile time on its own)
    is not compiled yet and this process may use two cores or more, compile it in a second
    process while this one compiles the others; :func:`wait_for_solver` (the solve, before its
    kernel) then waits for it and loads its code from the cache. A process that ends before
    (a scene without constraints) stops it."""
    if "process" in _solver_compile:
        return
    _solver_compile["process"] = None
    cores = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count()
    if (cores or 1) < 2 or "solve" not in uncompiled_kernels():
        return
    try:
        child = subprocess.Popen(SOLVER_COMMAND, stdout=subprocess.DEVNULL,
                                 stderr=subprocess.DEVNULL)
    except OSError:  # cannot start a process: this one compiles the solver itself
        return
    _solver_compile["process"] = child
    atexit.register(_stop_solver_compile)


def wait_for_solver() -> None:
    """Called by :func:`ecs_anim.runtime.kernels.solve.solve` before its kernel: wait for the solver
    compiling aside, if it is. Whatever became of it, the kernel then loads from the cache, or
    compiles here (if the other process failed)."""
    child = _solver_compile.get("process")
    if child is not None:
        child.wait()
        _solver_compile["process"] = None


def _stop_solver_compile() -> None:
    child = _solver_compile.get("process")
    if child is not None and child.poll() is None:
        child.terminate()
        child.wait()


def available_threads() -> int:
    """How many threads the kernels may use: the cores this process may run on
    (``os.sched_getaffinity``, else ``os.cpu_count``)."""
    if hasattr(os, "sched_getaffinity"):
        return max(1, len(os.sched_getaffinity(0)))
    return max(1, os.cpu_count() or 1)


def default_threads() -> int:
    """The threads the kernels run on unless told (``run``, ``view``): the cores left idle by
    the rest of the machine, ``available_threads() - os.getloadavg()[0]`` rounded, at least one.
    On a loaded machine two threads were 1.3-1.9x slower than one (each hand-over waits for a
    core another process holds)."""
    most = available_threads()
    try:
        busy = os.getloadavg()[0]
    except (AttributeError, OSError):  # no load average (Windows): one thread, the safe side
        return 1
    return max(1, min(most, round(most - busy)))


_thread_count: list[int] = []  # set by set_threads; empty: not yet (default_threads, once)


def set_threads(n: int | None) -> int:
    """Run the kernels' loops over characters on ``n`` threads (:func:`over_chunks`); None:
    :func:`default_threads`. Returns the number set. Results never depend on it (each character
    is computed by one thread, independently of the others)."""
    most = available_threads()
    if n is None:
        n = default_threads()
    if not 1 <= n <= most:
        raise UsageError(f"expected 1 to {most} threads (the cores this process may use), got {n}")
    _thread_count[:] = [n]
    return n


def threads() -> int:
    """The number of threads the kernels run on now (unless set: :func:`default_threads`, as
    the machine is when first asked)."""
    return _thread_count[0] if _thread_count else set_threads(None)


def thread_comparison(tick: Callable[[], None], threads_n: int, ticks: int) -> dict[str, float]:
    """Time ``tick`` (one tick of a scene) on one thread and on ``threads_n``, alternating tick
    by tick so both see the same machine load (the bench's ``--threads N``): ``ticks`` ticks
    each. Returns the mean wall and CPU ms per tick of each (``wall_ms_1``, ``cpu_ms_1``,
    ``wall_ms_N``, ``cpu_ms_N``) and ``speedup`` (one thread's wall time over N's). Leaves the
    thread count as it found it."""
    before = threads()
    totals = {1: [0.0, 0.0], threads_n: [0.0, 0.0]}
    try:
        for _ in range(ticks):
            for count in (1, threads_n):
                set_threads(count)
                wall, cpu = time.perf_counter(), time.process_time()
                tick()
                totals[count][0] += time.perf_counter() - wall
                totals[count][1] += time.process_time() - cpu
    finally:
        set_threads(before)
    out = {f"{kind}_ms_{count}": value / max(ticks, 1) * 1e3
           for count, pair in totals.items()
           for kind, value in zip(("wall", "cpu"), pair, strict=True)}
    out["speedup"] = out["wall_ms_1"] / max(out[f"wall_ms_{threads_n}"], 1e-12)
    return out


#: Fewest rows worth handing to another thread: below, waking it costs more than it saves.
MIN_ROWS_PER_THREAD = 4
#: The same for a light kernel (tens of ns a row: the winners, the feet's directions, a table
#: sampled, the errors): a hand-over (16-20 µs, the threads taking the GIL in turn) costs more
#: than half of a few thousand rows; measured on two threads at 3,200 characters, each of them
#: ran 1.2-3.4x slower split than on one.
LIGHT_ROWS_PER_THREAD = 8192
_pools: dict[int, SpinningThreads] = {}  # by process id: a forked child makes its own
_pools_lock = threading.Lock()


def _pool() -> SpinningThreads:
    """This process's threads for :func:`over_chunks`, one fewer than
    :func:`available_threads` (made on first use: threads do not survive a fork, so the batch's
    forked workers each make their own)."""
    pid = os.getpid()
    with _pools_lock:  # two threads ticking for the first time make one pool
        pool = _pools.get(pid)
        if pool is None:
            from ecs_anim.runtime.kernels.handover import SpinningThreads

            _pools.clear()
            pool = _pools[pid] = SpinningThreads(available_threads() - 1)
    return pool


def over_chunks(kernel: Callable[..., None], n: int, *args: object,
                rows_per_thread: int = MIN_ROWS_PER_THREAD) -> None:
    """Run ``kernel(lo, hi, *args)``, a compiled kernel (``nogil=True``: it releases the GIL)
    over the loop indices ``lo..hi-1``, on the whole of ``0..n`` split into :func:`threads`
    contiguous chunks, one per thread (this one runs the first; the others wait for theirs
    spinning, :mod:`ecs_anim.runtime.kernels.handover`), and wait for all of them; an error of any chunk
    is raised once all are done. On one thread, or for fewer than ``rows_per_thread`` rows a
    thread (:data:`LIGHT_ROWS_PER_THREAD` for a light kernel), it is one call here. The chunks
    write disjoint rows, so the result does not depend on the split."""
    count = min(threads(), n // rows_per_thread)
    if count <= 1:
        kernel(0, n, *args)
        return
    _pool().run(kernel, [n * i // count for i in range(count + 1)], args)
