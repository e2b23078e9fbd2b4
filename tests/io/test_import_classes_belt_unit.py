"""Issue 31, import classes 2 and 7: no invented treadmill belt (a belt must be one a treadmill
runs at for the gait seen, carrying the planted feet backwards), and a length unit questioned
only by the parts that were measured (never by legs filled in a neutral pose)."""

from __future__ import annotations

import re
from dataclasses import replace

import numpy as np
import pytest

from conftest import MOCAP_DIR, require_mocap
from ecs_anim.apps.cli.main import main
from ecs_anim.core.errors import EcsAnimError
from ecs_anim.core.skeleton import JOINT_INDEX as J
from ecs_anim.io.bvh import read_bvh
from ecs_anim.io.c3d.importing import canonical_clip_c3d
from ecs_anim.io.c3d.reading import read_c3d
from ecs_anim.io.contacts import max_belt_speed, treadmill_belt
from ecs_anim.io.importing import canonical_clip, import_bvh, normalize_clip
from support.bvh_reference import in_place_copy

# --- class 2: treadmill belts ------------------------------------------------------------------


def test_belt_speed_limits_follow_the_gait_and_the_leg():
    """Froude 1 for a walk, a sprint's 6.25 for a run: 2.8 and 7.0 m/s for a 0.8 m leg."""
    assert max_belt_speed(0.8, running=False) == pytest.approx(2.80, abs=0.01)
    assert max_belt_speed(0.8, running=True) == pytest.approx(7.00, abs=0.01)
    assert max_belt_speed(0.5, running=True) < max_belt_speed(0.8, running=True)


def test_a_video_estimated_dance_gets_no_belt(tmp_path, capsys):
    """MediaPipe's tumbling dance (varied2/README.md): the root stays put while the lower ankle
    jitters; a belt of 17.9 m/s was made from one of its 37 low samples (before: "belt at
    17.921 m/s: turned into root motion")."""
    require_mocap()
    path = MOCAP_DIR / "varied2" / "mediapipe_16joints_notoes_dance_30fps.bvh"
    if not path.exists():
        pytest.skip(f"{path} not available")
    clip = canonical_clip(read_bvh(path))
    assert treadmill_belt(clip.positions, clip.fps) is None
    assert main(["import", str(path), "-o", str(tmp_path)]) == 0
    out = capsys.readouterr().out
    assert "belt" not in out and "treadmill" not in out


def _in_place_walk(tmp_path, speedup: float):
    """bandai_walk on a treadmill, played ``speedup`` times faster
    (:func:`support.bvh_reference.in_place_copy`)."""
    require_mocap()
    path = MOCAP_DIR / "bandai_walk.bvh"
    if not path.exists():
        pytest.skip(f"{path} not available")
    return in_place_copy(path, tmp_path, speedup)


def test_a_walk_too_fast_for_walking_gets_no_belt(tmp_path):
    """The in-place walk keeps its belt (1.23 m/s; twice as fast, 2.49 m/s, still a walk), but
    four times as fast its stance feet slide back at 4.98 m/s with a foot always low: no walk
    goes that fast (Froude 1: 2.8 m/s for its 0.8 m leg), so no belt (before: 4.98 m/s)."""
    for speedup, low, high in ((1, 1.1, 1.35), (2, 2.3, 2.7)):
        motion = import_bvh(_in_place_walk(tmp_path, speedup))
        belt = motion.info["treadmill"]
        assert belt["converted"] and low < belt["speed_mps"] < high, (speedup, belt)
    fast = _in_place_walk(tmp_path, 4)
    clip = canonical_clip(read_bvh(fast))
    assert treadmill_belt(clip.positions, clip.fps) is None
    assert "treadmill" not in import_bvh(fast).info


# --- class 7: the unit questioned only by measured parts ----------------------------------------


def _tennis_clip():
    """Vicon's tennis serve (full Plug-in Gait, POINT:UNITS 'm': the unit is right)."""
    require_mocap()
    path = MOCAP_DIR / "ktk_tennis_serve.c3d"
    if not path.exists():
        pytest.skip(f"{path} not available")
    clip, _ = canonical_clip_c3d(read_c3d(path))
    return clip


def _legs_filled(clip, leg_factor: float):
    """The clip with both legs absent: knee, ankle and toe filled in a neutral pose (straight
    down from the hip, the toe forward), ``leg_factor`` times the measured legs' length, as a
    neutral fill sized from a wrong basis makes them; not measured."""
    p = clip.positions.copy()
    measured = clip.measured.copy()
    up = np.array([0.0, 0.0, 1.0])
    for s in "lr":
        hip = p[:, J[f"hip_{s}"]]
        thigh = np.median(np.linalg.norm(p[:, J[f"knee_{s}"]] - hip, axis=-1)) * leg_factor
        shank = np.median(np.linalg.norm(p[:, J[f"ankle_{s}"]] - p[:, J[f"knee_{s}"]], axis=-1)) * leg_factor
        p[:, J[f"knee_{s}"]] = hip - up * thigh
        p[:, J[f"ankle_{s}"]] = p[:, J[f"knee_{s}"]] - up * shank
        p[:, J[f"toe_{s}"]] = p[:, J[f"ankle_{s}"]] + np.array([0.1, 0.0, -0.05]) * leg_factor
        for part in ("knee", "ankle", "toe"):
            measured[J[f"{part}_{s}"]] = False
    return replace(clip, positions=p, measured=measured)


def test_neutral_filled_legs_never_question_a_right_unit():
    """Legs filled at 3.5 times their length make the body 3.8 m tall; the measured parts
    (pelvis, spine, arms, head) are an adult's in the file's right unit. Before: "the captured
    body comes out 3.8 m tall with the length unit 'm' ... is the unit right? (--unit)"; now the
    import goes through, the filled legs resized to the measured parts' body, and says so."""
    clip = _legs_filled(_tennis_clip(), 3.5)
    motion = normalize_clip(clip, "legs_absent", "test")
    assert 1.4 < motion.source_morphology.stature < 2.1
    line = motion.info["filled_legs_resized"]
    assert "\n" not in line and re.search(r"made the body 3\.8\d m tall; resized to the measured "
                                          r"parts' 1\.\d+ m \(if the file has leg markers", line)
    # Legs filled in proportion to a right body are left as they are.
    plain = normalize_clip(_legs_filled(_tennis_clip(), 1.0), "legs_absent", "test")
    assert "filled_legs_resized" not in plain.info


def test_a_wrong_unit_is_still_questioned_by_the_measured_parts():
    """The same legless clip read 1000 times too large (millimetres taken for metres): the
    measured parts alone say the unit is wrong, in one line naming them."""
    clip = _legs_filled(_tennis_clip(), 1.0)
    clip = replace(clip, positions=clip.positions * 1000.0)
    with pytest.raises(EcsAnimError) as err:
        normalize_clip(clip, "legs_absent", "test")
    text = str(err.value)
    assert "\n" not in text and text.startswith("the measured parts (")
    assert "is the unit right? (--unit)" in text
    # With the legs measured, the whole body's stature asks, as before.
    whole = _tennis_clip()
    with pytest.raises(EcsAnimError, match=r"the captured body comes out .* is the unit right"):
        normalize_clip(replace(whole, positions=whole.positions * 1000.0), "scaled", "test")
