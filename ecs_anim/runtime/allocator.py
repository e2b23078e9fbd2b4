"""Keep the memory a tick frees for the next tick (glibc's allocator, Linux).

Every tick makes its arrays afresh (goals, decoded poses, scratch), many of them larger than
glibc's threshold for serving an allocation by its own ``mmap``: freed, such an array goes back
to the kernel, and the same array of the next tick is faulted in again page by page. At 3,200
constrained characters that was about 950 page faults and 1.6 ms of system time a tick (of
about 27 ms), and the faults' cache misses cost as much again. With the threshold raised to its
largest (32 MB) and the heap trimmed only above 64 MB free, the tick's arrays come from memory
the process already holds: no fault a tick. The process keeps its peak memory instead of
handing it back between ticks, as a game engine's frame allocator does.
"""

from __future__ import annotations

import ctypes
import functools
import sys

#: glibc's ``mallopt`` parameters (malloc.h) and the values set.
M_TRIM_THRESHOLD, M_MMAP_THRESHOLD = -1, -3
MMAP_THRESHOLD_BYTES = 32 * 1024 * 1024  # glibc's largest (DEFAULT_MMAP_THRESHOLD_MAX, 64-bit)
TRIM_THRESHOLD_BYTES = 2 * MMAP_THRESHOLD_BYTES  # glibc's own ratio when it adapts them


@functools.cache
def keep_freed_memory() -> bool:
    """Ask glibc (once per process) to serve arrays up to 32 MB from its heap and keep freed
    memory for reuse. Returns whether the allocator took the settings (False off glibc: macOS,
    Windows, musl; nothing changes there)."""
    if not sys.platform.startswith("linux"):
        return False
    try:
        mallopt = ctypes.CDLL(None).mallopt
    except (OSError, AttributeError):  # not glibc
        return False
    return bool(mallopt(M_MMAP_THRESHOLD, MMAP_THRESHOLD_BYTES)) and \
        bool(mallopt(M_TRIM_THRESHOLD, TRIM_THRESHOLD_BYTES))
