"""The threads :func:`ecs_anim.runtime.kernels.over_chunks` hands chunks of a kernel's rows to, without
putting them to sleep between kernels.

A thread asleep on a lock or a condition takes 15-50 µs to run again once woken on this kind of
virtual machine: handing a kernel that does nothing to a ``ThreadPoolExecutor`` and waiting for
it took 55 µs, as long as a small kernel over thousands of characters, and a tick hands over
about fifteen. So, as OpenMP's threads do, each thread waits for its next chunk by spinning on a
counter for :data:`SPIN_S` seconds before it sleeps, and the caller waits for the chunks by
spinning on the threads' done counters instead of sleeping on a future (the same hand-over of
nothing: 12-20 µs, the rest being the two threads taking the GIL in turn to call the kernel).
The spin is compiled and runs without the GIL, so it does not slow the thread running the
simulation's Python between two kernels; it costs the other core up to :data:`SPIN_S` after each
chunk.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable, Sequence
from typing import Any, cast

import numpy as np
from numba import types
from numba.extending import intrinsic
from numpy.typing import NDArray

from ecs_anim.runtime.kernels.vec import jit

#: How long a thread spins for its next chunk before it sleeps (seconds): longer than the
#: Python between two kernels of a tick (tens to hundreds of µs), short against a frame.
SPIN_S = 0.0005


def _load_acquire(typingctx: Any, counters: Any, index: Any) -> Any:
    """The typing and code of :data:`load_acquire` (numba's ``intrinsic``)."""
    if not (isinstance(counters, types.Array) and counters.dtype == types.int64
            and counters.ndim == 1 and counters.layout == "C"):
        return None  # only the counters' own kind of array
    signature = types.int64(counters, index)

    def codegen(context: Any, builder: Any, sig: Any, args: Any) -> Any:
        array = context.make_array(sig.args[0])(context, builder, args[0])
        return builder.load_atomic(builder.gep(array.data, [args[1]]), "acquire", 8)

    return signature, codegen


#: ``load_acquire(counters, index)``: ``counters[index]`` (a contiguous int64 array) read as an
#: atomic load with acquire ordering, for compiled code: read again on every call (a plain load
#: may be hoisted out of a loop that only reads), and what another thread wrote before the
#: counter is seen after it.
load_acquire = cast("Callable[[NDArray[np.int64], int], int]", intrinsic(_load_acquire))


@jit(nogil=True)
def spin_while_equal(counters: NDArray[np.int64], index: int, value: int, spins: int) -> int:
    """Read ``counters[index]`` until it differs from ``value``, at most ``spins`` times;
    returns the last value read (``value``: it did not change)."""
    for _ in range(spins):
        now = load_acquire(counters, index)
        if now != value:
            return now
    return value


def spins_per_second() -> float:
    """How many reads :func:`spin_while_equal` makes in a second on this machine (timed once)."""
    counters = np.zeros(1, np.int64)
    spin_while_equal(counters, 0, 0, 1)  # compiled (or loaded) before it is timed
    spins = 200_000
    start = time.perf_counter()
    spin_while_equal(counters, 0, 0, spins)
    return spins / max(time.perf_counter() - start, 1e-6)


class SpinningThreads:
    """``workers`` threads besides the caller's that run chunks of a kernel's rows.

    Worker ``i`` watches ``counters[i]``: the number of the last chunk given to it, -1 to stop;
    it writes that number to ``counters[workers + i]`` when the chunk is done."""

    def __init__(self, workers: int, spin_s: float = SPIN_S) -> None:
        self.workers = workers
        self.counters = np.zeros(2 * workers, np.int64)
        self._jobs: list[tuple[Callable[..., None], int, int, Sequence[object]] | None] = \
            [None] * workers
        self._errors: list[BaseException | None] = [None] * workers
        self._asleep = [False] * workers
        self._wake = [threading.Event() for _ in range(workers)]
        self._given = 0
        self._busy = threading.Lock()
        rate = spins_per_second()
        self._spins = max(1, int(spin_s * rate))
        self._wait_spins = max(1, int(0.01 * rate))  # the caller looks at signals every 10 ms
        self._threads = [threading.Thread(target=self._work, args=(i,), daemon=True,
                                          name=f"ecs_anim_kernel_{i}") for i in range(workers)]
        for thread in self._threads:
            thread.start()

    def _work(self, i: int) -> None:
        counters, seen = self.counters, 0
        while True:
            given = spin_while_equal(counters, i, seen, self._spins)
            if given == seen:  # nothing within the spin: sleep until :meth:`run` sets the event
                self._asleep[i] = True
                if counters[i] == seen:  # (run reads _asleep after it writes the counter)
                    self._wake[i].wait()
                self._wake[i].clear()
                self._asleep[i] = False
                continue
            if given < 0:
                return
            seen = given
            job = self._jobs[i]
            self._jobs[i] = None
            try:
                if job is not None:
                    kernel, lo, hi, args = job
                    kernel(lo, hi, *args)
            except BaseException as error:  # raised by run, in the caller's thread
                self._errors[i] = error
            counters[self.workers + i] = given

    def _give(self, i: int, number: int) -> None:
        self.counters[i] = number
        if self._asleep[i]:
            self._wake[i].set()

    def _wait_for(self, i: int, number: int) -> None:
        """Spin until worker ``i`` has done chunk ``number`` (looking at signals every 10 ms)."""
        done = self.workers + i
        seen = int(self.counters[done])
        while seen != number:
            seen = spin_while_equal(self.counters, done, seen, self._wait_spins)

    def run(self, kernel: Callable[..., None], bounds: Sequence[int],
            args: Sequence[object]) -> None:
        """``kernel(bounds[c], bounds[c + 1], *args)`` for every chunk ``c``: the first in this
        thread, the others on the workers (at most ``workers`` of them); waits for all, then
        raises the first error a chunk raised. A call made while another thread's call runs
        does its chunks itself, one after the other."""
        chunks = len(bounds) - 1
        if chunks - 1 > self.workers or not self._busy.acquire(blocking=False):
            for c in range(chunks):
                kernel(bounds[c], bounds[c + 1], *args)
            return
        others = range(chunks - 1)
        try:
            self._given += 1
            number = self._given
            for i in others:
                self._jobs[i] = (kernel, bounds[i + 1], bounds[i + 2], args)
                self._give(i, number)
            try:
                kernel(bounds[0], bounds[1], *args)
            finally:  # every chunk done before anything is raised: they write the arrays
                for i in others:
                    self._wait_for(i, number)
        finally:
            errors = self._errors[:chunks - 1]
            self._errors[:chunks - 1] = [None] * (chunks - 1)
            self._busy.release()
        for error in errors:
            if error is not None:
                raise error

    def close(self) -> None:
        """Stop the workers (each finishes its chunk first) and wait for them."""
        for i in range(self.workers):
            self._give(i, -1)
        for thread in self._threads:
            thread.join()
