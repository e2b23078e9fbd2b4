"""Issue 31's import classes 6 and 9, each fixed as a class.

Class 6: a valid C3D file whose per-channel analog parameters are stored as single values of
another type (Xsens MVN's exporter: ``ANALOG:OFFSET`` and ``ANALOG:SCALE`` as one 16-bit
integer each, no analog channel) was refused as "damaged or truncated?" (the ``c3d`` package
reads them as arrays of the standard's type). Before: ``not a readable C3D file (damaged or
truncated?): "OFFSET: cannot get value as <class 'numpy.int16'> array!"``; after: 774 frames of
64 markers, imported as ``xsens_mvn`` with every body part measured.

Class 9: marker spellings. Labels are compared without case or separators (``r_knee``,
``R.Heel``), and the presets know the lateral/medial pairs (``LKNEL``/``LKNEM``,
``LMALL``/``LMALM``) and MoSh's SehoonVSK front and back shoulder (``LFSH``/``LBSH``). Before:
the nimblephysics lift imported with both legs absent (filled: "lacks LTAM", "lacks RFAL,
RTAM"); after: both legs measured from the epicondyle and malleolus midpoints, the bar's
markers ignored, both feet planted.
"""

from __future__ import annotations

import numpy as np
import pytest

from conftest import MOCAP_DIR, require_mocap
from ecs_anim.core.errors import InputError
from ecs_anim.core.skeleton import JOINT_INDEX
from ecs_anim.io.c3d.importing import import_c3d
from ecs_anim.io.c3d.marker_sets import group_status, label_key, match_markers
from ecs_anim.io.c3d.reading import read_c3d
from support.c3d_files import write_c3d

VARIED2 = MOCAP_DIR / "varied2"
XSENS = VARIED2 / "c3dorg_xsens_mvn_basketball_120hz.c3d"
NIMBLE = VARIED2 / "nimble_vicon_lift_with_bar_200hz.c3d"
LEG_JOINTS = ("hip", "knee", "ankle", "toe")


def _each_side(names: list[str], unsided: tuple[str, ...] = ()) -> list[str]:
    return [name.format(S=s) for name in names for s in "LR"] + list(unsided)


# --- class 6: valid files the c3d package refused ------------------------------------------------


def test_the_xsens_mvn_file_reads_and_imports_its_body_from_the_virtual_landmarks():
    require_mocap()
    raw = read_c3d(XSENS)
    assert raw.positions.shape == (774, 64, 3) and raw.rate == 120.0 and raw.units == "mm"
    assert raw.valid.all() and "pRightKneeLatEpicondyle" in raw.labels
    motion = import_c3d(XSENS)
    assert motion.info["marker_set"] == "xsens_mvn"
    assert motion.info["absent"] == [] and motion.info["parts_not_computed"] == {}
    filled = set(motion.info["filled_in"])
    assert not filled & {"head", "neck", *(f"{j}_{s}" for j in (*LEG_JOINTS, "shoulder", "elbow",
                                                                  "wrist") for s in "lr")}
    assert motion.contacts().any(axis=0).all()  # each foot planted somewhere in the clip


#: How a writer may store ANALOG:OFFSET and ANALOG:SCALE: (bytes per element, dimensions, bytes).
STORAGES: dict[str, dict[str, tuple[int, list[int], bytes]]] = {
    "single_int16_each": {"OFFSET": (2, [], b"\x00\x00"), "SCALE": (2, [], b"\x01\x00")},
    "single_float_scale": {"OFFSET": (2, [], b"\x00\x00"), "SCALE": (4, [], b"\x00\x00\x80?")},
    "int16_scale_array": {"OFFSET": (2, [1], b"\x00\x00"), "SCALE": (2, [1], b"\x01\x00")},
}


