"""The real-time pipeline: schedule, isolation, terrain walks on every body, changes while playing,
scenario errors."""

from __future__ import annotations

import esper
import numpy as np
import pytest

from conftest import DATA_DIR, MOCAP_DIR, MOTIONS_DIR, REPO, require_mocap
from ecs_anim.apps.cli.main import main
from ecs_anim.components import MotionPlayer, Placement, QueuedClip
from ecs_anim.core.errors import InputError
from ecs_anim.core.ground import Bumps, Combined, Stairs
from ecs_anim.core.morphology import Morphology, bone_lengths_of
from ecs_anim.core.skeleton import BONE_JOINTS
from ecs_anim.io.importing import import_bvh
from ecs_anim.runtime.metrics import MetricsRecorder
from ecs_anim.runtime.simulation import Simulation
from ecs_anim.scenario import build_simulation, load_scenario
from ecs_anim.systems import SCHEDULE

IS_BONE = np.array([a >= 0 for a, _ in BONE_JOINTS])


def test_schedule_is_declared_once_in_paper_order(walk):
    paper = ["MotionPlayback", "MorphologyAdapt", "GroundAdapt", "ConstraintSolve", "COMControl",
             "PostureConvert", "Render"]  # the design card (DESIGN §6), in its order
    assert [c.__name__ for c in SCHEDULE if c.__name__ in paper] == paper
    sim = Simulation({"walk": walk}, window=True)
    with sim._active():
        order = [type(p).__name__ for p in esper._processors]  # esper keeps them sorted
    assert order == [c.__name__ for c in SCHEDULE]
    sim.close()


def test_two_simulations_do_not_see_each_other(walk):
    a = Simulation({"walk": walk})
    b = Simulation({"walk": walk})
    for i in range(2):
        a.spawn(f"a{i}", Morphology.preset("child"), MotionPlayer("walk"))
    for i in range(3):
        b.spawn(f"b{i}", Morphology.preset("tall"), MotionPlayer("walk"))
    a.step()
    with a._active():
        assert len(esper.get_component(Morphology)) == 2
    with b._active():
        assert len(esper.get_component(Morphology)) == 3
    assert b.tick == 0 and not np.any(b.store.positions)  # stepping a did not touch b
    assert a.names() == ["a0", "a1"] and b.names() == ["b0", "b1", "b2"]
    a.close()
    b.close()
    assert a.world not in esper.list_worlds()


def _run(sim: Simulation, seconds: float) -> dict:
    metrics = MetricsRecorder(sim)
    for _ in range(round(seconds * sim.fps)):
        sim.step()
        metrics.record()
    return metrics.report()


def test_terrain_walk_scenario_holds_feet_ground_and_bones():
    scenario = load_scenario(REPO / "scenarios" / "terrain_walk.yaml")
    statures = sorted(round(c.morphology.stature, 2) for c in scenario.characters)
    assert {1.2, 1.75, 2.0} <= set(statures)
    report = _run(build_simulation(scenario), scenario.duration_s)
    walkers = [c for c in report["characters"] if c["stride_per_leg_length"] is not None]
    assert len(walkers) >= 3
    for c in report["characters"]:
        assert c["foot_sliding_mm_per_frame"]["max"] < 1.0, c
        assert c["ground_penetration_mm_max"] < 1.0, c
        assert c["bone_length_error_m_max"] < 1e-6, c
        assert not c["frozen"]
    ratios = np.array([c["stride_per_leg_length"] for c in walkers])
    assert ratios.max() / ratios.min() < 1.05  # step length scales with leg length
    strides = np.array([c["stride_m_median"] for c in walkers])
    assert strides.max() / strides.min() > 1.5  # ... and so differs between the bodies


def test_real_captured_walk_on_stairs():
    require_mocap()
    motion = import_bvh(MOCAP_DIR / "bandai_walk.bvh")
    path = motion.poses.root_position[-1, :2] - motion.poses.root_position[0, :2]
    heading_deg = float(np.degrees(np.arctan2(path[1], path[0])))  # stairs across the walk
    ground = Combined((Stairs(rise_m=0.14, run_m=0.32, steps=8, start_m=1.5,
                              heading_deg=heading_deg), Bumps(0.02, 2.0, 2.5)))
    sim = Simulation({"walk": motion}, ground)
    for i, preset in enumerate(["child", "adult_female", "tall"]):
        across = np.radians(heading_deg + 90.0)
        sim.spawn(preset, Morphology.preset(preset), MotionPlayer("walk", loop=False),
                  Placement((1.2 * i * np.cos(across), 1.2 * i * np.sin(across))))
    report = _run(sim, motion.duration_s + 0.5)  # past the end: holds the last pose
    for c in report["characters"]:
        assert c["foot_sliding_mm_per_frame"]["max"] < 1.0, c
        assert c["ground_penetration_mm_max"] < 1.0, c
        assert c["bone_length_error_m_max"] < 1e-6, c
    pelvis = sim.store.positions[:, 0]
    under = ground.height(pelvis[:, :2])
    assert np.all(under > 2 * 0.14)  # everyone ended up at least two steps up
    standing = sim.leg_length() + sim.store.lengths[:, 8]
    assert np.all((pelvis[:, 2] - under > 0.8 * standing) & (pelvis[:, 2] - under < 1.1 * standing))


