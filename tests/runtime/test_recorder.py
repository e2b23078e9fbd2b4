"""``sim.record()`` and ``rec.save()`` (issue 33, items 4 and 5): what is recorded, by entity,
across removals and body changes; the files agree with each other on every frame; saving is
atomic, refuses to overwrite without force, and writes the bytes ``run --export`` writes."""

from __future__ import annotations

import os

import numpy as np
import pytest

from conftest import MOTIONS_DIR, SCENARIOS_DIR
from ecs_anim import (
    Morphology,
    MotionPlayer,
    Placement,
    Simulation,
    build_simulation,
    bvh_from_rotations,
    glb_bytes,
    import_bvh,
    load_scenario,
)
from ecs_anim.apps.cli.main import main
from ecs_anim.core.errors import EcsAnimError, UsageError
from ecs_anim.core.files import MANIFEST_NAME
from ecs_anim.runtime import recorder as recorder_module
from support.export_readback import bvh_joints, glb_joints
from support.gltf_validator import assert_valid

MM = 1e-3


@pytest.fixture(scope="module")
def walk():
    return import_bvh(MOTIONS_DIR / "walk.bvh")


def two_walkers(walk) -> tuple[Simulation, int, int]:
    sim = Simulation({"walk": walk})
    kid = sim.spawn("kid", Morphology.preset("child"), MotionPlayer("walk"))
    adult = sim.spawn("adult", Morphology.preset("adult_male"), MotionPlayer("walk"),
                      Placement((0.0, 1.5)))
    return sim, kid, adult


def test_a_body_changed_mid_run_is_exported_as_it_changed_bvh_glb_and_npz_agreeing(tmp_path, walk):
    """A child grown to 2.0 m over 0.6 s, an adult shrunk to a child at once: each file, read
    back by an independent forward kinematics, equals the .npz within 1 mm on every frame (the
    files written on the first body were up to 520 mm off)."""
    sim, kid, adult = two_walkers(walk)
    rec = sim.record()
    for tick in range(60):
        if tick == 15:
            sim.set_body(kid, Morphology.preset("tall"), blend_s=0.6)
        if tick == 36:
            sim.set_body(adult, Morphology.preset("child"))
        sim.step()
    written = rec.save(tmp_path / "out")
    assert sorted(p.name for p in written) == ["adult.bvh", "adult.glb", "adult.npz",
                                               "kid.bvh", "kid.glb", "kid.npz"]
    for name, final in (("kid", "tall"), ("adult", "child")):
        recorded = rec.character(sim.entity(name))
        assert recorded.body_changed and recorded.frames == 60
        np.testing.assert_array_equal(recorded.body.lengths, Morphology.preset(final).lengths)
        npz = np.load(tmp_path / "out" / f"{name}.npz")["positions"]
        np.testing.assert_array_equal(npz, recorded.positions)
        for what, got in (("bvh", bvh_joints(tmp_path / "out" / f"{name}.bvh")),
                          ("glb", glb_joints(tmp_path / "out" / f"{name}.glb"))):
            assert got.shape == npz.shape
            error = np.linalg.norm(got - npz, axis=-1).max()
            assert error < 1 * MM, (name, what, f"{error / MM:.3f} mm")
    bvh = (tmp_path / "out" / "kid.bvh").read_text()
    assert "JOINT head_top" in bvh and "JOINT hand_l" in bvh  # end sites that changed: joints
    assert bvh.count("CHANNELS 6") > 1  # position channels beyond the root's
    assert_valid(sorted((tmp_path / "out").glob("*.glb")))


def test_a_body_that_never_changed_is_written_as_without_lengths(tmp_path, walk):
    sim, kid, _ = two_walkers(walk)
    rec = sim.record()
    for _ in range(20):
        sim.step()
    rec.save(tmp_path / "out", formats=("bvh", "glb"))
    recorded = rec.character(kid)
    assert not recorded.body_changed
    body, pelvis, local = recorded.body, recorded.positions[:, 0], recorded.local_rotations
    assert (tmp_path / "out" / "kid.bvh").read_text() == bvh_from_rotations(body, pelvis, local,
                                                                            sim.fps)
    assert (tmp_path / "out" / "kid.glb").read_bytes() == glb_bytes(body, pelvis, local, sim.fps)
    assert "CHANNELS 6" not in (tmp_path / "out" / "kid.bvh").read_text().split("JOINT", 1)[1]
    assert sorted(os.listdir(tmp_path / "out")) == [MANIFEST_NAME, "adult.bvh", "adult.glb",
                                                    "kid.bvh", "kid.glb"]


def test_save_writes_the_bytes_of_run_export_for_a_shipped_scenario(tmp_path):
    scenario = SCENARIOS_DIR / "reach_and_touch.yaml"
    assert main(["run", str(scenario), "--seconds", "1", "--export", str(tmp_path / "cli")]) == 0
    loaded = load_scenario(scenario)
    with build_simulation(loaded) as sim:
        rec = sim.record()
        for _ in range(round(1.0 * loaded.fps)):
            sim.step()
        rec.save(tmp_path / "api")
    names = sorted(os.listdir(tmp_path / "cli"))
    assert names == sorted(os.listdir(tmp_path / "api")) and len(names) > 3
    for name in names:
        assert (tmp_path / "cli" / name).read_bytes() == (tmp_path / "api" / name).read_bytes(), name


