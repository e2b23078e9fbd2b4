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
#: The labs' events are reported beside the contacts (``info.contacts.events_check``), never a
#: bound on them (issue 31, item 3): the force plates are (tests/io/test_contact_phases.py).
#: A lab's event may contradict its own plate: vicon_pig's right strike lies 92 ms after its plate
#: 1 measured that foot loading it; vicon_cgm24's right strikes (no plate) lie 0-10 ms before
#: the heel marker is lowest at the first two and 40-50 ms after it (where the toe marker lands)
#: at the last three, so its detected right touch-downs lie 10-70 ms from them while its one
#: plated stance is read within 12 ms of the plate at both edges.


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


@pytest.mark.parametrize("name", sorted(WITH_EVENTS))
def test_the_labs_events_are_reported_beside_the_contacts(name):
    """Each lab event away from the clip's ends gets the signed distance to the nearest detected
    touch-down (strike) or lift-off (off) of its foot, as the stored contacts say; no bound."""
    motion = import_c3d(_varied(name))
    check = motion.info["contacts"]["events_check"]
    assert check["events"] and all(e["error_ms"] is not None for e in check["events"]), check
    foot = motion.planted_part("on_ground")
    fps = motion.fps
    for e in check["events"]:
        runs = true_runs(foot[:, "lr".index(e["side"])])
        edges = [a / fps for a, _ in runs if a > 0] if e["kind"] == "strike" \
            else [(b + 1) / fps for _, b in runs if b < len(foot) - 1]
        nearest = min(abs(t - e["time_s"]) for t in edges)
        assert nearest * 1000 == pytest.approx(abs(e["error_ms"]), abs=0.1)
    assert check["worst_ms"] == max(abs(e["error_ms"]) for e in check["events"])


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
