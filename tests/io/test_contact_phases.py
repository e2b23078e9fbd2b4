"""Contacts from the clip itself (issue 31, item 3): each walk's and run's stance share of its
gait cycle (duty factor) from the stored contacts, one foot's contact constraints never
overlapping (ramps included), heel and ball planted as a rolling foot, and the contacts against
the force plates (``info.contacts.plates_check``: mean and worst)."""

from __future__ import annotations

from itertools import pairwise

import numpy as np
import pytest

from conftest import DATA_DIR, MOCAP_DIR
from ecs_anim.io.c3d.importing import import_c3d
from ecs_anim.io.contacts import contact_constraints, rigid_legs, true_runs
from ecs_anim.io.importing import import_bvh

#: Gait kind of each walk and run of the dev set (their README files).
GAITS = {
    "bandai_walk.bvh": "walk", "bandai_walk_turn_left.bvh": "walk", "bandai_run.bvh": "run",
    "cmumax_131_02_start_walk_stop_m.bvh": "slow walk", "c3dorg_eb015pi_gait.c3d": "slow walk",
    "varied/asf_noneck_walk_circle_120hz.bvh": "walk",
    "varied/asf_noneck_walk_speeds_120hz.bvh": "walk",
    "varied/bts_spaced_lowercase_nounits_yup.c3d": "walk",
    "varied/cmu_walk_120hz_adelaide.bvh": "walk",
    "varied/cmudaz_03_01_uneven_terrain.bvh": "walk",
    "varied/cmudaz_03_02_uneven_terrain.bvh": "walk",
    "varied/codamotion_dotted_gait_2015_200hz.c3d": "walk",
    "varied/fair_zup_child_walk_120hz.bvh": "walk", "varied/fair_zup_walk_inch_120hz.bvh": "walk",
    "varied/mac_helenhayes_events_vjc_60hz.c3d": "walk",
    "varied/qualisys_lowercase_underscore_240hz.c3d": "walk",
    "varied/qualisys_pig_yup_events_100hz.c3d": "walk",
    "varied/rehazenter_isb_events_100hz.c3d": "walk",
    "varied/vicon_cgm24_events_jc_100hz.c3d": "walk",
    "varied/vicon_pig_noclav_prefix_events_60hz.c3d": "walk",
    "varied/vicon_treadmill_run_clusters_240hz.c3d": "run",
    "varied2/cmudaz_run_notoes_zyx_root_120hz.bvh": "run",
}
#: Stance share of the gait cycle per kind. A slow walk (0.25-0.4 m/s) stands longer: the
#: c3d.org walk's own plates measure its right stances at 85 % of the cycle (2.27 s of 2.67 s).
DUTY = {"walk": (0.50, 0.70), "slow walk": (0.60, 0.88), "run": (0.25, 0.45)}
#: Measured where the bound does not hold (open in issue 31, item 3), per foot, and why:
#: - cmudaz_03_02 (right foot): its one whole cycle (touch-down 0.008 s, stance to 0.59 s, next
#:   touch-down 1.283 s) starts on a platform (toe 0.19-0.23 m up) and steps down off it: the
#:   toe lands 0.25 m lower at -0.025 m, after a 0.69 s swing while the left foot alone lowers
#:   the body (pelvis 0.998 -> 0.776 m). A stance of 46 % is that cycle's, not level walking's.
#: - vicon_pig_noclav (left foot): its plate measures that stance at 0.9875 s (0.9225-1.91 s)
#:   and the contact lasts 1.0 s (0.95-1.95 s), the plate's edges read 24 and 28 ms late (see
#:   OPEN_PLATES: this file's plates lead its markers); the next touch-down (no plate under it)
#:   is read at 2.333 s, a frame before the lab's strike (2.35 s), where the heel point has come
#:   down to within 2.5 mm of its lowest: 72 % of a 1.383 s cycle. With the lab's strikes (0.924 s,
#:   on its plate, and 2.35 s) the plate's stance is 69.2 % of the cycle, at the bound itself: a
#:   frame (17 ms at 60 Hz) at either edge moves the share by 1.2 points.
OPEN_DUTY = {
    "varied/cmudaz_03_02_uneven_terrain.bvh": (0.60, 0.46),
    "varied/vicon_pig_noclav_prefix_events_60hz.c3d": (0.72, 0.68),
}
MAPS = {"varied/qualisys_lowercase_underscore_240hz.c3d":
        str(DATA_DIR / "maps" / "qualisys_knee_joint_line.yaml")}
