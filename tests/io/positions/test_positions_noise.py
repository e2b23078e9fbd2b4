"""Issue 34, item 1: joint positions as estimators produce them. 2 cm of Gaussian jitter on
every coordinate and bones breathing ±3 % import (``--lowpass 6``) to a body whose bones are
within 1 % of the clean file's, and play with no foot sliding on a 1.2 m and a 2.0 m body,
through the batch pipeline's scenario and metrics."""

from __future__ import annotations

import numpy as np
import pytest

from conftest import MOCAP_DIR, require_mocap
from ecs_anim.core.ground import Plane
from ecs_anim.core.skeleton import JOINT_INDEX, LENGTHS, N_JOINTS
from ecs_anim.io.export import play_on
from ecs_anim.io.export.positions import in_layout_axes, layout_positions
from ecs_anim.io.importing import import_bvh
from ecs_anim.io.position_layouts import HUMANML3D
from ecs_anim.io.positions import (
    PositionOptions,
    bone_noise_variance,
    import_positions,
    robust_bone_lengths,
    zero_lag_lowpass,
)
from ecs_anim.runtime.metrics import MetricsRecorder
from ecs_anim.scenario import build_simulation
from support.scenarios import clip_on_body

#: SMPL's kinematic tree over HumanML3D's 22 joints (parent of each, -1 for the pelvis).
SMPL_PARENTS = (-1, 0, 0, 0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 9, 9, 12, 13, 14, 16, 17, 18, 19)
JITTER_M = 0.02
BREATH = 0.03
#: Bones the file measures (HumanML3D has no hands or head top) at least this long are held
#: to 1 %: shorter ones are within the jitter's statistics, which no estimator beats
#: (:func:`test_a_short_bone_is_as_exact_as_its_jitter_allows`; measured on the 63 s dance, 1,890
#: frames: neck 6.5 cm -1.33 % at seed 34, over 12 seeds -0.13 % on average with a spread of
#: 0.80 %, 3 of 12 beyond 1 %); the ankle heights are no bone but the ankles' low height over the
#: floor, which jitter lowers (-8 to -10 %).
HELD_M = 0.1
MEASURED = [k for k, name in enumerate(LENGTHS)
            if not name.startswith(("ankle_height", "hand", "head"))]


def clean_and_noisy(clip: str, tmp_path, seed: int):
    """The clip in HumanML3D's layout, clean and with breathing bones and jitter, as files."""
    motion = import_bvh(MOCAP_DIR / clip)
    pose = play_on(motion, motion.source_morphology, True)
    clean = layout_positions(pose, motion.source_morphology.leg_length, HUMANML3D)
    rng = np.random.default_rng(seed)
    t = np.arange(len(clean)) / motion.fps
    noisy = clean.copy()
    for k, parent in enumerate(SMPL_PARENTS):
        if parent >= 0:  # each bone breathes at its own rate and phase
            breath = 1 + BREATH * np.sin(2 * np.pi * rng.uniform(0.3, 1.5) * t
                                         + rng.uniform(0, 2 * np.pi))
            noisy[:, k] = noisy[:, parent] + (clean[:, k] - clean[:, parent]) * breath[:, None]
    noisy += rng.normal(0.0, JITTER_M, noisy.shape)
    paths = tmp_path / "clean.npy", tmp_path / "noisy.npy"
    for path, array in zip(paths, (clean, noisy), strict=True):
        np.save(path, in_layout_axes(array, HUMANML3D))
    options = PositionOptions(layout="humanml3d", fps=motion.fps)
    return (import_positions(paths[0], options),
            import_positions(paths[1], PositionOptions("humanml3d", motion.fps, lowpass_hz=6.0)))


def test_jitter_and_breathing_keep_the_bones_within_one_percent(tmp_path):
    require_mocap()
    clean, noisy = clean_and_noisy("bandai_dance.bvh", tmp_path, seed=34)
    ref, got = clean.source_morphology.lengths, noisy.source_morphology.lengths
    for k in MEASURED:
        error = abs(got[k] / ref[k] - 1)
        if ref[k] >= HELD_M:
            assert error < 0.01, (LENGTHS[k], ref[k], got[k])
        assert error < 0.02, (LENGTHS[k], ref[k], got[k])
    assert noisy.info["positions"]["jitter_mm"] > 15  # the jitter is seen and said


