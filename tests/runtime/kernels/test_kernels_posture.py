"""Compiled posture conversion and centre of mass (ecs_anim.runtime.kernels.posture, .com) equal the
numpy references (exporting.local_rotations, normalized.vertebrae, morphology.centres_of_mass,
and PostureConvert's numpy frozen rule).

On the same decoded pose the rotations agree to about 1e-15, straight limbs included (the limb
frames come from the pose's quaternions). In the whole tick, tiny differences upstream (1e-15 m)
pass through ground adaptation and the solver, which re-aim a nearly straight limb's half-plane
from its joint positions: there the twist is decided by rounding and frames may differ by about
2e-6 while every position agrees to 1e-9 m.
"""

from __future__ import annotations

import itertools

import numpy as np
import pytest

from conftest import MOTIONS_DIR
from ecs_anim.core.morphology import MASS_SEGMENTS, Morphology, centres_of_mass, segment_mass_table
from ecs_anim.core.normalized import decode, vertebrae
from ecs_anim.core.skeleton import JOINT_INDEX, N_JOINTS
from ecs_anim.io.export.skeleton import local_rotations
from ecs_anim.io.importing import import_bvh
from ecs_anim.runtime.kernels import com as kc
from ecs_anim.runtime.kernels import decode as kd
from ecs_anim.runtime.kernels import posture as kp
from support.solve import random_bodies, random_poses

TOL = 1e-9


def bent_poses(rng, n):
    poses = random_poses(rng, n)
    poses.leg_fraction = rng.uniform(0.3, 0.95, (n, 2))
    poses.arm_fraction = rng.uniform(0.3, 0.95, (n, 2))
    return poses


def test_local_rotations_match_numpy_on_random_bent_poses():
    rng = np.random.default_rng(1311)
    poses = bent_poses(rng, 200)
    pose = decode(poses, random_bodies(rng, 200))
    got = kp.local_rotations(pose)
    assert got.shape == (200, kp.N_EXPORT, 3, 3)
    np.testing.assert_allclose(got, local_rotations(pose), rtol=0, atol=TOL)


def test_local_rotations_match_numpy_on_straight_limbs():
    rng = np.random.default_rng(1312)
    poses = random_poses(rng, 200)
    poses.leg_fraction[::2] = 1.05  # fully straight (clamped)
    poses.arm_fraction[1::2] = 1.0
    pose = decode(poses, random_bodies(rng, 200))
    np.testing.assert_allclose(kp.local_rotations(pose), local_rotations(pose), rtol=0, atol=TOL)


@pytest.mark.parametrize("clip", ["walk.bvh", "dance.bvh", "reach.bvh"])
def test_local_rotations_match_numpy_on_shipped_clips(clip):
    poses = import_bvh(MOTIONS_DIR / clip).poses
    for name in ("child", "tall"):
        pose = decode(poses, Morphology.preset(name).lengths)
        np.testing.assert_allclose(kp.local_rotations(pose), local_rotations(pose), rtol=0,
                                   atol=TOL)


@pytest.mark.parametrize("count", [1, 3, 7, 12])
def test_vertebrae_match_numpy(count):
    rng = np.random.default_rng(1313 + count)
    poses = random_poses(rng, 100)
    lengths = random_bodies(rng, 100)
    np.testing.assert_allclose(kp.vertebrae(poses, lengths, count),
                               vertebrae(poses, lengths, count), rtol=0, atol=TOL)
    walk = import_bvh(MOTIONS_DIR / "walk.bvh").poses
    body = Morphology.preset("short_legs").lengths
    np.testing.assert_allclose(kp.vertebrae(walk, body, count), vertebrae(walk, body, count),
                               rtol=0, atol=TOL)


def numpy_posture(poses, lengths, frozen, positions, local, previous_spine, count):
    """PostureConvert's numpy rule: a row is frozen while its pose is not finite (it keeps its
    last good posture) and published again once it is; returns the new frozen, newly bad,
    positions, frames, local rotations and vertebrae."""
    final = decode(poses, lengths)
    good = np.all(np.isfinite(final.positions), axis=(1, 2))
    rot = local_rotations(final)
    good &= np.all(np.isfinite(rot), axis=(1, 2, 3))
    newly_bad = ~good & ~frozen
    frozen = ~good
    keep = frozen[:, None, None]
    positions = np.where(keep, positions, final.positions)
    local = np.where(keep[..., None], local, rot)
    spine = vertebrae(poses, lengths, count)
    spine = np.where(keep, spine if previous_spine is None else previous_spine, spine)
    return frozen, newly_bad, positions, final, local, spine


