"""``python -m ecs_anim.runtime.kernels``: compile (or load from the cache) every kernel the tick uses,
by running one tick of a small constrained scene with joint rotations; say how long it took.
CI runs it before the tests so that no test waits for a compilation.

``python -m ecs_anim.runtime.kernels --solver`` compiles only the solver's kernel, by solving no
character: the process :func:`ecs_anim.runtime.kernels.compile_solver_aside` starts on a first run."""

from __future__ import annotations

import sys
import time

from ecs_anim.runtime.kernels import cache_dir, compile_notice
from ecs_anim.runtime.kernels.handover import spins_per_second


def compile_solver() -> None:
    """Compile :func:`ecs_anim.runtime.kernels.solve.solve_rows` (into the cache) by solving no
    character: the arguments have the types of a real solve (``solve`` makes every array it
    hands the kernel a contiguous float64, int64 or bool one), so a real solve loads it."""
    import numpy as np

    from ecs_anim.core.morphology import MASS_SEGMENTS
    from ecs_anim.core.skeleton import N_LENGTHS
    from ecs_anim.runtime.kernels.decode import decoded_pose, empty_decoded
    from ecs_anim.runtime.kernels.playback import empty_poses
    from ecs_anim.runtime.kernels.solve import solve
    from ecs_anim.solver.goals import TickGoals

    ints, floats, flags = np.zeros(0, np.int64), np.zeros(0), np.zeros(0, bool)
    points = np.zeros((0, 3))
    no_goals = TickGoals(
        rows=ints, owner=ints, table_index=ints, orientation=flags, group=ints, bone=ints,
        segment=ints, fraction=floats, offset=points, chain=ints, priority=floats, goal=points,
        weight=floats, axis=points, footprint=np.zeros((0, 2, 3)),
        in_contact=np.zeros((0, 2), bool),
        com_desired=points, com_on=flags, on_self=ints, self_segment=ints, self_fraction=floats,
        self_offset=points, self_start=points, held=flags)
    solve(empty_poses(0), np.zeros((0, N_LENGTHS)), no_goals, np.zeros((0, len(MASS_SEGMENTS))),
          np.zeros((0, len(MASS_SEGMENTS))), decoded=decoded_pose(empty_decoded(0)))


def compile_avoidance() -> None:
    """Compile :mod:`ecs_anim.runtime.kernels.avoidance` (into the cache) on two walkers."""
    import numpy as np

    from ecs_anim.runtime.kernels.avoidance import orca_velocities

    two = np.array([[0.0, 0.0], [1.0, 0.0]])
    orca_velocities(two, np.zeros((2, 2)), np.array([[1.0, 0.0], [-1.0, 0.0]]), np.full(2, 0.3),
                    np.ones(2), np.ones(2, bool), range_m=5.0, time_horizon_s=2.0,
                    max_neighbours=10, dt=1.0 / 30.0)


def main() -> int:
    if sys.argv[1:] == ["--solver"]:
        compile_solver()
        return 0
    start = time.perf_counter()
    notice = compile_notice()
    if notice is not None:
        print(notice, file=sys.stderr, flush=True)
    from ecs_anim.runtime.bench_scene import first_tick

    phases = first_tick()
    compile_avoidance()  # the bench scene steers nobody
    spins_per_second()  # the threads' hand-over too (a tick on one thread does not compile it)
    print(f"kernels ready in {time.perf_counter() - start:.1f} s ({'compiled' if notice else 'loaded'}; "
          f"import {phases['import_s']:.1f} s, first tick {phases['first_tick_s']:.1f} s), "
          f"cached in {cache_dir()}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