@pytest.mark.parametrize("stature_m", [1.2, 2.0])
def test_jittered_walk_plays_without_foot_sliding(tmp_path, stature_m):
    require_mocap()
    _, noisy = clean_and_noisy("bandai_walk.bvh", tmp_path, seed=35)
    assert noisy.contacts().mean() > 0.4  # the feet are found planted through the jitter
    scenario = clip_on_body(noisy, stature_m, Plane())
    with build_simulation(scenario) as sim:
        metrics = MetricsRecorder(sim)
        for _ in range(round(scenario.duration_s * scenario.fps)):
            sim.step()
            metrics.record()
        figures = metrics.report()["characters"][0]
    assert figures["foot_sliding_mm_per_frame"]["max"] < 1.0, figures
    assert figures["ground_penetration_mm_max"] < 1.0, figures


def test_mocap_grade_positions_keep_their_bones(tmp_path):
    """Without --lowpass nothing is smoothed or rescaled (the clean file's bones are the BVH
    import's), and the import line's warning names jitter only where there is some."""
    require_mocap()
    clean, _ = clean_and_noisy("bandai_walk.bvh", tmp_path, seed=36)
    source = import_bvh(MOCAP_DIR / "bandai_walk.bvh")
    assert np.allclose(clean.source_morphology.lengths[MEASURED],
                       source.source_morphology.lengths[MEASURED], atol=1e-9)
    assert "warnings" not in clean.info
    again = import_positions(tmp_path / "noisy.npy", PositionOptions("humanml3d", clean.fps))
    assert "--lowpass" in again.info["warnings"][0]


def test_a_short_bone_is_as_exact_as_its_jitter_allows():
    """Issue 34's 1 % on a 6.5 cm neck under 2 cm of jitter is beyond what the data holds: each
    frame tells the bone's length only through the jitter along it (2.8 cm on a bone vector, two
    joints' worth), so over N frames no estimator does better than 2.8 cm / sqrt(N): 1.0 % of
    6.5 cm over the dance's 1,890 frames. Over 200 jitters of one motion, the import's estimate
    (low-pass, mean squared length less the noise it leaves) is unbiased (mean within 0.3 %) and
    as exact as that bound allows (spread within 20 % of it), and an estimator told the bone's
    true direction in every frame misses 1 % as often (over a quarter of the jitters)."""
    fps, n, neck_m = 30.0, 1890, 0.0646
    sigma_bone = JITTER_M * np.sqrt(2.0)  # per axis, on head - neck
    t = np.arange(n) / fps
    direction = np.stack([0.3 * np.cos(t), 0.3 * np.sin(t), np.ones(n)], axis=-1)
    direction /= np.linalg.norm(direction, axis=-1, keepdims=True)
    head = JOINT_INDEX["head"]
    ours, told = [], []
    for seed in range(200):
        jitter = np.random.default_rng(seed).normal(0.0, sigma_bone, (n, 3))
        positions = np.zeros((n, N_JOINTS, 3))
        positions[:, head] = neck_m * direction + jitter  # the neck joint at the origin
        noise = bone_noise_variance(positions, fps, 6.0)
        smooth = zero_lag_lowpass(positions, fps, 6.0)[0]
        ours.append(robust_bone_lengths(smooth, noise)[head] / neck_m - 1)
        told.append(np.mean(np.sum((neck_m * direction + jitter) * direction, axis=-1)) / neck_m - 1)
    bound = sigma_bone / np.sqrt(n) / neck_m
    assert abs(bound - 0.01) < 0.0005
    assert abs(np.mean(ours)) < 0.003, np.mean(ours)
    assert np.std(ours) < 1.2 * bound, (np.std(ours), bound)
    assert np.mean(np.abs(told) > 0.01) > 0.25