@pytest.mark.parametrize("storage", sorted(STORAGES))
def test_per_channel_analog_parameters_stored_otherwise_do_not_refuse_the_file(storage, tmp_path,
                                                                             monkeypatch):
    """By structure, not by file: the parameters rewritten as the reader sees them, the way
    Xsens MVN (single int16 values) and other writers store them."""
    import c3d

    rng = np.random.default_rng(6)
    path = write_c3d(tmp_path / "m.c3d", ["A", "B", "C"], rng.normal(size=(12, 3, 3)))
    reference = read_c3d(path)
    original = c3d.Reader.__init__

    def as_stored(self, *args, **kwargs):
        original(self, *args, **kwargs)
        for name, (size, dims, data) in STORAGES[storage].items():
            param = self.get(f"ANALOG:{name}")
            param.bytes_per_element, param.dimensions, param.bytes = size, list(dims), data

    monkeypatch.setattr(c3d.Reader, "__init__", as_stored)
    raw = read_c3d(path)
    np.testing.assert_array_equal(raw.positions, reference.positions)
    assert raw.labels == reference.labels and raw.valid.all()


# --- class 9: marker spellings --------------------------------------------------------------------


@pytest.mark.parametrize("label, key", [
    ("r_knee", "RKNEE"), ("L_knee", "LKNEE"), ("r.ASIS", "RASIS"), ("R.Heel", "RHEEL"),
    ("Athlete:l.mall-m", "LMALLM"), ("Bob Smith:R Knee 1", "RKNEE1"), ("lkneL", "LKNEL"),
])
def test_a_label_is_compared_without_case_separators_or_subject(label, key):
    assert label_key(label) == key


#: Whole label sets as each convention writes them: the preset they are read as, and the roles
#: that must land on which label.
SPELLINGS = {
    # MoSh's SehoonVSK layout: front/back shoulder, inner elbow and knee, HEL heel, MT1.
    "mosh_sehoonvsk": (
        _each_side(["{S}FHD", "{S}BHD", "{S}FSH", "{S}BSH", "{S}UPA", "{S}ELB", "{S}IEL", "{S}FRM",
                    "{S}IWR", "{S}OWR", "{S}FWT", "{S}BWT", "{S}THI", "{S}KNE", "{S}KNI", "{S}SHN",
                    "{S}ANK", "{S}HEL", "{S}MT1", "{S}MT5", "{S}TOE"], ("ARIEL", "C7", "T10", "CLAV",
                                                                        "STRN")),
        "plug_in_gait", {"SHOULDER_FRONT_l": "LFSH", "SHOULDER_BACK_l": "LBSH",
                         "ELBOW_MED_l": "LIEL", "KNEE_MED_l": "LKNI", "HEEL_l": "LHEL",
                         "MT1_l": "LMT1"}),
    # Cortex with mixed case and dots.
    "cortex_mixed": (["r_knee", "L_knee", "r.ASIS", "L.ASIS", "R.Heel", "L.Heel", "r_ankle",
                      "L_ankle", "V.Sacral", "r.Thigh", "L.Thigh", "r.Shank", "L.Shank", "R.Toe",
                      "l.toe"],
                     "helen_hayes", {"KNEE_LAT_r": "r_knee", "KNEE_LAT_l": "L_knee",
                                     "ASIS_r": "r.ASIS", "HEEL_r": "R.Heel", "TOE_l": "l.toe"}),
    # A Vicon Nexus custom set of lateral and medial pairs, with a second subject (a barbell).
    "nexus_pairs_two_subjects": (
        [f"Athlete:{lab}" for lab in _each_side(["{S}ASI", "{S}PSI", "{S}KNEL", "{S}KNEM",
                                                 "{S}MALL", "{S}MALM", "{S}HEE", "{S}TOE", "{S}M5",
                                                 "{S}ACR", "{S}CUBL", "{S}CUBM", "{S}WRR",
                                                 "{S}WRU"])]
        + ["Bar:BL", "Bar:BR", "Bar:LASI", "Bar:RKNEL"],
        "isb_anatomical", {"KNEE_LAT_l": "Athlete:LKNEL", "KNEE_MED_r": "Athlete:RKNEM",
                           "ANKLE_LAT_r": "Athlete:RMALL", "ANKLE_MED_l": "Athlete:LMALM",
                           "ELBOW_LAT_l": "Athlete:LCUBL", "WRIST_ULN_r": "Athlete:RWRU"}),
}


