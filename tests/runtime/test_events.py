"""Events and triggers (ecs_anim.runtime.events): edges each tick, reactions wired in YAML or code, the
reactive fight, moving targets, characters removed and added while triggers watch them."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest

from conftest import MOTIONS_DIR, REPO, SCENARIOS_DIR
from ecs_anim.components import MotionPlayer, Placement, QueuedClip
from ecs_anim.core.body_points import SEG_DISTAL, SEG_PROXIMAL, body_point
from ecs_anim.core.errors import EcsAnimError
from ecs_anim.core.morphology import Morphology
from ecs_anim.core.skeleton import JOINT_INDEX as J
from ecs_anim.io.importing import import_bvh
from ecs_anim.motion.constraints import Activation
from ecs_anim.runtime.actions import interpolate_keyframes, switched_off
from ecs_anim.runtime.simulation import Simulation
from ecs_anim.runtime.triggers import (
    AtTime,
    ClipEnded,
    ClipStarted,
    ContactBegan,
    Near,
    Play,
    Reached,
    Remove,
    Removed,
    SwitchOff,
    SwitchOn,
    Trigger,
)
from ecs_anim.scenario import build_simulation, load_scenario


@pytest.fixture(scope="module")
def clips():
    return {name: import_bvh(MOTIONS_DIR / f"{name}.bvh")
            for name in ("walk", "idle", "guard", "kick", "ward_off_punch", "dodge")}


# --- the reactive fight -------------------------------------------------------------------------

def fight(spacing_m: float, kick_delay_s: float, seconds: float):
    """The shipped fight with every pair ``spacing_m`` apart and every kick at ``kick_delay_s``;
    per tick (the posture of step i at i / 30 s) the positions, the events and each character's
    clip."""
    scenario = load_scenario(SCENARIOS_DIR / "fight_training.yaml")
    for c in scenario.characters:
        if c.name.startswith("defender"):
            _, y = c.placement.position_m
            c.placement = Placement((spacing_m, y), c.placement.heading_rad)
    scenario.triggers = [replace(t, when=AtTime(kick_delay_s)) if t.name.startswith("kick")
                         else t for t in scenario.triggers]
    positions, events, playing = [], [], []
    with build_simulation(scenario) as sim:
        for _ in range(round(seconds * scenario.fps)):
            playing.append([sim.bank.names[c] for c in sim.store.clip])  # as the step begins
            sim.step()
            positions.append(sim.store.positions.copy())
            events.append(sim.events())
        names = sim.names()
    return names, np.array(positions), events, np.array(playing)


@pytest.mark.parametrize("spacing_m, kick_delay_s", [(0.8, 0.0), (0.95, 0.5), (1.1, 1.0),
                                                     (0.8, 1.0), (1.1, 0.25)])
def test_every_ward_off_starts_within_one_tick_of_its_trigger_condition(spacing_m, kick_delay_s):
    names, p, events, clips_playing = fight(spacing_m, kick_delay_s, kick_delay_s + 1.5)
    for pair in (1, 2, 3, 4):
        k, d = names.index(f"kicker_{pair}"), names.index(f"defender_{pair}")
        # The condition, measured here from the joints: the kicker's right ankle within 0.9 m
        # of the defender's torso, the trigger's own point (spine_upper at its default
        # fraction: along the segment from its proximal joint, spine_2, to the neck).
        torso = body_point("spine_upper")
        base, tip = p[:, d, SEG_PROXIMAL[torso.segment]], p[:, d, SEG_DISTAL[torso.segment]]
        distance = np.linalg.norm(p[:, k, J["ankle_r"]] - (base + torso.fraction * (tip - base)),
                                  axis=-1)
        condition = int(np.argmax(distance <= 0.9))
        assert distance[condition] <= 0.9, (pair, distance.min())
        # Its clip_started event gives the time of the first posture playing the ward-off.
        start = [round(e.time_s * 30) for tick in events for e in tick
                 if e.kind == "clip_started" and e.character == f"defender_{pair}"
                 and e.detail == "ward_off_punch"]
        assert len(start) == 1, (pair, start)
        assert start[0] - condition == 1, (pair, condition, start)
        assert clips_playing[start[0] - 1, d] != "ward_off_punch"
        assert clips_playing[start[0], d] == "ward_off_punch"
        near = [i for i, tick in enumerate(events) for e in tick
                if e.kind == "near" and e.detail == f"ward_off_{pair}"]
        assert near == [condition]


def test_shipped_fight_reacts_in_order_for_every_pair():
    """kick -> ward-off (when the ankle comes) -> dodge (when the fist comes), for each pair."""
    _, _, events, _ = fight(0.9, 0.3, 3.0)
    for pair in (1, 2, 3, 4):
        kick = [e.time_s for tick in events for e in tick if e.kind == "clip_started"
                and e.character == f"kicker_{pair}" and e.detail == "kick"]
        ward = [e.time_s for tick in events for e in tick if e.kind == "clip_started"
                and e.character == f"defender_{pair}" and e.detail == "ward_off_punch"]
        dodge = [e.time_s for tick in events for e in tick if e.kind == "clip_started"
                 and e.character == f"kicker_{pair}" and e.detail == "dodge"]
        assert len(kick) == len(ward) == len(dodge) == 1, (pair, kick, ward, dodge)
        assert kick[0] == pytest.approx(0.3) and kick[0] < ward[0] < dodge[0]


# --- events and triggers from code --------------------------------------------------------------

#: A constraint off until a trigger switches it on, easing in and out over 0.1 s.
ALWAYS_OFF = switched_off(0.1, 0.1)

def one(clips, *players, fps=30.0):
    """A simulation of characters ``c0, c1, ...`` playing ``players``, 1 m apart along y."""
    sim = Simulation({k: clips[k] for k in ("walk", "idle", "guard", "kick", "dodge")}, fps=fps)
    entities = [sim.spawn(f"c{i}", Morphology.preset("adult_male"), p, Placement((0.0, float(i))))
                for i, p in enumerate(players)]
    return sim, entities


def steps(sim, ticks):
    """Step ``ticks`` times; every event, and each posture's positions (an array (ticks, n, J,
    3), or a list of (n, J, 3) when characters were removed meanwhile)."""
    events, positions = [], []
    for _ in range(ticks):
        sim.step()
        events += sim.events()
        positions.append(sim.store.positions.copy())
    same = len({q.shape for q in positions}) == 1
    return events, np.array(positions) if same else positions


def test_clips_starting_and_ending_and_contacts_beginning_are_events(clips):
    sim, _ = one(clips, MotionPlayer("kick", loop=False, queue=(QueuedClip("guard", 0.3, True),)),
                 MotionPlayer("walk"))
    weights: list[np.ndarray] = []
    events = []
    for _ in range(90):
        sim.step()
        events += sim.events()
        weights.append(sim.store.contact_weight[1].copy())
    mine = [(e.kind, e.detail) for e in events if e.character == "c0" and e.kind != "contact_began"]
    times = [e.time_s for e in events if e.character == "c0" and e.kind != "contact_began"]
    # The queued guard starts crossfade_s (0.3 s) before the kick's end (1.5 s), at the first
    # tick there: the kick ends then.
    assert mine == [("clip_started", "kick"), ("clip_ended", "kick"), ("clip_started", "guard")]
    assert times[0] == 0.0 and times[1] == times[2] and 1.2 - 1e-9 <= times[1] <= 1.2 + 1 / 30
    weight = np.array(weights)
    began = [(round(e.time_s * 30), e.detail) for e in events
             if e.kind == "contact_began" and e.character == "c1"]
    before = np.vstack([np.zeros((1, 2)), weight[:-1]])  # no contact before the first tick
    expected = [(k, foot) for k in range(90) for f, foot in enumerate(("left", "right"))
                if weight[k, f] >= 0.5 > before[k, f]]
    assert began == expected and len(began) >= 4


def test_the_events_are_the_same_whether_a_trigger_waits_on_them_or_none_does(clips):
    """With no trigger waiting, a tick's clip and contact events are kept as arrays and made
    only when asked for; they are the same events, in the same order, as when a trigger waits
    on them (and they are made and emitted at once)."""
    def run(watch: bool) -> list:
        sim, (_, e1, e2) = one(clips, MotionPlayer("kick", loop=False), MotionPlayer("walk"),
                               MotionPlayer("walk", start_s=0.4))
        # (a constraint in both runs, for the trigger's action: clips and contacts come from
        # the motions, not from the solve)
        uid = sim.add_constraint(e2, "reach", "wrist_r", 1, Activation(0.0, 1e9), (1.0, 2.0, 1.2))
        if watch:
            sim.add_trigger(Trigger("step", ContactBegan(e1), (SwitchOff(uid),), repeat=True))
        events = []
        for _ in range(45):
            sim.step()
            events.append(sim.events())
        sim.close()
        return events

    kept, emitted = run(False), run(True)
    assert kept == emitted
    assert sum(e.kind == "contact_began" for tick in kept for e in tick) >= 6


def test_near_fires_once_or_on_every_edge_with_repeat(clips):
    sim, (walker,) = one(clips, MotionPlayer("walk"))
    uid = sim.add_constraint(walker, "reach", "wrist_r", activation=ALWAYS_OFF,
                             target_in_world=(0.5, 0.0, 1.0))
    ankles = (body_point("ankle_l", as_target=True), body_point("ankle_r", as_target=True))
    sim.add_trigger(Trigger("once", Near(walker, *ankles[:1], walker, ankles[1], 0.3),
                            (SwitchOn(uid, 0.2),)))
    sim.add_trigger(Trigger("every", Near(walker, ankles[0], walker, ankles[1], 0.3),
                            (SwitchOn(uid, 0.2),), repeat=True))
    events, p = steps(sim, 120)
    gap = np.linalg.norm(p[:, 0, J["ankle_l"]] - p[:, 0, J["ankle_r"]], axis=-1) <= 0.3
    edges = [k for k in range(120) if gap[k] and (k == 0 or not gap[k - 1])]
    assert len(edges) >= 4  # the ankles pass each other at every step
    assert [round(e.time_s * 30) for e in events if e.detail == "every"] == edges
    assert [round(e.time_s * 30) for e in events if e.detail == "once"] == edges[:1]


def test_a_time_and_a_delay_show_in_the_first_posture_at_or_after_them(clips):
    sim, (a, b) = one(clips, MotionPlayer("guard"), MotionPlayer("guard"))
    sim.add_trigger(Trigger("at", AtTime(0.5), (Play(a, "kick", crossfade_s=0.2),)))
    sim.add_trigger(Trigger("later", AtTime(0.5), (Play(b, "kick"),), delay_s=0.25))
    kick = sim.bank.index("kick")
    first: list[int | None] = [None, None]
    for k in range(40):
        sim.step()  # the posture at k / 30 s: which clips made it (their time has advanced)
        for i in range(2):
            if first[i] is None and sim.store.clip[i] == kick and sim.store.clip_time_s[i] < 0.1:
                first[i] = k
    assert first == [15, math.ceil(0.75 * 30 - 1e-9)]  # the postures at 0.5 s and 0.75 s


def test_a_clip_starting_fires_the_triggers_waiting_for_it_in_the_same_tick(clips):
    sim, (a,) = one(clips, MotionPlayer("guard"))
    uid = sim.add_constraint(a, "aim", "wrist_r", activation=ALWAYS_OFF,
                             target_in_world=(0.5, 0.0, 1.2))
    sim.add_trigger(Trigger("kick", AtTime(0.3), (Play(a, "kick"),)))
    sim.add_trigger(Trigger("aim_when_kicking", ClipStarted(a, "kick"), (SwitchOn(uid, 0.5),)))
    sim.add_trigger(Trigger("stop_aiming", ClipEnded(a, "kick"), (SwitchOff(uid),)))
    events, _ = steps(sim, 12)
    kinds = [(e.kind, e.detail, round(e.time_s, 3)) for e in events if e.time_s == pytest.approx(0.3)]
    assert kinds == [("time", "kick", 0.3), ("clip_ended", "guard", 0.3), ("clip_started", "kick", 0.3)]
    start, stop, _, _ = sim.constraints.activation[sim.constraints.rows_of(np.array([uid]))[0]]
    assert (start, stop) == (pytest.approx(0.3), pytest.approx(0.8))


def test_a_cycle_of_triggers_at_run_time_warns_and_the_others_go_on(clips):
    sim, (a, _) = one(clips, MotionPlayer("guard"), MotionPlayer("walk"))
    sim.add_trigger(Trigger("go", AtTime(0.2), (Play(a, "kick"),)))
    sim.add_trigger(Trigger("ping", ClipStarted(a, "kick"), (Play(a, "dodge"),), repeat=True))
    sim.add_trigger(Trigger("pong", ClipStarted(a, "dodge"), (Play(a, "kick"),), repeat=True))
    _, p = steps(sim, 30)
    assert any("'ping' would fire again in the same tick" in m for m in sim.messages)
    assert np.all(np.isfinite(p))
    walked = p[-1, 1, J["pelvis"], 0] - p[0, 1, J["pelvis"], 0]
    assert walked > 0.5  # the walker went on (about 1.3 m/s)


def test_both_feet_landing_in_one_tick_fire_a_repeating_trigger_twice_and_no_cycle(clips):
    """A character's first tick plants both feet: two contact_began events, each firing the
    repeating trigger once (a 'cycle' was warned, and the second firing skipped)."""
    sim, (a, b) = one(clips, MotionPlayer("idle"), MotionPlayer("walk"))
    sim.add_trigger(Trigger("landed", ContactBegan(a), (Play(b, "walk", from_s=0.5),),
                            repeat=True))
    events, _ = steps(sim, 1)
    assert [e.detail for e in events if e.kind == "contact_began" and e.entity == a] == [
        "left", "right"]
    started = [e for e in events if e.kind == "clip_started" and e.entity == b]
    assert len(started) == 1 + 2 and not sim.messages  # its own first clip, then one per foot


def test_finding_a_cycle_looks_only_at_the_triggers_an_action_can_fire(monkeypatch):
    """A chain of 5,000 triggers, each playing a clip the next one waits for: no cycle, found
    by looking up each action's listeners, not by comparing every pair (which took minutes at
    30,000 triggers)."""
    import ecs_anim.runtime.triggers as triggers_module

    calls = []
    real = triggers_module.listens_to

    def counted(*args):
        calls.append(1)
        return real(*args)

    monkeypatch.setattr(triggers_module, "listens_to", counted)
    n = 5000
    chain = [Trigger(f"t{k}", ClipStarted(k, "kick"), (Play(k + 1, "kick"),), repeat=True)
             for k in range(n)]
    assert triggers_module.find_cycle(chain) == []
    assert len(calls) <= 2 * n
    assert triggers_module.find_cycle(
        [*chain, Trigger("back", ClipStarted(n, "kick"), (Play(0, "kick"),), repeat=True)])


def test_thousands_of_triggers_load_build_and_fire_without_a_false_cycle(tmp_path):
    from support.many_triggers import many_triggers_yaml

    path = tmp_path / "many.yaml"
    path.write_text(many_triggers_yaml(3000), encoding="utf-8")
    with build_simulation(load_scenario(path)) as sim:
        assert len(sim.reactions.triggers) == 3000
        for _ in range(3):
            sim.step()
        assert not sim.messages


def test_reached_is_the_first_tick_a_constraint_is_met(clips):
    sim, (a,) = one(clips, MotionPlayer("idle"))
    uid = sim.add_constraint(a, "touch", "wrist_r", activation=Activation(0.2, 1e9, 0.3, 0.0),
                             target_in_world=(0.35, -0.25, 1.0))
    sim.add_trigger(Trigger("touched", Reached(uid, 0.001), (SwitchOff(uid),)))
    errors, weights, reached = [], [], []
    for _ in range(30):
        sim.step()
        row = sim.constraints.rows_of(np.array([uid]))[0]
        errors.append(sim.constraints.error[row])
        weights.append(sim.constraints.weight[row])
        reached += [round(e.time_s * 30) for e in sim.events() if e.kind == "reached"]
    met = [k for k in range(30) if weights[k] > 0 and errors[k] <= 0.001]
    assert reached == met[:1] and met


def test_removing_a_character_is_an_event_and_its_triggers_are_dropped(clips, capsys):
    sim, (a, b, c) = one(clips, MotionPlayer("guard"), MotionPlayer("guard"), MotionPlayer("walk"))
    head = body_point("head", as_target=True)
    sim.add_trigger(Trigger("b_gone", Removed(b), (Play(a, "dodge"),)))
    sim.add_trigger(Trigger("b_near", Near(a, head, b, head, 0.1), (Play(a, "kick"),)))
    sim.add_trigger(Trigger("b_kicks", AtTime(2.0), (Play(b, "kick"),)))
    steps(sim, 5)
    sim.remove(b)
    events, p = steps(sim, 10)
    assert [(e.kind, e.character) for e in events[:1]] == [("removed", "c1")]
    assert ("clip_started", "c0", "dodge") in [(e.kind, e.character, e.detail) for e in events]
    assert any("triggers b_near, b_kicks" in m and "dropped" in m for m in sim.messages)
    assert all(np.all(np.isfinite(q)) for q in p) and sim.names() == ["c0", "c2"]
    # A trigger's own Remove action does the same.
    sim.add_trigger(Trigger("drop_walker", AtTime(0.6), (Remove(c),)))
    events, _ = steps(sim, 5)
    assert [e.character for e in events if e.kind == "removed"] == ["c2"]
    assert sim.names() == ["c0"]


def test_a_character_added_mid_run_plays_and_can_be_watched(clips):
    sim, _ = one(clips, MotionPlayer("walk"))
    steps(sim, 10)
    b = sim.spawn("late", Morphology.preset("child"), MotionPlayer("guard"), Placement((0.0, 2.0)))
    sim.add_trigger(Trigger("late_kick", AtTime(0.5), (Play(b, "kick"),)))
    events, p = steps(sim, 20)
    assert ("clip_started", "late", "guard") == (events[0].kind, events[0].character, events[0].detail)
    assert ("clip_started", "late", "kick") in [(e.kind, e.character, e.detail) for e in events]
    assert np.all(np.isfinite(p))
    assert p[-1, 0, J["pelvis"], 0] - p[0, 0, J["pelvis"], 0] > 0.5  # the first walks on


def test_keyframed_targets_are_interpolated_linearly(clips):
    rng = np.random.default_rng(1414)
    times = np.sort(rng.uniform(0, 2, (5, 4)), axis=1)
    points = rng.normal(size=(5, 4, 3))
    for t in (-1.0, 0.3, 0.9, 1.7, 5.0):
        got = interpolate_keyframes(times, points, t)
        for k in range(5):
            expected = [np.interp(t, times[k], points[k, :, axis]) for axis in range(3)]
            np.testing.assert_allclose(got[k], expected, atol=1e-12)
    sim, (a,) = one(clips, MotionPlayer("idle"))
    uid = sim.add_constraint(a, "follow", "wrist_r", target_in_world=(0.3, -0.2, 1.0))
    sim.add_target_track(uid, [0.0, 1.0], [(0.3, -0.2, 1.0), (0.3, -0.5, 1.3)])
    for k in range(40):
        sim.step()
        u = min(k / 30, 1.0)
        target = sim.constraints.target_world[sim.constraints.rows_of(np.array([uid]))[0]]
        np.testing.assert_allclose(target, (0.3, -0.2 - 0.3 * u, 1.0 + 0.3 * u), atol=1e-12)
    with pytest.raises(EcsAnimError, match="increasing"):
        sim.add_target_track(uid, [1.0, 0.5], [(0, 0, 1), (0, 0, 1)])


def test_triggers_are_checked_when_added(clips):
    sim, (a,) = one(clips, MotionPlayer("idle"))
    with pytest.raises(EcsAnimError, match="trigger 'x': no character with entity id 99"):
        sim.add_trigger(Trigger("x", AtTime(1.0), (Play(99, "kick"),)))
    with pytest.raises(EcsAnimError, match="unknown motion 'kik'"):
        sim.add_trigger(Trigger("x", AtTime(1.0), (Play(a, "kik"),)))
    with pytest.raises(EcsAnimError, match="constraint id 7 is not in the simulation"):
        sim.add_trigger(Trigger("x", ContactBegan(a), (SwitchOn(7),)))
    with pytest.raises(EcsAnimError, match="delay_s"):
        sim.add_trigger(Trigger("x", AtTime(1.0), (Play(a, "kick"),), delay_s=-1.0))


# --- triggers and moving targets in YAML ----------------------------------------------------------

BASE = f"""duration_s: 1.0
motions:
  guard: {MOTIONS_DIR / 'guard.bvh'}
  kick: {MOTIONS_DIR / 'kick.bvh'}
  dodge: {MOTIONS_DIR / 'dodge.bvh'}
