"""Compiled decode (ecs_anim.runtime.kernels.decode) equals the numpy reference (normalized.decode)."""

from __future__ import annotations

import numpy as np
import pytest

from conftest import MOCAP_DIR, MOTIONS_DIR, require_mocap
from ecs_anim.core.morphology import Morphology
from ecs_anim.core.normalized import DecodedPose, NormalizedPoses, decode, decode_legs
from ecs_anim.io.importing import import_bvh
from ecs_anim.runtime.kernels import available_threads, over_chunks, set_threads
from ecs_anim.runtime.kernels import decode as kd
from ecs_anim.runtime.kernels import threads as threads_now
from ecs_anim.runtime.kernels.lanes import BLOCK
from support.solve import random_bodies, random_poses

FIELDS = ("positions", "pelvis2world", "thorax2world", "head2world", "leg2world", "arm2world")
TOL = 1e-9


def assert_same(got: DecodedPose, ref: DecodedPose) -> None:
    for name in FIELDS:
        a, b = getattr(got, name), getattr(ref, name)
        assert a.shape == b.shape, name
        np.testing.assert_allclose(a, b, rtol=0, atol=TOL, err_msg=name)


def test_random_poses_on_random_bodies_match_numpy():
    rng = np.random.default_rng(1301)
    poses = random_poses(rng, 300)
    lengths = random_bodies(rng, 300)
    assert_same(kd.decode(poses, lengths), decode(poses, lengths))


def test_one_body_for_all_rows_and_out_written_in_place():
    rng = np.random.default_rng(1302)
    poses = random_poses(rng, 50)
    body = Morphology.from_stature(1.62).lengths
    out = DecodedPose(*(np.full_like(a, np.nan) for a in kd.empty_decoded(50)))
    result = kd.decode(poses, body, out)
    assert result is out
    assert_same(out, decode(poses, body))


def test_decode_rows_writes_only_its_rows():
    rng = np.random.default_rng(1303)
    poses = random_poses(rng, 40)
    lengths = random_bodies(rng, 40)
    arrays = kd.empty_decoded(40)
    for a in arrays:
        a.fill(np.nan)
    rows = np.array([3, 17, 39, 0], dtype=np.int64)
    kd.decode_rows(0, rows.size, rows, kd.pose_arrays(poses), lengths, arrays,
                   kd.spine_scratch(rows.size))
    ref = decode(poses, lengths)
    untouched = np.setdiff1d(np.arange(40), rows)
    for name, a in zip(FIELDS, arrays, strict=True):
        np.testing.assert_allclose(a[rows], getattr(ref, name)[rows], rtol=0, atol=TOL)
        assert np.all(np.isnan(a[untouched]))


def test_decode_legs_row_matches_numpy():
    rng = np.random.default_rng(1304)
    poses = random_poses(rng, 20)
    seg = random_bodies(rng, 20)
    base = random_bodies(rng, 20)
    ref = decode_legs(poses, seg, base)
    pose = kd.pose_arrays(poses)
    for c in range(20):
        pelvis, pelvis2world, hips, knees, ankles, toes, legs, shanks = kd.decode_legs_row(
            c, pose, seg[c], base[c])
        np.testing.assert_allclose(pelvis, ref.pelvis[c], rtol=0, atol=TOL)
        # Frames as tuples of their axes (columns).
        np.testing.assert_allclose(np.array(pelvis2world).T, ref.pelvis2world[c], rtol=0, atol=TOL)
        for got, want in ((hips, ref.hips), (knees, ref.knees), (ankles, ref.ankles),
                          (toes, ref.toes)):
            np.testing.assert_allclose(np.array(got), want[c], rtol=0, atol=TOL)
        for s in range(2):
            np.testing.assert_allclose(np.array(legs[s]).T, ref.leg2world[c, s], rtol=0, atol=TOL)
            np.testing.assert_allclose(np.array(shanks[s]).T, ref.shank2world[c, s], rtol=0,
                                       atol=TOL)


def test_leg_pose_arrays_are_the_poses_own():
    pose = kd.pose_arrays(random_poses(np.random.default_rng(1308), 4))
    legs = kd.leg_pose_arrays(pose)
    assert set(legs._fields) <= set(pose._fields)
    assert all(getattr(legs, k) is getattr(pose, k) for k in legs._fields)


