"""Solver and decode test inputs: seeded random poses and bodies, the bench scene's solve calls
captured with the numpy reference solving them, and the numpy-vs-compiled solve comparison."""

from __future__ import annotations

import copy

import numpy as np
import pytest

import ecs_anim.systems.constraint_solve as system
from ecs_anim.core.morphology import Morphology
from ecs_anim.core.normalized import NormalizedPoses
from ecs_anim.core.skeleton import N_LENGTHS
from ecs_anim.motion.constraints import Activation
from ecs_anim.runtime.bench_scene import walkers_on_bumps
from ecs_anim.runtime.kernels import solve as compiled
from ecs_anim.solver import shell as solver_shell

ALWAYS = Activation(0.0, 1e9)
NUMPY_SOLVE = solver_shell.solve


def unit(rng: np.random.Generator, shape: tuple[int, ...]) -> np.ndarray:
    """Seeded random unit vectors, shape ``shape`` (normalized along the last axis)."""
    v = rng.normal(size=shape)
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


def random_poses(rng: np.random.Generator, n: int) -> NormalizedPoses:
    """Seeded random poses: unit quaternions and directions, fractions in [0.3, 1.05] (some
    straight limbs), a spine that rises with noise."""
    rising = np.array([[0.0, 0.0, 1 / 3], [0.0, 0.0, 2 / 3], [0.0, 0.0, 1.0]])
    return NormalizedPoses(
        root_position=rng.uniform(-3.0, 3.0, (n, 3)),
        root_heading=rng.uniform(-np.pi, np.pi, n),
        pelvis_local=unit(rng, (n, 4)),
        hip_dir=unit(rng, (n, 2, 3)),
        leg_frame=unit(rng, (n, 2, 4)),
        leg_fraction=rng.uniform(0.3, 1.05, (n, 2)),
        foot_dir=unit(rng, (n, 2, 3)),
        spine_points=rising + rng.normal(scale=0.12, size=(n, 3, 3)),
        thorax=unit(rng, (n, 4)),
        neck_dir=unit(rng, (n, 3)),
        head=unit(rng, (n, 4)),
        head_top_dir=unit(rng, (n, 3)),
        clavicle_dir=unit(rng, (n, 2, 3)),
        arm_frame=unit(rng, (n, 2, 4)),
        arm_fraction=rng.uniform(0.3, 1.05, (n, 2)),
        hand_dir=unit(rng, (n, 2, 3)),
        stretch=np.ones((n, N_LENGTHS)),
    )


def random_bodies(rng: np.random.Generator, n: int) -> np.ndarray:
    """Bone lengths (n, N_LENGTHS) of seeded random bodies: 0.9-2.1 m, leg scale 0.85-1.15."""
    return np.stack([Morphology.from_stature(float(s), leg_scale=float(k)).lengths
                     for s, k in zip(rng.uniform(0.9, 2.1, n), rng.uniform(0.85, 1.15, n),
                                     strict=True)])


class Capture:
    """Wraps the system's solver: records a copy of every call's arguments and solves with
    the numpy reference."""

    def __init__(self, monkeypatch: pytest.MonkeyPatch) -> None:
        self.calls: list[tuple] = []

        def solve(*args):
            self.calls.append(copy.deepcopy(args))
            return NUMPY_SOLVE(*args)

        monkeypatch.setattr(system, "solve", solve)


def bench_run(monkeypatch, n=6, ticks=12):
    """Walkers on bumps with a wrist (high) and an elbow (low priority) world target on the
    right arm moving every tick, mostly out of reach (the bench's targets before issue 36 made
    them reachable): unreachable goals, stalls and the centre of mass at work."""
    capture = Capture(monkeypatch)
    sim, _ = walkers_on_bumps(n)
    entities = sim.store.entity.tolist()
    moving = np.array([sim.add_constraint(e, f"w{i}", "wrist_r", 10, ALWAYS, (0.0, 0.0, 1.2))
                       for i, e in enumerate(entities)]
                      + [sim.add_constraint(e, f"e{i}", "elbow_r", 1, ALWAYS, (0.0, 0.0, 1.0))
                         for i, e in enumerate(entities)])
    owners = sim.constraints.owner[sim.constraints.rows_of(moving)]
    offsets = np.where((np.arange(moving.size) < n)[:, None], [0.45, -0.3, 1.2], [0.0, -0.5, 1.0])
    for _ in range(ticks):
        pelvis = sim.store.positions[owners, 0]
        wobble = 0.1 * np.sin(2 * np.pi * 0.5 * sim.time_s + owners)[:, None]
        sim.set_targets(moving, pelvis * [1, 1, 0] + offsets + wobble)
        sim.step()
    sim.close()
    return capture.calls


def assert_same_solve(args):
    """Numpy and compiled solves of the same arguments agree to 1e-9 m (joint positions and
    each goal's error), take the same iterations and move self-following goals the same."""
    numpy_args, compiled_args = copy.deepcopy(args), copy.deepcopy(args)
    poses, used, dec = NUMPY_SOLVE(*numpy_args)
    poses_c, used_c, dec_c = compiled.solve(*compiled_args)
    np.testing.assert_array_equal(used_c, used)
    np.testing.assert_allclose(dec_c.positions, dec.positions, rtol=0, atol=1e-9)
    goals, goals_c = numpy_args[2], compiled_args[2]
    np.testing.assert_allclose(solver_shell._errors(goals_c, dec_c), solver_shell._errors(goals, dec),
                               rtol=0, atol=1e-9)
    np.testing.assert_allclose(goals_c.goal, goals.goal, rtol=0, atol=1e-9)
    np.testing.assert_allclose(poses_c.root_position, poses.root_position, rtol=0, atol=1e-9)
    # Where limbs are bent their frames are decided (a straight limb's twist is rounding).
    bent = (poses.arm_fraction < 0.999)[..., None, None]
    np.testing.assert_allclose(np.where(bent, dec_c.arm2world, 0), np.where(bent, dec.arm2world, 0),
                               rtol=0, atol=1e-9)