def test_posture_rows_keeps_the_last_good_posture_like_numpy():
    rng = np.random.default_rng(1314)
    n, count = 12, 5
    lengths = random_bodies(rng, n)
    k = kp.export_constants()
    frozen = np.zeros(n, bool)
    frozen[7] = True  # frozen before, its pose fine now: published again
    positions = rng.normal(size=(n, N_JOINTS, 3))
    local = np.broadcast_to(np.eye(3), (n, kp.N_EXPORT, 3, 3)).copy()
    spine = None
    for tick in range(3):
        poses = bent_poses(rng, n)
        if tick == 1:
            poses.thorax[3] = np.nan  # positions go bad
            poses.head[9, 0] = np.inf  # only the head's frame: the rotations go bad
        with np.errstate(invalid="ignore"):
            ref = numpy_posture(poses, lengths, frozen, positions, local, spine, count)
        decoded = kd.empty_decoded(n)
        newly_bad = np.zeros(n, bool)
        got_frozen, got_positions, got_local = frozen.copy(), positions.copy(), local.copy()
        got_spine = np.empty((n, count, 3)) if spine is None else spine.copy()
        kp.posture_rows(0, n, np.arange(n, dtype=np.int64), kd.pose_arrays(poses), lengths,
                        decoded, got_frozen, newly_bad, got_positions, True,
                        np.empty((n, kp.N_EXPORT, 3, 3)), got_local, k.rest_hips,
                        k.bvh_from_world, k.rest2body, k.parents, got_spine, spine is not None,
                        kd.spine_scratch(n))
        np.testing.assert_array_equal(got_frozen, ref[0])
        np.testing.assert_array_equal(newly_bad, ref[1])
        np.testing.assert_allclose(got_positions, ref[2], rtol=0, atol=TOL)
        good = ~ref[0]
        for name, a in zip(kd.DecodedArrays._fields[1:], decoded[1:], strict=True):
            np.testing.assert_allclose(a[good], getattr(ref[3], name)[good], rtol=0, atol=TOL)
        np.testing.assert_allclose(got_local, ref[4], rtol=0, atol=TOL)
        np.testing.assert_allclose(got_spine, ref[5], rtol=0, atol=TOL)
        frozen, positions, local, spine = ref[0], ref[2], ref[4], ref[5]
        # row 7 published again at once, rows 3 and 9 frozen on the bad tick only
        assert list(np.flatnonzero(frozen)) == ([3, 9] if tick == 1 else [])


def test_posture_rows_without_rotations_or_vertebrae_writes_positions_only():
    rng = np.random.default_rng(1315)
    n = 8
    poses = bent_poses(rng, n)
    lengths = random_bodies(rng, n)
    k = kp.export_constants()
    positions = np.zeros((n, N_JOINTS, 3))
    rows = np.array([1, 4, 6], dtype=np.int64)
    kp.posture_rows(0, rows.size, rows, kd.pose_arrays(poses), lengths, kd.empty_decoded(n),
                    np.zeros(n, bool), np.zeros(n, bool), positions, False,
                    np.empty((0, kp.N_EXPORT, 3, 3)), np.empty((0, kp.N_EXPORT, 3, 3)),
                    k.rest_hips, k.bvh_from_world, k.rest2body, k.parents, np.empty((n, 0, 3)),
                    False, kd.spine_scratch(rows.size))
    np.testing.assert_allclose(positions[rows], decode(poses, lengths).positions[rows], rtol=0,
                               atol=TOL)
    assert np.all(positions[np.setdiff1d(np.arange(n), rows)] == 0.0)


