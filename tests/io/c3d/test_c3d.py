"""C3D import: real files import, marker-derived bones are nearly rigid and adult-sized, export on
the source body gives the computed joint centres back, gaps are filled or reported, partial
bodies are marked absent, the walk plays on other bodies, and bad files give clear errors.

Real files are read from ../shared/mocap (never copied here); small synthetic C3D files are
written at test time with the ``c3d`` package's writer.
"""

from __future__ import annotations

import re
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from conftest import MOCAP_DIR, MOTIONS_DIR, mocap_params, require_mocap
from ecs_anim.apps.cli.main import main
from ecs_anim.core.errors import EcsAnimError, InputError
from ecs_anim.core.morphology import bone_lengths_of
from ecs_anim.core.normalized import decode
from ecs_anim.core.rotations import rot_axis
from ecs_anim.core.skeleton import BONE_JOINTS, LENGTHS
from ecs_anim.core.skeleton import JOINT_INDEX as J
from ecs_anim.core.skeleton import LENGTH_INDEX as L
from ecs_anim.io.c3d.centre_kernels import chord_centre, cluster_poses, score_centre
from ecs_anim.io.c3d.importing import canonical_clip_c3d, import_c3d
from ecs_anim.io.c3d.marker_sets import check_usable, match_markers
from ecs_anim.io.c3d.reading import read_c3d
from ecs_anim.io.c3d.repair import fill_gaps
from ecs_anim.io.importing import import_bvh
from ecs_anim.motion.clip import load_nmo
from ecs_anim.runtime.metrics import MetricsRecorder
from ecs_anim.scenario import build_simulation, load_scenario
from support.c3d_files import write_c3d

MM = 1e-3
TENNIS = MOCAP_DIR / "ktk_tennis_serve.c3d"
GAIT = MOCAP_DIR / "c3dorg_eb015pi_gait.c3d"
#: Bones every marker set here measures, and a plausible adult range for each (m).
ADULT_RANGE_M = {"thigh": (0.33, 0.52), "shank": (0.32, 0.50), "upper_arm": (0.24, 0.38),
                 "forearm": (0.20, 0.32)}
#: Bound on the spread of a marker-derived bone over a trial: std / mean (measured: 0.6-0.8 %
#: for the cluster gait, 1.5-3.7 % for the tennis serve's skin markers).
SPREAD_BOUND = 0.05


def _reliable(clip, extra) -> np.ndarray:
    ok = np.ones(len(clip.positions), dtype=bool)
    for a, b in extra["gaps"]["long_gap_frames"]:
        ok[a:b + 1] = False
    return ok


# --- kernels -----------------------------------------------------------------------------------

def test_fill_gaps_interpolates_short_and_reports_long_and_held_ends():
    f = np.arange(100, dtype=float)
    points = np.stack([np.stack([f, 2 * f, np.full(100, 5.0)], axis=-1)] * 2, axis=1)
    valid = np.ones((100, 2), dtype=bool)
    valid[10:15, 0] = False  # 5 frames: short
    valid[40:70, 1] = False  # 30 frames: long
    valid[:3, 1] = False  # at the start: held, so unreliable however short
    filled, unreliable = fill_gaps(points * np.where(valid, 1.0, 0.0)[..., None], valid, max_gap=10)
    np.testing.assert_allclose(filled[10:15, 0], points[10:15, 0])  # linear motion comes back
    np.testing.assert_allclose(filled[40:70, 1], points[40:70, 1])
    np.testing.assert_allclose(filled[:3, 1], np.repeat(points[3:4, 1], 3, axis=0))
    assert not unreliable[:, 0].any()
    assert unreliable[40:70, 1].all() and unreliable[:3, 1].all() and unreliable[:, 1].sum() == 33
    assert np.all(np.isfinite(filled))


def test_score_finds_a_ball_joint_and_the_hinge_point_nearest_the_prior_up_the_segment():
    rng = np.random.default_rng(6)
    n = 200
    parent_rot = rot_axis(2, rng.uniform(-0.3, 0.3, n)) @ rot_axis(0, rng.uniform(-0.2, 0.2, n))
    parent_origin = rng.normal(size=(n, 3))
    centre_in_parent = np.array([0.1, -0.05, -0.3])
    centre_in_child = np.array([0.0, 0.02, 0.25])
    child_rot = parent_rot @ rot_axis(1, rng.uniform(-1.0, 1.0, n)) @ rot_axis(0, rng.uniform(-0.5, 0.5, n))
    centre = np.einsum("fij,j->fi", parent_rot, centre_in_parent) + parent_origin
    child_origin = centre - np.einsum("fij,j->fi", child_rot, centre_in_child)
    use = np.ones(n, dtype=bool)
    cp, cc, world = score_centre((parent_rot, parent_origin), (child_rot, child_origin), use)
    np.testing.assert_allclose(cp, centre_in_parent, atol=1e-9)
    np.testing.assert_allclose(cc, centre_in_child, atol=1e-9)
    np.testing.assert_allclose(world, centre, atol=1e-9)
    # A hinge about the parent's y axis: any point on that axis fits; the prior (the proximal
    # joint, up the segment along z) picks one.
    hinge_rot = parent_rot @ rot_axis(1, rng.uniform(-1.0, 1.0, n))
    hinge_origin = centre - np.einsum("fij,j->fi", hinge_rot, centre_in_child)
    prior = centre_in_parent + np.array([0.05, 0.1, 0.4])
    hinge = ((parent_rot, parent_origin), (hinge_rot, hinge_origin), use)
    cp, _, world = score_centre(*hinge, prior)
    np.testing.assert_allclose(cp, centre_in_parent + [0.0, 0.1, 0.0], atol=1e-9)
    # A weakest direction pointing at the prior is no flexion axis across the segment (a
    # twist): the prior does not move the centre along it.
    free, _, _ = score_centre(*hinge)
    along, _, _ = score_centre(*hinge, centre_in_parent + np.array([0.05, 0.4, 0.1]))
    np.testing.assert_allclose(along, free, atol=1e-9)


