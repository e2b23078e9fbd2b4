"""Gait events of C3D files (issue 12, item 2): the ``EVENT`` group read, reported by ``info``,
usable as the foot contacts (``--contacts events``), and the detected contacts compared with
them on every dev file that has events."""

from __future__ import annotations

import json

import numpy as np
import pytest

from conftest import MOCAP_DIR
from ecs_anim.apps.cli.main import main
from ecs_anim.io.c3d.importing import import_c3d
from ecs_anim.io.c3d.reading import read_c3d
from ecs_anim.io.contacts import contacts_from_events, gait_event_kind, true_runs

VARIED = MOCAP_DIR / "varied"
#: Files with gait events and how many foot strikes and foot offs each stores (varied/README.md).
WITH_EVENTS = {
    "mac_helenhayes_events_vjc_60hz.c3d": 8,
    "qualisys_pig_yup_events_100hz.c3d": 8,
    "rehazenter_isb_events_100hz.c3d": 7,
    "vicon_cgm24_events_jc_100hz.c3d": 17,
    "vicon_pig_noclav_prefix_events_60hz.c3d": 8,
}
BOUND_MS = 25.0
#: Measured worst differences (ms) between a detected contact edge and the lab's event, where
#: the bound does not hold yet (open in issue 12). Touch-down is when the heel point stops
#: sinking, lift-off when the toe joint rises over 1.5 cm or faster than 0.4 m/s (ecs_anim.
#: contacts.touch_down_to_lift_off). Measured against each file's own markers, its events
#: disagree with each other by more than 50 ms, so no rule on these points holds 25 ms on all:
#: - vicon_cgm24: left strikes 8-30 ms before the heel marker is lowest (the force-plate one,
#:   2.732 s in the file, 8 ms: detected 8 ms from it), right strikes 0-10 ms before it (first
#:   two) and 40-50 ms after it (last three, where the toe marker lands): any edge tied to the
#:   heel's landing is 40 ms or more from one of them;
#: - vicon_pig (no heel marker): the force-plate strike (1.041 s) 70 ms before the heel point
#:   stops sinking (the ankle still falls at 0.2 m/s), the right strike at 1.883 s 25 ms after;
#: - mac (Cortex, 60 Hz: 25 ms allows one frame): strikes where the heel marker is lowest, which
#:   the joints' heel point reaches 3-4 frames later at the right strikes; foot offs with the
#:   toe marker 19-37 mm up, where Qualisys marks them 4-12 mm up (no toe height or rising speed
#:   is within 25 ms of both files' foot offs);
#: - rehazenter: the right foot off at 0.39 s with the toe 8 mm above its stance height, those
#:   at 1.70 s and 2.98 s with it 19-21 mm up, rising at 0.2 m/s in all three (55-65 ms apart).
#: Tried and measured, none closing a file without opening another: a heel point fixed in the
#: foot where these labs' heel markers sit, touch-down within 2-6 mm of the heel's local
#: lowest, a sink threshold relative to the heel's own descent, lift-off from the toe's rising
#: speed relative to its swing peak or from its upward acceleration, a point ahead of the toe
#: joint, and Zeni et al.'s 2008 heel and toe extremes relative to the pelvis.
#: Also measured (0.05 s smoothing; worst ms on cgm24 / pig / mac / rehazenter / qualisys, the
#: current rule 50 / 42 / 33 / 20 / 20 at strikes and 50 / 33 / 33 / 30 / 20 at offs): foot-velocity
#: (O'Connor et al. 2007) strike at the last local minimum 60 / 133 / 50 / 10 / 30, off at the
#: rising peak 50 / 17 / 17 / 60 / 50 (its mean offsets +25 / -4 / +6 / -37 / +43 ms: the labs
#: disagree in sign); Hreljac & Marshall 2000 strike at the heel's acceleration peak
#: 250 / 158 / 100 / 20 / 150, off at the toe's forward acceleration peak 50 / 50 / 17 / 20 / 40;
#: Desailly et al. 2009 strike 110 / 33 / 17 / 90 / 60, off 40 / 33 / 17 / 70 / 30. Even the best
#: rule per event and file leaves cgm24 at 30-40 ms, and its own heel marker does not close it
#: either (its strikes are 8-50 ms from the marker's lowest, above): the events follow the
#: force plates and each lab's hand-placed marks, which no kinematic rule reproduces.
#: The files' own force plates (tests/io/c3d/test_force_plates.py) say so too: every strike a lab made
#: on a plate lies within 10 ms of the plate's measured touch-down, but vicon_pig's right strike
#: at 1.883 s lies 92 ms after its plate 1 measured that foot loading it, and the labs' foot
#: offs lie 21 ms before to 40 ms after the plates' unloading. Against the plates' measured
#: edges (7 files) the detected ones lie within 17-59 ms; a sweep of the edge thresholds (height
#: 1-6 cm, rise 0.25-0.8 m/s, sink 0.05-0.16 m/s, filter 0.02-0.05 s) found none closer on the
#: worst file, plates or events, than the defaults.
OPEN_MS = {
    "vicon_cgm24_events_jc_100hz.c3d": 50,
    "vicon_pig_noclav_prefix_events_60hz.c3d": 43,
    "mac_helenhayes_events_vjc_60hz.c3d": 34,
    "rehazenter_isb_events_100hz.c3d": 30,
}


