"""Foot contacts from the foot's own stillness over any ground (issue 12, item 1), on every walk
of ../shared/mocap and varied/: heel and ball planted, the local ground, an in-place
(treadmill) stance turned into root motion, and the planted arrays stored in the .nmo."""

from __future__ import annotations

import re

import numpy as np
import pytest

from conftest import MOCAP_DIR, REPO
from ecs_anim.apps.cli.main import main
from ecs_anim.core.normalized import decode
from ecs_anim.core.skeleton import JOINT_INDEX as J
from ecs_anim.io.bvh import read_bvh
from ecs_anim.io.c3d.importing import import_c3d
from ecs_anim.io.contacts import horizontal_speed, local_ground
from ecs_anim.io.importing import canonical_clip, import_bvh
from ecs_anim.motion.clip import load_nmo, save_nmo
from support.bvh_reference import in_place_copy

VARIED = MOCAP_DIR / "varied"
#: Walks (over-ground, both feet), with the flags a file needs (see docs/import.md's table): the
#: child's unit (no proportion tells it). (The converters' rest-pose first frames of the CMU
#: walks are dropped on import, with no flag.)
WALKS = {
    "bandai_walk.bvh": {}, "bandai_walk_turn_left.bvh": {},
    "varied/cmu_walk_120hz_adelaide.bvh": {},
    "varied/fair_zup_walk_inch_120hz.bvh": {},
    "varied/fair_zup_child_walk_120hz.bvh": {"unit": "inch"},
    "varied/asf_noneck_walk_speeds_120hz.bvh": {}, "varied/asf_noneck_walk_circle_120hz.bvh": {},
    "varied/cmudaz_03_01_uneven_terrain.bvh": {}, "varied/cmudaz_03_02_uneven_terrain.bvh": {},
    "c3dorg_eb015pi_gait.c3d": {}, "varied/codamotion_dotted_gait_2015_200hz.c3d": {},
    "varied/vicon_cgm24_events_jc_100hz.c3d": {},
    "varied/vicon_pig_noclav_prefix_events_60hz.c3d": {},
    "varied/mac_helenhayes_events_vjc_60hz.c3d": {}, "varied/rehazenter_isb_events_100hz.c3d": {},
    "varied/qualisys_pig_yup_events_100hz.c3d": {},
}
#: Measured where a bound does not hold (open in issue 12), as the worst figures today. On the
#: uneven-terrain walks (CMU 03, Daz release, no toe joint: the toe is the End Site, the toe's
#: tip) the stance foot drifts 8-16 cm while it is planted (0.10-0.28 m/s net, the ankle rising
#: 5-11 cm): with the stillness threshold lowered to 0.2 m/s 03_01's planted median is still
#: 0.16 m/s while a foot is planted only 29 % of the time. Both feet are up in 03_01 (its rest
#: frame 0 dropped: 51 of 432 frames) at the file's frames 149-168, where the left foot steps down 16 cm lower after the right toe has left (4 cm up
#: and rising at the first; the joints' centroid falls at 9-13 m/s^2 for 40 ms of it), and
#: 404-432, where the clip ends in a step down 22 cm lower after the left toe has left (3 cm
#: up); in 03_02 twice for 8-9 frames while a foot comes down (9-11 cm above the ground at the
#: first). (The c3d.org walk, very slow, had its right foot planted 85.5 % of the time until
#: the plant ended at the foot's lift-off.)
OPEN = {
    "varied/cmudaz_03_01_uneven_terrain.bvh": {"median": 0.212, "both_up": 0.1181},
    "varied/cmudaz_03_02_uneven_terrain.bvh": {"both_up": 0.0499},
}
SHARE, MEDIAN_MPS, MAX_MPS = (0.30, 0.85), 0.15, 0.5


def _import(name: str):
    path = MOCAP_DIR / name
    if not path.exists():
        pytest.skip(f"{path} not available")
    if path.suffix == ".c3d":
        return import_c3d(path)
    return import_bvh(path, unit=WALKS.get(name, {}).get("unit"))


