"""``python -m ecs_anim.runtime.kernels``: compile (or load from the cache) every kernel the tick uses
(:func:`ecs_anim.runtime.kernels.load_kernels`); say how long it took.
CI runs it before the tests so that no test waits for a compilation.

``python -m ecs_anim.runtime.kernels --solver`` compiles only the solver's kernel, by solving no
character: the process :func:`ecs_anim.runtime.kernels.compile_solver_aside` starts on a first run."""

from __future__ import annotations

import sys

from ecs_anim.runtime.kernels import (
    cache_dir,
    compile_notice,
    compile_solver,
    load_figures,
    load_kernels,
)
from ecs_anim.runtime.kernels.handover import spins_per_second


def main() -> int:
    if sys.argv[1:] == ["--solver"]:
        compile_solver()
        return 0
    notice = compile_notice()
    if notice is not None:
        print(notice, file=sys.stderr, flush=True)
    load_kernels()
    spins_per_second()  # the threads' hand-over too (a tick on one thread does not compile it)
    print(f"kernels ready in {load_figures['seconds']:.1f} s, {load_figures['cpu_seconds']:.1f} s "
          f"of CPU in this process ({'compiled' if load_figures['compiled'] else 'loaded'}), "
          f"cached in {cache_dir()}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