characters:
  - name: red
    morphology: adult_male
    motion: guard
    constraints:
      - name: reach
        point: wrist_r
        target:
          world_m: [{{t_s: 0.0, at_m: [0.3, -0.2, 1.0]}}, {{t_s: 0.5, at_m: [0.3, -0.5, 1.3]}}]
      - name: lean
        point: head
        chain: [head]
        target: {{character: blue, point: hand_r}}
        kind: area
        area: {{shape: sphere, radius_m: 0.3, inside: false}}
        activation: {{by_trigger: true, ease_in_s: 0.1, ease_out_s: 0.1}}
  - name: blue
    morphology: adult_female
    position_m: [0.9, 0.0]
    heading_deg: 180
    motion: guard
"""


def scenario_file(tmp_path, triggers):
    path = tmp_path / "s.yaml"
    path.write_text(BASE + triggers)
    return path


EVERY_KIND = """triggers:
  - name: kick
    when: {at_s: 0.2}
    then:
      - play: red.kick
        crossfade_s: 0.1
        then: [{motion: guard, loop: true}]
      - arm: dodge
  - name: dodge
    armed: false
    when: {near: blue.hand_r, fraction: 0.6, to: red.head, within_m: 2.0}
    delay_s: 0.1
    then:
      - play: red.dodge
        from_s: 0.3
      - switch_on: red.lean
        for_s: 0.4
  - name: stop
    when: {clip_started: red.dodge}
    then: [{switch_off: red.lean}, {move_target: red.reach, world_m: [0.3, 0.0, 1.0]}]
  - name: grow
    when: {clip_ended: red.kick}
    then: [{set_body: blue, morphology: tall, blend_s: 0.5}]
  - when: {reached: red.reach, within_m: 0.01}
    repeat: true
    then: [{switch_on: red.lean}]
  - when: {contact_began: red, foot: left}
    delay_s: 0.8
    then: [{remove: blue}]
  - when: {removed: blue}
    then: [{play: red.guard, loop: true}]
