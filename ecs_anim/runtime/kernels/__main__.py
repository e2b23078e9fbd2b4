"""``python -m ecs_anim.runtime.kernels``: compile (or load from the cache) every kernel the tick uses
(:func:`ecs_anim.runtime.kernels.load_kernels`); say how long it took.
CI runs it before the tests so that no test waits for a compilation.

``python -m ecs_anim.runtime.kernels --compile`` compiles every kernel into the cache by calling
them on small scenes (:func:`compile_every_kernel`): the process a first run's
:func:`~ecs_anim.runtime.kernels.load_kernels` starts. ``--solver`` compiles only the solver's
kernel, by solving no character: the process
:func:`ecs_anim.runtime.kernels.compile_solver_aside` starts. The scenes sit above the kernels'
package (a simulation, the shipped walk): they are here, where nothing imports them."""

from __future__ import annotations

import logging
import sys
from typing import TYPE_CHECKING

from ecs_anim.runtime.kernels import (
    cache_dir,
    compile_notice,
    compile_solver_aside,
    compiled_aside,
    compiling_by_calls,
    load_figures,
    load_kernels,
)
from ecs_anim.runtime.kernels.handover import spins_per_second

if TYPE_CHECKING:
    from ecs_anim.runtime.simulation import Simulation


def compile_every_kernel() -> None:
    """Compile every kernel a tick uses into the cache: one tick of the smallest scene that runs
    them all (:func:`ecs_anim.runtime.bench_scene.first_tick`), the solver in a second process
    where there are two cores (:func:`compile_solver_aside`), local avoidance, bodies kept
    apart and the solver's speed bound."""
    from ecs_anim.runtime.bench_scene import first_tick

    compiling_by_calls()
    compile_solver_aside()
    first_tick()  # a tick and the cross-fade's blend of no character
    compile_avoidance()  # the bench scene steers nobody
    compile_separation()  # nor do its walkers meet, nor is its solve bounded


def compile_separation() -> None:
    """Compile :mod:`ecs_anim.runtime.kernels.separate` and
    :mod:`ecs_anim.runtime.kernels.joint_speed` (into the cache): two ticks of two walkers
    started side by side 0.4 m apart, one reaching out under the solver's speed bound (on by
    default), 5 cm in each other, which CollisionSeparate pushes apart (started 0.15 m apart,
    neither body could move: ``push_rows`` was not compiled, and the fight compiled it mid-run).
    Then the bound's second pass on the characters it held back (no one here: on no row) and
    the targets on the other walker's body moved onto its surface (this process ticks on numpy:
    called here on its own)."""
    from ecs_anim.components import MotionPlayer, Placement
    from ecs_anim.core.morphology import Morphology
    from ecs_anim.io.importing import import_bvh
    from ecs_anim.io.library import MOTIONS_DIR
    from ecs_anim.motion.constraints import Activation
    from ecs_anim.runtime.simulation import Simulation

    log = logging.getLogger("ecs_anim")  # the scene's own overlap warnings are no one's
    was_disabled, log.disabled = log.disabled, True
    try:
        with Simulation({"walk": import_bvh(MOTIONS_DIR / "walk.bvh")}, rotations=True) as sim:
            walkers = [sim.spawn(f"c{i}", Morphology.from_stature(1.7), MotionPlayer("walk"),
                                 Placement((0.0, 0.4 * i))) for i in range(2)]
            sim.add_constraint(walkers[0], "reach", "wrist_r", 1.0, Activation(0.0, 1e9),
                               (0.5, -0.5, 1.2))
            sim.add_constraint(walkers[1], "touch", "wrist_l", 1.0, Activation(0.0, 1e9),
                               target_entity=walkers[0], target_point="spine_middle")
            sim.step()
            sim.step()
            compile_speed_and_surfaces(sim)
    finally:
        log.disabled = was_disabled


def compile_speed_and_surfaces(sim: Simulation) -> None:
    """Compile :func:`ecs_anim.runtime.kernels.joint_speed.again_rows` and ``put_rows`` (on no
    row, with the arrays' types of a real call) and
    :func:`ecs_anim.runtime.kernels.goals.surface_rows` (on ``sim``'s constraints)."""
    import numpy as np

    from ecs_anim.core.skeleton import N_JOINTS, N_LENGTHS
    from ecs_anim.runtime.kernels import goals, joint_speed
    from ecs_anim.runtime.kernels.decode import decode
    from ecs_anim.runtime.kernels.playback import empty_poses
    from ecs_anim.solver.joint_speed import N_VALUES, MotionBefore

    none, values, joints = np.zeros(0, np.int64), np.zeros((0, N_VALUES)), np.zeros((0, N_JOINTS, 3))
    poses = empty_poses(0)
    before = MotionBefore(values, values, values, joints, joints, joints, np.zeros(0))
    part, part_decoded = joint_speed.limit_again(poses, none, before, np.zeros((0, N_LENGTHS)),
                                                 np.zeros((0, 2), bool), 0.1)
    joint_speed.put_back(poses, part_decoded, none, part, part_decoded)
    decoded = decode(sim.store.poses, sim.store.lengths)
    goals.on_other_surfaces(sim.constraints, sim.constraints.target_world.copy(),
                            sim.store.lengths, decoded, decoded)


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
    if sys.argv[1:] == ["--compile"]:
        try:
            compile_every_kernel()
        finally:
            compiled_aside()  # a run compiling aside, and any started meanwhile, load them now
        return 0
    notice = compile_notice()
    if notice is not None:
        print(notice, file=sys.stderr, flush=True)
    load_kernels()
    spins_per_second()  # the threads' hand-over too (a tick on one thread does not compile it)
    print(f"kernels ready in {load_figures['seconds']:.1f} s, {load_figures['cpu_seconds']:.1f} s "
          f"of CPU, its compiling processes included ({'compiled' if load_figures['compiled'] else 'loaded'}), "
          f"cached in {cache_dir()}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
