"""Contacts only where the source measures the foot (issue 31, item 3): a leg the markers do not
place is filled in a neutral pose, standing still, and would read as a stance on every frame
(82-83 % "contacts" on such legs, then checked against force plates "within 826.7 ms")."""

from __future__ import annotations

from conftest import MOCAP_DIR, require_mocap
from ecs_anim.io.c3d.importing import import_c3d

#: Quiet standing, Z up, force plates; its knee markers are spelled so that no leg is computed.
STANDING = MOCAP_DIR / "varied2" / "c3dorg_qualisys_standing_knjntln_240hz_2400f.c3d"


def test_a_leg_filled_in_gets_no_contact_and_no_plate_check():
    require_mocap()
    motion = import_c3d(STANDING)
    assert {"ankle_l", "ankle_r"} <= set(motion.info["filled_in"])
    assert not motion.contacts().any()  # was 100 % of frames on both filled-in feet
    contacts = motion.info["contacts"]
    assert contacts["not_measured"] == ["left", "right"]
    assert "plates_check" not in contacts  # the plates' edges are not compared with nothing
    assert motion.info["force_plates"]  # the plates were still read, and reported


def test_measured_feet_keep_their_contacts():
    require_mocap()
    walk = import_c3d(MOCAP_DIR / "c3dorg_eb015pi_gait.c3d")  # a gait trial, both legs marked
    assert "not_measured" not in walk.info["contacts"]
    assert walk.contacts().any(axis=0).all()  # both feet planted at some frames