def walk_figures(name: str) -> dict[str, float]:
    """The issue's walk figures: per foot the share of frames planted, the planted part's
    horizontal speed (ankle where the heel is planted, toe where the ball is, the slower where
    both; 50 ms filter) median and max, and the share of frames with both feet off the ground
    (neither on the ground from touch-down to lift-off)."""
    motion = _import(name)
    p = decode(motion.poses, motion.source_morphology.lengths, use_stretch=True).positions
    speed = horizontal_speed(p[:, [J["ankle_l"], J["ankle_r"], J["toe_l"], J["toe_r"]]], motion.fps)
    heel, ball, foot = (motion.planted_part(k) for k in ("heel", "ball", "foot"))
    part = np.minimum(np.where(heel, speed[:, :2], np.inf), np.where(ball, speed[:, 2:], np.inf))
    planted = part[np.isfinite(part)]
    return {"left": float(foot[:, 0].mean()), "right": float(foot[:, 1].mean()),
            "median": float(np.median(planted)), "max": float(planted.max()),
            "both_up": float((~motion.planted_part("on_ground").any(axis=1)).mean())}


@pytest.mark.parametrize("name", [pytest.param(n, marks=pytest.mark.xfail(
    reason=f"measured {OPEN[n]}", strict=True)) if n in OPEN else n for n in sorted(WALKS)])
def test_walks_plant_each_foot_30_to_85_percent_still_and_never_both_up(name):
    f = walk_figures(name)
    assert SHARE[0] <= f["left"] <= SHARE[1] and SHARE[0] <= f["right"] <= SHARE[1], f
    assert f["median"] < MEDIAN_MPS and f["max"] < MAX_MPS, f
    assert f["both_up"] == 0.0, f


@pytest.mark.parametrize("name", sorted(OPEN))
def test_open_walks_hold_every_other_bound_and_are_no_worse_than_measured(name):
    f = walk_figures(name)
    limits = {"left": SHARE[1], "right": SHARE[1], "median": MEDIAN_MPS, "max": MAX_MPS,
              "both_up": 0.0}
    for key, bound in limits.items():
        assert f[key] <= OPEN[name].get(key, bound), (key, f)
    assert f["left"] >= SHARE[0] and f["right"] >= SHARE[0], f


def test_local_ground_is_where_feet_stood_nearby():
    """A foot standing on the floor, then on a 0.3 m box: each stance is low over its own
    ground, the swing far from both has none (-inf), one floor for the clip would not do."""
    fps = 10.0
    z = np.r_[np.zeros(10), np.linspace(0.0, 0.5, 5), np.linspace(0.5, 0.3, 5), np.full(10, 0.3)]
    x = np.r_[np.zeros(10), np.linspace(0.0, 1.0, 10), np.ones(10)]
    points = np.stack([x, np.zeros_like(x), z], axis=-1)[:, None, :]
    still = np.r_[np.ones(10, bool), np.zeros(10, bool), np.ones(10, bool)][:, None]
    ground = local_ground(points, fps, 2.0, 0.1, still)[:, 0]
    np.testing.assert_allclose(ground[:10], 0.0)
    np.testing.assert_allclose(ground[20:], 0.3)
    assert np.isneginf(ground[14])


def test_stance_on_a_box_is_a_contact(tmp_path):
    """bandai_walk with its second half raised 0.3 m (a box under the walker): the feet on
    the box are planted as often as on the floor."""
    path = MOCAP_DIR / "bandai_walk.bvh"
    if not path.exists():
        pytest.skip(f"{path} not available")
    text = path.read_text()
    head, motion = text.split("MOTION", 1)
    lines = motion.strip().splitlines()
    frames = lines[2:]
    half = len(frames) // 2
    raised = []
    for k, line in enumerate(frames):
        values = line.split()
        if k >= half:  # Hips' Ypos is the 8th channel (joint_Root has 6, all 0)
            values[7] = f"{float(values[7]) + 30.0:.4f}"
        raised.append(" ".join(values))
    copy = tmp_path / "walk_on_box.bvh"
    copy.write_text(head + "MOTION\n" + "\n".join(lines[:2] + raised) + "\n")
    flat = import_bvh(path).contacts()
    box = import_bvh(copy).contacts()
    settle = slice(half + 10, None)
    assert box[settle].mean() > 0.8 * flat[settle].mean()


