"""Sampling clips: exact on frames, smooth across loops with root motion carried, clamped ends."""

import numpy as np
import pytest

from conftest import MOTIONS_DIR
from ecs_anim.core.morphology import Morphology
from ecs_anim.core.normalized import decode
from ecs_anim.io.importing import import_bvh
from ecs_anim.motion import sampling
from ecs_anim.motion.sampling import ClipBank, sample, sample_root
from ecs_anim.runtime.playback_queue import start_clips
from ecs_anim.runtime.store import CharacterStore


@pytest.fixture(scope="module")
def bank():
    return ClipBank.from_motions({"idle": import_bvh(MOTIONS_DIR / "idle.bvh"),
                                  "walk": import_bvh(MOTIONS_DIR / "walk.bvh")})


def test_sampling_on_frame_times_gives_the_stored_frames(bank):
    walk = bank.index("walk")
    frames = np.array([0, 5, 131])
    poses = sample(bank, np.full(3, walk), frames / 30.0, np.zeros(3, bool))
    stored = bank.poses.take(bank.start[walk] + frames)
    for k, v in stored.arrays().items():
        np.testing.assert_allclose(getattr(poses, k), v, rtol=0, atol=1e-8, err_msg=k)


def test_looping_walk_carries_root_motion_without_a_jump(bank):
    walk = bank.index("walk")
    lengths = Morphology.preset("adult_male").lengths
    t = np.arange(0, 3 * 4.4, 1 / 60.0)  # three loops at 60 Hz (clip is 30 Hz)
    poses = sample(bank, np.full(t.size, walk), t, np.ones(t.size, bool))
    pelvis = decode(poses, lengths).positions[:, 0]
    step = np.linalg.norm(np.diff(pelvis, axis=0), axis=-1)
    speed = step * 60.0
    own = np.linalg.norm(np.diff(decode(bank.poses.take(slice(bank.start[walk], bank.start[walk]
                                                              + bank.n_frames[walk])), lengths)
                                 .positions[:, 0], axis=0), axis=-1) * 30.0
    assert speed.max() < own.max() + 0.02  # no jump at the loop points: as smooth as the clip
    assert pelvis[-1, 0] - pelvis[0, 0] == pytest.approx(3 * 4.4 * np.median(speed), rel=0.05)


def test_non_looping_clip_holds_its_last_pose(bank):
    idle = bank.index("idle")
    late = sample(bank, np.array([idle, idle]), np.array([100.0, 7.9667]), np.zeros(2, bool))
    last = bank.poses.take(np.array([bank.start[idle] + bank.n_frames[idle] - 1]))
    np.testing.assert_allclose(late.root_position[0], last.root_position[0])


def test_batch_of_mixed_clips_equals_single_samples(bank):
    rng = np.random.default_rng(3)
    clips = rng.integers(0, 2, 20)
    times = rng.uniform(0, 20, 20)
    loop = rng.random(20) < 0.5
    batched = sample(bank, clips, times, loop)
    for i in range(0, 20, 7):
        single = sample(bank, clips[i:i + 1], times[i:i + 1], loop[i:i + 1])
        for k, v in single.arrays().items():
            np.testing.assert_allclose(getattr(batched, k)[i], v[0], atol=1e-12)


def test_root_sample_is_the_whole_samples_root_bit_for_bit(bank):
    rng = np.random.default_rng(5)
    clips = rng.integers(0, 2, 30)
    times = rng.uniform(0, 20, 30)
    loop = rng.random(30) < 0.5
    whole = sample(bank, clips, times, loop)
    root_xy, root_heading = sample_root(bank, clips, times, loop)
    np.testing.assert_array_equal(root_xy, whole.root_position[:, :2])
    np.testing.assert_array_equal(root_heading, whole.root_heading)


def test_starting_a_clip_blends_no_whole_pose(bank, monkeypatch):
    """A trigger's clip start places the clip by its root: no pose is blended (no slerp) for it."""
    store = CharacterStore()
    store.add_rows(2, entity=np.arange(2))
    store.lengths[:] = Morphology.preset("adult_male").lengths
    blended = []
    monkeypatch.setattr(sampling, "blend", lambda *args: blended.append(args))
    rows = np.array([1])
    start_clips(store, bank, rows, np.array([bank.index("walk")]), np.array([0.4]),
                np.array([0.3]), np.array([True]))
    assert blended == []
    assert store.clip[1] == bank.index("walk") and store.fade_s[1] == pytest.approx(0.3)
