"""Encode/decode kernels: batch == single, exact bone lengths on any body, no NaN when straight."""

from __future__ import annotations

import numpy as np
import pytest

from conftest import MOTIONS_DIR
from ecs_anim.core.errors import EcsAnimError
from ecs_anim.core.morphology import (
    DE_LEVA_1996,
    PRESET_SPECS,
    Morphology,
    bone_lengths_of,
    centres_of_mass,
    load_morphology_yaml,
    segment_mass_table,
)
from ecs_anim.core.normalized import decode, encode, frames_from_positions, spine_joints
from ecs_anim.core.skeleton import BONE_JOINTS, JOINT_INDEX, LENGTHS, PARENTS
from ecs_anim.io.bvh import read_bvh
from ecs_anim.io.importing import canonical_clip, import_bvh
from ecs_anim.motion.clip import load_nmo, save_nmo


def test_parents_are_topological():
    assert PARENTS[0] == -1
    assert all(p < i for i, p in enumerate(PARENTS) if i > 0)


@pytest.mark.parametrize("name", list(PRESET_SPECS))
def test_presets_have_their_stature_and_de_leva_masses_sum_to_body_mass(name):
    m = Morphology.preset(name)
    expected = PRESET_SPECS[name]["stature_m"]
    assert m.stature == pytest.approx(expected, abs=1e-9)
    assert sum(v[0] for v in DE_LEVA_1996[m.sex].values()) + sum(
        DE_LEVA_1996[m.sex][k][0] for k in ("upper_arm", "forearm", "hand", "thigh", "shank", "foot")
    ) == pytest.approx(1.0, abs=2e-3)


def test_from_stature_and_leg_scale():
    child = Morphology.from_stature(1.20)
    assert child.stature == pytest.approx(1.20)
    long_legs, short = Morphology.preset("long_legs"), Morphology.preset("short_legs")
    assert long_legs.leg_length / long_legs.stature > Morphology.preset("adult_male").leg_length / 1.75
    assert short.leg_length / short.stature < Morphology.preset("adult_male").leg_length / 1.75
    with pytest.raises(EcsAnimError, match="did you mean 'child'"):
        Morphology.preset("chld")


def test_decode_on_any_body_has_exact_bone_lengths_and_finite_positions(walk):
    rng = np.random.default_rng(7)
    for stature in (1.2, 1.5, 2.0):
        base = Morphology.from_stature(stature).lengths
        lengths = base * rng.uniform(0.8, 1.25, size=base.shape)  # non-proportional bodies
        pos = decode(walk.poses, lengths).positions
        assert np.all(np.isfinite(pos))
        got = bone_lengths_of(pos)
        for k, (a, _b) in enumerate(BONE_JOINTS):
            if a >= 0:
                assert np.abs(got[:, k] - lengths[k]).max() < 1e-9, LENGTHS[k]


def test_batched_decode_equals_frame_by_frame(walk):
    lengths = Morphology.preset("tall").lengths
    batched = decode(walk.poses, lengths).positions
    for f in (0, 17, walk.n_frames - 1):
        single = decode(walk.poses.take(slice(f, f + 1)), lengths).positions[0]
        np.testing.assert_allclose(single, batched[f], atol=1e-12)


def test_encode_decode_round_trip_on_the_source_body():
    clip = canonical_clip(read_bvh(MOTIONS_DIR / "walk.bvh"))
    motion = import_bvh(MOTIONS_DIR / "walk.bvh")
    pos = decode(motion.poses, motion.source_morphology.lengths, use_stretch=True).positions
    assert np.abs(pos - clip.positions).max() < 1e-9


