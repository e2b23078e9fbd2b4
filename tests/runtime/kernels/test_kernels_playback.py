"""Compiled playback equals the numpy playback (sample, placement, contact weights, fades) on
the shipped motions, to 1e-9."""

from __future__ import annotations

import numpy as np
import pytest

from ecs_anim.components import MotionPlayer, Placement, QueuedClip
from ecs_anim.core.morphology import Morphology, leg_length
from ecs_anim.core.normalized import QUATERNION_FIELDS, NormalizedPoses
from ecs_anim.core.skeleton import N_LENGTHS
from ecs_anim.io.importing import import_bvh
from ecs_anim.io.library import MOTIONS_DIR
from ecs_anim.motion.sampling import (
    ClipBank,
    blend,
    rotate_xy,
    sample,
    sample_table,
    wrap_angle,
)
from ecs_anim.runtime import kernels
from ecs_anim.runtime.kernels.decode import pose_arrays
from ecs_anim.runtime.kernels.lanes import BLOCK
from ecs_anim.runtime.kernels.playback import (
    PlaybackWork,
    advance_clocks,
    blend_root,
    blend_rows,
    complex_power,
    first_of_each_sample,
    place_rows,
    playback_bank,
    sample_placed,
    sample_rows,
)
from ecs_anim.runtime.simulation import Simulation
from ecs_anim.systems import MotionPlayback


@pytest.fixture(scope="module")
def bank() -> ClipBank:
    motions = {p.stem: import_bvh(p) for p in sorted(MOTIONS_DIR.glob("*.bvh"))}
    return ClipBank.from_motions(motions)


def _placed(poses: NormalizedPoses, xy: np.ndarray, heading: np.ndarray,
            leg: np.ndarray) -> NormalizedPoses:
    """MotionPlayback._placed, the numpy reference."""
    root = poses.root_position.copy()
    root[:, :2] = (rotate_xy(root[:, :2] * leg[:, None], heading) + xy) / leg[:, None]
    poses.root_position = root
    poses.root_heading = poses.root_heading + heading
    return poses


def _empty(n: int, like: NormalizedPoses) -> NormalizedPoses:
    return NormalizedPoses(**{k: np.full((n,) + v.shape[1:], np.nan)
                              for k, v in like.arrays().items()})


def _assert_poses_equal(got: NormalizedPoses, want: NormalizedPoses) -> None:
    for name, w in want.arrays().items():
        g = getattr(got, name)
        if name in QUATERNION_FIELDS:  # q and -q are one rotation
            sign = np.where(np.sum(g * w, axis=-1, keepdims=True) < 0.0, -1.0, 1.0)
            g = g * sign
        np.testing.assert_allclose(g, w, rtol=0, atol=1e-9, err_msg=name)


