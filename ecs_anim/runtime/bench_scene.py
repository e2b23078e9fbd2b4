"""The benchmark's scene (and the soak test's, and the kernels' warm-up): walkers on bumps, in
lanes or crossing each other, with wrist and elbow targets when constrained."""

from __future__ import annotations

import time
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import NDArray

if TYPE_CHECKING:
    from ecs_anim.motion.clip import NormalizedMotion
    from ecs_anim.runtime.simulation import Simulation


def walkers_on_bumps(n: int, rotations: bool = False, seed: int = 0,
                     crossing: bool = True) -> tuple[Simulation, np.random.Generator]:
    """``n`` characters walking on bumps from a 1.5 m grid, every other one a preset body and
    the rest random statures of 1.10-2.05 m. With ``crossing`` (the soak test's and the
    collision tests' crowd) each starts at a random time of the walk (its clip's origin on its
    grid point, so it starts up to 5 m further along) heading within 0.3 rad of +x: a crowd
    that ignores itself, about a tenth of it in someone else's body every tick. Without it
    (the benchmark's crowd) each row along +x is a lane of one body heading +x, each walker
    starting on its grid point at its own time of the walk: walkers 1.5 m apart that never
    meet, no two in step. Returns (simulation, the
    seeded generator, for the caller's further draws)."""
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
    if crossing:
        for i in range(n):
            bodies.append(preset_bodies[i % len(presets)] if i % 2 == 0 else
                          Morphology.from_stature(float(rng.uniform(1.1, 2.05))))
            players.append(MotionPlayer("walk", start_s=float(rng.uniform(0, 4))))
            placements.append(Placement((1.5 * (i // side), 1.5 * (i % side)),
                                        float(rng.uniform(-0.3, 0.3))))
    else:
        # One body a lane: its walkers go at one speed, the same distance apart. Each starts
        # at its own time of the walk (no two in step, as in a real crowd), its clip's origin
        # set back by the way the walk has come by then, so it starts on its grid point.
        lane_bodies = [preset_bodies[lane // 2 % len(presets)] if lane % 2 == 0 else
                       Morphology.from_stature(float(rng.uniform(1.1, 2.05)))
                       for lane in range(side)]
        starts_s = rng.uniform(0, 4, n)
        for i in range(n):
            lane = i % side
            body = lane_bodies[lane]
            come_x, come_y = walked_m(walk, float(starts_s[i]), body.leg_length)
            bodies.append(body)
            players.append(MotionPlayer("walk", start_s=float(starts_s[i])))
            placements.append(Placement((1.5 * (i // side) - come_x, 1.5 * lane - come_y), 0.0))
    sim.spawn_many([f"c{i}" for i in range(n)], bodies, players, placements)
    return sim, rng


def walked_m(motion: NormalizedMotion, time_s: float, leg_length_m: float
             ) -> tuple[float, float]:
    """How far (x, y, m) the root of ``motion`` looped from its start has come at ``time_s``
    on a body of ``leg_length_m``: the frames' root positions interpolated, each loop adding
    the way from the first frame to the one after the last (extrapolated, as playback does)."""
    root_xy = motion.poses.root_position[:, :2]
    after_last = 2 * root_xy[-1] - root_xy[-2] if len(root_xy) >= 2 else root_xy[-1]
    path = np.vstack([root_xy, after_last]) - root_xy[0]
    loops, frame = divmod(time_s * motion.fps, float(motion.n_frames))
    at = np.arange(motion.n_frames + 1)
    xy = loops * path[-1] + np.array([np.interp(frame, at, path[:, k]) for k in (0, 1)])
    return float(xy[0] * leg_length_m), float(xy[1] * leg_length_m)


#: The bench's wrist target in the thorax frame (x forward, y left, z up) from the right
#: shoulder: this direction, at :data:`WRIST_REACH_SHARE` of the arm's length.
WRIST_DIRECTION = (0.7, -0.3, -0.4)
WRIST_REACH_SHARE = 0.8
#: The side the elbow falls to (thorax frame): down and out, made normal to shoulder-wrist.
ELBOW_SIDE = (0.0, -0.5, -1.0)


def arm_targets(upper_arm_m: np.ndarray, forearm_m: np.ndarray,
                direction: tuple[float, float, float] = WRIST_DIRECTION,
                reach_share: float = WRIST_REACH_SHARE,
                elbow_side: tuple[float, float, float] = ELBOW_SIDE) -> tuple[np.ndarray, np.ndarray]:
    """A wrist and an elbow target an arm takes exactly, as offsets (n, 3) from its shoulder
    (in the frame ``direction`` and ``elbow_side`` are given in), for arms of ``upper_arm_m``
    and ``forearm_m`` (n,) m: the wrist ``reach_share`` of the arm's length along
    ``direction``; the elbow where the upper arm from the shoulder meets the forearm from the
    wrist (the circle of elbows that keep the wrist), on its ``elbow_side``."""
    u, f = np.asarray(upper_arm_m, float), np.asarray(forearm_m, float)
    along = np.asarray(direction, float) / np.linalg.norm(direction)
    d = reach_share * (u + f)
    centre = (u * u - f * f + d * d) / (2.0 * d)  # the circle's centre along shoulder-wrist
    radius = np.sqrt(np.maximum(u * u - centre * centre, 0.0))
    side = np.asarray(elbow_side, float)
    side = side - side @ along * along
    side /= np.linalg.norm(side)
    return d[:, None] * along, centre[:, None] * along + radius[:, None] * side


class BenchScene:
    """:func:`walkers_on_bumps`, and with ``constrained`` a wrist target (high priority) and an
    elbow target (low) on each character's right arm that the arm takes exactly (foot contacts
    come from the walk itself, and the centre of mass is held): both are points of its own
    body, fixed to its right shoulder in its thorax's frame (:func:`arm_targets`), so they move
    with the walker every tick and stay within the arm's reach and consistent with each other
    however the walk and the centre-of-mass control carry the shoulder. ``budget_ms`` the
    solver's frame budget (None: none); ``crossing``: the walkers cross each other instead of
    walking in lanes (:func:`walkers_on_bumps`)."""

    def __init__(self, n: int, rotations: bool = False, constrained: bool = False,
                 budget_ms: float | None = None, crossing: bool = False) -> None:
        from ecs_anim.solver.shell import SolverSettings

        self.sim, _ = walkers_on_bumps(n, rotations, crossing=crossing)
        sim = self.sim
        sim.solver_settings = SolverSettings(budget_ms=budget_ms)
        self.wrists = self.elbows = np.zeros(0, np.int64)
        if constrained:
            from ecs_anim.core.skeleton import LENGTH_INDEX
            from ecs_anim.motion.constraints import Activation

            always = Activation(0.0, 1e9)
            entities = sim.store.entity.tolist()
            lengths = sim.store.lengths
            wrist, elbow = arm_targets(lengths[:, LENGTH_INDEX["upper_arm_r"]],
                                       lengths[:, LENGTH_INDEX["forearm_r"]])
            self.wrists = np.array([sim.add_constraint(
                e, f"w{i}", "wrist_r", 10, always, target_entity=e, target_point="shoulder_r",
                target_offset_m=tuple(wrist[i])) for i, e in enumerate(entities)], np.int64)
            self.elbows = np.array([sim.add_constraint(
                e, f"e{i}", "elbow_r", 1, always, target_entity=e, target_point="shoulder_r",
                target_offset_m=tuple(elbow[i])) for i, e in enumerate(entities)], np.int64)

    def errors_mm(self) -> dict[str, float]:
        """This tick's errors of the constrained scene (mm): mean and max of the wrists'
        and the elbows' distances from their targets, and of the centres of mass from where
        they should be (horizontal), over the characters solved this tick (NaN: none)."""
        sim = self.sim
        wrist = sim.constraints.error[sim.constraints.rows_of(self.wrists)] * 1e3
        elbow = sim.constraints.error[sim.constraints.rows_of(self.elbows)] * 1e3
        com = sim.store.com_error_m * 1e3
        def solved(mm: NDArray[np.float64]) -> NDArray[np.float64]:
            # (a frame budget leaves the characters it did not solve this tick NaN)
            return mm[np.isfinite(mm)]

        wrist, elbow, com = solved(wrist), solved(elbow), solved(com)
        return {"wrist_mean": _mean(wrist), "wrist_max": _max(wrist),
                "elbow_mean": _mean(elbow), "elbow_max": _max(elbow),
                "com_mean": _mean(com), "com_max": _max(com)}

    def tick(self) -> None:
        self.sim.step()


def _mean(values: NDArray[np.float64]) -> float:
    return float(values.mean()) if values.size else float("nan")


def _max(values: NDArray[np.float64]) -> float:
    return float(values.max()) if values.size else float("nan")


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


#: The peer task's arm reach: forward, a little out and up, at 0.8 of the arm's length.
PEER_WRIST_DIRECTION = (0.8, -0.3, 0.1)
#: Ticks the peer task runs with its targets on (each solved from the motion's pose again).
PEER_TICKS = 10


def peer_task(ticks: int = PEER_TICKS) -> dict[str, float]:
    """The wrist-elbow-feet-centre-of-mass task of the published IK comparisons (pinocchio,
    mink): one standing adult (the shipped idle, held still), a wrist target and an elbow
    target the right arm takes exactly from where its shoulder stands (:func:`arm_targets`,
    fixed in the world), both allowed to move the trunk; the feet stay planted and the
    centre of mass is held over its place. Solved ``ticks`` ticks; returns the last one's
    wrist and elbow errors (mm), how far the shoulder moved from where the motion has it
    (mm), how far the shoulder ended from the sphere of elbows the target leaves it (mm:
    0 wherever the elbow target can be met), the centre of mass's horizontal error and the
    largest foot move (mm), and the solver's iterations."""
    from ecs_anim.components import MotionPlayer, Placement
    from ecs_anim.core.morphology import Morphology
    from ecs_anim.core.normalized import frames_from_positions
    from ecs_anim.core.skeleton import JOINT_INDEX, LENGTH_INDEX
    from ecs_anim.io.importing import import_bvh
    from ecs_anim.io.library import MOTIONS_DIR
    from ecs_anim.motion.constraints import Activation
    from ecs_anim.runtime.simulation import Simulation

    sim = Simulation({"idle": import_bvh(MOTIONS_DIR / "idle.bvh")})
    body = sim.spawn("peer", Morphology.preset("adult_male"), MotionPlayer("idle", speed=0.0),
                     Placement((0.0, 0.0)))
    sim.step()
    start = sim.store.positions[0].copy()
    lengths = sim.store.lengths[0]
    upper_arm = lengths[LENGTH_INDEX["upper_arm_r"]]
    wrist, elbow = arm_targets(np.array([upper_arm]),
                               np.array([lengths[LENGTH_INDEX["forearm_r"]]]),
                               PEER_WRIST_DIRECTION)
    shoulder = start[JOINT_INDEX["shoulder_r"]]
    _, thorax2world, _ = frames_from_positions(start)
    wrist_in_world = shoulder + thorax2world @ wrist[0]
    elbow_in_world = shoulder + thorax2world @ elbow[0]
    always = Activation(0.0, 1e9)
    chain = ("arm_r", "trunk")
    uids = [sim.add_constraint(body, "wrist", "wrist_r", 10, always, tuple(wrist_in_world),
                               chain=chain),
            sim.add_constraint(body, "elbow", "elbow_r", 1, always, tuple(elbow_in_world),
                               chain=chain)]
    for _ in range(ticks):
        sim.step()
    end = sim.store.positions[0]
    error = sim.constraints.error[sim.constraints.rows_of(np.array(uids))]
    ankles = [JOINT_INDEX["ankle_l"], JOINT_INDEX["ankle_r"]]
    shoulder_now = end[JOINT_INDEX["shoulder_r"]]
    report = sim.solver_report()
    result = {
        "wrist_mm": float(error[0]) * 1e3, "elbow_mm": float(error[1]) * 1e3,
        "shoulder_moved_mm": float(np.linalg.norm(shoulder_now - shoulder)) * 1e3,
        "shoulder_off_sphere_mm": abs(float(np.linalg.norm(elbow_in_world - shoulder_now))
                                      - upper_arm) * 1e3,
        "com_mm": float(sim.store.com_error_m[0]) * 1e3,
        "feet_moved_mm": float(np.linalg.norm(end[ankles] - start[ankles], axis=1).max()) * 1e3,
        "iterations": float(report.iterations) if report is not None else 0.0}
    sim.close()
    return result