def test_centres_of_mass_match_numpy_for_some_rows():
    rng = np.random.default_rng(1316)
    n = 30
    bodies = [Morphology.from_stature(float(s), sex=str(x), mass_kg=float(m))
              for s, x, m in zip(rng.uniform(1.0, 2.0, n), rng.choice(["male", "female"], n),
                                 rng.uniform(20, 110, n), strict=True)]
    masses = np.stack([segment_mass_table(b)[0] for b in bodies])
    fraction = np.stack([segment_mass_table(b)[1] for b in bodies])
    positions = decode(random_poses(rng, n), np.stack([b.lengths for b in bodies])).positions
    ref = centres_of_mass(positions, masses, fraction)
    rows = np.array([2, 5, 11, 29, 0], dtype=np.int64)
    out = np.full((n, 3), np.nan)
    kc.centres_of_mass(0, rows.size, rows, rows, positions, masses, fraction, out)
    np.testing.assert_allclose(out[rows], ref[rows], rtol=0, atol=TOL)
    assert np.all(np.isnan(np.delete(out, rows, axis=0)))
    # Gathered positions (as the solver gives them): positions[i] belongs to rows[i].
    gathered = np.full((n, 3), np.nan)
    kc.centres_of_mass(0, rows.size, rows, np.arange(rows.size, dtype=np.int64), positions[rows],
                       masses, fraction, gathered)
    np.testing.assert_allclose(gathered[rows], ref[rows], rtol=0, atol=TOL)
    # COMControl's pass (in two chunks): the same centres, bit for bit, and their horizontal
    # distances from the desired ones.
    desired = rng.normal(size=(n, 3))
    com, error = np.full((n, 3), np.nan), np.full(n, np.nan)
    for lo, hi in ((0, 2), (2, rows.size)):
        kc.com_and_error_rows(lo, hi, rows, positions[rows], masses, fraction, desired, com,
                              error)
    assert np.array_equal(com.view(np.int64), gathered.view(np.int64))
    np.testing.assert_array_equal(error[rows], np.linalg.norm(com[rows, :2] - desired[rows, :2],
                                                              axis=1))
    assert np.all(np.isnan(np.delete(error, rows)))


def test_segment_joints_are_the_mass_segments():
    """The kernels' constant joints of each mass segment are those of MASS_SEGMENTS (a change
    there does not recompile the cached kernels: this test says so)."""
    assert kc.SEGMENT_JOINTS == tuple((JOINT_INDEX[proximal], JOINT_INDEX[distal])
                                      for _, proximal, distal, _ in MASS_SEGMENTS)


@pytest.mark.parametrize("rotations", [False, True])
def test_posture_rows_puts_back_frozen_rows_in_any_block_and_chunk(rotations):
    """The decode writes the store's positions where they are all finite (decode.finite_lanes);
    a row that turns out frozen keeps its positions before, whichever block of a chunk it is
    in, in chunks shorter than a block too (their own columns of the second set of block
    scratches), its positions NaN or infinite, with rotations or without (with them each chunk
    sets a block aside in its own first rows of the scratch, for a row whose rotations only
    are not finite: test_solved_posture's)."""
    rng = np.random.default_rng(1316)
    n = 3 * 32 + 5
    poses = bent_poses(rng, n)
    lengths = random_bodies(rng, n)
    poses.thorax[[3, 40, 77, 99]] = np.nan
    poses.root_position[19, 2] = np.inf
    bad = [3, 19, 40, 77, 99]
    k = kp.export_constants()
    before = rng.normal(size=(n, N_JOINTS, 3))
    with np.errstate(invalid="ignore"):
        fresh = decode(poses, lengths).positions
    rows = np.arange(n, dtype=np.int64)
    world = np.empty((n if rotations else 0, kp.N_EXPORT, 3, 3))
    for bounds in ((0, n), (0, 37, 70, n), (0, 20, 45, 45 + 32 + 3, n)):  # one chunk, more
        positions, frozen, newly_bad = before.copy(), np.zeros(n, bool), np.zeros(n, bool)
        scratch, decoded = kd.spine_scratch(n), kd.empty_decoded(n)
        local = np.zeros((n if rotations else 0, kp.N_EXPORT, 3, 3))
        for lo, hi in itertools.pairwise(bounds):
            kp.posture_rows(lo, hi, rows, kd.pose_arrays(poses), lengths, decoded, frozen,
                            newly_bad, positions, rotations, world, local, k.rest_hips,
                            k.bvh_from_world, k.rest2body, k.parents, np.empty((n, 0, 3)), False,
                            scratch)
        assert list(np.flatnonzero(frozen)) == bad and list(np.flatnonzero(newly_bad)) == bad
        np.testing.assert_array_equal(positions[bad], before[bad])
        good = ~frozen
        np.testing.assert_allclose(positions[good], fresh[good], rtol=0, atol=TOL)