@pytest.mark.parametrize("clip", ["walk.bvh", "dance.bvh", "kick.bvh"])
def test_shipped_clips_on_several_bodies_match_numpy(clip):
    poses = import_bvh(MOTIONS_DIR / clip).poses
    for name in ("child", "adult_female", "tall", "long_legs", "short_legs"):
        body = Morphology.preset(name).lengths
        assert_same(kd.decode(poses, body), decode(poses, body))


def test_real_captured_clips_on_several_bodies_match_numpy():
    require_mocap()
    rng = np.random.default_rng(1305)
    for path in sorted(MOCAP_DIR.glob("*.bvh"))[:4]:
        poses = import_bvh(path).poses
        n = poses.batch_shape[0]
        lengths = random_bodies(rng, n)
        assert_same(kd.decode(poses, lengths), decode(poses, lengths))


def test_pose_arrays_and_decoded_pose_share_memory():
    rng = np.random.default_rng(1306)
    poses = random_poses(rng, 5)
    pose = kd.pose_arrays(poses)
    assert pose._fields == tuple(poses.arrays())
    assert all(np.shares_memory(a, getattr(poses, k))
               for k, a in zip(pose._fields, pose, strict=True))
    arrays = kd.empty_decoded(5)
    decoded = kd.decoded_pose(arrays)
    assert all(a is b for a, b in zip(kd.decoded_arrays(decoded), arrays, strict=True))
    assert kd.fits(decoded, 5) and not kd.fits(decoded, 6) and not kd.fits(None, 5)


def test_the_kernels_tuples_name_the_dataclasses_fields_in_order():
    """PoseArrays / DecodedArrays are built positionally from the dataclasses (numba needs the
    tuples spelled out): a field added to one side only would shift every array after it."""
    from dataclasses import fields

    from ecs_anim.core.normalized import DecodedPose
    from ecs_anim.runtime.kernels.decode import DecodedArrays, PoseArrays

    assert PoseArrays._fields == tuple(f.name for f in fields(NormalizedPoses))
    assert DecodedArrays._fields == tuple(f.name for f in fields(DecodedPose))


def decoded_in_chunks(pose: kd.PoseArrays, lengths: np.ndarray, rows: np.ndarray,
                      chunks: tuple[tuple[int, int], ...]) -> kd.DecodedArrays:
    """decode_rows over ``rows`` split into ``chunks`` (lo, hi), one scratch for all."""
    out, scratch = kd.empty_decoded(rows.size), kd.spine_scratch(rows.size)
    for lo, hi in chunks:
        kd.decode_rows(lo, hi, rows, pose, lengths, out, scratch)
    return out


def decoded_row_by_row(pose: kd.PoseArrays, lengths: np.ndarray) -> kd.DecodedArrays:
    """decode_row (the solver's, the reference of decode_rows' blocks) on every row."""
    from numba import njit

    @njit(error_model="numpy")
    def one_row_at_a_time(pose, lengths, out):
        for c in range(lengths.shape[0]):
            kd.decode_row(c, pose, lengths[c], out)

    out = kd.empty_decoded(lengths.shape[0])
    one_row_at_a_time(pose, lengths, out)
    return out


def test_decode_rows_by_blocks_does_not_depend_on_the_chunks_and_equals_the_row_decode():
    """decode_rows decodes the spines of a block of characters together (lanes.BLOCK at a time,
    stopping the block's Newton iteration once all its spines have converged): any split of
    the rows into chunks, none a multiple of the block, gives the same bits, and so does the
    decode of one row at a time (decode_row, the solver's)."""
    rng = np.random.default_rng(1309)
    n = 3 * BLOCK + 5
    poses = random_poses(rng, n)
    lengths = random_bodies(rng, n)
    rows = rng.permutation(n).astype(np.int64)
    pose = kd.pose_arrays(poses)
    whole = decoded_in_chunks(pose, lengths, rows, ((0, n),))
    chunked = decoded_in_chunks(pose, lengths, rows, ((0, 7), (7, 40), (40, 41), (41, n)))
    by_row = decoded_row_by_row(pose, lengths)
    for name, a, b, c in zip(FIELDS, whole, chunked, by_row, strict=True):
        np.testing.assert_array_equal(a, b, err_msg=name)
        np.testing.assert_array_equal(a, c, err_msg=name)
    assert_same(kd.decoded_pose(whole), decode(poses, lengths))