def test_body_replaced_while_playing(walk):
    sim = Simulation({"walk": walk})
    e = sim.spawn("grows", Morphology.preset("child"), MotionPlayer("walk"))
    pelvis = []
    for tick in range(90):
        if tick == 45:
            sim.set_body(e, Morphology.preset("tall"))
        sim.step()
        pelvis.append(sim.store.positions[0, 0].copy())
    lengths = bone_lengths_of(sim.store.positions)[0]
    np.testing.assert_allclose(lengths[IS_BONE], Morphology.preset("tall").lengths[IS_BONE], atol=1e-9)
    horizontal = np.linalg.norm(np.diff(np.array(pelvis)[:, :2], axis=0), axis=-1)
    assert horizontal.max() < 0.1  # m per tick: it grows where it stands, no jump along its path
    assert np.array(pelvis)[46:, 2].min() > 0.85  # the tall body stands up, feet re-planted


def test_queued_clip_crossfades_without_a_jump(walk):
    idle = import_bvh(MOTIONS_DIR / "idle.bvh")
    sim = Simulation({"walk": walk, "idle": idle})
    sim.spawn("a", Morphology.preset("adult_male"),
              MotionPlayer("walk", loop=False, queue=(QueuedClip("idle", 0.5, loop=True),)))
    pelvis = []
    for _ in range(7 * 30):
        sim.step()
        pelvis.append(sim.store.positions[0, 0].copy())
    step = np.linalg.norm(np.diff(np.array(pelvis), axis=0), axis=-1) * 30
    assert sim.store.clip[0] == sim.bank.index("idle")
    assert step.max() < 2.0  # m/s: never a teleport at the switch
    assert step[-30:].max() < 0.3  # standing at rest at the end


BAD = DATA_DIR / "bad_scenarios"
BAD_CASES = [
    ("unknown_preset.yaml", 6, "characters[0].morphology: unknown morphology preset 'chld'; did you mean 'child'?"),
    ("missing_motion.yaml", 3, "motions.walk: motion file '../../../scenarios/motions/nope.bvh' not found"),
    ("grid_wrong_shape.yaml", 8, "ground.heights_m: expected a rectangular grid"),
    ("nan_placement.yaml", 7, "characters[0].position_m[1]: expected a number in m, found nan"),
    ("typo_key.yaml", 7, "characters[0].motoin: unknown key; did you mean 'motion'?"),
    ("unknown_motion.yaml", 7, "characters[0].motion: unknown motion 'wlak'; did you mean 'walk'?"),
    ("unknown_ground.yaml", 4, "ground.type: unknown ground 'stair'; did you mean 'stairs'?"),
    ("bad_yaml.yaml", 3, "not valid YAML"),
    ("constraint_kind_typo.yaml", 15, "characters[1].constraints[0].kind: unknown kind 'postion'; did you mean 'position'?"),
    ("constraint_bad_chain.yaml", 14, "constraint 'hit': 'forearm_r' cannot be moved by leg_l"),
    ("constraint_area_without_area.yaml", 14, "constraint 'above': an area constraint needs its area"),
    ("constraint_unknown_character.yaml", 16, "constraints[0].target.character: no character named 'c'"),
    ("constraint_unknown_segment.yaml", 15, "constraints[0].point: unknown body point 'forarm_r'; did you mean 'forearm_r'?"),
    ("ground_contains_itself.yaml", 5, "ground.parts[0]: a ground cannot contain itself"),
    ("constraint_aims_at_itself.yaml", 10, "constraints[0].target: the target is the constrained point itself"),
    ("constraint_name_twice.yaml", 11, "constraints[1].name: 'reach' is used twice on 'a'"),
    ("com_target_far.yaml", 10, "com_target_m: 70.71 m from the character's position_m"),
    ("distance_on_position.yaml", 12, "distance_m: only a distance constraint takes distance_m"),
    ("table_without_size.yaml", 6, "tables[0].size_m: a table's length and width must be > 0"),
]


