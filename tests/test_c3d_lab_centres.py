"""Our joint centres against the lab's own, where a C3D file stores them (issue 12, item 3):
hips within 25 mm, knees and ankles within 15 mm (median distance over the frames where the
lab's point holds a sample); and C3D files without POINT:UNITS, or Y up, import with no flag."""

from __future__ import annotations

import pytest

from conftest import MOCAP_DIR
from ecs_anim.c3d_import import import_c3d
from ecs_anim.cli import main

VARIED = MOCAP_DIR / "varied"
BOUND_MM = {"hip": 25.0, "knee": 15.0, "ankle": 15.0}
#: Files storing the lab's centres and the joints they hold (varied/README.md).
WITH_CENTRES = {
    "vicon_cgm24_events_jc_100hz.c3d": ("hip", "knee", "ankle"),
    "mac_helenhayes_events_vjc_60hz.c3d": ("hip", "knee", "ankle"),
    "bts_spaced_lowercase_nounits_yup.c3d": ("hip", "knee", "ankle"),
    "vicon_treadmill_run_clusters_240hz.c3d": ("hip",),
}
#: Measured medians (mm) where the bound does not hold (open in issue 12). BTS's left hip and
#: right ankle lie just beyond the bounds: our hips 10-18 mm in front of and 16-17 mm above the
#: lab's (its pelvis depth from the sacrum marker is 198 mm; the Davis 1991 regression with the
#: file's SUBJECT anthropometry fits no better, 28-36 mm), and the right ankle 45-50 mm off for
#: a few frames after each heel strike, where the shank wand swings 60 deg about the shank.
OPEN_MM = {
    ("bts_spaced_lowercase_nounits_yup.c3d", "hip_l"): 25.5,
    ("bts_spaced_lowercase_nounits_yup.c3d", "ankle_r"): 15.8,
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