def test_zero_quaternions_decode_as_no_turn_like_numpy():
    """A zero quaternion is no turn in numpy's matrix_from_quat (normalized by at least TINY):
    the decode's frames composed as quaternion products (decode.world_quat) keep the parent's
    frame there too, whichever rotation is zero."""
    rng = np.random.default_rng(1310)
    poses = random_poses(rng, 6)
    lengths = random_bodies(rng, 6)
    poses.pelvis_local[0] = 0.0
    poses.leg_frame[1, 0] = 0.0
    poses.thorax[2] = 0.0
    poses.head[3] = 0.0
    poses.arm_frame[4, 1] = 0.0
    poses.leg_frame[5] = 0.0
    poses.arm_frame[5] = 0.0
    assert_same(kd.decode(poses, lengths), decode(poses, lengths))


def test_decode_block_equals_the_row_decode_bit_for_bit_on_edge_poses():
    """decode_rows runs the whole decode by blocks on the vector units (decode_block: gathered,
    the pelvis and legs, the spines and the upper body in loops over the block, put back): the
    same bits as decode_row, the row by row reference, on poses with zero quaternions, straight
    and folded limbs, bones of no length and a NaN; in a short chunk across a multiple of the
    block (its own columns of the second set of block scratches), a chunk not starting on a
    multiple of the block with a block not full, and a whole one."""
    rng = np.random.default_rng(1311)
    n = 4 * BLOCK + 9
    poses = random_poses(rng, n)
    lengths = random_bodies(rng, n)
    poses.pelvis_local[1] = 0.0
    poses.leg_frame[2, 1] = 0.0
    poses.thorax[3] = 0.0
    poses.head[4] = 0.0
    poses.arm_frame[5, 0] = 0.0
    poses.leg_fraction[6] = 1.0
    poses.arm_fraction[7] = 0.0
    poses.leg_fraction[8] = 3.0
    lengths[9, 4] = 0.0  # a shank
    lengths[10, 19] = 0.0  # a forearm
    poses.hip_dir[11, 0, 1] = np.nan
    poses.spine_points[12] = 0.0
    rows = rng.permutation(n).astype(np.int64)
    pose = kd.pose_arrays(poses)
    blocks = decoded_in_chunks(pose, lengths, rows,
                               ((0, 20), (20, 45), (45, 45 + BLOCK + 3), (45 + BLOCK + 3, n)))
    by_row = decoded_row_by_row(pose, lengths)
    for name, a, b in zip(FIELDS, blocks, by_row, strict=True):
        np.testing.assert_array_equal(a, b, err_msg=name)
    assert np.isnan(blocks.positions[11]).any() and np.isfinite(blocks.positions[:11]).all()


def test_a_spine_that_never_converges_leaves_its_block_mates_as_they_decode_alone():
    """A NaN spine never converges: its block's Newton iteration runs to the end for it (the
    others keep their converged parameters). decode_rows over every row gives the bits of
    decode_row row by row, and the NaN row's block-mates the bits they have without it (the
    NaN row's own joints finite: a spine joint with no direction goes up, at_distance)."""
    rng = np.random.default_rng(1312)
    n = 2 * BLOCK + 5
    poses = random_poses(rng, n)
    lengths = random_bodies(rng, n)
    rows = np.arange(n, dtype=np.int64)
    finite = decoded_in_chunks(kd.pose_arrays(poses), lengths, rows, ((0, n),))
    stuck = BLOCK + 7  # inside the second block
    poses.spine_points[stuck] = np.nan
    pose = kd.pose_arrays(poses)
    whole = decoded_in_chunks(pose, lengths, rows, ((0, n),))
    by_row = decoded_row_by_row(pose, lengths)
    others = rows != stuck
    for name, a, b, c in zip(FIELDS, whole, by_row, finite, strict=True):
        np.testing.assert_array_equal(a, b, err_msg=name)
        np.testing.assert_array_equal(a[others], c[others], err_msg=name)
    assert np.isfinite(whole.positions).all()
    assert not np.array_equal(whole.positions[stuck], finite.positions[stuck])


