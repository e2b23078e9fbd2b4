"""``python -m ecs_anim.kernels``: compile (or load from the cache) every kernel the tick uses,
by running one tick of a small constrained scene with joint rotations; say how long it took.
CI runs it before the tests so that no test waits for a compilation."""

from __future__ import annotations

import sys
import time

from . import cache_dir, compile_notice


def main() -> int:
    start = time.perf_counter()
    notice = compile_notice()
    if notice is not None:
        print(notice, file=sys.stderr, flush=True)
    from ..benchmark import first_tick

    phases = first_tick()
    print(f"kernels ready in {time.perf_counter() - start:.1f} s ({'compiled' if notice else 'loaded'}; "
          f"import {phases['import_s']:.1f} s, first tick {phases['first_tick_s']:.1f} s), "
          f"cached in {cache_dir()}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