@pytest.mark.parametrize("name,line,fragment", BAD_CASES, ids=[c[0] for c in BAD_CASES])
def test_bad_scenarios_give_file_line_and_key(name, line, fragment, capsys):
    path = BAD / name
    with pytest.raises(InputError) as err:
        load_scenario(path)
    message = str(err.value)
    assert message.startswith(f"{path}:{line}: "), message
    assert fragment in message and "\n" not in message
    assert main(["run", str(path)]) == 1
    assert "Traceback" not in capsys.readouterr().err


def test_run_exports_and_refuses_to_overwrite(tmp_path, capsys):
    scenario = REPO / "scenarios" / "terrain_walk.yaml"
    out = tmp_path / "out"
    assert main(["run", str(scenario), "--seconds", "1", "--export", str(out),
                 "--report", str(tmp_path / "r.json")]) == 0
    child = np.load(out / "child.npz")
    assert child["positions"].shape == (30, 22, 3) and child["contacts"].shape == (30, 2)
    before = (out / "child.bvh").read_bytes()
    assert main(["run", str(scenario), "--seconds", "1", "--export", str(out)]) == 1
    assert "--force" in capsys.readouterr().err
    assert (out / "child.bvh").read_bytes() == before


def test_one_broken_character_does_not_stop_the_others(walk, capsys):
    sim = Simulation({"walk": walk})
    for i in range(3):
        sim.spawn(f"c{i}", Morphology.preset("adult_male"), MotionPlayer("walk"), Placement((0.0, i)))
    for _ in range(5):
        sim.step()
    good = sim.store.positions[1].copy()
    sim.store.lengths[1, 2] = np.nan  # corrupt one body behind the API's back
    for _ in range(5):
        sim.step()
    assert sim.store.frozen.tolist() == [False, True, False]
    np.testing.assert_array_equal(sim.store.positions[1], good)  # holds its last good posture
    assert np.all(np.isfinite(sim.store.positions))
    assert not np.array_equal(sim.store.positions[0], sim.store.positions[0] * 0)
    assert "character 'c1' got a non-finite pose" in capsys.readouterr().err
    assert len(sim.messages) == 1


def test_posture_with_a_finer_spine(walk):
    sim = Simulation({"walk": walk}, vertebrae=7)
    sim.spawn("a", Morphology.preset("tall"), MotionPlayer("walk"))
    sim.step()
    spine = np.concatenate([sim.store.positions[:, :1], sim.store.vertebrae], axis=1)
    m = Morphology.preset("tall")
    total = m["spine_lower"] + m["spine_middle"] + m["spine_upper"]
    np.testing.assert_allclose(np.linalg.norm(np.diff(spine, axis=1), axis=-1), total / 7, atol=1e-9)


def test_idle_then_walk_replants_the_feet(walk):
    idle = import_bvh(MOTIONS_DIR / "idle.bvh")
    sim = Simulation({"walk": walk, "idle": idle})
    sim.spawn("a", Morphology.preset("adult_male"),
              MotionPlayer("idle", loop=False, queue=(QueuedClip("walk", 0.5, loop=True),)))
    metrics = MetricsRecorder(sim)
    pelvis = []
    for _ in range(14 * 30):
        sim.step()
        metrics.record()
        pelvis.append(sim.store.positions[0, 0].copy())
    z = np.array(pelvis)[:, 2]
    # No drop and spring-back at the switch: the idle ends at 8 s, the walk fades in over the
    # 0.5 s before it; from then to a stride after, the pelvis moves at most 3 cm a tick. (Later,
    # where a walk contact runs a tick into heel-off, the pelvis dips as far as the planted leg
    # needs: up to 31.6 mm in one tick, the walk's own, the same on its own.)
    switch = slice(int(7.5 * 30) - 15, int(8.0 * 30) + 30)
    assert np.abs(np.diff(z[switch])).max() < 0.03
    alone = Simulation({"walk": walk})
    alone.spawn("a", Morphology.preset("adult_male"), MotionPlayer("walk"))
    walk_z = []
    for _ in range(6 * 30):
        alone.step()
        walk_z.append(alone.store.positions[0, 0, 2])
    assert z.min() > min(walk_z) - 1e-3 and z.min() > 0.78  # never lower than the walk itself
    report = metrics.report()["characters"][0]
    assert report["foot_sliding_mm_per_frame"]["max"] < 1.0
    assert report["ground_penetration_mm_max"] < 1.0


def test_bad_names_and_bench_size(tmp_path, capsys):
    text = (BAD / "typo_key.yaml").read_text().replace("motoin", "motion").replace(
        "name: a", "name: ../escaped")
    bad = BAD / "tmp_bad_name.yaml"  # beside the others: same relative motion paths
    bad.write_text(text)
    try:
        with pytest.raises(InputError, match=r"characters\[0\].name: '../escaped'"):
            load_scenario(bad)
    finally:
        bad.unlink()
    assert main(["bench", "--characters", "3"]) == 1
    assert "8 or more" in capsys.readouterr().err
