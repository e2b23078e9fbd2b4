"""Spawning in bulk: the store grows by capacity doubling, spawn_many equals spawning one by one,
systems that replace whole arrays keep working, and removal still renumbers."""

from __future__ import annotations

import dataclasses

import esper
import numpy as np
import pytest

from conftest import shipped_motion
from ecs_anim.components import CharacterRow, Morphology, MotionPlayer, Placement, QueuedClip
from ecs_anim.core.errors import EcsAnimError
from ecs_anim.core.normalized import NormalizedPoses
from ecs_anim.runtime.simulation import Simulation
from ecs_anim.runtime.store import CharacterStore


@pytest.fixture(scope="module")
def motions():
    """The shipped walk and idle (conftest's locomotion set without the run)."""
    return {name: shipped_motion(name) for name in ("walk", "idle")}


def _characters(rng, n):
    bodies = [Morphology.from_stature(float(rng.uniform(1.1, 2.05)), "female" if i % 3 else "male")
              for i in range(n)]
    players = [MotionPlayer("walk", speed=float(rng.uniform(0.5, 1.5)),
                            start_s=float(rng.uniform(0, 2)),
                            queue=(QueuedClip("idle", 0.4),) if i % 2 else ()) for i in range(n)]
    placements = [Placement(tuple(rng.uniform(-5, 5, 2)), float(rng.uniform(-3, 3)))
                  for _ in range(n)]
    return bodies, players, placements


def _store_arrays(st):
    out = {f.name: getattr(st, f.name) for f in dataclasses.fields(st)
           if isinstance(getattr(st, f.name), np.ndarray)}
    out.update({f"poses.{k}": v for k, v in st.poses.arrays().items()})
    return out


def test_spawn_many_is_spawning_one_by_one(motions):
    rng = np.random.default_rng(5)
    bodies, players, placements = _characters(rng, 7)
    names = [f"c{i}" for i in range(7)]
    one = Simulation(motions)
    for args in zip(names, bodies, players, placements, strict=True):
        one.spawn(*args, com_target_xy=(1.0, 2.0) if args[0] == "c3" else None)
    many = Simulation(motions)
    many.spawn_many(names, bodies, players, placements,
                    com_target_xy=[(1.0, 2.0) if n == "c3" else None for n in names])
    a, b = _store_arrays(one.store), _store_arrays(many.store)
    assert a.keys() == b.keys()
    for key in a:
        np.testing.assert_array_equal(a[key], b[key], err_msg=key)
    for _ in range(20):
        one.step()
        many.step()
    np.testing.assert_array_equal(one.store.positions, many.store.positions)
    assert one.names() == many.names() == names


def test_the_store_grows_by_doubling_and_shows_n_rows():
    st = CharacterStore()
    capacities = set()
    for i in range(100):
        st.add_row(entity=i, speed=float(i))
        capacities.add(st._buffers["speed"][0].shape[0])
    assert st.n == 100 and st.speed.shape == (100,) and st.poses.root_position.shape == (100, 3)
    np.testing.assert_array_equal(st.speed, np.arange(100.0))
    assert len(capacities) <= 5  # 16, 32, 64, 128: a handful of reallocations, not 100
    assert st.poses.pelvis_local[:, 3].tolist() == [1.0] * 100  # identity quaternions


def test_a_system_replacing_a_whole_array_keeps_it_across_spawns():
    st = CharacterStore()
    st.add_rows(3, entity=np.arange(3))
    st.contact_weight = np.full((3, 2), 0.5)  # as MotionPlayback does every tick
    st.ground_ref += 1.0  # in place, on the view
    st.poses = NormalizedPoses(**{k: v + 0.0 for k, v in st.poses.arrays().items()})
    st.add_rows(2, entity=np.arange(3, 5))
    np.testing.assert_array_equal(st.contact_weight, [[0.5, 0.5]] * 3 + [[0.0, 0.0]] * 2)
    np.testing.assert_array_equal(st.ground_ref, [1.0, 1.0, 1.0, 0.0, 0.0])
    assert st.poses.root_position.shape == (5, 3) and st.entity.tolist() == [0, 1, 2, 3, 4]


def test_removing_after_a_bulk_spawn_renumbers_the_rows(motions):
    rng = np.random.default_rng(11)
    sim = Simulation(motions)
    entities = sim.spawn_many([f"c{i}" for i in range(6)], *_characters(rng, 6))
    sim.step()
    positions = sim.store.positions.copy()
    sim.remove(int(entities[2]))
    sim.remove(int(entities[0]))
    assert sim.names() == ["c1", "c3", "c4", "c5"]
    np.testing.assert_array_equal(sim.store.positions, positions[[1, 3, 4, 5]])
    with sim._active():
        rows = {e: r.row for e, r in esper.get_component(CharacterRow)}
    assert [rows[int(e)] for e in entities[[1, 3, 4, 5]]] == [0, 1, 2, 3]
    sim.spawn_many(["d0", "d1"], *_characters(rng, 2))
    sim.step()
    assert sim.store.n == 6 and np.all(np.isfinite(sim.store.positions))


def test_a_bad_character_in_a_bulk_spawn_adds_none(motions):
    rng = np.random.default_rng(2)
    bodies, players, placements = _characters(rng, 3)
    sim = Simulation(motions)
    players[1] = MotionPlayer("run")
    with pytest.raises(EcsAnimError, match="character 'b'"):
        sim.spawn_many(["a", "b", "c"], bodies, players, placements)
    placements[1] = Placement((np.nan, 0.0))
    with pytest.raises(EcsAnimError, match=r"character 'b'.*finite"):
        sim.spawn_many(["a", "b", "c"], bodies, [MotionPlayer("walk")] * 3, placements)
    with pytest.raises(EcsAnimError, match="3 names"):
        sim.spawn_many(["a", "b", "c"], bodies[:2], players, placements)
    assert sim.store.n == 0 and sim.structure_version == 0


def test_the_benchmark_scene_spawns_in_bulk():
    from ecs_anim.runtime.bench_scene import walkers_on_bumps

    sim, _ = walkers_on_bumps(500)
    assert sim.store.n == 500 and len(set(sim.names())) == 500
    sim.step()
    assert np.all(np.isfinite(sim.store.positions))


def test_spawning_nobody_changes_nothing(motions):
    sim = Simulation(motions)
    assert sim.spawn_many([], [], []).tolist() == [] and sim.store.n == 0