def test_cluster_poses_recover_a_rigid_motion_with_a_missing_marker():
    rng = np.random.default_rng(3)
    shape = rng.normal(scale=0.05, size=(4, 3))
    n = 50
    rot = rot_axis(2, np.linspace(0, 2, n)) @ rot_axis(0, np.linspace(0, 1, n))
    origin = rng.normal(size=(n, 3))
    points = np.einsum("fij,kj->fki", rot, shape) + origin[:, None]
    weights = np.ones((n, 4))
    weights[10:20, 2] = 0.0
    points[10:20, 2] = 99.0  # garbage where missing
    got_rot, got_origin = cluster_poses(points, weights)
    fitted = np.einsum("fij,fkj->fki", np.swapaxes(got_rot, -1, -2), points - got_origin[:, None])
    rebuilt = np.einsum("fij,kj->fki", got_rot, fitted[0]) + got_origin[:, None]
    keep = weights > 0
    np.testing.assert_allclose(rebuilt[keep], points[keep], atol=1e-9)


def test_chord_centre_is_offset_perpendicular_and_away_from_the_wand():
    hip = np.array([[0.0, 0.1, 0.9]])
    knee_marker = np.array([[0.0, 0.2, 0.5]])
    wand = np.array([[0.05, 0.25, 0.7]])  # lateral of the hip-knee line
    centre = chord_centre(hip, wand, knee_marker, 0.06)
    assert np.linalg.norm(centre - knee_marker) == pytest.approx(0.06)
    assert float(np.dot((hip - centre)[0], (knee_marker - centre)[0])) == pytest.approx(0.0, abs=1e-12)
    assert centre[0, 1] < knee_marker[0, 1]  # moved medially, away from the wand side


# --- real files ----------------------------------------------------------------------------------

@pytest.mark.parametrize("path", mocap_params("*.c3d"))
def test_every_c3d_imports_with_rigid_adult_bones(path, tmp_path, capsys):
    assert main(["import", str(path), "-o", str(tmp_path)]) == 0
    out = capsys.readouterr().out
    assert "marker set" in out
    motion = load_nmo(tmp_path / f"{path.stem}.nmo")
    assert all(np.all(np.isfinite(v)) for v in motion.poses.arrays().values())
    clip, extra = canonical_clip_c3d(read_c3d(path))
    reliable = _reliable(clip, extra)
    lengths = bone_lengths_of(clip.positions[reliable])
    for bone, (lo, hi) in ADULT_RANGE_M.items():
        for s in "lr":
            name = f"{bone}_{s}"
            if bone in ("upper_arm", "forearm") and f"arm_{s}" in extra["absent"]:
                continue
            x = lengths[:, L[name]]
            assert lo <= x.mean() <= hi, (name, x.mean())
            assert x.std() / x.mean() < SPREAD_BOUND, (name, x.std() / x.mean())
    # Every other marker-derived segment too: trunk, neck, head, hands and feet within 6 %; the
    # clavicles (neck base to shoulder centre) within 15 %, the acromion marker riding on the
    # shoulder girdle as it elevates (14 % in the tennis serve, stated in docs/import.md).
    measured = np.array(clip.measured)
    for name, (a, b) in zip(LENGTHS, BONE_JOINTS, strict=True):
        if a < 0 or not (measured[a] and measured[b]) or name[:-2] in ADULT_RANGE_M:
            continue
        x = lengths[:, L[name]]
        bound = 0.15 if name.startswith("clavicle") else 0.06
        assert x.std() / x.mean() < bound, (name, x.std() / x.mean())
    assert 1.5 < motion.source_morphology.stature < 2.0
    contacts = motion.contacts()
    assert 0.3 < contacts.mean() < 0.95  # both feet touch down some of the time


@pytest.mark.parametrize("path", mocap_params("*.c3d"))
def test_source_export_reproduces_joint_centres_within_1_mm(path, tmp_path):
    assert main(["import", str(path), "-o", str(tmp_path)]) == 0
    npz = tmp_path / "source.npz"
    assert main(["export", str(tmp_path / f"{path.stem}.nmo"), "--morphology", "source",
                 "-o", str(npz)]) == 0
    exported = np.load(npz)["positions"]
    clip, extra = canonical_clip_c3d(read_c3d(path))
    reliable = _reliable(clip, extra)
    error = np.linalg.norm(exported - clip.positions, axis=-1)[reliable]
    assert error.max() < 1 * MM, error.max()


