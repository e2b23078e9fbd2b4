"""Issue 31, item 1: planted soles on the ground on every body, from real captures.

Real clips whose subjects differ from the bodies they play on (a 2.0 m body's heel hung 50-85 mm
up through every stance of a CMU walk; a jump's planted toe sat 12-15 cm up after landing) are
played on the smallest and the tallest body over flat ground and stairs. Each fully planted
foot must stand on the ground within 1 mm (its heel or its ball, whichever it stands on), no
sole under it by more than 1 mm, the point it stands on still within 1 mm per frame, and the
foot must roll: heel-off frames (standing on the ball, the heel lifted) as the capture has them.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from conftest import MOCAP_DIR, require_mocap
from ecs_anim import Plane, Stairs
from ecs_anim.apps.batch.jobs import import_clip
from ecs_anim.core.ground import Ground
from ecs_anim.core.ground_adapt import BALL_HEIGHT_PER_LEG
from ecs_anim.core.normalized import SIDE_JOINTS, SIDE_LENGTHS
from ecs_anim.runtime.metrics import MetricsRecorder
from ecs_anim.scenario import build_simulation
from support.scenarios import clip_on_body

#: A walk whose heel hung 50-85 mm up on a 2.0 m body, and a two-feet jump landing on its toes.
CLIPS = ("varied/cmu_walk_120hz_adelaide.bvh", "varied2/sfu_0005_2feetjump_cm_xyz_120hz.bvh")
GROUNDS: dict[str, Ground] = {"flat": Plane(), "stairs": Stairs(rise_m=0.15, run_m=0.3)}


def _play(clip: str, stature_m: float, ground: Ground) -> tuple[dict, np.ndarray]:
    """The run's report and, per fully planted foot and tick, (pivot, heel mm, ball mm above the
    ground)."""
    require_mocap()
    path = MOCAP_DIR / clip
    if not path.is_file():
        pytest.skip(f"{path} not found")
    motion = import_clip(Path(path))
    scenario = clip_on_body(motion, stature_m, ground)
    ankles, toes = list(SIDE_JOINTS["ankle"]), list(SIDE_JOINTS["toe"])
    rows = []
    with build_simulation(scenario) as sim:
        recorder = MetricsRecorder(sim)
        for _ in range(round(scenario.duration_s * scenario.fps)):
            sim.step()
            recorder.record()
            st = sim.store
            p = st.positions[0]
            ankle_height = st.lengths[0, SIDE_LENGTHS["ankle_height"]]
            heel = p[ankles, 2] - ankle_height - ground.height(p[ankles, :2])
            ball_height = sim.leg_length()[0] * BALL_HEIGHT_PER_LEG
            ball = p[toes, 2] - ball_height - ground.height(p[toes, :2])
            for side in np.flatnonzero(st.contact_weight[0] >= 1.0):
                rows.append((st.pivot[0, side], heel[side] * 1e3, ball[side] * 1e3))
        return recorder.report()["characters"][0], np.array(rows)


@pytest.mark.parametrize("ground", list(GROUNDS))
@pytest.mark.parametrize("stature_m", [1.0, 2.1])
@pytest.mark.parametrize("clip", CLIPS)
def test_planted_soles_stand_on_the_ground_on_every_body(clip: str, stature_m: float,
                                                          ground: str) -> None:
    report, planted = _play(clip, stature_m, GROUNDS[ground])
    assert report["floating_mm_max"] <= 1.0, report
    assert report["ground_penetration_mm_max"] <= 1.0, report
    assert report["foot_sliding_mm_per_frame"]["max"] <= 1.0, report
    pivot, heel, ball = planted.T
    stood_on = np.where(pivot == 0, heel, ball)
    assert np.abs(stood_on).max() <= 1.0  # the point stood on is on the ground, either way
    assert min(heel.min(), ball.min()) >= -1.0


def test_a_planted_foot_rolls_from_heel_to_ball() -> None:
    """Through a walk's stances the foot stands on its heel first, then on its ball with the
    heel lifted (heel off, as the capture has it), on a short and a tall body alike."""
    for stature_m in (1.0, 2.1):
        _, planted = _play(CLIPS[0], stature_m, GROUNDS["flat"])
        pivot, heel, _ = planted.T
        on_ball = pivot == 1
        assert 0.03 < on_ball.mean() < 0.5, on_ball.mean()
        # the heel rises through heel off: up to a few centimetres on either body
        assert heel[on_ball].max() > 20.0 * stature_m / 1.75
        assert np.median(heel[~on_ball]) == pytest.approx(0.0, abs=0.01)