def _varied(name: str):
    path = VARIED / name
    if not path.exists():
        pytest.skip(f"{path} not available")
    return path


@pytest.mark.parametrize("label, context, expected", [
    ("Foot Strike", "Left", ("l", "strike")), ("Foot Off", "Right", ("r", "off")),
    ("Foot Strike2", "Right", ("r", "strike")), ("", "LHS", ("l", "strike")),
    ("", "RTO", ("r", "off")), ("Heel Strike", "Left", ("l", "strike")),
    ("Toe Off", "Right", ("r", "off")), ("Left-FP", "General", None), ("Event", "General", None),
])
def test_event_labels_as_labs_write_them(label, context, expected):
    assert gait_event_kind(label, context) == expected


def test_contacts_from_events_run_from_strike_to_off():
    events = [{"side": "l", "kind": "off", "time_s": 0.2}, {"side": "l", "kind": "strike", "time_s": 0.6},
              {"side": "r", "kind": "strike", "time_s": 0.3}]
    flags = contacts_from_events(events, 11, 10.0)
    assert flags[:, 0].tolist() == [True, True] + [False] * 4 + [True] * 5
    assert flags[:, 1].tolist() == [False] * 3 + [True] * 8


@pytest.mark.parametrize("name", sorted(WITH_EVENTS))
def test_events_are_read_in_the_clips_seconds(name):
    path = _varied(name)
    raw = read_c3d(path)
    motion = import_c3d(path)
    events = [e for e in motion.info["gait_events"] if e["kind"]]
    assert len(events) == WITH_EVENTS[name]
    # Clip time = capture time - (first frame - 1 + frames dropped) / rate.
    shift = (raw.first_frame - 1 + motion.info["first_file_frame"]) / raw.rate
    for e in events:
        assert e["time_s"] == pytest.approx(e["file_time_s"] - shift, abs=1e-6)
    assert {e["side"] for e in events} == {"l", "r"}


def _worst_ms(name: str) -> float:
    motion = import_c3d(_varied(name))
    check = motion.info["contacts"]["events_check"]
    assert all(e["error_ms"] is not None for e in check["events"]), check
    # The check is what a test here computes: the nearest touch-down / lift-off of that foot.
    foot = motion.planted_part("on_ground")
    fps = motion.fps
    for e in check["events"]:
        side = "lr".index(e["side"])
        runs = true_runs(foot[:, side])
        edges = [a / fps for a, _ in runs if a > 0] if e["kind"] == "strike" \
            else [(b + 1) / fps for _, b in runs if b < len(foot) - 1]
        nearest = min(abs(t - e["time_s"]) for t in edges)
        assert nearest * 1000 == pytest.approx(abs(e["error_ms"]), abs=0.1)
    return float(check["worst_ms"])


@pytest.mark.parametrize("name", [
    pytest.param(n, marks=pytest.mark.xfail(reason=f"worst {OPEN_MS[n]} ms", strict=True))
    if n in OPEN_MS else n for n in sorted(WITH_EVENTS)])
def test_detected_touch_downs_and_lift_offs_within_25_ms_of_the_events(name):
    worst = _worst_ms(name)
    assert worst <= BOUND_MS, f"{name}: worst {worst:g} ms"


@pytest.mark.parametrize("name", sorted(OPEN_MS))
def test_open_event_files_are_no_worse_than_measured(name):
    assert _worst_ms(name) <= OPEN_MS[name]


def test_contacts_events_uses_them_and_info_reports_them(tmp_path, capsys):
    path = _varied("vicon_pig_noclav_prefix_events_60hz.c3d")
    assert main(["import", str(path), "-o", str(tmp_path), "--contacts", "events"]) == 0
    out = capsys.readouterr().out
    assert "(from the gait events)" in out and "8 gait events" in out
    nmo = tmp_path / f"{path.stem}.nmo"
    assert main(["info", str(nmo)]) == 0
    out = capsys.readouterr().out
    assert "event         0.924 s  L foot strike" in out and "R foot off" in out
    assert main(["info", str(nmo), "--json"]) == 0
    info = json.loads(capsys.readouterr().out)["info"]
    assert info["contacts"]["method"] == "gait events"
    from ecs_anim.motion.clip import load_nmo
    motion = load_nmo(nmo)
    events = [e for e in info["gait_events"] if e["kind"]]
    expected = contacts_from_events(events, motion.n_frames, motion.fps)
    np.testing.assert_array_equal(motion.contacts(), expected)


def test_contacts_events_without_events_is_one_line(tmp_path, capsys):
    for path in (MOCAP_DIR / "c3dorg_eb015pi_gait.c3d", MOCAP_DIR / "bandai_walk.bvh"):
        if not path.exists():
            pytest.skip(f"{path} not available")
        assert main(["import", str(path), "-o", str(tmp_path), "--contacts", "events"]) == 1
        err = capsys.readouterr().err.strip().splitlines()
        assert "--contacts events" in err[0] and len(err[0]) < 300