def test_straight_limbs_and_folded_limbs_do_not_make_nan():
    m = Morphology.preset("adult_male")
    pos = decode(import_bvh(MOTIONS_DIR / "idle.bvh").poses.take(slice(0, 1)), m.lengths).positions[0]
    # Straighten the left leg and arm fully, fold the right arm onto itself.
    pos = pos[None].repeat(2, axis=0)
    for a, b, c in (("hip_l", "knee_l", "ankle_l"), ("shoulder_l", "elbow_l", "wrist_l")):
        d = pos[:, JOINT_INDEX[b]] - pos[:, JOINT_INDEX[a]]
        pos[:, JOINT_INDEX[c]] = pos[:, JOINT_INDEX[b]] + d / np.linalg.norm(d, axis=-1, keepdims=True) * 0.3
    pos[1, JOINT_INDEX["wrist_r"]] = pos[1, JOINT_INDEX["shoulder_r"]]
    poses = encode(pos, *frames_from_positions(pos), m.lengths)
    for value in poses.arrays().values():
        assert np.all(np.isfinite(value))
    assert np.all(np.isfinite(decode(poses, m.lengths).positions))


def test_spine_walk_lands_on_control_points_with_matching_lengths():
    control = np.array([[0, 0, 0], [0.02, 0, 0.1], [0.0, 0, 0.2], [-0.03, 0, 0.28]], dtype=float)
    lengths = np.linalg.norm(np.diff(control, axis=0), axis=-1)
    joints = spine_joints(control[None], lengths[None])[0]
    np.testing.assert_allclose(joints, control[1:], atol=1e-12)
    longer = spine_joints(control[None], 1.3 * lengths[None])[0]
    np.testing.assert_allclose(np.linalg.norm(np.diff(np.vstack([control[:1], longer]), axis=0), axis=-1),
                               1.3 * lengths, atol=1e-12)


def test_centre_of_mass_of_a_standing_body_is_above_the_feet(walk):
    m = Morphology.preset("adult_male")
    pos = decode(import_bvh(MOTIONS_DIR / "idle.bvh").poses, m.lengths).positions
    masses, fraction = segment_mass_table(m)[:2]
    frames = pos.shape[0]
    com = centres_of_mass(pos, np.tile(masses, (frames, 1)), np.tile(fraction, (frames, 1)))
    feet = pos[:, [JOINT_INDEX["ankle_l"], JOINT_INDEX["ankle_r"]], :2].mean(axis=1)
    assert np.linalg.norm(com[:, :2] - feet, axis=-1).max() < 0.12
    assert np.all((com[:, 2] > 0.5 * 1.75) & (com[:, 2] < 0.62 * 1.75))  # about 55 % of stature


def test_nmo_round_trip(tmp_path, walk):
    path = tmp_path / "walk.nmo"
    save_nmo(walk, path)
    back = load_nmo(path)
    for k, v in walk.poses.arrays().items():
        np.testing.assert_array_equal(getattr(back.poses, k), v)
    assert back.fps == walk.fps and back.constraints == walk.constraints
    np.testing.assert_array_equal(back.source_morphology.lengths, walk.source_morphology.lengths)
    with pytest.raises(FileExistsError):
        save_nmo(walk, path)


def test_morphology_yaml(tmp_path):
    path = tmp_path / "me.yaml"
    path.write_text("stature_m: 1.68\nsex: female\nlengths_m:\n  thigh: 0.43\n  forearm_l: 0.25\n")
    m = load_morphology_yaml(path)
    assert m["thigh_l"] == m["thigh_r"] == 0.43 and m["forearm_l"] == 0.25 and m.sex == "female"


def test_any_number_of_vertebrae_along_the_spine(walk):
    from ecs_anim.core.normalized import vertebrae

    m = Morphology.preset("adult_male")
    pos = decode(walk.poses, m.lengths).positions
    for count in (1, 3, 12):
        v = vertebrae(walk.poses, m.lengths, count)
        assert v.shape == (walk.n_frames, count, 3)
        chain = np.concatenate([pos[:, None, JOINT_INDEX["pelvis"]], v], axis=1)
        seg = np.linalg.norm(np.diff(chain, axis=1), axis=-1)
        total = m["spine_lower"] + m["spine_middle"] + m["spine_upper"]
        np.testing.assert_allclose(seg, total / count, atol=1e-9)
        # The curve ends near the neck base (within 1 cm: chords of a curve vs the spline's).
        assert np.linalg.norm(v[:, -1] - pos[:, JOINT_INDEX["neck"]], axis=-1).max() < 0.01