@pytest.mark.parametrize("convention", sorted(SPELLINGS))
def test_a_conventions_spellings_are_read_as_the_roles_they_mean(convention):
    labels, preset, roles = SPELLINGS[convention]
    mmap = match_markers(labels)
    present, _, incomplete = group_status(mmap)
    assert mmap.preset.name == preset
    assert {role: labels[mmap.marker[role]] for role in roles if role in mmap.marker} == roles
    assert {"pelvis", "leg_l", "leg_r"} <= set(present), incomplete
    if convention == "mosh_sehoonvsk":  # the acromion from the shoulder pair: the arms computed
        assert {"arm_l", "arm_r"} <= set(present)
    if convention.endswith("two_subjects"):
        assert mmap.subject == "Athlete" and "Bar:BL" in mmap.ignored


def test_the_shoulder_pair_places_the_shoulder_at_its_midpoint(tmp_path):
    """SehoonVSK's LFSH/LBSH stand for the acromion at their midpoint: the shoulder comes out
    where a file with LSHO at that midpoint puts it."""
    from ecs_anim.io.c3d.importing import canonical_clip_c3d

    require_mocap()
    raw = read_c3d(MOCAP_DIR / "varied" / "qualisys_pig_yup_events_100hz.c3d")
    reference = canonical_clip_c3d(raw)[0].positions
    labels = list(raw.labels)
    offset = np.array([0.0, 0.0, 30.0])  # mm, along the file's axes
    positions, valid = raw.positions.copy(), raw.valid.copy()
    extra_labels, extra = [], []
    for s in "LR":
        i = labels.index(f"{s}SHO")
        labels[i] = f"{s}XSHO"  # no longer a shoulder marker
        extra_labels += [f"{s}FSH", f"{s}BSH"]
        extra += [positions[:, i] + offset, positions[:, i] - offset]
    positions = np.concatenate([positions, np.stack(extra, axis=1)], axis=1)
    valid = np.concatenate([valid, np.repeat(valid[:, [labels.index("LXSHO")]], 4, axis=1)], axis=1)
    from dataclasses import replace

    clip, extra_info = canonical_clip_c3d(replace(raw, labels=labels + extra_labels,
                                                  positions=positions, valid=valid,
                                                  descriptions=[""] * len(valid[0])))
    assert "arm_l" not in extra_info["absent"] and "arm_r" not in extra_info["absent"]
    for s in "lr":
        j = JOINT_INDEX[f"shoulder_{s}"]
        assert np.abs(clip.positions[:, j] - reference[:, j]).max() < 1e-4


def test_the_nimble_lift_has_both_legs_measured_and_its_feet_planted():
    require_mocap()
    motion = import_c3d(NIMBLE)
    assert motion.info["marker_set"] == "isb_anatomical"
    assert "leg_l" not in motion.info["absent"] and "leg_r" not in motion.info["absent"]
    assert not {"leg_l", "leg_r"} & set(motion.info["parts_not_computed"])
    filled = set(motion.info["filled_in"])
    assert not filled & {f"{j}_{s}" for j in LEG_JOINTS for s in "lr"}
    # A lift: both feet stay planted.
    assert motion.contacts().mean(axis=0).min() > 0.9
    # The bar's markers (BL, BR) place nothing.
    raw = read_c3d(NIMBLE)
    assert {"BL", "BR"} <= set(raw.labels)


def test_a_file_with_no_known_marker_set_is_refused_in_one_line_naming_what_to_do(tmp_path):
    rng = np.random.default_rng(9)
    path = write_c3d(tmp_path / "unknown.c3d", [f"pThing{k}" for k in range(10)],
                     rng.normal(size=(5, 10, 3)))
    with pytest.raises(InputError) as exc:
        import_c3d(path)
    message = str(exc.value)
    assert "\n" not in message and "--map" in message and "damaged" not in message
