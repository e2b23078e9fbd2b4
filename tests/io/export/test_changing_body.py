"""The BVH and glTF writers given each frame's body (``lengths=``, issue 33 item 4): the batched
offsets equal the single body's, a body that never changed gives the bytes it gave without
``lengths``, and one that changed reads back (our reader and an independent one) with the
offsets of each frame's body."""

from __future__ import annotations

import numpy as np

from ecs_anim.core.morphology import Morphology
from ecs_anim.core.skeleton import LENGTH_INDEX
from ecs_anim.io.bvh import forward_kinematics, parse_bvh
from ecs_anim.io.export import bvh_from_rotations, glb_bytes
from ecs_anim.io.export.skeleton import EXPORT_NAMES, rest_offsets, rest_offsets_of


def test_batched_offsets_equal_the_single_body_ones():
    rng = np.random.default_rng(3301)
    base = Morphology.preset("adult_male").lengths
    lengths = base * rng.uniform(0.5, 1.5, size=(6, base.shape[0]))
    joints, ends = rest_offsets_of(lengths)
    for i in range(lengths.shape[0]):
        single = rest_offsets(Morphology(lengths[i]))
        np.testing.assert_array_equal(joints[i], single[0])
        np.testing.assert_array_equal(ends[i], single[1])


def _motion(frames: int) -> tuple[np.ndarray, np.ndarray]:
    """A pelvis path (frames, 3) and random local rotations (frames, E, 3, 3)."""
    rng = np.random.default_rng(3302)
    q, r = np.linalg.qr(rng.normal(size=(frames, len(EXPORT_NAMES), 3, 3)))
    local = q * np.sign(np.diagonal(r, axis1=-2, axis2=-1))[..., None, :]
    local *= np.sign(np.linalg.det(local))[..., None, None]  # proper rotations
    return rng.normal(size=(frames, 3)), local


def test_a_body_that_never_changed_gives_the_same_bytes_as_without_lengths():
    body = Morphology.preset("child")
    pelvis, local = _motion(5)
    same = np.tile(body.lengths, (5, 1))
    assert bvh_from_rotations(body, pelvis, local, 30.0, same) == \
        bvh_from_rotations(body, pelvis, local, 30.0)
    assert glb_bytes(body, pelvis, local, 30.0, same) == glb_bytes(body, pelvis, local, 30.0)


def test_a_changed_body_reads_back_with_each_frames_offsets():
    child, tall = Morphology.preset("child"), Morphology.preset("tall")
    weights = np.linspace(0.0, 1.0, 7)[:, None]
    lengths = child.lengths * (1 - weights) + tall.lengths * weights  # a blend, frame by frame
    pelvis, local = _motion(7)
    text = bvh_from_rotations(tall, pelvis, local, 30.0, lengths)
    motion = parse_bvh(text)
    names = motion.skeleton.names
    assert "head_top" in names and "toe_tip_r" in names and "head.end" not in names
    _, positions = forward_kinematics(motion)
    # Each frame: the knee is the thigh's length of that frame's body below the hip.
    for side in "lr":
        hip, knee = names.index(f"hip_{side}"), names.index(f"knee_{side}")
        bone = np.linalg.norm(positions[:, knee] - positions[:, hip], axis=-1)
        np.testing.assert_allclose(bone, lengths[:, LENGTH_INDEX[f"thigh_{side}"]], atol=2e-6)
    top = np.linalg.norm(positions[:, names.index("head_top")] - positions[:, names.index("head")],
                         axis=-1)
    np.testing.assert_allclose(top, lengths[:, LENGTH_INDEX["head"]], atol=2e-6)
