"""Force plates of C3D files (issue 12, item 2: the lab's ground truth): each plate's loaded
spans read from its vertical signal, the foot on it, the measured touch-downs and lift-offs in
``info.force_plates``, and the contacts compared with them (``info.contacts.plates_check``)."""

from __future__ import annotations

import struct

import numpy as np
import pytest

from conftest import DATA_DIR, MOCAP_DIR
from ecs_anim.apps.cli.main import main
from ecs_anim.io.c3d.force_plates import ForcePlate, loaded_spans, plate_contacts, plate_edges
from ecs_anim.io.c3d.importing import import_c3d
from ecs_anim.io.c3d.reading import read_c3d
from support.c3d_files import parameter_offset

VARIED = MOCAP_DIR / "varied"
#: Per file with force plates: the foot on each loaded span, in the order info lists them
#: (plate by plate), and how many of its touch-downs and lift-offs are measured.
PLATE_FEET = {
    "c3dorg_eb015pi_gait.c3d": (["r", "r"], 4),
    "varied/bts_spaced_lowercase_nounits_yup.c3d": (["r"], 0),  # 100 Hz: jumps from zero
    "varied/codamotion_dotted_gait_2015_200hz.c3d": (["r", "l", "r", "l"], 8),
    "varied/mac_helenhayes_events_vjc_60hz.c3d": (["l", "r"], 4),
    "varied/qualisys_pig_yup_events_100hz.c3d": (["r", "l", "r"], 5),  # the last runs on
    "varied/qualisys_lowercase_underscore_240hz.c3d": (["r", "l"], 4),  # type 3: 4 Fz sensors
    "varied/rehazenter_isb_events_100hz.c3d": (["r", "l"], 0),  # zeroed below 50 N
    "varied/vicon_cgm24_events_jc_100hz.c3d": (["l"], 2),
    "varied/vicon_pig_noclav_prefix_events_60hz.c3d": (["r", "l"], 4),
}
#: The labs' foot strikes (file seconds, varied/README.md) made where the foot landed on a
#: plate: Vicon Nexus and Qualisys place those at the plate's force threshold.
STRIKES_ON_PLATES = {
    "vicon_cgm24_events_jc_100hz.c3d": [("l", 2.732)],
    "vicon_pig_noclav_prefix_events_60hz.c3d": [("l", 1.041)],
    "mac_helenhayes_events_vjc_60hz.c3d": [("l", 0.567), ("r", 1.15)],
    "qualisys_pig_yup_events_100hz.c3d": [("r", 1.59), ("l", 2.17), ("r", 2.80)],
}
#: Worst distance (ms) from a measured plate edge to the nearest touch-down or lift-off the
#: import detected (measured; no bound is asked of these: they show how close the stillness
#: rule comes to the physical contact, which a plate's 2 % threshold places within +-20 ms).
DETECTED_VS_PLATES_MS = {
    "c3dorg_eb015pi_gait.c3d": 35.0,
    "varied/codamotion_dotted_gait_2015_200hz.c3d": 42.0,
    "varied/mac_helenhayes_events_vjc_60hz.c3d": 34.3,
    "varied/qualisys_pig_yup_events_100hz.c3d": 22.0,
    "varied/qualisys_lowercase_underscore_240hz.c3d": 16.7,
    "varied/vicon_cgm24_events_jc_100hz.c3d": 40.0,
    "varied/vicon_pig_noclav_prefix_events_60hz.c3d": 59.1,
}
#: The user map a file needs (docs/import.md's table).
MAPS = {"varied/qualisys_lowercase_underscore_240hz.c3d":
        str(DATA_DIR / "maps" / "qualisys_knee_joint_line.yaml")}
_CACHE: dict[str, object] = {}


def _motion(name: str):
    path = MOCAP_DIR / name
    if not path.exists():
        pytest.skip(f"{path} not available")
    if name not in _CACHE:
        _CACHE[name] = import_c3d(path, MAPS.get(name))
    return _CACHE[name]