def _scene(bank: ClipBank, rng: np.random.Generator, n: int):
    clip = rng.integers(0, len(bank.names), n).astype(np.int64)
    period = bank.duration_s(clip)
    # Inside the clip, past its end (loops, or held), before its start, and exactly on frames;
    # a quarter of the characters in step with another (the same clip, time and loop).
    time_s = period * rng.choice([rng.uniform(0, 1), rng.uniform(1, 40), rng.uniform(-3, 0)], n)
    time_s[n // 2:] = period[n // 2:] * rng.uniform(-3, 40, n - n // 2)
    time_s[: n // 8] = np.round(time_s[: n // 8] * 30.0) / 30.0
    loop = rng.random(n) < 0.6
    in_step = rng.choice(n, n // 4)
    clip[-(n // 4):], time_s[-(n // 4):], loop[-(n // 4):] = (clip[in_step], time_s[in_step],
                                                               loop[in_step])
    xy = rng.uniform(-20.0, 20.0, (n, 2))
    heading = rng.uniform(-7.0, 7.0, n)
    lengths = rng.uniform(0.15, 0.55, (n, N_LENGTHS))
    return clip, time_s, loop, xy, heading, lengths


def _reference(bank: ClipBank, clip: np.ndarray, time_s: np.ndarray, loop: np.ndarray,
               xy: np.ndarray, heading: np.ndarray, lengths: np.ndarray):
    """MotionPlayback.run_numpy's poses (the capture ground taken out), contact weights and
    sole rolls."""
    poses = _placed(sample(bank, clip, time_s, loop), xy, heading, leg_length(lengths))
    poses.root_position[:, 2] -= sample_table(bank, bank.capture_ground, clip, time_s, loop)[:, 0]
    return (poses, sample_table(bank, bank.contact_weight, clip, time_s, loop),
            sample_table(bank, bank.sole_roll, clip, time_s, loop))


def _compiled(bank: ClipBank, rows: np.ndarray, clip: np.ndarray, time_s: np.ndarray,
              loop: np.ndarray, xy: np.ndarray, heading: np.ndarray, lengths: np.ndarray,
              out: NormalizedPoses, out_rows: np.ndarray):
    """sample_placed of ``rows`` into ``out_rows`` of ``out``: (contact weights, sole rolls),
    NaN outside ``rows``."""
    n = clip.shape[0]
    weights, rolls = np.full((n, 2), np.nan), np.full((n, 2), np.nan)
    sample_placed(playback_bank(bank), rows, clip, time_s, loop, xy, heading, lengths,
                  pose_arrays(out), out_rows, weights, rolls, PlaybackWork())
    return weights, rolls


def test_sample_placed_equals_numpy(bank: ClipBank) -> None:
    rng = np.random.default_rng(1311)
    n = 400
    clip, time_s, loop, xy, heading, lengths = _scene(bank, rng, n)
    want, want_weights, want_rolls = _reference(bank, clip, time_s, loop, xy, heading, lengths)
    got = _empty(n, want)
    rows = np.arange(n, dtype=np.int64)
    weights, rolls = _compiled(bank, rows, clip, time_s, loop, xy, heading, lengths, got, rows)
    _assert_poses_equal(got, want)
    np.testing.assert_allclose(weights, want_weights, rtol=0, atol=1e-12)
    np.testing.assert_allclose(rolls, want_rolls, rtol=0, atol=1e-12)


def test_only_the_given_rows_are_written(bank: ClipBank) -> None:
    rng = np.random.default_rng(1312)
    n = 50
    clip, time_s, loop, xy, heading, lengths = _scene(bank, rng, n)
    want, want_weights, _ = _reference(bank, clip, time_s, loop, xy, heading, lengths)
    rows = np.flatnonzero(rng.random(n) < 0.5).astype(np.int64)
    got = _empty(rows.size, want)
    weights, _ = _compiled(bank, rows, clip, time_s, loop, xy, heading, lengths, got,
                           np.arange(rows.size, dtype=np.int64))
    _assert_poses_equal(got, want.take(rows))
    np.testing.assert_allclose(weights[rows], want_weights[rows], rtol=0, atol=1e-12)
    assert np.isnan(np.delete(weights, rows, axis=0)).all()


def test_long_loops_carry_root_motion_as_numpy(bank: ClipBank) -> None:
    rng = np.random.default_rng(1313)
    n = 200
    clip = np.full(n, bank.index("walk"), dtype=np.int64)
    time_s = bank.duration_s(clip) * rng.uniform(0, 5000, n)  # up to 5000 loops
    loop = np.ones(n, bool)
    xy, heading = np.zeros((n, 2)), np.zeros(n)
    lengths = np.full((n, N_LENGTHS), 0.45)  # legs of 0.9 m
    want, _, _ = _reference(bank, clip, time_s, loop, xy, heading, lengths)
    got = _empty(n, want)
    rows = np.arange(n, dtype=np.int64)
    _compiled(bank, rows, clip, time_s, loop, xy, heading, lengths, got, rows)
    np.testing.assert_allclose(got.root_position * 0.9, want.root_position * 0.9, rtol=0,
                               atol=1e-9)
    _assert_poses_equal(got, want)


def test_every_sample_its_own_equals_numpy(bank: ClipBank) -> None:
    """A crowd of which no two characters are in step (the bench's): no pose is copied
    (``place_rows``' copies skipped), and every row is numpy's, its weights and rolls too."""
    rng = np.random.default_rng(1321)
    n = 3 * BLOCK + 7
    clip, _, loop, xy, heading, lengths = _scene(bank, rng, n)
    time_s = bank.duration_s(clip) * rng.uniform(-3.0, 40.0, n)
    rows = rng.permutation(n).astype(np.int64)
    work = PlaybackWork()
    work.ensure(n)
    assert first_of_each_sample(rows, clip, time_s.view(np.int64), loop, work.table,
                                work.first, work.unique) == n
    want, want_weights, want_rolls = _reference(bank, clip, time_s, loop, xy, heading, lengths)
    got = _empty(n, want)
    weights, rolls = _compiled(bank, rows, clip, time_s, loop, xy, heading, lengths, got, rows)
    _assert_poses_equal(got, want)
    np.testing.assert_allclose(weights, want_weights, rtol=0, atol=1e-12)
    np.testing.assert_allclose(rolls, want_rolls, rtol=0, atol=1e-12)


def test_characters_in_step_share_one_sample(bank: ClipBank) -> None:
    """Characters playing the same clip from the same time with the same loop flag are
    sampled once: the groups are those of the keys, and each character's pose is the bits it
    gets sampled alone."""
    rng = np.random.default_rng(1320)
    n = 300
    clip, time_s, loop, xy, heading, lengths = _scene(bank, rng, n)
    rows = rng.permutation(n).astype(np.int64)
    work = PlaybackWork()
    work.ensure(n)
    m = first_of_each_sample(rows, clip, time_s.view(np.int64), loop, work.table, work.first,
                             work.unique)
    keys = [(int(clip[c]), float(time_s[c]), bool(loop[c])) for c in rows]
    assert m == len(set(keys)) < n
    first = work.first[:n]
    assert [keys[f] for f in first] == keys
    assert all(keys.index(keys[i]) == f for i, f in enumerate(first))
    together = _empty(n, sample(bank, clip[:1], time_s[:1], loop[:1]))
    _compiled(bank, rows, clip, time_s, loop, xy, heading, lengths, together, rows)
    alone = _empty(n, together)
    for c in rows[:40]:
        one = np.array([c], dtype=np.int64)
        _compiled(bank, one, clip, time_s, loop, xy, heading, lengths, alone, one)
    for name, a in together.arrays().items():
        np.testing.assert_array_equal(getattr(alone, name)[rows[:40]], a[rows[:40]],
                                      err_msg=name)


def test_sample_placed_does_not_depend_on_the_chunks(bank: ClipBank) -> None:
    """The slerps' weights are computed by blocks of lanes.BLOCK samples on the vector
    units: any split of the samples and of the rows into chunks, none a multiple of the block,
    gives the same bits."""
    rng = np.random.default_rng(1319)
    n = 8 * BLOCK + 5
    clip, time_s, loop, xy, heading, lengths = _scene(bank, rng, n)
    rows = rng.permutation(n).astype(np.int64)
    like = sample(bank, clip[:1], time_s[:1], loop[:1])
    whole, chunked = _empty(n, like), _empty(n, like)
    _compiled(bank, rows, clip, time_s, loop, xy, heading, lengths, whole, rows)
    pbank, work = playback_bank(bank), PlaybackWork()
    work.ensure(n, pbank, n)
    m = first_of_each_sample(rows, clip, time_s.view(np.int64), loop, work.table, work.first,
                             work.unique)
    assert m > 3 * BLOCK
    weights, rolls = np.zeros((n, 2)), np.zeros((n, 2))
    placing = (False, xy, heading, lengths, weights, rolls, work.heading_key, work.heading_turn)
    for lo, hi in ((0, 7), (7, 40), (40, 41), (41, m)):
        sample_rows(lo, hi, work.unique, rows, pbank, clip, time_s, loop, pose_arrays(chunked),
                    rows, work.scratch, work.lanes, work.loop_clip, work.loop_count,
                    work.loop_turn, *placing)
    for lo, hi in ((0, 33), (33, 34), (34, n)):
        place_rows(lo, hi, rows, work.first, xy, heading, lengths, pose_arrays(chunked), rows,
                   work.scratch, weights, rolls, work.heading_key, work.heading_turn)
    for name, a in whole.arrays().items():
        np.testing.assert_array_equal(getattr(chunked, name), a, err_msg=name)


def test_rows_placed_as_sampled_do_not_depend_on_the_chunks(bank: ClipBank) -> None:
    """Every sample its own (the bench's crowd): sample_rows places each row itself, in any
    chunks (none a multiple of the block, one crossing a block's end), on one or two
    threads, to the bits of sample_placed's whole call, rows placed at NaN too."""
    rng = np.random.default_rng(1323)
    n = 3 * BLOCK + 5
    clip, _, loop, xy, heading, lengths = _scene(bank, rng, n)
    time_s = bank.duration_s(clip) * rng.uniform(-3.0, 40.0, n)
    heading[7], xy[9, 0] = np.nan, np.nan
    rows = rng.permutation(n).astype(np.int64)
    like = sample(bank, clip[:1], time_s[:1], loop[:1])
    whole, chunked = _empty(n, like), _empty(n, like)
    want_weights, want_rolls = _compiled(bank, rows, clip, time_s, loop, xy, heading, lengths,
                                         whole, rows)
    pbank, work = playback_bank(bank), PlaybackWork()
    work.ensure(n, pbank, n)
    assert first_of_each_sample(rows, clip, time_s.view(np.int64), loop, work.table, work.first,
                                work.unique) == n
    weights, rolls = np.full((n, 2), np.nan), np.full((n, 2), np.nan)
    for lo, hi in ((0, 7), (7, 40), (40, 41), (41, n)):
        sample_rows(lo, hi, work.unique, rows, pbank, clip, time_s, loop, pose_arrays(chunked),
                    rows, work.scratch, work.lanes, work.loop_clip, work.loop_count,
                    work.loop_turn, True, xy, heading, lengths, weights, rolls,
                    work.heading_key, work.heading_turn)
    for name, a in whole.arrays().items():
        np.testing.assert_array_equal(getattr(chunked, name).view(np.int64), a.view(np.int64),
                                      err_msg=name)
    np.testing.assert_array_equal(weights, want_weights)
    np.testing.assert_array_equal(rolls, want_rolls)
    assert np.isnan(whole.root_position[7, :2]).all() and np.isnan(whole.root_position[9, 0])
    try:
        for count in range(1, min(2, kernels.available_threads()) + 1):
            kernels.set_threads(count)
            threaded = _empty(n, like)
            _compiled(bank, rows, clip, time_s, loop, xy, heading, lengths, threaded, rows)
            for name, a in whole.arrays().items():
                np.testing.assert_array_equal(getattr(threaded, name).view(np.int64),
                                              a.view(np.int64), err_msg=f"{name}, {count} threads")
    finally:
        kernels.set_threads(None)


def test_kept_turns_give_the_bits_computed_anew(bank: ClipBank) -> None:
    """The loop transforms and the placement headings' cosines and sines kept from tick to
    tick (PlaybackWork) give the bits a fresh PlaybackWork computes: over ticks whose clocks
    move on (loops done, held clips), some characters changing clip or heading (a heading of
    -0.0 after 0.0 too), a removal renumbering the rows, and another bank."""
    rng = np.random.default_rng(1321)
    n = 3 * BLOCK + 7
    clip, time_s, loop, xy, heading, lengths = _scene(bank, rng, n)
    heading[:4] = 0.0
    like = sample(bank, clip[:1], time_s[:1], loop[:1])
    pbank, kept = playback_bank(bank), PlaybackWork()
    rows = np.arange(n, dtype=np.int64)
    for tick in range(12):
        if tick == 6:  # a removal: the rows after the fifth renumbered
            keep = np.delete(np.arange(n), 5)
            clip, time_s, loop, xy, heading, lengths = (a[keep] for a in (clip, time_s, loop, xy,
                                                                          heading, lengths))
            n -= 1
            rows = np.arange(n, dtype=np.int64)
        if tick == 9:  # another bank (the same clips): nothing kept is read
            pbank = playback_bank(bank)
        got, want = _empty(n, like), _empty(n, like)
        weights = [np.zeros((n, 2)) for _ in range(4)]
        sample_placed(pbank, rows, clip, time_s, loop, xy, heading, lengths, pose_arrays(got),
                      rows, weights[0], weights[1], kept)
        sample_placed(pbank, rows, clip, time_s, loop, xy, heading, lengths, pose_arrays(want),
                      rows, weights[2], weights[3], PlaybackWork())
        for name, a in want.arrays().items():
            np.testing.assert_array_equal(getattr(got, name).view(np.int64), a.view(np.int64),
                                          err_msg=f"{name} at tick {tick}")
        np.testing.assert_array_equal(weights[0], weights[2])
        np.testing.assert_array_equal(weights[1], weights[3])
        time_s = time_s + bank.duration_s(clip) * rng.uniform(0.0, 0.7, n)
        change = rng.random(n) < 0.2
        clip = np.where(change, rng.integers(0, len(bank.names), n), clip).astype(np.int64)
        heading = np.where(rng.random(n) < 0.2, rng.uniform(-7.0, 7.0, n), heading)
        heading[:4] = -0.0 if tick % 2 == 0 else 0.0


def test_blended_headings_are_numpys_to_the_bit() -> None:
    """``blend_root``'s heading (its wrap without ``fmod`` where the two headings are within a
    turn of each other) is :func:`ecs_anim.motion.sampling.blend`'s bit for bit: headings a
    little and several turns apart, at and beside the wrap's edges, zeros of either sign, NaN."""
    rng = np.random.default_rng(1320)
    edges = np.array([-5.0, -3.0, -1.0, 0.0, 1.0, 3.0, 5.0]) * np.pi
    gaps = np.concatenate([edges, np.nextafter(edges, np.inf), np.nextafter(edges, -np.inf),
                           rng.uniform(-0.2, 0.2, 3000), rng.uniform(-30.0, 30.0, 3000),
                           [-0.0, 1e-300, -1e-300, np.nan]])
    ha = rng.uniform(-7.0, 7.0, gaps.size)
    ha[:4] = -0.0
    hb = ha + gaps
    w = rng.uniform(0.0, 1.0, gaps.size)
    expected = ha + w * wrap_angle(hb - ha)
    got = np.array([blend_root((0.0, 0.0, 0.0), a, (0.0, 0.0, 0.0), b, t)[1]
                    for a, b, t in zip(ha.tolist(), hb.tolist(), w.tolist(), strict=True)])
    same = (got.view(np.int64) == expected.view(np.int64)) | (np.isnan(got) & np.isnan(expected))
    assert same.all(), gaps[~same][:5]


def test_complex_power_equals_numpy() -> None:
    rng = np.random.default_rng(1314)
    for yaw in rng.uniform(-0.01, 0.01, 20):
        step = np.exp(1j * yaw)
        for exponent in np.concatenate([np.arange(-120.0, 120.0), rng.integers(0, 10**5, 50)]):
            re, im = complex_power(step.real, step.imag, float(exponent))
            assert abs(complex(re, im) - step**exponent) < 1e-12


def test_fade_blend_equals_numpy(bank: ClipBank) -> None:
    rng = np.random.default_rng(1316)
    n = 300
    clip, time_s, loop, xy, heading, lengths = _scene(bank, rng, n)
    leg = leg_length(lengths)
    old_clip, old_time, old_loop, old_xy, old_heading, _ = _scene(bank, rng, n)
    new = _placed(sample(bank, clip, time_s, loop), xy, heading, leg)
    old = _placed(sample(bank, old_clip, old_time, old_loop), old_xy, old_heading, leg)
    w = np.clip(rng.uniform(-0.2, 1.2, n), 0.0, 1.0)
    want = blend(old, new, w)
    rows = np.flatnonzero(rng.random(n) < 0.7).astype(np.int64)
    out = NormalizedPoses(**{k: v.copy() for k, v in new.arrays().items()})
    blend_rows(0, rows.size, rows, pose_arrays(old.take(rows)), w[rows], pose_arrays(out))
    _assert_poses_equal(out.take(rows), want.take(rows))
    untouched = np.setdiff1d(np.arange(n), rows)
    _assert_poses_equal(out.take(untouched), new.take(untouched))


def test_compiled_motion_playback_equals_numpy_with_fades_and_queues() -> None:
    rng = np.random.default_rng(1317)
    motions = {p.stem: import_bvh(p) for p in sorted(MOTIONS_DIR.glob("*.bvh"))}
    names = list(motions)

    def make() -> Simulation:
        sim = Simulation(motions)
        local = np.random.default_rng(1318)
        for k in range(10):
            queue = tuple(QueuedClip(names[int(j)], float(local.uniform(0.0, 0.6)),
                                     bool(local.random() < 0.5))
                          for j in local.integers(0, len(names), int(local.integers(0, 4))))
            player = MotionPlayer(names[int(local.integers(0, len(names)))],
                                  speed=float(local.uniform(0.5, 2.0)),
                                  loop=bool(local.random() < 0.5),
                                  start_s=float(local.uniform(0.0, 3.0)), queue=queue)
            sim.spawn(f"c{k}", Morphology.from_stature(float(local.uniform(1.1, 2.0))), player,
                      Placement((float(local.uniform(-5, 5)), float(local.uniform(-5, 5))),
                                float(local.uniform(-3, 3))))
        return sim

    compiled, reference = make(), make()
    system = next(s for s in reference.systems if isinstance(s, MotionPlayback))
    system.run = system.run_numpy  # type: ignore[method-assign]
    faded = 0
    for tick in range(int(rng.integers(200, 260))):
        faded += int(np.count_nonzero(compiled.store.fade_s > 0.0))
        compiled.step()
        reference.step()
        got, want = compiled.store, reference.store
        np.testing.assert_allclose(got.positions, want.positions, rtol=0, atol=1e-9,
                                   err_msg=f"tick {tick}")
        np.testing.assert_allclose(got.contact_weight, want.contact_weight, rtol=0, atol=1e-12)
        # numpy blends every row while any fades (weight 1 for the others), which may move a
        # heading by a whole turn: the same pose.
        turns = (got.poses.root_heading - want.poses.root_heading) / (2 * np.pi)
        np.testing.assert_allclose(turns, np.round(turns), rtol=0, atol=1e-10)
        np.testing.assert_array_equal(got.fade_s, want.fade_s)
        np.testing.assert_array_equal(got.clip, want.clip)
    assert faded > 0


def test_advance_clocks_equals_numpy() -> None:
    rng = np.random.default_rng(1319)
    n = 3 * BLOCK + 5
    speed, fade_speed = rng.uniform(-2.0, 2.0, n), rng.uniform(0.0, 2.0, n)
    speed[3] = np.nan
    times = [rng.uniform(-1.0, 100.0, n) for _ in range(3)]
    rows = np.flatnonzero(rng.random(n) < 0.7)
    got = [t.copy() for t in times]
    advance_clocks(rows, 1.0 / 60.0, speed, fade_speed, *got)
    want = [t.copy() for t in times]
    want[0][rows] += 1.0 / 60.0 * speed[rows]
    want[1][rows] += 1.0 / 60.0 * fade_speed[rows]
    want[2][rows] += 1.0 / 60.0
    for g, w in zip(got, want, strict=True):
        np.testing.assert_array_equal(g.view(np.int64), w.view(np.int64))


def test_pose_arrays_replaced_between_ticks_are_written() -> None:
    """MotionPlayback keeps the store's pose arrays from tick to tick: one replaced (a copy,
    or a read-only array) is the one written next."""
    walk = import_bvh(MOTIONS_DIR / "walk.bvh")
    sims = []
    for _ in range(2):
        sim = Simulation({"walk": walk})
        for k in range(3):
            sim.spawn(f"c{k}", Morphology.from_stature(1.6 + 0.1 * k),
                      MotionPlayer("walk", start_s=0.3 * k), Placement((0.0, 2.0 * k)))
        sim.step()
        assert sim.compiled  # (MotionPlayback's kept arrays are the kernels' path)
        sims.append(sim)
    replaced, kept = sims
    thorax = replaced.store.poses.thorax.copy()
    thorax.setflags(write=False)
    replaced.store.poses.thorax = thorax
    replaced.store.poses.head = replaced.store.poses.head.copy()
    for _ in range(2):
        replaced.step()
        kept.step()
    for name in ("thorax", "head", "pelvis_local"):
        np.testing.assert_array_equal(getattr(replaced.store.poses, name),
                                      getattr(kept.store.poses, name))
    assert not np.array_equal(replaced.store.poses.thorax, thorax)