def test_tennis_serve_prefix_and_every_part_present():
    require_mocap()
    motion = import_c3d(TENNIS)
    assert motion.info["marker_set"] == "plug_in_gait" and motion.info["subject"] == "Derrick"
    assert motion.info["absent"] == []
    assert motion.info["unit"] == "m" and motion.info["up_axis"] == "z"
    # Both wrists rise above the head in each serve (mocap README).
    clip, _ = canonical_clip_c3d(read_c3d(TENNIS))
    above = clip.positions[:, [J["wrist_l"], J["wrist_r"]], 2] > clip.positions[:, [J["head_top"]], 2]
    assert above[:, 0].any() and above[:, 1].any()


def test_cluster_gait_is_lower_body_with_functional_centres():
    require_mocap()
    motion = import_c3d(GAIT)
    assert motion.info["marker_set"] == "cluster_gait" and motion.info["unit"] == "mm"
    assert motion.info["absent"] == ["trunk", "head", "arm_l", "arm_r"]
    assert "SCoRE" in motion.info["joints"]["knee_l"]
    # Walks about 2.2 m along +Y in 9 s (mocap README).
    pelvis = motion.poses.root_position * motion.source_morphology.leg_length
    travel = pelvis[-1] - pelvis[0]
    assert 1.8 < travel[1] < 2.8 and abs(travel[0]) < 0.4


def _tennis_markers() -> tuple[list[str], np.ndarray, float]:
    raw = read_c3d(TENNIS)
    labels = [lab.split(":")[-1] for lab in raw.labels]
    return labels, raw.positions[:300], raw.rate


def test_a_part_missing_at_the_ends_has_those_frames_trimmed_and_said(tmp_path):
    """A marker held before it is first seen, or after it is last seen, is no measurement: Vicon
    Matt's RANK, missing in the first 7 frames, stood still while the knee walked on (the shank
    0.175 m of 0.40). Such frames at the ends go, with one line each naming the part and its
    markers; where that would keep less than half the trial, they stay and are reported."""
    require_mocap()
    labels, positions, rate = _tennis_markers()
    valid = np.ones(positions.shape[:2], dtype=bool)
    valid[:6, labels.index("RANK")] = False
    valid[-4:, labels.index("LWRA")] = False
    clip, extra = canonical_clip_c3d(read_c3d(write_c3d(tmp_path / "ends.c3d", labels, positions,
                                                        valid, rate)))
    assert len(clip.positions) == 290 and extra["first_file_frame"] == 6
    assert extra["root_frames_trimmed"] == []
    assert extra["parts_frames_trimmed"] == [
        "frames 0-5 of the file trimmed: the markers of the right leg (RANK) are unseen or in a "
        "long gap there",
        "frames 296-299 of the file trimmed: the markers of the left arm (LWRA) are unseen or in a "
        "long gap there"]
    whole, _ = canonical_clip_c3d(read_c3d(write_c3d(tmp_path / "whole.c3d", labels, positions,
                                                     None, rate)))
    shank = np.linalg.norm(clip.positions[:, J["ankle_r"]] - clip.positions[:, J["knee_r"]], axis=-1)
    shank_whole = np.linalg.norm(whole.positions[6:296, J["ankle_r"]] - whole.positions[6:296, J["knee_r"]],
                                 axis=-1)
    assert np.abs(shank - shank_whole).max() < 0.002
    valid[:, :] = True
    valid[:200, labels.index("RTOE")] = False  # trimming would keep a third of the trial
    clip, extra = canonical_clip_c3d(read_c3d(write_c3d(tmp_path / "toe.c3d", labels, positions,
                                                        valid, rate)))
    assert len(clip.positions) == 300 and extra["parts_frames_trimmed"] == []
    assert extra["gaps"]["long_gap_frames"] == [[0, 199]]


def test_lower_body_subset_with_prefix_other_objects_and_gaps(tmp_path):
    require_mocap()
    labels, positions, rate = _tennis_markers()
    lower = [i for i, lab in enumerate(labels) if lab[1:] in
             ("ASI", "PSI", "THI", "KNE", "TIB", "ANK", "HEE", "TOE")]
    names = [f"Bob:{labels[i]}" for i in lower] + ["Ball:M1", "Ball:M2"]
    points = np.concatenate([positions[:, lower], np.full((300, 2, 3), 0.5)], axis=1)
    valid = np.ones(points.shape[:2], dtype=bool)
    lkne = names.index("Bob:LKNE")
    valid[100:104, lkne] = False  # 4 frames (80 ms at 50 Hz): filled
    ltoe = names.index("Bob:LTOE")
    valid[150:180, ltoe] = False  # 30 frames (0.6 s): reported
    points[200:203, names.index("Bob:RHEE")] = np.nan  # not-a-number samples: filled too
    path = write_c3d(tmp_path / "lower.c3d", names, points, valid, rate)
    motion = import_c3d(path)
    info = motion.info
    assert info["marker_set"] == "plug_in_gait" and info["subject"] == "Bob"
    assert info["ignored_markers"] == ["Ball:M1", "Ball:M2"]
    assert info["absent"] == ["trunk", "head", "arm_l", "arm_r"]
    assert info["gaps"]["long_gap_frames"] == [[150, 179]]
    assert info["gaps"]["long_gap_samples_per_marker"] == {"Bob:LTOE": 30}
    assert info["gaps"]["samples_filled"] == 4 + 30 + 3
    assert all(np.all(np.isfinite(v)) for v in motion.poses.arrays().values())
    # The short gap was interpolated: the knee stays close to the full file's knee.
    full, _ = canonical_clip_c3d(read_c3d(path))
    reference, _ = canonical_clip_c3d(read_c3d(TENNIS))
    knee_error = np.linalg.norm(full.positions[100:104, J["knee_l"]]
                                - reference.positions[100:104, J["knee_l"]], axis=-1)
    assert knee_error.max() < 0.02
    # The absent parts are a neutral pose: arms hang straight down.
    arm = full.positions[:, J["wrist_l"]] - full.positions[:, J["shoulder_l"]]
    np.testing.assert_allclose(arm[:, :2], 0.0, atol=1e-12)