@pytest.mark.parametrize("name", sorted(PLATE_FEET))
def test_each_plate_contact_has_its_foot_and_its_measured_edges(name):
    motion = _motion(name)
    feet, measured = PLATE_FEET[name]
    contacts = motion.info["force_plates"]
    assert [c["side"] for c in contacts] == feet
    assert sum(c["touch_down"] + c["lift_off"] for c in contacts) == measured
    for c in contacts:
        assert 0.1 <= c["off_s"] - c["on_s"] <= 2.5  # a stance, seconds (slow walks included)


@pytest.mark.parametrize("name", sorted(STRIKES_ON_PLATES))
def test_the_labs_strikes_on_a_plate_are_its_measured_touch_downs(name):
    """The plate is read right (channels, analog time, the foot on it): each foot strike the lab
    placed on a plate lies within 10 ms of that plate's measured touch-down of that foot."""
    motion = _motion(f"varied/{name}")
    start_s = motion.info["gait_events"][0]["file_time_s"] - motion.info["gait_events"][0]["time_s"]
    for side, file_s in STRIKES_ON_PLATES[name]:
        downs = [c["on_s"] for c in motion.info["force_plates"] if c["side"] == side and c["touch_down"]]
        nearest_ms = min(abs(t - (file_s - start_s)) for t in downs) * 1000
        assert nearest_ms <= 10.0, (side, file_s, nearest_ms)


def test_a_lab_strike_off_the_plate_timing_contradicts_the_plate():
    """Why no rule holds 25 ms on every lab event (issue 12): the Plug-in Gait file's right
    foot strike at 1.883 s lies 92 ms after plate 1 measured that foot loading it, so a rule
    within 25 ms of the event would be 67 ms or more from the foot's physical contact."""
    motion = _motion("varied/vicon_pig_noclav_prefix_events_60hz.c3d")
    event = next(e for e in motion.info["gait_events"]
                 if e["side"] == "r" and e["kind"] == "strike" and abs(e["file_time_s"] - 1.883) < 1e-3)
    plate = next(c for c in motion.info["force_plates"] if c["plate"] == 1)
    assert plate["side"] == "r" and plate["touch_down"]
    assert 90.0 <= (event["time_s"] - plate["on_s"]) * 1000 <= 95.0


@pytest.mark.parametrize("name", sorted(DETECTED_VS_PLATES_MS))
def test_detected_contacts_are_no_further_from_the_plates_than_measured(name):
    check = _motion(name).info["contacts"]["plates_check"]
    assert check["worst_ms"] is not None and check["worst_ms"] <= DETECTED_VS_PLATES_MS[name], check
    assert len(check["events"]) + check["at_clip_ends"] == len(plate_edges(_motion(name).info["force_plates"]))


def test_a_plate_stood_on_all_along_gives_no_contact_and_says_so():
    motion = _motion("varied/qualisys_pig_noarms_squat_100hz.c3d")
    assert "force_plates" not in motion.info and "plates_check" not in motion.info["contacts"]
    assert motion.info["force_plate_notes"] == [
        "plate 1: never unloaded (its lowest load is not zero)",
        "plate 2: never unloaded (its lowest load is not zero)"]


def _plate(signal: np.ndarray, rate: float = 1000.0) -> ForcePlate:
    corners = np.array([[0.0, 0.0, 0.0], [500.0, 0.0, 0.0], [500.0, 400.0, 0.0], [0.0, 400.0, 0.0]])
    return ForcePlate(1, corners, signal, rate)


def _steps(rate: float = 1000.0, offset: float = 0.0, sign: float = 1.0, clamp: float = 0.0):
    """Two 0.6 s stances of 700 N peak with 50 ms ramps, on 3 s of noise (seeded)."""
    rng = np.random.default_rng(8384)
    t = np.arange(int(3.0 * rate)) / rate
    load = np.zeros_like(t)
    for start in (0.5, 1.8):
        ramp = np.clip(np.minimum(t - start, start + 0.6 - t) / 0.05, 0.0, 1.0)
        load = np.maximum(load, 700.0 * ramp)
    load = np.where(load < clamp, 0.0, load)
    noise = rng.normal(0.0, 0.3, t.shape) if clamp == 0.0 else 0.0
    return offset + sign * load + noise