UNITS = {"varied/fair_zup_child_walk_120hz.bvh": "inch"}
#: Contacts against the plates' measured edges: mean and worst |error| (ms) ...
PLATES_MEAN_MS, PLATES_WORST_MS = 10.0, 25.0
#: ... measured where they do not hold (open in issue 31, item 3): (mean, worst), and why. An
#: edge is measured halfway between the last frame off and the first on (gait_events.
#: between_frames_agreement); the estimates between frames are given first.
#: - c3dorg_eb015pi (a very slow walk, 0.25-0.4 m/s, 50 Hz, plates at 200 Hz): both touch-downs
#:   are estimated 27 and 35 ms (frames: 35 and 25 ms) before the plate's load reaches 2 % of its
#:   peak; the heel point sinks only 2-3 mm over those 35 ms (0.03-0.08 m/s) while the load
#:   creeps at 0.7-1.6 % of its peak (at 4.525 s it leaves zero 35 ms before): a soft landing
#:   whose 2 % instant no height or speed of these joints resolves to 10 ms. Lift-offs +5 and
#:   -10 ms (0 and -10).
#: - vicon_cgm24 (one plate, 100 Hz): touch-down -6 ms, lift-off +13 ms (frames: -7 and +15):
#:   a mean of 9.5 ms before the frames, 11 ms after; each other plate file holds at these thresholds.
#: - vicon_pig_noclav (60 Hz, no heel marker): at plate 1's touch-down the right heel point is
#:   23 mm above its stance level and moves at 2.7 m/s (89 % of its swing speed), the lab's
#:   own strike is 92 ms later (that edge is held 42 ms late, the most an edge moves); at plate
#:   2's the left heel point is 6 mm up at 1.47 m/s (52 % of its swing; read 24 ms late): the
#:   plates load while the markers' feet still swing. Lift-offs -5 and +28 ms.
OPEN_PLATES = {
    "c3dorg_eb015pi_gait.c3d": (17.5, 35.0),
    "varied/vicon_cgm24_events_jc_100hz.c3d": (11.0, 15.0),
    "varied/vicon_pig_noclav_prefix_events_60hz.c3d": (21.2, 34.1),
}
#: Every dev file with force plates measurably loaded and unloaded.
WITH_PLATES = sorted({*OPEN_PLATES, "varied/codamotion_dotted_gait_2015_200hz.c3d",
                      "varied/mac_helenhayes_events_vjc_60hz.c3d",
                      "varied/qualisys_lowercase_underscore_240hz.c3d",
                      "varied/qualisys_pig_yup_events_100hz.c3d"})
_CACHE: dict[str, object] = {}


def _motion(name: str):
    path = MOCAP_DIR / name
    if not path.exists():
        pytest.skip(f"{path} not available")
    if name not in _CACHE:
        _CACHE[name] = (import_c3d(path, MAPS.get(name)) if path.suffix == ".c3d"
                        else import_bvh(path, unit=UNITS.get(name)))
    return _CACHE[name]


def duty_factors(on_ground: np.ndarray) -> list[float]:
    """Per foot, the stance share of its gait cycles: over each cycle from one touch-down to
    the next (the clip's cut first contact left out), the contact's frames over the cycle's,
    summed over the cycles; nan where a foot has no whole cycle."""
    out = []
    for side in range(on_ground.shape[1]):
        runs = [r for r in true_runs(on_ground[:, side]) if r[0] > 0]
        stance = sum(b - a + 1 for (a, b), _ in pairwise(runs))
        cycle = sum(c - a for (a, _), (c, _) in pairwise(runs))
        out.append(stance / cycle if cycle else float("nan"))
    return out