def test_characters_are_followed_by_entity_across_a_removal(walk):
    sim, kid, adult = two_walkers(walk)
    rec = sim.record()
    kept: dict[int, list[np.ndarray]] = {kid: [], adult: []}
    for tick in range(30):
        if tick == 12:
            sim.remove(kid)  # adult's row moves down to 0
        sim.step()
        for entity in kept:
            if entity != kid or tick < 12:
                kept[entity].append(sim.store.positions[sim.row(entity)].copy())
    gone, stays = rec.character(kid), rec.character(adult)
    assert gone.frames == 12 and stays.frames == 30
    np.testing.assert_array_equal(gone.positions, np.array(kept[kid]))
    np.testing.assert_array_equal(stays.positions, np.array(kept[adult]))
    assert gone.removed_at_s == pytest.approx(12 / sim.fps) and stays.removed_at_s is None
    assert gone.local_rotations.shape == (12, 25, 3, 3) and gone.contacts.shape == (12, 2)
    assert any(e.kind == "removed" and e.entity == kid for e in rec.events)


def test_entities_chooses_the_characters_and_none_follows_those_spawned_later(walk):
    sim, kid, adult = two_walkers(walk)
    only_kid, every = sim.record([kid]), sim.record()
    sim.step()
    late = sim.spawn("late", Morphology.preset("tall"), MotionPlayer("walk"), Placement((0.0, 3.0)))
    for _ in range(4):
        sim.step()
    assert [c.name for c in only_kid.characters()] == ["kid"]
    assert [(c.name, c.frames) for c in every.characters()] == [("kid", 5), ("adult", 5),
                                                               ("late", 4)]
    assert every.character(late).start_s == pytest.approx(1 / sim.fps)
    with pytest.raises(UsageError, match="not recorded"):
        only_kid.character(adult)
    with pytest.raises(EcsAnimError, match="no character with entity id 999"):
        sim.record([999])


def test_recording_reads_names_and_bodies_only_when_something_is_new(walk, monkeypatch):
    """No Python work per character per tick: names are read for characters seen for the first
    time, bodies after a structural change (a body replaced, a character spawned)."""
    sim, kid, _ = two_walkers(walk)
    rec = sim.record()
    calls = {"new": 0, "bodies": 0}
    add, refresh = rec._add, rec._refresh_bodies

    def counting_add(*args):
        calls["new"] += 1
        return add(*args)

    def counting_refresh():
        calls["bodies"] += 1
        return refresh()

    monkeypatch.setattr(rec, "_add", counting_add)
    monkeypatch.setattr(rec, "_refresh_bodies", counting_refresh)
    for _ in range(10):
        sim.step()
    assert calls == {"new": 1, "bodies": 1}  # at the first tick
    sim.set_body(kid, Morphology.preset("tall"))
    for _ in range(10):
        sim.step()
    assert calls == {"new": 1, "bodies": 2}  # and after the change
    sim.spawn("late", Morphology.preset("tall"), MotionPlayer("walk"), Placement((0.0, 3.0)))
    for _ in range(10):
        sim.step()
    assert calls == {"new": 2, "bodies": 3}
    assert rec.character(kid).frames == 30 and rec.character(sim.entity("late")).frames == 10


def test_save_never_leaves_a_half_written_set_and_never_overwrites_without_force(
        tmp_path, walk, monkeypatch):
    sim, _, _ = two_walkers(walk)
    rec = sim.record()
    for _ in range(5):
        sim.step()
    out = tmp_path / "out"
    rec.save(out)
    before = {p.name: p.read_bytes() for p in out.iterdir()}
    with pytest.raises(EcsAnimError, match="holds an earlier export"):
        rec.save(out)
    for _ in range(5):
        sim.step()
    written = []

    def failing(*args, **kwargs):  # the second character's .glb fails
        written.append(1)
        if len(written) == 2:
            raise OSError("disk full")
        return glb_bytes(*args, **kwargs)

    monkeypatch.setattr(recorder_module, "glb_bytes", failing)
    with pytest.raises(EcsAnimError, match=r"adult\.glb: cannot write: disk full"):
        rec.save(out, force=True)
    assert {p.name: p.read_bytes() for p in out.iterdir()} == before  # the old set, whole
    assert sorted(os.listdir(tmp_path)) == ["out"]  # no partial folder left
    monkeypatch.undo()
    rec.save(out, force=True)
    assert np.load(out / "kid.npz")["positions"].shape[0] == 10
    (out / "notes.txt").write_text("mine")
    with pytest.raises(EcsAnimError, match=r"notes\.txt"):
        rec.save(out, force=True)
    assert (out / "notes.txt").read_text() == "mine"


def test_save_refuses_onto_unknown_formats_and_names_that_collide(tmp_path, walk):
    sim = Simulation({"walk": walk})
    for y in (0.0, 1.5):
        sim.spawn("twin", Morphology.preset("child"), MotionPlayer("walk"), Placement((0.0, y)))
    rec = sim.record()
    sim.step()
    with pytest.raises(UsageError, match=r"^save: onto must be a rig file's path or a Rig, got "):
        rec.save(tmp_path / "out", onto=3)  # type: ignore[arg-type]
    with pytest.raises(EcsAnimError, match=r"rig\.bvh: no such rig file"):
        rec.save(tmp_path / "out", onto=tmp_path / "rig.bvh")
    for formats in (("fbx",), (), "bvh"):
        with pytest.raises(UsageError, match="formats"):
            rec.save(tmp_path / "out", formats=formats)
    with pytest.raises(UsageError, match="named 'twin'"):
        rec.save(tmp_path / "out")
    assert not (tmp_path / "out").exists()
