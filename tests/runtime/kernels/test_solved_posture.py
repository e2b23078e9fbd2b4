"""PostureConvert takes the solver's decoded pose for the characters it moved (decoded once per
tick): the posture equals a fresh decode of the final poses to 1e-9 m, rotations included."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

import ecs_anim.systems.posture_convert as posture_convert
from ecs_anim.core.normalized import DecodedPose, decode
from ecs_anim.core.skeleton import N_JOINTS
from ecs_anim.io.export.skeleton import local_rotations
from ecs_anim.runtime.bench_scene import BenchScene
from ecs_anim.runtime.kernels import decode as kd
from ecs_anim.runtime.kernels import posture as kp
from ecs_anim.runtime.kernels.solved_posture import posture_solved_rows
from support.scenarios import run
from support.solve import random_bodies, random_poses


def assert_posture_is_the_decoded_poses(sim):
    st = sim.store
    fresh = decode(st.poses, st.lengths)
    good = ~st.frozen
    for name in (f.name for f in dataclasses.fields(DecodedPose)):
        np.testing.assert_allclose(getattr(st.posture, name)[good], getattr(fresh, name)[good],
                                   rtol=0, atol=1e-9, err_msg=name)
    np.testing.assert_allclose(st.positions[good], fresh.positions[good], rtol=0, atol=1e-9)
    return fresh


def test_the_bench_scene_posture_and_rotations_equal_a_fresh_decode(monkeypatch):
    handed = []
    real = posture_solved_rows

    def counting(lo, hi, rows, *args):
        handed.append(rows.size)
        return real(lo, hi, rows, *args)

    monkeypatch.setattr(posture_convert, "posture_solved_rows", counting)
    scene = BenchScene(6, rotations=True, constrained=True)
    for _ in range(8):
        scene.tick()
        fresh = assert_posture_is_the_decoded_poses(scene.sim)
        np.testing.assert_allclose(scene.sim.store.local_rotations, local_rotations(fresh),
                                   rtol=0, atol=1e-9)
    assert handed == [6] * 8  # every character solved, none decoded again
    scene.sim.close()


def test_a_scenario_with_some_characters_unconstrained(monkeypatch):
    """fight_training: the solved rows are handed over, the others decoded; each tick's
    posture equals a fresh decode."""
    checked = []
    real_run = posture_convert.PostureConvert.run

    def checking(self, dt):
        real_run(self, dt)
        assert_posture_is_the_decoded_poses(self.sim)
        checked.append(self.sim.tick)

    monkeypatch.setattr(posture_convert.PostureConvert, "run", checking)
    run("fight_training")
    assert len(checked) > 30


@pytest.mark.parametrize(("frames_shared", "rotations"), [(False, False), (True, False),
                                                          (False, True)])
def test_a_solved_row_not_finite_keeps_its_last_positions(frames_shared, rotations):
    """posture_solved_rows publishes the solver's rows (frames copied, or shared when the
    posture's frames are the solver's arrays) and freezes one that is not finite, its
    positions before kept: its positions not finite, or with rotations only a frame (its
    rotations not finite: its positions put back)."""
    rng = np.random.default_rng(1317)
    n = 40
    poses, lengths = random_poses(rng, n), random_bodies(rng, n)
    solved = kd.decoded_arrays(kd.decode(poses, lengths))
    solved.positions[[5, 33]] = np.nan
    bad = [5, 33]
    if rotations:
        solved.head2world[12] = np.inf
        bad = [5, 12, 33]
    before = rng.normal(size=(n, N_JOINTS, 3))
    positions, frozen, newly_bad = before.copy(), np.zeros(n, bool), np.zeros(n, bool)
    frames = solved if frames_shared else kd.empty_decoded(n)
    decoded = frames._replace(positions=np.empty((n, N_JOINTS, 3)))
    k = kp.export_constants()
    shape = (n if rotations else 0, kp.N_EXPORT, 3, 3)
    with np.errstate(invalid="ignore"):
        posture_solved_rows(0, n, np.arange(n, dtype=np.int64), solved, kd.pose_arrays(poses),
                            lengths, decoded, frozen, newly_bad, positions, rotations,
                            np.empty(shape), np.zeros(shape), k.rest_hips, k.bvh_from_world,
                            k.rest2body, k.parents, np.empty((n, 0, 3)), False, frames_shared)
    assert list(np.flatnonzero(frozen)) == bad and list(np.flatnonzero(newly_bad)) == bad
    np.testing.assert_array_equal(positions[bad], before[bad])
    good = ~frozen
    np.testing.assert_array_equal(positions[good], solved.positions[good])
    for got, want in zip(decoded[1:], solved[1:], strict=True):
        np.testing.assert_array_equal(got, want)