def _in_place_copy(tmp_path, name: str = "bandai_walk.bvh"):
    """The walk on a treadmill (:func:`support.bvh_reference.in_place_copy`)."""
    path = MOCAP_DIR / name
    if not path.exists():
        pytest.skip(f"{path} not available")
    return in_place_copy(path, tmp_path)


def test_treadmill_stance_becomes_root_motion_and_the_foot_is_planted(tmp_path, capsys):
    copy = _in_place_copy(tmp_path)
    assert main(["import", str(copy), "-o", str(tmp_path / "out")]) == 0
    out = capsys.readouterr().out
    assert re.search(r"in place on a treadmill-like belt at [0-9.]+ m/s: turned into root motion", out)
    motion = load_nmo(tmp_path / "out" / "walk_in_place.nmo")
    belt = motion.info["treadmill"]
    assert belt["converted"] and 0.8 < belt["speed_mps"] < 1.5  # the walk goes 1.24 m/s
    contact = motion.contacts()
    assert np.all((contact.mean(axis=0) > 0.3) & (contact.mean(axis=0) < 0.85))
    p = decode(motion.poses, motion.source_morphology.lengths, use_stretch=True).positions
    speed = horizontal_speed(p[:, [J["ankle_l"], J["ankle_r"]]], motion.fps)
    assert np.median(speed[contact]) < 0.15
    # --no-treadmill keeps it in place (and says so).
    assert main(["import", str(copy), "-o", str(tmp_path / "kept"), "--no-treadmill"]) == 0
    kept = load_nmo(tmp_path / "kept" / "walk_in_place.nmo")
    assert not kept.info["treadmill"]["converted"]
    root = kept.poses.root_position[:, :2] * 0.8
    assert np.ptp(root, axis=0).max() < 0.2


def test_the_treadmill_run_gets_its_belt_as_root_motion():
    """Vicon's treadmill run (cluster model, 240 Hz): the body stays in place while each stance
    foot moves back with the belt at about 3.2 m/s (varied/README.md)."""
    path = VARIED / "vicon_treadmill_run_clusters_240hz.c3d"
    if not path.exists():
        pytest.skip(f"{path} not available")
    motion = import_c3d(path)
    belt = motion.info["treadmill"]
    assert belt["converted"] and 2.9 < belt["speed_mps"] < 3.6
    from ecs_anim.core.morphology import leg_length
    root = motion.poses.root_position[:, :2] * float(leg_length(motion.source_morphology.lengths))
    assert np.linalg.norm(root[-1] - root[0]) > 25.0  # 10 s at 3.3 m/s, as over ground
    p = decode(motion.poses, motion.source_morphology.lengths, use_stretch=True).positions
    speed = horizontal_speed(p[:, [J["ankle_l"], J["ankle_r"], J["toe_l"], J["toe_r"]]], motion.fps)
    heel, ball = motion.planted_part("heel"), motion.planted_part("ball")
    part = np.minimum(np.where(heel, speed[:, :2], np.inf), np.where(ball, speed[:, 2:], np.inf))
    planted = part[np.isfinite(part)]
    assert len(planted) and np.median(planted) < 0.15 and planted.max() < 0.5
    contact = motion.contacts()
    assert np.all((contact.mean(axis=0) > 0.1) & (contact.mean(axis=0) < 0.5))  # a run


def test_over_ground_clips_are_not_taken_for_treadmills():
    for name in ("bandai_walk.bvh", "bandai_run.bvh", "bandai_bow.bvh", "bandai_dance.bvh"):
        path = MOCAP_DIR / name
        if path.exists():
            assert "treadmill" not in import_bvh(path).info, name