def newton_steps(poses: NormalizedPoses, lengths: np.ndarray, c: int) -> list[int]:
    """The Newton steps spine_joint takes for each of row ``c``'s three spine joints (its loop
    in Python on the compiled curve_at): 0 where the first guess is at the length already."""
    seg = lengths[c]
    spine_len = seg[10] + seg[11] + seg[12]
    p = [(float(x), float(y), float(z)) for x, y, z in poses.spine_points[c] * spine_len]
    control = ((0.0, 0.0, 0.0), p[0], p[1], p[2])
    chords = [np.linalg.norm(np.subtract(control[k + 1], control[k])) for k in range(3)]
    t, prev = 0.0, np.array(control[0])
    steps = []
    for k in range(3):
        length, prev_t = seg[10 + k], t
        t = prev_t + length / max(chords[k], 1e-9)
        taken = 0
        for _ in range(6):
            point, tangent = map(np.array, kd.curve_at(control, t))
            d = point - prev
            g = d @ d - length**2
            if abs(g) <= 1e-13 * length**2:
                break
            slope = 2.0 * (d @ tangent)
            t = min(max(t - (g / slope if abs(slope) > 1e-12 else 0.0), prev_t + 1e-6), 9.0)
            taken += 1
        point, tangent = map(np.array, kd.curve_at(control, t))
        prev = np.array(kd.at_distance(tuple(prev), tuple(point), tuple(tangent), length))
        steps.append(taken)
    return steps


@pytest.mark.parametrize("threads", [1, 2])
def test_spines_converging_unevenly_in_a_block_give_the_row_decode_bits(threads):
    """spine_joint_lanes passes over the whole block while many of its spines still move, then
    finishes the few left one by one: blocks where a few spines take more Newton steps than
    the rest, a block where most do, a NaN spine (never converging: its passes run out) and
    pieces too short for a pass over the block, on one and two threads and on chunks that
    cross blocks, all give decode_row's bits row by row."""
    if threads > available_threads():
        pytest.skip("one core")
    rng = np.random.default_rng(1313)
    n = 4 * BLOCK + 11
    poses = random_poses(rng, n)
    lengths = random_bodies(rng, n)
    rising = np.array([[0.0, 0.0, 1 / 3], [0.0, 0.0, 2 / 3], [0.0, 0.0, 1.0]])
    poses.spine_points[:] = rising + rng.normal(scale=0.02, size=(n, 3, 3))  # one or two steps
    bent = np.r_[3, 17, 29, 2 * BLOCK:3 * BLOCK]  # a few in the first block, the whole third
    poses.spine_points[bent] = rising + rng.normal(scale=0.35, size=(bent.size, 3, 3))
    poses.spine_points[BLOCK + 5] = np.nan
    steps = np.array([newton_steps(poses, lengths, c) for c in range(n)])
    first = steps[:BLOCK].max(axis=1)
    assert 0 < (first > np.median(first)).sum() <= 8  # few moving longer than the rest
    assert (steps[2 * BLOCK:3 * BLOCK].max(axis=1) >= 3).sum() > 8  # many moving long
    pose = kd.pose_arrays(poses)
    by_row = decoded_row_by_row(pose, lengths)
    rows = np.arange(n, dtype=np.int64)
    before = threads_now()
    try:
        set_threads(threads)
        out = kd.empty_decoded(n)
        over_chunks(kd.decode_rows, n, rows, pose, lengths, out, kd.spine_scratch(n),
                    rows_per_thread=1)
    finally:
        set_threads(before)
    chunks = decoded_in_chunks(pose, lengths, rows, ((0, 5), (5, BLOCK + 3), (BLOCK + 3, n)))
    for name, a, b, c in zip(FIELDS, out, chunks, by_row, strict=True):
        np.testing.assert_array_equal(a, c, err_msg=name)
        np.testing.assert_array_equal(b, c, err_msg=name)
    assert np.isfinite(out.positions).all()


def test_decode_into_an_out_not_contiguous_writes_it_like_a_contiguous_one():
    """The kernels write C-contiguous arrays (flat views, scatter_block): decode into an ``out``
    that is not (a view with a step) decodes aside and copies, and fits says no to it."""
    rng = np.random.default_rng(1314)
    n = BLOCK + 3
    poses = random_poses(rng, n)
    lengths = random_bodies(rng, n)
    wide = kd.decoded_pose(kd.empty_decoded(2 * n))
    strided = DecodedPose(*(a[::2] for a in kd.decoded_arrays(wide)))
    assert not kd.fits(strided, n) and kd.fits(kd.empty_decoded(n), n)
    assert kd.decode(poses, lengths, out=strided) is strided
    for name, a, b in zip(FIELDS, kd.decoded_arrays(strided),
                          kd.decoded_arrays(kd.decode(poses, lengths)), strict=True):
        np.testing.assert_array_equal(a, b, err_msg=name)
