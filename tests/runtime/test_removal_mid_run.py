"""Characters removed mid-run (issue 35): the metrics recorder keeps each character's figures by
entity, and the reactions of one tick see the world as it was when they began."""

from __future__ import annotations

import numpy as np
import pytest

from ecs_anim.components import MotionPlayer, Placement
from ecs_anim.core.morphology import Morphology
from ecs_anim.runtime.metrics import MetricsRecorder
from ecs_anim.runtime.simulation import Simulation
from ecs_anim.runtime.triggers import AtTime, Play, Reached, Remove, SwitchOff, Trigger


def crowd(walk, idle, clips=("walk", "idle", "walk")) -> tuple[Simulation, list[int]]:
    """Characters ``c0, c1, ...`` playing ``clips``, 1.5 m apart along y."""
    sim = Simulation({"walk": walk, "idle": idle})
    bodies = ("adult_male", "adult_female", "child")
    entities = [sim.spawn(f"c{i}", Morphology.preset(bodies[i % 3]), MotionPlayer(clip),
                          Placement((0.0, 1.5 * i))) for i, clip in enumerate(clips)]
    return sim, entities


def recorded(walk, idle, ticks: int, remove_at: int | None = None) -> dict:
    """The report of ``ticks`` ticks of :func:`crowd`, ``c1`` removed (from code) after tick
    ``remove_at``."""
    sim, (_, middle, _) = crowd(walk, idle)
    with sim:
        metrics = MetricsRecorder(sim)
        for tick in range(ticks):
            sim.step()
            metrics.record()
            if tick + 1 == remove_at:
                sim.remove(middle)
        return metrics.report()


def test_the_recorder_keeps_each_characters_figures_when_one_before_it_is_removed(walk, idle):
    """c1 removed after 20 ticks (the row of c2 moves down): every character is reported, the
    removed one with the figures it had then and the tick it was first missing from, the
    others with the same figures as in a run where nobody was removed."""
    report = recorded(walk, idle, 45, remove_at=20)
    alone = {c["name"]: c for c in recorded(walk, idle, 45)["characters"]}
    until = {c["name"]: c for c in recorded(walk, idle, 20)["characters"]}
    by_name = {c["name"]: c for c in report["characters"]}
    assert list(by_name) == ["c0", "c1", "c2"]
    assert by_name["c1"].pop("removed_at_s") == round(20 / 30, 4)  # the first posture without it
    assert by_name["c1"] == until["c1"]  # its figures end at its removal
    assert by_name["c0"] == alone["c0"] and by_name["c2"] == alone["c2"]
    assert alone["c2"]["stride_m_median"] is not None  # c2 walks: its strides were recorded
    assert report["ticks"] == 45


# --- reactions of one tick ----------------------------------------------------------------------


def reaching_pair(walk, idle) -> tuple[Simulation, tuple[int, int], tuple[int, int]]:
    """Two idle characters, each with a wrist target it reaches on the first tick."""
    sim, (a, b) = crowd(walk, idle, ("idle", "idle"))
    ua = sim.add_constraint(a, "reach", "wrist_r", target_in_world=(0.3, -0.2, 1.0))
    ub = sim.add_constraint(b, "reach", "wrist_r", target_in_world=(0.3, 1.3, 1.0))
    return sim, (a, b), (ua, ub)


@pytest.mark.parametrize("first", ["removes", "switches"])
def test_two_reached_triggers_of_one_tick_both_act_whichever_comes_first(walk, idle, first):
    """Both constraints are reached in the same tick; one trigger removes b, the other switches
    b's constraint off and starts a walk on a. Whichever comes first, the world after the tick
    is the same: b gone, a walking; the action naming b's constraint, when b is gone by then,
    is skipped with one warning, and the tick goes on."""
    sim, (a, b), (ua, ub) = reaching_pair(walk, idle)
    removes = Trigger("removes", Reached(ua, 0.05), (Remove(b),))
    switches = Trigger("switches", Reached(ub, 0.05), (SwitchOff(ub), Play(a, "walk", loop=True)))
    for trigger in (removes, switches) if first == "removes" else (switches, removes):
        sim.add_trigger(trigger)
    with sim:
        sim.step()
        events = [(e.kind, e.character, e.detail) for e in sim.events()]
        assert ("reached", "c0", "removes") in events and ("reached", "c1", "switches") in events
        assert ("removed", "c1", "") in events
        assert sim.names() == ["c0"]
        assert sim.bank.names[int(sim.store.clip[sim.row(a)])] == "walk"
        skipped = [m for m in sim.messages if "skipped" in m]
        if first == "removes":
            assert len(skipped) == 1
            assert "'switches'" in skipped[0] and "switch_off" in skipped[0] \
                and f"constraint id {ub}" in skipped[0]
        else:
            assert skipped == []
        for _ in range(30):  # the others go on
            sim.step()
        assert np.all(np.isfinite(sim.store.positions))


def test_a_trigger_of_the_same_tick_acts_on_the_living_and_skips_the_removed(walk, idle):
    """Two time triggers due in the same tick: the first removes c1; the second (which names
    c1 too) still fires, its action on c1 skipped with one warning naming c1, the one on c2
    applied. Later it is dropped: it names a removed character."""
    sim, (_, middle, last) = crowd(walk, idle, ("idle", "idle", "idle"))
    sim.add_trigger(Trigger("leave", AtTime(0.2), (Remove(middle),)))
    sim.add_trigger(Trigger("walk", AtTime(0.2), (Play(middle, "walk"), Play(last, "walk")),
                            repeat=True))
    with sim:
        for _ in range(12):
            sim.step()
        assert sim.names() == ["c0", "c2"]
        assert sim.bank.names[int(sim.store.clip[sim.row(last)])] == "walk"
        skipped = [m for m in sim.messages if "skipped" in m]
        assert len(skipped) == 1 and "'walk'" in skipped[0] and "character 'c1'" in skipped[0]
        assert sim.reactions.dropped.tolist() == [False, True]