@pytest.mark.parametrize("name", sorted(GAITS))
def test_each_walk_and_run_stands_its_share_of_the_gait_cycle(name):
    motion = _motion(name)
    duty = duty_factors(motion.planted_part("on_ground"))
    low, high = DUTY[GAITS[name]]
    if name in OPEN_DUTY:
        # No worse than measured, each foot (within 2 points); the bound is still open.
        for got, then in zip(duty, OPEN_DUTY[name], strict=True):
            assert abs(got - then) <= 0.02 or low <= got <= high, (duty, OPEN_DUTY[name])
        pytest.xfail(f"duty factors {duty} outside {low}-{high} (open in issue 31, item 3)")
    assert all(low <= d <= high for d in duty if np.isfinite(d)), duty
    assert any(np.isfinite(d) for d in duty)


@pytest.mark.parametrize("name", ["cmu_01_01_playground_jumps.bvh", "bandai_dance.bvh",
                                  "varied2/sfu_0005_2feetjump_cm_xyz_120hz.bvh",
                                  "ktk_tennis_serve.c3d"])
def test_one_feet_contacts_never_overlap_ramps_included(name):
    motion = _motion(name)
    for side in "lr":
        spans = sorted((c.activation.start_s, c.activation.stop_s) for c in motion.constraints
                       if c.kind == "foot_contact" and c.segment == f"ankle_{side}")
        for (_, stop), (start, _) in pairwise(spans):
            assert start >= stop - 1e-9, (side, stop, start)


def test_close_contacts_share_the_gap_between_their_ramps():
    contact = np.zeros((100, 2), dtype=bool)
    contact[10:40, 0] = contact[44:80, 0] = True  # a 4-frame gap, 0.04 s at 100 Hz
    spans = [c.activation for c in contact_constraints(contact, 100.0)]
    assert len(spans) == 2
    assert spans[0].stop_s == pytest.approx(0.415) and spans[1].start_s == pytest.approx(0.415)
    assert spans[0].ease_in_s == pytest.approx(0.05) and spans[1].ease_out_s == pytest.approx(0.05)


def test_a_leg_that_never_moves_in_the_pelvis_frame_is_not_measured():
    from ecs_anim.core.skeleton import JOINT_INDEX as J
    from ecs_anim.core.skeleton import N_JOINTS

    rng = np.random.default_rng(8384)
    n = 50
    positions = rng.normal(0.0, 0.3, (1, N_JOINTS, 3)).repeat(n, axis=0)
    positions[:, :, 0] += np.linspace(0.0, 2.0, n)[:, None]  # the body walks along x
    positions[:, J["knee_r"]] += rng.normal(0.0, 0.01, (n, 3))  # the right leg moves
    pelvis2world = np.repeat(np.eye(3)[None], n, axis=0)
    assert rigid_legs(positions, pelvis2world).tolist() == [True, False]


@pytest.mark.parametrize("name", WITH_PLATES)
def test_contacts_lie_within_10_ms_mean_and_25_ms_worst_of_the_plates(name):
    check = _motion(name).info["contacts"]["plates_check"]
    assert check["mean_ms"] is not None and check["worst_ms"] is not None, check
    if name in OPEN_PLATES:
        # No worse than measured; the bound is still open.
        mean, worst = OPEN_PLATES[name]
        assert check["mean_ms"] <= max(mean, PLATES_MEAN_MS) + 0.1, check
        assert check["worst_ms"] <= max(worst, PLATES_WORST_MS) + 0.1, check
        pytest.xfail(f"plates mean {check['mean_ms']} ms, worst {check['worst_ms']} ms "
                     "(open in issue 31, item 3)")
    assert check["mean_ms"] <= PLATES_MEAN_MS and check["worst_ms"] <= PLATES_WORST_MS, check


def test_a_plate_stood_on_to_the_end_is_not_checked():
    """The standing trial: both plates stepped on and never unloaded again; the unloaded level is
    the zeroed one (not the standing load), and no edge of theirs is checked."""
    motion = _motion("varied2/c3dorg_qualisys_standing_knjntln_240hz_2400f.c3d")
    plates = motion.info["force_plates"]
    assert [(c["plate"], c["touch_down"], c["lift_off"]) for c in plates] == [
        (1, True, False), (2, True, False)]
    assert "plates_check" not in motion.info["contacts"]