def test_isb_landmark_names_give_the_same_centres_as_midpoints(tmp_path):
    """ISB/CAST epicondyles and malleoli placed symmetrically about the Plug-in-Gait centres:
    the anatomical import finds the same knees, ankles and elbows."""
    require_mocap()
    labels, positions, rate = _tennis_markers()
    reference, _ = canonical_clip_c3d(read_c3d(TENNIS))
    ref = reference.positions[:300]
    side_axis = np.array([0.0, 1.0, 0.0])
    markers: dict[str, np.ndarray] = {}
    rename = {"ASI": "ASIS", "PSI": "PSIS", "SHO": "AC", "WRA": "RSP", "WRB": "USP",
              "FHD": "FHD", "BHD": "BHD"}
    for i, lab in enumerate(labels):
        if lab[1:] in rename:
            markers[f"{lab[0]}_{rename[lab[1:]]}"] = positions[:, i]
    for name in ("C7", "T10", "CLAV", "STRN"):
        markers[{"CLAV": "IJ", "STRN": "PX", "T10": "T8"}.get(name, name)] = positions[:, labels.index(name)]
    for s, S in (("l", "L"), ("r", "R")):
        for joint, (lat, med), half in (("knee", ("FLE", "FME"), 0.05), ("ankle", ("FAL", "TAM"), 0.035),
                                        ("elbow", ("HLE", "HME"), 0.03)):
            markers[f"{S}_{lat}"] = ref[:, J[f"{joint}_{s}"]] + half * side_axis
            markers[f"{S}_{med}"] = ref[:, J[f"{joint}_{s}"]] - half * side_axis
        markers[f"{S}_FM1"] = ref[:, J[f"toe_{s}"]] + 0.03 * side_axis
        markers[f"{S}_FM5"] = ref[:, J[f"toe_{s}"]] - 0.03 * side_axis
    names = list(markers)
    path = write_c3d(tmp_path / "isb.c3d", names, np.stack([markers[n] for n in names], axis=1), rate=rate)
    clip, extra = canonical_clip_c3d(read_c3d(path))
    assert extra["marker_set"] == "isb_anatomical" and extra["absent"] == []
    for joint in ("knee_l", "ankle_r", "elbow_l", "toe_r"):
        error = np.linalg.norm(clip.positions[:, J[joint]] - ref[:, J[joint]], axis=-1)
        assert np.median(error) < 1e-5, (joint, np.median(error))  # float32 in the file
    # Hips: the same regression, with pelvis width and depth taken over 300 of the 1092 frames.
    error = np.linalg.norm(clip.positions[:, J["hip_l"]] - ref[:, J["hip_l"]], axis=-1)
    assert error.max() < 2 * MM


C3D_SCENARIO = """\
description: the c3d.org walk (lower body only) on a child and a tall adult, bumps and stairs
duration_s: 9.0
fps: 30
motions:
  walk: {path}
ground:
  type: combined
  parts:
    - {{type: bumps, amplitude_m: 0.03, wavelength_x_m: 2.5, wavelength_y_m: 3.0}}
    - {{type: stairs, rise_m: 0.10, run_m: 0.40, steps: 3, start_m: 1.0, heading_deg: 90}}
characters:
  - {{name: child, morphology: child, position_m: [0.0, 0.0], motion: walk, loop: false}}
  - {{name: tall, morphology: tall, position_m: [1.2, 0.0], motion: walk, loop: false}}
"""


def test_c3d_walk_plays_on_a_child_and_a_tall_adult_without_sliding(tmp_path):
    """terrain_walk.yaml's checks on the C3D walk: feet locked during contacts (< 1 mm per
    frame), no ground penetration, rigid bones, and both bodies end up the stairs."""
    require_mocap()
    scenario_path = tmp_path / "c3d_walk.yaml"
    scenario_path.write_text(C3D_SCENARIO.format(path=GAIT))
    scenario = load_scenario(scenario_path)
    sim = build_simulation(scenario)
    metrics = MetricsRecorder(sim)
    for _ in range(round(scenario.duration_s * sim.fps)):
        sim.step()
        metrics.record()
    report = metrics.report()["characters"]
    for c in report:
        assert c["foot_sliding_mm_per_frame"]["max"] < 1.0, c
        assert c["ground_penetration_mm_max"] < 1.0, c
        assert c["bone_length_error_m_max"] < 1e-6, c
    ratios = [c["stride_per_leg_length"] for c in report]
    assert max(ratios) / min(ratios) < 1.05  # the step scales with the leg
    pelvis = sim.store.positions[:, J["pelvis"]]
    assert np.all(sim.ground.height(pelvis[:, :2]) > 0.15)  # both climbed (the child 2 steps)


