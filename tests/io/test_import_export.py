"""The foundation's promises on real captured clips: no loss, exact lengths, sane contacts.

Source joint positions are recomputed here with a deliberately separate, plain forward
kinematics (explicit axis matrices, units from ../shared/mocap/README.md), so the importer is
checked against an independent reading of each file, not against itself.
"""

from __future__ import annotations

import json

import numpy as np
import pytest

from conftest import MOCAP_DIR, MOTIONS_DIR, mocap_params, require_mocap
from ecs_anim.apps.cli.main import main
from ecs_anim.core.morphology import Morphology, bone_lengths_of
from ecs_anim.core.skeleton import BONE_JOINTS, JOINT_INDEX, JOINTS, LENGTHS
from ecs_anim.io.bvh import read_bvh
from ecs_anim.io.contacts import horizontal_speed, true_runs
from ecs_anim.io.importing import canonical_clip, import_bvh
from support.bvh_reference import reference_positions

MM = 1e-3
# Units as documented in ../shared/mocap/README.md, independent of our detection.
DOCUMENTED_UNIT_M = {"bandai": 0.01, "cmu_": 0.0254 / 0.45, "cmubiped": 0.0254, "cmumax": 1.0}


def _documented_scale(name: str) -> float:
    for prefix, scale in sorted(DOCUMENTED_UNIT_M.items(), key=lambda kv: -len(kv[0])):
        if name.startswith(prefix):
            return scale
    raise KeyError(name)


@pytest.mark.parametrize("path", mocap_params())
def test_source_export_reproduces_every_mapped_joint_within_0_1_mm(path, tmp_path):
    assert main(["import", str(path), "-o", str(tmp_path)]) == 0
    nmo = tmp_path / f"{path.stem}.nmo"
    npz = tmp_path / "source.npz"
    assert main(["export", str(nmo), "--morphology", "source", "-o", str(npz)]) == 0
    exported = np.load(npz)
    assert list(exported["joints"]) == list(JOINTS)
    info = json.loads(str(np.load(nmo)["header_json"]))["info"]
    names, ref = reference_positions(path)
    ref = ref[info.get("first_file_frame", 0):]  # a converter's T-pose frame 0 is dropped
    scale = _documented_scale(path.name)
    ref_world = np.stack([ref[..., 0], -ref[..., 2], ref[..., 1]], axis=-1) * scale  # Y up -> Z up
    mapped = {j: s for j, s in info["joints"].items() if s is not None and j not in info["filled_in"]}
    assert {"pelvis", "hip_l", "knee_l", "ankle_l", "neck", "head", "wrist_r"} <= set(mapped)
    errors = {
        j: np.linalg.norm(exported["positions"][:, JOINT_INDEX[j]] - ref_world[:, names.index(s)],
                          axis=-1).max()
        for j, s in mapped.items()
    }
    worst = max(errors, key=lambda j: errors[j])
    assert errors[worst] < 0.1 * MM, f"{worst} off by {errors[worst] * 1e3:.4f} mm"
    assert exported["positions"].shape == (ref.shape[0], len(JOINTS), 3)
    assert np.all(np.isfinite(exported["positions"]))


@pytest.mark.parametrize("path", mocap_params())
def test_every_clip_gets_a_plausible_unit_and_body(path):
    clip = canonical_clip(read_bvh(path))
    assert clip.unit == {0.01: "cm", 0.0254: "inch", 1.0: "m"}.get(_documented_scale(path.name), "cmu")
    motion = import_bvh(path)
    stature = motion.source_morphology.stature
    assert 1.4 < stature < 1.95, stature
    assert 0.7 < motion.source_morphology.leg_length < 1.0


def _bvh_bone_lengths(path) -> np.ndarray:
    positions = canonical_clip(read_bvh(path)).positions
    return bone_lengths_of(positions)


@pytest.mark.parametrize("preset,stature", [("child", 1.20), ("tall", 2.00)])
def test_exported_bvh_reads_back_and_has_the_morphology_lengths(tmp_path, preset, stature):
    walk = MOTIONS_DIR / "walk.bvh"
    assert main(["import", str(walk), "-o", str(tmp_path)]) == 0
    nmo = tmp_path / "walk.nmo"
    bvh, npz = tmp_path / f"{preset}.bvh", tmp_path / f"{preset}.npz"
    assert main(["export", str(nmo), "--morphology", preset, "-o", str(bvh)]) == 0
    assert main(["export", str(nmo), "--morphology", preset, "-o", str(npz)]) == 0
    morph = Morphology.preset(preset)
    assert morph.stature == pytest.approx(stature, abs=1e-9)
    # Read back by our own reader: same positions as the .npz within 0.1 mm.
    clip = canonical_clip(read_bvh(bvh))
    assert clip.joint_map.how.startswith("preset ecs_anim")
    from_npz = np.load(npz)["positions"]
    assert np.abs(clip.positions - from_npz).max() < 0.1 * MM
    # Exactly the morphology's segment lengths, in the file and on every frame.
    lengths = bone_lengths_of(clip.positions)
    for k, (a, _b) in enumerate(BONE_JOINTS):
        if a >= 0:
            np.testing.assert_allclose(lengths[:, k], morph.lengths[k], atol=1e-5,
                                       err_msg=LENGTHS[k])
    skeleton = read_bvh(bvh).skeleton
    offsets = {j.name: np.linalg.norm(j.offset) for j in skeleton.joints}
    assert offsets["knee_l"] == pytest.approx(morph["thigh_l"], abs=1e-6)
    assert offsets["ankle_r"] == pytest.approx(morph["shank_r"], abs=1e-6)
    assert offsets["elbow_l"] == pytest.approx(morph["upper_arm_l"], abs=1e-6)
    assert offsets["wrist_l.end"] == pytest.approx(morph["hand_l"], abs=1e-6)
    # Its T-pose stands exactly the morphology's stature tall (sole to vertex, Y up).
    from ecs_anim.io.bvh import rest_positions
    rest = rest_positions(skeleton)
    tpose_height = rest[skeleton.names.index("head.end"), 1] - rest[skeleton.names.index("ankle_l"), 1]
    assert tpose_height + morph["ankle_height_l"] == pytest.approx(stature, abs=1e-5)  # 6 decimals
    # The exported file stands upright in its own Y-up axes: head above the pelvis.
    _, ref = reference_positions(bvh)
    names = skeleton.names
    assert np.all(ref[:, names.index("head"), 1] > ref[:, names.index("pelvis"), 1] + 0.2 * stature)