@pytest.mark.parametrize("offset, sign", [(0.0, 1.0), (240.0, -1.0), (-80.0, 1.0)])
def test_loaded_spans_are_found_at_two_percent_of_the_peak_whatever_the_level_and_sign(offset, sign):
    spans, why = loaded_spans(_plate(_steps(offset=offset, sign=sign)))
    assert why == ""
    # 2 % of the 700 N peak, 14 N, is reached 1 ms into a 50 ms ramp (2 ms with the noise).
    assert len(spans) == 2
    for span, (first, last) in zip(spans, [(501, 1099), (1801, 2399)], strict=True):
        assert abs(span.first - first) <= 1 and abs(span.last - last) <= 1
    assert all(s.rises and s.falls for s in spans)


def test_a_signal_zeroed_below_a_threshold_has_no_measured_edge():
    spans, _ = loaded_spans(_plate(_steps(clamp=50.0)))
    assert len(spans) == 2 and not any(s.rises or s.falls for s in spans)


def test_plate_contacts_name_the_foot_over_the_plate_and_the_clip_seconds():
    """Two feet 0.3 m apart, the left one over the plate (mm corners, 0.001 m per unit); the
    clip starts 0.2 s into the file."""
    from ecs_anim.core.skeleton import JOINT_INDEX as J
    from ecs_anim.core.skeleton import N_JOINTS

    fps, n = 100.0, 260
    positions = np.zeros((n, N_JOINTS, 3))
    for joint, xy in (("ankle_l", (0.15, 0.2)), ("toe_l", (0.30, 0.2)),
                      ("ankle_r", (0.15, -0.4)), ("toe_r", (0.30, -0.4))):
        positions[:, J[joint], :2] = xy
    contacts, notes = plate_contacts([_plate(_steps())], 0.001 * np.eye(3), positions, fps, 0.2)
    assert notes == []
    assert [(c["side"], c["touch_down"], c["lift_off"]) for c in contacts] == [("l", True, True)] * 2
    # The ramps start 0.5 and 1.8 s into the file and end 0.6 s later (2 ms for the threshold).
    np.testing.assert_allclose([(c["on_s"], c["off_s"]) for c in contacts],
                               [(0.3, 0.9), (1.6, 2.2)], atol=0.0025)


@pytest.mark.parametrize("parameter, entry, value, note", [
    ("TYPE", 0, 7, "plate 1: type 7 is not read (types 1-4 are)"),
    ("CHANNEL", 2, 99, "plate 1: a channel outside the 18 analog channels"),  # its Fz
])
def test_a_damaged_plate_parameter_leaves_that_plate_out_and_says_why(tmp_path, parameter, entry,
                                                                      value, note, capsys):
    source = VARIED / "qualisys_pig_yup_events_100hz.c3d"
    if not source.exists():
        pytest.skip(f"{source} not available")
    data = bytearray(source.read_bytes())
    at = parameter_offset(bytes(data), "FORCE_PLATFORM", parameter) + 2 * entry  # int16 entries
    struct.pack_into("<h", data, at, value)
    path = tmp_path / "damaged_plate.c3d"
    path.write_bytes(bytes(data))
    assert read_c3d(path).force_plate_note == note
    assert main(["import", str(path), "-o", str(tmp_path)]) == 0
    assert ", 2 force-plate contacts" in capsys.readouterr().out  # plates 2 and 3
    assert main(["info", str(tmp_path / "damaged_plate.nmo")]) == 0
    assert f"  plates     {note}" in capsys.readouterr().out


def test_a_plate_nobody_stepped_on_has_no_contact_and_no_note():
    rng = np.random.default_rng(8384)
    assert loaded_spans(_plate(rng.normal(3.0, 0.4, 3000))) == ([], "")