# --- bad files ---------------------------------------------------------------------------------

def _small_markers(labels: list[str], n: int = 20) -> np.ndarray:
    rng = np.random.default_rng(1)
    return rng.uniform(0.0, 1.0, size=(n, len(labels), 3))


def _assert_error(path: Path, fragment: str) -> str:
    with pytest.raises(InputError) as err:
        import_c3d(path)
    text = str(err.value)
    assert text.startswith(f"{path}: ") and "\n" not in text and fragment in text, text
    return text


def test_truncated_file(tmp_path):
    good = write_c3d(tmp_path / "good.c3d", ["A", "B"], _small_markers(["A", "B"], 200))
    data = good.read_bytes()
    cut = tmp_path / "cut.c3d"
    cut.write_bytes(data[: len(data) - 1024])
    _assert_error(cut, "truncated")
    header_only = tmp_path / "header_only.c3d"
    header_only.write_bytes(data[:600])
    _assert_error(header_only, "not a readable C3D file")


def test_garbage_and_empty_files(tmp_path):
    garbage = tmp_path / "garbage.c3d"
    garbage.write_bytes(b"this is not a c3d file at all\n" * 40)
    _assert_error(garbage, "not a readable C3D file")
    empty = tmp_path / "empty.c3d"
    empty.write_bytes(b"")
    _assert_error(empty, "not a readable C3D file")


def test_unlabelled_markers(tmp_path):
    path = write_c3d(tmp_path / "nolabels.c3d", ["", "", ""], _small_markers(["", "", ""]))
    _assert_error(path, "no labels")


def test_unknown_marker_set_lists_labels(tmp_path):
    labels = ["Marker1", "Marker2", "Marker3"]
    path = write_c3d(tmp_path / "unknown.c3d", labels, _small_markers(labels))
    text = _assert_error(path, "no marker set recognised")
    assert "Marker1" in text


def test_missing_markers_listed_per_body_part(tmp_path):
    labels = ["LASI", "RASI", "LPSI", "RPSI", "LTHI", "LKNE", "LTIB", "LANK", "LTOE",
              "RTHI", "RKNE", "RTIB", "RTOE", "LSHO", "LELB", "LWRA"]
    mmap = match_markers(labels)
    present, absent = check_usable(mmap, labels)
    assert present == ["pelvis", "leg_l"] and "leg_r" in absent and "arm_l" in absent
    notes = mmap.not_computed
    assert notes["leg_r"] == "right leg not computed: found RKNE, RTHI, RTIB, RTOE; lacks RANK"
    assert "lacks LWRB or LWRI" in notes["arm_l"]


def test_cli_reports_a_bad_c3d_and_imports_the_others(tmp_path, capsys):
    require_mocap()
    garbage = tmp_path / "garbage.c3d"
    garbage.write_bytes(b"\x00" * 10)
    out = tmp_path / "out"
    assert main(["import", str(garbage), str(TENNIS), "-o", str(out)]) == 1
    err = capsys.readouterr().err
    assert "Traceback" not in err
    assert f"error: {garbage}: not a readable C3D file" in err
    assert (out / "ktk_tennis_serve.nmo").exists() and not (out / "garbage.nmo").exists()
    assert main(["import", str(TENNIS), "-o", str(out)]) == 1  # no overwrite without --force
    assert "--force" in capsys.readouterr().err
    assert main(["import", str(TENNIS), "-o", str(out), "--force"]) == 0


def test_user_marker_map_overrides_a_label(tmp_path):
    require_mocap()
    labels, positions, rate = _tennis_markers()
    labels = ["KnieLinks" if lab == "LKNE" else lab for lab in labels]
    path = write_c3d(tmp_path / "renamed.c3d", labels, positions, rate=rate)
    notes = import_c3d(path).info["parts_not_computed"]
    assert notes["leg_l"] == "left leg not computed: found LANK, LTHI, LTIB, LTOE; lacks LKNE"
    user_map = tmp_path / "map.yaml"
    user_map.write_text("base: plug_in_gait\nmarkers:\n  KNEE_LAT_l: KnieLinks\n")
    motion = import_c3d(path, str(user_map))
    assert str(user_map) in motion.info["joint_map"]
    bad_map = tmp_path / "bad_map.yaml"
    bad_map.write_text("markers:\n  KNEE_LAT_x: KnieLinks\n")
    with pytest.raises(InputError) as err:
        import_c3d(path, str(bad_map))
    assert str(err.value).startswith(f"{bad_map}:2: markers.KNEE_LAT_x: unknown role")


def test_unreadable_file_gives_an_error_not_a_crash(tmp_path):
    with pytest.raises(EcsAnimError, match="cannot read file"):
        import_c3d(tmp_path / "nope.c3d")


def test_lower_body_preset_ignores_the_upper_body():
    require_mocap()
    lower, extra = canonical_clip_c3d(read_c3d(TENNIS), "plug_in_gait_lower")
    full, _ = canonical_clip_c3d(read_c3d(TENNIS))
    assert extra["marker_set"] == "plug_in_gait_lower"
    assert extra["absent"] == ["trunk", "head", "arm_l", "arm_r"]
    legs = [J[f"{j}_{s}"] for j in ("hip", "knee", "ankle", "toe") for s in "lr"]
    np.testing.assert_allclose(lower.positions[:, legs], full.positions[:, legs], atol=1e-12)