"""


def test_every_condition_and_action_loads_from_yaml_and_runs(tmp_path):
    scenario = load_scenario(scenario_file(tmp_path, EVERY_KIND))
    assert [t.name for t in scenario.triggers] == ["kick", "dodge", "stop", "grow", "triggers[4]",
                                                   "triggers[5]", "triggers[6]"]
    with build_simulation(scenario) as sim:
        events, _ = steps(sim, 30)
        assert sim.names() == ["red"]
    kinds = {(e.kind, e.character, e.detail) for e in events}
    assert {("time", "", "kick"), ("clip_started", "red", "kick"), ("near", "blue", "dodge"),
            ("clip_started", "red", "dodge"), ("clip_ended", "red", "kick"),
            ("removed", "blue", ""), ("clip_started", "red", "guard")} <= kinds
    dodge = next(e.time_s for e in events if e.kind == "clip_started" and e.detail == "dodge")
    near = next(e.time_s for e in events if e.kind == "near")
    assert dodge == pytest.approx(near + 0.1)


def test_a_keyframed_target_in_yaml_moves_linearly(tmp_path):
    scenario = load_scenario(scenario_file(tmp_path, ""))
    reach = scenario.characters[0].constraints[0]
    assert reach.target_keyframes == ((0.0, 0.5), ((0.3, -0.2, 1.0), (0.3, -0.5, 1.3)))
    with build_simulation(scenario) as sim:
        uid = sim.constraint_index(int(sim.store.entity[sim.names().index("red")]), "reach")
        for k in range(20):
            sim.step()
            u = min(k / 30 / 0.5, 1.0)
            row = sim.constraints.rows_of(np.array([uid]))[0]
            np.testing.assert_allclose(sim.constraints.target_world[row],
                                       (0.3, -0.2 - 0.3 * u, 1.0 + 0.3 * u), atol=1e-12)


@pytest.mark.parametrize("triggers, message", [
    ("triggers:\n  - when: {at_s: 0.2}\n    then: [{play: rad.kick}]\n",
     r"s.yaml:\d+: triggers\[0\].then\[0\].play: no character named 'rad'; did you mean 'red'\?"),
    ("triggers:\n  - when: {near: red.ankel_r, to: blue.head, within_m: 0.5}\n    then: [{play: red.kick}]\n",
     r"s.yaml:\d+: triggers\[0\].when.near: unknown body point 'ankel_r'; did you mean 'ankle_r'\?"),
    ("triggers:\n  - when: {at_s: 0.2}\n    then: [{play: red.kik}]\n",
     r"s.yaml:\d+: triggers\[0\].then\[0\].play: unknown motion 'kik'; did you mean 'kick'\?"),
    ("triggers:\n  - when: {at_s: 0.2}\n    then: [{switch_on: red.leen}]\n",
     r"s.yaml:\d+: triggers\[0\].then\[0\].switch_on: 'red' has no constraint 'leen'; did you mean 'lean'\?"),
    ("triggers:\n  - when: {clip_started: red.kick}\n    then: [{swich_on: red.lean}]\n",
     r"s.yaml:\d+: triggers\[0\].then\[0\].swich_on: unknown action; did you mean 'switch_on'\?"),
    ("triggers:\n  - when: {clip_startd: red.kick}\n    then: [{switch_on: red.lean}]\n",
     r"s.yaml:\d+: triggers\[0\].when.clip_startd: unknown condition; did you mean 'clip_started'\?"),
    ("triggers:\n  - when: {at_s: 0.2}\n    then: [{arm: dogde}]\n  - name: dodge\n"
     "    when: {at_s: 0.5}\n    then: [{play: red.kick}]\n",
     r"s.yaml:\d+: triggers\[0\].then\[0\].arm: no trigger named 'dogde'; did you mean 'dodge'\?"),
])
def test_a_trigger_naming_what_is_not_there_is_refused_at_load(tmp_path, triggers, message):
    with pytest.raises(EcsAnimError, match=message) as info:
        load_scenario(scenario_file(tmp_path, triggers))
    assert "\n" not in str(info.value)


def test_a_cycle_of_triggers_is_refused_at_load_with_its_line(tmp_path):
    cycle = """triggers:
  - name: start
    when: {at_s: 0.1}
    then: [{play: red.kick}]
  - name: ping
    repeat: true
    when: {clip_started: red.kick}
    then: [{play: red.dodge}]
  - name: pong
    repeat: true
    when: {clip_started: red.dodge}
    then: [{play: red.kick}]
