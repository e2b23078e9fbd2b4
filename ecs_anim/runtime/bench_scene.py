"""The benchmark's scene (and the soak test's, and the kernels' warm-up): walkers on bumps, with
moving wrist and elbow targets when constrained."""

from __future__ import annotations

import time
from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:
    from ecs_anim.runtime.simulation import Simulation


def walkers_on_bumps(n: int, rotations: bool = False,
                     seed: int = 0) -> tuple[Simulation, np.random.Generator]:
    """The benchmark's scene (and the soak test's): ``n`` characters walking on bumps on a
    1.5 m grid, every other one a preset body and the rest random statures of 1.10-2.05 m, each
    starting at a random time of the walk and heading within 0.3 rad of +x. Returns
    (simulation, the seeded generator, for the caller's further draws)."""
    from ecs_anim.components import MotionPlayer, Placement
    from ecs_anim.core.ground import Bumps
    from ecs_anim.core.morphology import PRESET_SPECS, Morphology
    from ecs_anim.io.importing import import_bvh
    from ecs_anim.io.library import MOTIONS_DIR
    from ecs_anim.runtime.simulation import Simulation

    walk = import_bvh(MOTIONS_DIR / "walk.bvh")
    sim = Simulation({"walk": walk}, Bumps(0.04, 2.5, 3.0), fps=30.0, rotations=rotations)
    rng = np.random.default_rng(seed)
    presets = list(PRESET_SPECS)
    side = int(np.ceil(np.sqrt(n)))
    preset_bodies = [Morphology.preset(p) for p in presets]  # frozen: shared by many
    bodies, players, placements = [], [], []
    for i in range(n):
        bodies.append(preset_bodies[i % len(presets)] if i % 2 == 0 else
                      Morphology.from_stature(float(rng.uniform(1.1, 2.05))))
        players.append(MotionPlayer("walk", start_s=float(rng.uniform(0, 4))))
        placements.append(Placement((1.5 * (i // side), 1.5 * (i % side)),
                                    float(rng.uniform(-0.3, 0.3))))
    sim.spawn_many([f"c{i}" for i in range(n)], bodies, players, placements)
    return sim, rng


class BenchScene:
    """:func:`walkers_on_bumps`, and with ``constrained`` a wrist target (high priority) and an
    elbow target (low) on each character's right arm, both moving every tick (foot contacts
    come from the walk itself); ``budget_ms`` the solver's frame budget (None: none)."""

    def __init__(self, n: int, rotations: bool = False, constrained: bool = False,
                 budget_ms: float | None = None) -> None:
        from ecs_anim.solver.shell import SolverSettings

        self.sim, _ = walkers_on_bumps(n, rotations)
        sim = self.sim
        sim.solver_settings = SolverSettings(budget_ms=budget_ms)
        self.moving = np.zeros(0, np.int64)
        self.owners = np.zeros(0, np.int64)
        self.offsets = np.zeros((0, 3))
        if constrained:
            from ecs_anim.motion.constraints import Activation

            always = Activation(0.0, 1e9)
            entities = sim.store.entity.tolist()
            self.moving = np.array(
                [sim.add_constraint(e, f"w{i}", "wrist_r", 10, always, (0.0, 0.0, 1.2))
                 for i, e in enumerate(entities)]
                + [sim.add_constraint(e, f"e{i}", "elbow_r", 1, always, (0.0, 0.0, 1.0))
                   for i, e in enumerate(entities)])
            self.owners = sim.constraints.owner[sim.constraints.rows_of(self.moving)]
            self.offsets = np.where((np.arange(self.moving.size) < n)[:, None],
                                    [0.45, -0.3, 1.2], [0.0, -0.5, 1.0])

    def move_targets(self) -> None:
        """The targets follow each pelvis, wobbling 0.1 m at 0.5 Hz."""
        if self.moving.size:
            sim = self.sim
            pelvis = sim.store.positions[self.owners, 0]
            wobble = 0.1 * np.sin(2 * np.pi * 0.5 * sim.time_s + self.owners)[:, None]
            sim.set_targets(self.moving, pelvis * [1, 1, 0] + self.offsets + wobble)

    def tick(self) -> None:
        self.move_targets()
        self.sim.step()


def first_tick(threads: int = 1) -> dict[str, float]:
    """Set up the smallest scene that runs every kernel (constrained, with rotations) and run
    one tick on ``threads`` threads, then a cross-fade of no character (the blend kernel a
    scene's first clip change runs). Returns the seconds of each phase in this process (the
    interpreter's own start is not included: the parent times that)."""
    t0 = time.perf_counter()
    from ecs_anim.runtime import (
        kernels,
        simulation,  # noqa: F401  (numba, numpy, esper and the kernels)
    )
    from ecs_anim.runtime.kernels.decode import pose_arrays
    from ecs_anim.runtime.kernels.playback import blend_rows, empty_poses
    from ecs_anim.systems import MotionPlayback

    kernels.set_threads(threads)
    t1 = time.perf_counter()
    scene = BenchScene(8, rotations=True, constrained=True)
    t2 = time.perf_counter()
    scene.tick()
    # the arguments MotionPlayback passes: rows (read-only), the old clip's poses, weights, the
    # store's poses
    kernels.over_chunks(blend_rows, 0, MotionPlayback.rows_of_old(0), pose_arrays(empty_poses(0)),
                        np.zeros(0), pose_arrays(empty_poses(0)))
    t3 = time.perf_counter()
    scene.sim.close()
    return {"import_s": t1 - t0, "setup_s": t2 - t1, "first_tick_s": t3 - t2}