def test_upper_body_only_places_the_pelvis_under_the_trunk(tmp_path):
    require_mocap()
    labels, positions, rate = _tennis_markers()
    upper = [i for i, lab in enumerate(labels)
             if lab in ("C7", "T10", "CLAV", "STRN", "RBAK") or lab[1:] in
             ("SHO", "UPA", "ELB", "FRM", "WRA", "WRB", "FIN", "FHD", "BHD")]
    path = write_c3d(tmp_path / "upper.c3d", [labels[i] for i in upper], positions[:, upper],
                     rate=rate)
    motion = import_c3d(path)
    assert motion.info["absent"] == ["pelvis", "leg_l", "leg_r"]
    assert all(np.all(np.isfinite(v)) for v in motion.poses.arrays().values())
    clip, _ = canonical_clip_c3d(read_c3d(path))
    full, _ = canonical_clip_c3d(read_c3d(TENNIS))
    for joint in ("wrist_l", "wrist_r", "shoulder_l", "neck", "head_top"):
        # Same markers, same rules; the shoulders' drop uses the acromion distance's median over
        # 300 frames instead of 1,092 (2 mm apart), the head length is in proportion to a leg
        # estimated from the shoulders instead of measured, and a few frames may differ where
        # joint-centre outliers were judged on the shorter trial.
        error = np.linalg.norm(clip.positions[:, J[joint]] - full.positions[:300, J[joint]], axis=-1)
        bound = {"shoulder_l": 3 * MM, "head_top": 10 * MM}.get(joint, 1e-5)
        assert np.percentile(error, 95) < bound, joint
    # The pelvis it guessed is near the real one (within 15 cm), legs hang straight.
    guess = np.linalg.norm(clip.positions[:, J["pelvis"]] - full.positions[:300, J["pelvis"]], axis=-1)
    assert np.median(guess) < 0.15, np.median(guess)
    shank = clip.positions[:, J["ankle_l"]] - clip.positions[:, J["knee_l"]]
    np.testing.assert_allclose(shank[:, :2], 0.0, atol=1e-12)


def _flexing_hip(seed: int, n: int):
    """``n`` frames of a hip that only flexes (about the parent's y): the parent's rotations and
    origins, the centre in the parent (m) and in the world (n, 3), the flexion angles (n,) rad
    and the child's rotations."""
    rng = np.random.default_rng(seed)
    parent_rot = rot_axis(2, rng.uniform(-0.2, 0.2, n))
    parent_origin = rng.normal(size=(n, 3))
    centre_in_parent = np.array([0.05, 0.09, -0.1])
    centre = np.einsum("fij,j->fi", parent_rot, centre_in_parent) + parent_origin
    flexion = rng.uniform(-0.6, 0.6, n)
    return parent_rot, parent_origin, centre_in_parent, centre, flexion, parent_rot @ rot_axis(1, flexion)


def test_score_hinge_plane_rule_places_the_centre_on_the_axis():
    """A hip that only flexes: the centre is put on its axis at a given lateral offset."""
    parent_rot, parent_origin, _, centre, _, child_rot = _flexing_hip(8, 100)
    n = len(centre)
    child_origin = centre - np.einsum("fij,j->fi", child_rot, np.array([0.0, 0.0, 0.3]))
    cp, _, _ = score_centre((parent_rot, parent_origin), (child_rot, child_origin),
                            np.ones(n, dtype=bool), hinge_plane_in_parent=(np.array([0.0, 1.0, 0.0]), 0.07))
    np.testing.assert_allclose(cp, [0.05, 0.07, -0.1], atol=1e-9)


def test_score_hinge_through_a_landmark_ignores_soft_tissue_sliding_along_the_thigh():
    """A flexion-only hip whose thigh cluster slides along the thigh with flexion (soft tissue):
    SCoRE's axis direction comes from the rotations alone and stays right, its location does
    not; through the greater trochanter (a point on the axis) the centre is found again."""
    parent_rot, parent_origin, centre_in_parent, centre, flexion, child_rot = _flexing_hip(9, 200)
    n = len(centre)
    slide = 0.03 * flexion[:, None] * child_rot[:, :, 2]  # 30 mm per radian along the thigh
    child_origin = centre - np.einsum("fij,j->fi", child_rot, np.array([0.0, 0.0, 0.3])) + slide
    plane = (np.array([0.0, 1.0, 0.0]), 0.07)
    args = ((parent_rot, parent_origin), (child_rot, child_origin), np.ones(n, dtype=bool))
    biased, _, _ = score_centre(*args, hinge_plane_in_parent=plane)
    assert np.linalg.norm(biased - [0.05, 0.07, -0.1]) > 0.005
    trochanter = centre_in_parent + np.array([0.0, 0.09, 0.0])
    cp, _, _ = score_centre(*args, hinge_plane_in_parent=plane, hinge_through_in_parent=trochanter)
    np.testing.assert_allclose(cp, [0.05, 0.07, -0.1], atol=1e-9)


