"""PostureConvert takes the solver's decoded pose for the characters it moved (decoded once per
tick): the posture equals a fresh decode of the final poses to 1e-9 m, rotations included."""

from __future__ import annotations

import dataclasses

import numpy as np

import ecs_anim.systems.posture_convert as posture_convert
from ecs_anim.core.normalized import DecodedPose, decode
from ecs_anim.io.export.skeleton import local_rotations
from ecs_anim.runtime.bench_scene import BenchScene
from ecs_anim.runtime.kernels.solved_posture import posture_solved_rows
from support.scenarios import run


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
