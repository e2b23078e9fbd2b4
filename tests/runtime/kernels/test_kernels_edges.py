"""The compiled clip and contact edges (ecs_anim.runtime.kernels.edges) equal the numpy reference
(ecs_anim.runtime.events.clip_and_contact_edges): the edges listed by kind, the clips replaced,
what is kept per entity for the next tick, over ticks where clips start, loop, end, go back and
are replaced, and contacts begin and end (NaN weights too: the contacts begun are those the
weights kept would give); its arrays kept from tick to tick."""

from __future__ import annotations

import numpy as np

from ecs_anim.runtime.events import TIME_SLACK_S, clip_and_contact_edges
from ecs_anim.runtime.kernels.edges import EdgeScratch
from ecs_anim.runtime.kernels.edges import clip_and_contact_edges as compiled
from ecs_anim.runtime.triggers import CONTACT_BEGAN_WEIGHT


def _seen(n_entities: int) -> list[np.ndarray]:
    return [np.full(n_entities, -1, np.int64), np.zeros(n_entities),
            np.zeros(n_entities, bool), np.ones((n_entities, 2), bool)]


def test_compiled_edges_equal_numpy_over_ticks():
    rng = np.random.default_rng(7)
    n, n_entities, dt = 200, 260, 1 / 30
    entity = rng.permutation(n_entities)[:n].astype(np.int64)  # ids with gaps, any order
    duration_s = np.array([1.0, 0.5, 2.0])
    loop = rng.random(n) < 0.5
    speed = rng.choice([0.5, 1.0, 2.0], n)
    clip = rng.integers(0, 3, n)
    clip_time_s = rng.random(n) * 0.5
    weights = rng.random((n, 2))
    seen_numpy, seen_compiled = _seen(n_entities), _seen(n_entities)
    kinds = np.zeros(5, np.int64)
    scratch = EdgeScratch()  # its arrays written again every tick, as Reactions does
    # the contacts begun as the weights themselves kept would give them (NaN included)
    weights_before = np.zeros((n_entities, 2))
    for _ in range(60):
        edges, previous = clip_and_contact_edges(
            entity, clip, clip_time_s, speed, loop, duration_s, weights, dt, TIME_SLACK_S,
            CONTACT_BEGAN_WEIGHT, *seen_numpy)
        listed, replaced_clip = compiled(
            entity, clip, clip_time_s, speed, loop, duration_s, weights, dt, TIME_SLACK_S,
            CONTACT_BEGAN_WEIGHT, *seen_compiled, scratch=scratch)
        # the edges listed: each clip column's rows, the contacts' (row, foot) in row order
        for k in range(3):
            np.testing.assert_array_equal(listed[k], np.flatnonzero(edges[:, k]))
        rows, feet = np.nonzero(edges[:, 3:])
        np.testing.assert_array_equal(listed[3], 2 * rows + feet)
        began = ((weights >= CONTACT_BEGAN_WEIGHT)
                 & (weights_before[entity] < CONTACT_BEGAN_WEIGHT))
        np.testing.assert_array_equal(edges[:, 3:], began)
        weights_before[entity] = weights
        np.testing.assert_array_equal(replaced_clip, previous[listed[0]])
        for got, expected in zip(seen_compiled, seen_numpy, strict=True):
            np.testing.assert_array_equal(got, expected)
        kinds += edges.sum(axis=0)
        # The next tick: clips advance (a looping one wraps), some are replaced or restarted,
        # the contacts move around the threshold (exactly on it too).
        clip_time_s = clip_time_s + dt * speed
        ends = duration_s[clip]
        clip_time_s = np.where(loop & (clip_time_s >= ends), clip_time_s - ends,
                               np.minimum(clip_time_s, ends + dt * speed))
        replaced = rng.random(n) < 0.05
        clip = np.where(replaced, rng.integers(0, 3, n), clip)
        clip_time_s = np.where(replaced | (rng.random(n) < 0.02), 0.0, clip_time_s)
        weights = np.clip(np.nan_to_num(weights, nan=0.2) + rng.normal(0, 0.3, (n, 2)), 0, 1)
        weights[rng.random((n, 2)) < 0.05] = CONTACT_BEGAN_WEIGHT
        weights[rng.random((n, 2)) < 0.03] = np.nan
    assert (kinds > 0).all(), kinds  # every kind of edge was met
