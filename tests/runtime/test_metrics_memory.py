"""Issue 35, item 12: the metrics recorder's memory stays flat however long a run lasts (it kept
every stride: 194 to 224 MB over 30 simulated minutes of the soak)."""

from __future__ import annotations

import pytest

from conftest import MOTIONS_DIR
from ecs_anim import Simulation
from ecs_anim.components import MotionPlayer, Placement
from ecs_anim.core.morphology import Morphology
from ecs_anim.io.importing import import_bvh
from ecs_anim.runtime.metrics import MAX_SLIDE_EVENTS, STRIDES_KEPT, MetricsRecorder


def test_the_recorder_keeps_the_latest_strides_only():
    sim = Simulation({"walk": import_bvh(MOTIONS_DIR / "walk.bvh")})
    sim.spawn("a", Morphology.preset("adult_male"), MotionPlayer("walk"), Placement())
    sim.step()
    metrics = MetricsRecorder(sim)
    st = sim.store
    for k in range(6 * STRIDES_KEPT):  # a footprint laid every other tick, 1.4 m apart
        st.locked[0] = [k % 2 == 0, False]
        st.footprint[0, 0, :2] = [0.7 * k, 0.0]
        metrics.record()
    assert len(metrics.strides[0]) == STRIDES_KEPT
    assert len(metrics.slides) <= MAX_SLIDE_EVENTS
    figures = metrics.report()["characters"][0]
    assert figures["stride_m_median"] == pytest.approx(1.4)