def test_y_up_file_is_detected_and_turned_z_up(tmp_path):
    require_mocap()
    labels, positions, rate = _tennis_markers()
    y_up = np.stack([positions[..., 0], positions[..., 2], -positions[..., 1]], axis=-1)
    path = write_c3d(tmp_path / "yup.c3d", labels, y_up, rate=rate)
    clip, extra = canonical_clip_c3d(read_c3d(path))
    assert clip.up_axis == "y" and extra["up_reason"] == "detected from the markers"
    z_up, _ = canonical_clip_c3d(read_c3d(write_c3d(tmp_path / "zup.c3d", labels, positions,
                                                    rate=rate)))
    np.testing.assert_allclose(clip.positions, z_up.positions, atol=1e-5)  # float32 in files


def test_info_names_the_absent_parts(tmp_path, capsys):
    require_mocap()
    assert main(["import", str(GAIT), "-o", str(tmp_path)]) == 0
    capsys.readouterr()
    assert main(["info", str(tmp_path / f"{GAIT.stem}.nmo")]) == 0
    assert "absent     trunk, head, arm_l, arm_r (no markers: neutral pose)" in capsys.readouterr().out


def test_absent_parts_from_a_default_motion(tmp_path, capsys):
    require_mocap()
    walk = MOTIONS_DIR / "walk.bvh"
    neutral = import_c3d(GAIT)
    filled = import_c3d(GAIT, fill_from=walk)
    assert filled.info["absent_fill"] == "from walk.bvh"
    default = import_bvh(walk)
    index = np.round(np.arange(filled.n_frames) / filled.fps * default.fps).astype(int) % default.n_frames
    np.testing.assert_array_equal(filled.poses.arm_frame, default.poses.arm_frame[index])
    np.testing.assert_array_equal(filled.poses.thorax, default.poses.thorax[index])
    np.testing.assert_array_equal(filled.poses.leg_frame, neutral.poses.leg_frame)  # captured
    np.testing.assert_array_equal(filled.poses.root_position, neutral.poses.root_position)
    arms = decode(filled.poses, filled.source_morphology.lengths).positions[:, J["wrist_l"]]
    assert np.ptp(arms[:, 0] - decode(neutral.poses, neutral.source_morphology.lengths)
                  .positions[:, J["wrist_l"], 0]) > 0.05  # the arms swing now
    assert main(["import", str(GAIT), "-o", str(tmp_path), "--fill-absent-from", str(walk)]) == 0
    assert "absent (from walk.bvh): trunk, head, arm_l, arm_r" in capsys.readouterr().out


def test_a_scenario_plays_absent_parts_from_another_of_its_motions(tmp_path):
    """``motions: {gait: {file: X.c3d, absent_from: walk}}``: the lower-body capture plays with
    the walk's trunk and arms, chosen at playback, not baked in at import; a motion that lacks
    nothing, or an unknown name, is a one-line error."""
    require_mocap()
    walk = MOTIONS_DIR / "walk.bvh"
    text = (f"duration_s: 1.0\nmotions:\n  walk: {walk}\n"
            f"  gait: {{file: {GAIT}, absent_from: walk}}\n"
            "characters:\n  - {name: a, morphology: tall, motion: gait}\n")
    path = tmp_path / "s.yaml"
    path.write_text(text)
    scenario = load_scenario(path)
    gait = scenario.motions["gait"]
    assert gait.info["absent_fill"] == "from walk"
    np.testing.assert_array_equal(gait.poses.arm_frame, import_c3d(GAIT, fill_from=walk).poses.arm_frame)
    with build_simulation(scenario) as sim:
        for _ in range(10):
            sim.step()
        assert np.all(np.isfinite(sim.store.positions))
    for bad, message in ((text.replace("absent_from: walk", "absent_from: wlak"),
                          ":4: motions.gait.absent_from: no other motion named 'wlak'; did you mean 'walk'?"),
                         (text.replace(f"  walk: {walk}", f"  walk: {{file: {walk}, absent_from: gait}}"),
                          ":3: motions.walk.absent_from: 'walk' has every body part")):
        path.write_text(bad)
        with pytest.raises(InputError, match=re.escape(message)):
            load_scenario(path)


