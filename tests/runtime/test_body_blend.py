"""A body changing while it plays (Simulation.set_body with blend_s, ecs_anim.runtime.body_change):
blended over the given time, planted feet on their footprints, joints about as fast as the
motion moves them on the faster body."""

from __future__ import annotations

import numpy as np
import pytest

from ecs_anim.components import MotionPlayer
from ecs_anim.core.errors import EcsAnimError
from ecs_anim.core.morphology import Morphology
from ecs_anim.core.skeleton import JOINT_INDEX as J
from ecs_anim.runtime.metrics import MetricsRecorder
from ecs_anim.runtime.simulation import Simulation

SMALL, TALL = Morphology.from_stature(1.2), Morphology.from_stature(2.0)
ANKLES = [J["ankle_l"], J["ankle_r"]]


def walking(walk, body, change=None, blend_s=0.0, at_tick=45, ticks=150):
    """Walk ``ticks`` ticks at 30 Hz on ``body``, switching to ``change`` at ``at_tick``;
    positions (ticks, J, 3), contact weights (ticks, 2) and the metrics report."""
    with Simulation({"walk": walk}) as sim:
        entity = sim.spawn("walker", body, MotionPlayer("walk"))
        metrics = MetricsRecorder(sim)
        positions, contacts = [], []
        for k in range(ticks):
            if k == at_tick and change is not None:
                sim.set_body(entity, change, blend_s=blend_s)
            sim.step()
            metrics.record()
            positions.append(sim.store.positions[0].copy())
            contacts.append(sim.store.contact_weight[0].copy())
        return np.array(positions), np.array(contacts), metrics.report(), sim.store.lengths[0].copy()


def planted_moves_mm(p, contacts):
    """Per tick and foot, how far a fully planted ankle moved (mm): horizontally, vertically."""
    both = (contacts[1:] >= 1.0) & (contacts[:-1] >= 1.0)
    step = np.diff(p[:, ANKLES], axis=0) * 1e3
    return (np.where(both, np.linalg.norm(step[..., :2], axis=-1), 0.0),
            np.where(both, np.abs(step[..., 2]), 0.0))


def test_growing_from_1_2_to_2_0_m_in_a_second_while_walking_keeps_the_feet(walk):
    p, contacts, report, lengths = walking(walk, SMALL, TALL, blend_s=1.0)
    np.testing.assert_allclose(lengths, TALL.lengths, atol=1e-12)  # it became the new body
    horizontal, vertical = planted_moves_mm(p, contacts)
    assert horizontal.max() < 1.0, horizontal.max()  # measured 0.0 mm
    # A foot's ankle height (61 -> 102 mm) grows while it swings: a planted ankle stays put.
    assert vertical.max() < 1.0, vertical.max()  # measured 0.0 mm
    assert (contacts[45:75] >= 1.0).all(axis=1).any()  # both feet were planted during the change
    c = report["characters"][0]
    assert c["foot_sliding_mm_per_frame"]["max"] < 1.0
    assert c["ground_penetration_mm_max"] < 1.0 and c["bone_length_error_m_max"] < 1e-6
    # Each joint about as fast as the walk moves it on the faster of the two bodies: the growth
    # adds to it (the head's top rises 0.8 m in the second, 1.4 m/s at the smoothstep's peak);
    # measured: at most 1.14 times (the head's top), 1.09 the pelvis (1.95 m/s).
    speed = np.linalg.norm(np.diff(p, axis=0), axis=-1) * 30
    own = np.maximum(*(np.linalg.norm(np.diff(walking(walk, b)[0], axis=0), axis=-1).max(axis=0) * 30
                       for b in (SMALL, TALL)))
    assert np.all(speed.max(axis=0) <= 1.2 * own), (speed.max(axis=0) / own).max()
    assert speed[:, J["pelvis"]].max() <= 1.1 * own[J["pelvis"]]


def test_a_body_changed_at_once_re_plants_its_feet(walk):
    """What blending avoids: the same change in one tick slides a foot and sets the pelvis going
    at several metres a second."""
    p, contacts, _, _ = walking(walk, SMALL, TALL, blend_s=0.0)
    horizontal, _ = planted_moves_mm(p, contacts)
    pelvis = np.linalg.norm(np.diff(p[:, J["pelvis"]], axis=0), axis=-1) * 30
    assert horizontal.max() > 10.0 or pelvis.max() > 5.0


def test_a_blend_can_be_redirected_and_a_bad_blend_time_is_refused(walk):
    with Simulation({"walk": walk}) as sim:
        entity = sim.spawn("walker", SMALL, MotionPlayer("walk"))
        for _ in range(10):
            sim.step()
        sim.set_body(entity, TALL, blend_s=1.0)
        for _ in range(10):
            sim.step()
        halfway = sim.store.lengths[0].copy()
        assert np.all((halfway > SMALL.lengths - 1e-12) & (halfway < TALL.lengths + 1e-12))
        sim.set_body(entity, SMALL, blend_s=0.5)  # from where it is, back
        for _ in range(30):
            sim.step()
        np.testing.assert_allclose(sim.store.lengths[0], SMALL.lengths, atol=1e-12)
        assert np.all(np.isfinite(sim.store.positions))
        with pytest.raises(EcsAnimError, match="blend_s"):
            sim.set_body(entity, TALL, blend_s=float("nan"))