"""
    lines = (BASE + cycle).splitlines()
    line = lines.index("  - name: ping") + 1
    with pytest.raises(EcsAnimError, match=rf"s.yaml:{line}: triggers\[1\]: triggers 'ping' -> "
                                           r"'pong' -> 'ping' would fire each other forever"):
        load_scenario(scenario_file(tmp_path, cycle))
    # A delay (or no repeat) breaks the cycle: it loads.
    load_scenario(scenario_file(tmp_path, cycle.replace("    repeat: true\n    when: {clip_started: red.dodge}",
                                                        "    repeat: true\n    delay_s: 0.2\n    when: {clip_started: red.dodge}")))


def test_the_documented_trigger_scenario_loads_and_reacts(tmp_path):
    """docs/scenarios.md, Triggers: its complete scenario, motions read from scenarios/motions."""
    text = (REPO / "docs" / "scenarios.md").read_text()
    section = text[text.index("## Triggers"):]
    example = section[section.index("```yaml\n") + 8:section.index("```\n", section.index("```yaml"))]
    path = tmp_path / "triggers.yaml"
    path.write_text(example.replace("motions/", f"{MOTIONS_DIR}/"))
    with build_simulation(load_scenario(path)) as sim:
        events, p = steps(sim, 60)
    happened = [(e.kind, e.character, e.detail) for e in events if e.kind != "contact_began"]
    assert ("clip_started", "red", "kick") in happened
    assert ("clip_started", "blue", "dodge") in happened
    assert happened.index(("clip_started", "red", "kick")) < happened.index(("clip_started", "blue", "dodge"))
    assert np.all(np.isfinite(p))


def _conditions(compiled):
    """A compiled set of conditions as plain values, to compare two."""
    return {k: (v.tolist() if isinstance(v, np.ndarray) else v)
            for k, v in vars(compiled).items() if k != "_listened"}


def test_a_trigger_fired_once_stops_being_watched_without_a_rebuild_of_every_condition():
    """The fight's 16 triggers all fire in its first 2.5 s: only its 4 Arm actions (a trigger
    watched anew) rebuild the conditions; a trigger done firing is taken out of them, leaving
    what a rebuild would make."""
    with build_simulation(load_scenario(SCENARIOS_DIR / "fight_training.yaml")) as sim:
        reactions = sim.reactions
        built = [reactions._compile()]
        for _ in range(75):
            sim.step()
            kept = reactions._compile()
            if kept is not built[-1]:
                built.append(kept)
            reactions._compiled = None
            assert _conditions(reactions._compile()) == _conditions(kept)
            reactions._compiled = kept
        fired = int(reactions.fired.sum())
    assert fired == 16
    assert len(built) == 1 + 4