def test_export_onto_a_bvh_skeleton_borrows_its_lengths(tmp_path):
    require_mocap()
    walk = MOTIONS_DIR / "walk.bvh"
    assert main(["import", str(walk), "-o", str(tmp_path)]) == 0
    target = MOCAP_DIR / "cmubiped_10_01_kick_30fps.bvh"
    out = tmp_path / "on_biped.npz"
    assert main(["export", str(tmp_path / "walk.nmo"), "--morphology", str(target), "-o", str(out)]) == 0
    got = bone_lengths_of(np.load(out)["positions"])
    want = bone_lengths_of(canonical_clip(read_bvh(target)).positions)[0]
    thigh = LENGTHS.index("thigh_l")
    assert got[:, thigh] == pytest.approx(want[thigh], abs=1e-9)
    assert want[thigh] == pytest.approx(18.47 * 0.0254, abs=1e-6)  # the Biped file's own OFFSET


WALKS = ["bandai_walk.bvh", "bandai_walk_turn_left.bvh"]


def _contact_stats(path):
    motion = import_bvh(path)
    clip = canonical_clip(read_bvh(path))
    contact = motion.contacts()
    p = clip.positions
    foot_speed = np.minimum(horizontal_speed(p[:, [JOINT_INDEX["ankle_l"], JOINT_INDEX["ankle_r"]]], clip.fps),
                            horizontal_speed(p[:, [JOINT_INDEX["toe_l"], JOINT_INDEX["toe_r"]]], clip.fps))
    return contact, foot_speed


@pytest.mark.parametrize("name", WALKS + ["our walk.bvh"])
def test_walk_contacts_cover_40_to_80_percent_alternate_and_hold_the_foot(name):
    if name.startswith("our "):
        path = MOTIONS_DIR / name.split()[1]
    else:
        require_mocap()
        path = MOCAP_DIR / name
    contact, speed = _contact_stats(path)
    fraction = contact.mean(axis=0)
    assert np.all((fraction >= 0.40) & (fraction <= 0.80)), fraction
    # Touchdowns (not counting feet already down on the first frame) alternate L, R, L, ...
    downs = sorted([(a, "L") for a, _ in true_runs(contact[:, 0]) if a > 0]
                   + [(a, "R") for a, _ in true_runs(contact[:, 1]) if a > 0])
    sides = "".join(s for _, s in downs)
    assert len(sides) >= 3 and "LL" not in sides and "RR" not in sides, sides
    # The stated bound: while in contact, the slower of ankle and toe moves at a median below
    # 5 cm/s and stays under 0.55 m/s (walking speed is 1.2-1.4 m/s, swing feet 3-4 m/s).
    in_contact = speed[contact]
    assert np.median(in_contact) < 0.05, np.median(in_contact)
    assert in_contact.max() < 0.55, in_contact.max()


def test_start_walk_stop_contacts_while_walking():
    require_mocap()
    path = MOCAP_DIR / "cmumax_131_02_start_walk_stop_m.bvh"
    clip = canonical_clip(read_bvh(path))
    contact = import_bvh(path).contacts()
    pelvis_speed = horizontal_speed(clip.positions[:, JOINT_INDEX["pelvis"]], clip.fps)
    walking = pelvis_speed > 0.3
    assert walking.mean() > 0.2  # a slow, stylised walk of about 1.7 m
    fraction = contact[walking].mean(axis=0)
    assert np.all((fraction >= 0.40) & (fraction <= 0.80)), fraction
    # Standing still at start and end, and slow steps: feet down. (Measured 0.799; the 0.806
    # planted before contacts ended at lift-off included swing frames, the ankle 10-21 cm up.)
    assert contact[~walking].mean() > 0.78


def test_bow_keeps_both_feet_down():
    require_mocap()
    contact = import_bvh(MOCAP_DIR / "bandai_bow.bvh").contacts()
    assert contact.mean() > 0.95