def test_planted_arrays_are_stored_and_old_files_still_load(tmp_path):
    path = MOCAP_DIR / "bandai_walk.bvh"
    if not path.exists():
        pytest.skip(f"{path} not available")
    motion = import_bvh(path)
    save_nmo(motion, tmp_path / "walk.nmo")
    back = load_nmo(tmp_path / "walk.nmo")
    for part in ("heel", "ball", "foot", "on_ground"):
        np.testing.assert_array_equal(back.planted_part(part), motion.planted_part(part))
    heel, ball, foot = (back.planted_part(k) for k in ("heel", "ball", "foot"))
    assert not (heel & ~foot).any() and not (ball & ~foot).any() and heel.any() and ball.any()
    np.testing.assert_array_equal(back.planted_part("foot"), back.contacts())
    # A version-1 file (no planted arrays) loads; every part answers with the contacts.
    motion.planted = None
    save_nmo(motion, tmp_path / "old.nmo")
    import json
    import zipfile
    with zipfile.ZipFile(tmp_path / "old.nmo") as z:
        entries = {n: z.read(n) for n in z.namelist()}
    header_name = "header_json.npy"
    header = np.lib.format.read_array(__import__("io").BytesIO(entries[header_name]))
    data = json.loads(str(header))
    data["version"] = 1
    buf = __import__("io").BytesIO()
    np.lib.format.write_array(buf, np.array(json.dumps(data)))
    entries[header_name] = buf.getvalue()
    with zipfile.ZipFile(tmp_path / "v1.nmo", "w") as z:
        for n, b in entries.items():
            z.writestr(n, b)
    old = load_nmo(tmp_path / "v1.nmo")
    assert old.planted is None
    np.testing.assert_array_equal(old.planted_part("heel"), old.contacts())


def test_contact_speed_can_be_given(tmp_path):
    path = MOCAP_DIR / "bandai_walk.bvh"
    if not path.exists():
        pytest.skip(f"{path} not available")
    assert main(["import", str(path), "-o", str(tmp_path), "--contact-speed", "0.2"]) == 0
    motion = load_nmo(tmp_path / "bandai_walk.nmo")
    assert motion.info["contacts"]["speed_threshold_mps"] == [0.2, 0.2]
    clip = canonical_clip(read_bvh(path))
    assert motion.n_frames == len(clip.positions)


def test_the_readme_contacts_examples_run(tmp_path, monkeypatch, capsys):
    """docs/import.md's foot-contact examples (--contacts events, info, --no-treadmill,
    --contact-speed), as a shell runs them from the repository (out/ becomes a temporary
    folder)."""

    repo = REPO
    text = (repo / "docs" / "import.md").read_text(encoding="utf-8")
    block = text.split("\n## Foot contacts\n", 1)[1].split("\n## ", 1)[0]
    commands = [line.strip().replace(".venv/bin/ecs-anim ", "") for line in block.splitlines()
                if line.strip().startswith(".venv/bin/ecs-anim")]
    assert len(commands) == 3
    if not (repo / "../shared/mocap/varied").is_dir():
        pytest.skip("../shared/mocap not available")
    monkeypatch.chdir(repo)
    for command in commands:
        assert main(command.replace("out/", f"{tmp_path}/").split()) == 0
    out = capsys.readouterr().out
    assert "(from the gait events)" in out and "event         0.924 s  L foot strike" in out
    # --contacts events: the lab's events against its plates (its left strike made on plate 2;
    # its right strike, on frame 106, lies 92.5 ms after plate 1's touch-down: 84.1 ms from
    # halfway between frames 105 and 106, where the plate check takes a contact's edge).
    assert "  plate 2       0.922-1.910 s  L foot (measured touch-down and lift-off)" in out
    assert "  plates     contacts within 84.1 ms of the plates' touch-downs and lift-offs" in out
    motion = load_nmo(tmp_path / "gait" / "bandai_walk.nmo")
    assert motion.info["contacts"]["speed_threshold_mps"] == [0.3, 0.3]
    assert "treadmill" not in motion.info  # over ground: --no-treadmill changes nothing