def test_a_wand_in_front_of_the_segment_gives_the_knee_and_ankle_on_the_flexion_axis(tmp_path):
    """The chord rule's wand (THI, TIB) moved from the side of the thigh and shank to their
    front, as some Helen Hayes sets place it: the centres come from the knee's flexion axis
    instead (found from the motion), near where the lateral wands put them, not behind the knee."""
    require_mocap()
    labels, positions, rate = _tennis_markers()
    reference, _ = canonical_clip_c3d(read_c3d(write_c3d(tmp_path / "lateral.c3d", labels, positions,
                                                          rate=rate)))
    ref = reference.positions
    moved = positions.copy()
    forward = reference.pelvis2world[:, :, 0]
    for s, S in (("l", "L"), ("r", "R")):
        for wand, top, bottom in (("THI", "hip", "KNE"), ("TIB", "knee", "ANK")):
            line_top = ref[:, J[f"{top}_{s}"]]
            line_bottom = positions[:, labels.index(f"{S}{bottom}")]
            u = (line_top - line_bottom) / np.linalg.norm(line_top - line_bottom, axis=-1, keepdims=True)
            w = positions[:, labels.index(f"{S}{wand}")] - line_bottom
            along = np.sum(w * u, axis=-1, keepdims=True)
            front = forward - np.sum(forward * u, axis=-1, keepdims=True) * u
            front /= np.linalg.norm(front, axis=-1, keepdims=True)
            moved[:, labels.index(f"{S}{wand}")] = line_bottom + along * u \
                + np.linalg.norm(w - along * u, axis=-1, keepdims=True) * front
    clip, _ = canonical_clip_c3d(read_c3d(write_c3d(tmp_path / "front.c3d", labels, moved, rate=rate)))
    for joint, proximal, marker, wand in (("knee", "hip", "KNE", "THI"), ("ankle", "knee", "ANK", "TIB")):
        for s, S in (("l", "L"), ("r", "R")):
            assert "in the plane of the flexion axis (the wand is" in str(clip.joint_map.names[f"{joint}_{s}"])
            error = np.linalg.norm(clip.positions[:, J[f"{joint}_{s}"]] - ref[:, J[f"{joint}_{s}"]], axis=-1)
            # Measured 10-21 mm (the lateral wands' centres are themselves skin-marker estimates);
            # the chord rule in the front wand's plane puts them 60-91 mm off.
            assert np.median(error) < 0.025, (joint, s, np.median(error))
            behind = chord_centre(ref[:, J[f"{proximal}_{s}"]], moved[:, labels.index(f"{S}{wand}")],
                                  moved[:, labels.index(f"{S}{marker}")], 0.05)
            assert np.median(np.linalg.norm(behind - ref[:, J[f"{joint}_{s}"]], axis=-1)) > 0.05


@pytest.mark.parametrize("medial_first", [True, False])
def test_a_label_naming_the_lateral_and_the_medial_marker_is_split_by_position(tmp_path, medial_first):
    """Cortex writes RKNE / RANK for both epicondyles and both malleoli: the one nearer the
    other leg is medial, wherever it comes in the file, and the centre is the midpoint."""
    require_mocap()
    labels, positions, rate = _tennis_markers()
    reference, _ = canonical_clip_c3d(read_c3d(write_c3d(tmp_path / "lateral.c3d", labels, positions,
                                                          rate=rate)))
    ref = reference.positions
    names, columns = list(labels), [positions[:, i] for i in range(len(labels))]
    for s, S in (("l", "L"), ("r", "R")):
        for joint, marker in (("knee", "KNE"), ("ankle", "ANK")):
            lateral = positions[:, labels.index(f"{S}{marker}")]
            medial = 2 * ref[:, J[f"{joint}_{s}"]] - lateral  # mirrored through the centre
            at = 0 if medial_first else len(names)
            names.insert(at, f"{S}{marker}")
            columns.insert(at, medial)
    path = write_c3d(tmp_path / "twins.c3d", names, np.stack(columns, axis=1), rate=rate)
    clip, _ = canonical_clip_c3d(read_c3d(path))
    for joint in ("knee_l", "knee_r", "ankle_l", "ankle_r"):
        assert clip.joint_map.names[joint] in ("midpoint of the femoral epicondyles", "midpoint of the malleoli")
        error = np.linalg.norm(clip.positions[:, J[joint]] - ref[:, J[joint]], axis=-1)
        assert np.median(error) < 1e-5, (joint, np.median(error))  # float32 in the file


def test_cluster_set_without_point_units_rejects_outliers_at_its_guessed_unit():
    """The cluster shape check's 15 mm tolerance is in the file's unit: a cluster trial in
    metres without ``POINT:UNITS`` imports as with it (before, the tolerance was taken in mm,
    15 m: no outlier was rejected and 18 frames more were kept, 413 of the file's 395)."""
    require_mocap()
    raw = read_c3d(GAIT)
    in_metres = replace(raw, positions=raw.positions * 1e-3, units="m")
    with_units, _ = canonical_clip_c3d(in_metres)
    without, extra_without = canonical_clip_c3d(replace(in_metres, units=""))
    reference, extra_mm = canonical_clip_c3d(raw)
    assert extra_without["gaps"]["samples_rejected_as_outliers"] == \
        extra_mm["gaps"]["samples_rejected_as_outliers"] > 0
    assert without.positions.shape == reference.positions.shape
    assert np.abs(without.positions - with_units.positions).max() == 0.0


def test_x_up_lab_is_recognised():
    """A lab whose vertical is X (the tennis serve turned so: x = its z, z = -its x) imports with
    no flag, X up detected, every joint centre within 0.1 mm of the file's own after the turn
    about the vertical that X up -> Z up gives ((x, y, z) -> (y, z, x)). It was refused."""
    require_mocap()
    raw = read_c3d(TENNIS)
    z_to_x = np.array([[0.0, 0.0, 1.0], [0.0, 1.0, 0.0], [-1.0, 0.0, 0.0]])
    turned = replace(raw, positions=raw.positions @ z_to_x.T)
    reference, _ = canonical_clip_c3d(raw)
    clip, _ = canonical_clip_c3d(turned)
    assert clip.up_axis == "x"
    p = clip.positions
    back = np.stack([-p[..., 1], p[..., 0], p[..., 2]], axis=-1)
    assert np.abs(back - reference.positions).max() < 0.1 * MM
