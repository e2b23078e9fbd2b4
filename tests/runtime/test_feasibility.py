"""The feasibility pass (issue 32, item 6): before a run, and when a body or a target changes,
each constraint is said in one line to reach its target or not, by how much
(``sim.feasibility()``, ``run``'s output and report, the viewer's pins)."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from conftest import MOTIONS_DIR, SCENARIOS_DIR
from ecs_anim.apps.cli.main import main
from ecs_anim.core.body_points import GROUP_INDEX, body_point
from ecs_anim.core.ground import Bumps, Combined, HeightGrid, Slope, Stairs, sheerest
from ecs_anim.core.morphology import Morphology
from ecs_anim.core.skeleton import LENGTH_INDEX as L
from ecs_anim.motion.constraint_table import TARGET_WORLD
from ecs_anim.runtime.feasibility import SHORT_TOLERANCE_M, chain_reach, feasibility, ground_lines
from ecs_anim.scenario import build_simulation, load_scenario

#: A 1.0 m kicker kicks at a 1.75 m defender 1.5 m away: its 0.48 m legs cannot reach.
FAR_KICK = f"""\
duration_s: 1.5
fps: 30
motions:
  guard: {MOTIONS_DIR / "guard.bvh"}
  kick: {MOTIONS_DIR / "kick.bvh"}
characters:
  - name: kicker
    morphology: {{stature_m: 1.0}}
    motion: guard
    constraints:
      - name: kick
        point: ankle_r
        chain: [leg_r]
        target: {{character: defender, point: spine_upper, fraction: 0.0}}
        activation: {{motion: kick, start_s: 0.45, stop_s: 0.95, ease_in_s: 0.2, ease_out_s: 0.2}}
  - name: defender
    morphology: adult_male
    position_m: [1.5, 0.0]
    heading_deg: 180
    motion: guard
triggers:
  - name: go
    when: {{at_s: 0.2}}
    then: [{{play: kicker.kick}}]
"""


def far_kick(tmp_path: Path) -> Path:
    path = tmp_path / "far_kick.yaml"
    path.write_text(FAR_KICK)
    return path


def test_run_says_an_unreachable_kick_before_the_first_tick(tmp_path: Path, capsys) -> None:
    report = tmp_path / "report.json"
    assert main(["run", str(far_kick(tmp_path)), "--report", str(report)]) == 0
    out = capsys.readouterr().out.splitlines()
    first, summary, table = out[0], out[1], out[2]
    assert first.startswith("feasibility: kick of kicker (1.00 m, leg_r 0.48 m) cannot reach "
                            "defender's spine_upper: "), first
    short_m = float(first.split(": ")[-1].removesuffix(" m short"))
    assert 0.5 < short_m < 1.0
    assert summary == "feasibility: 0 of 1 constraints can reach their targets"
    assert table.startswith(f"{far_kick(tmp_path)}: 45 ticks")  # the run's table comes after
    written = json.loads(report.read_text())["feasibility"]
    assert len(written) == 1 and written[0]["line"] == first.removeprefix("feasibility: ")
    assert written[0]["reachable"] is False and written[0]["short_m"] == pytest.approx(short_m,
                                                                                      abs=0.006)


def test_an_estimated_shortfall_is_no_more_than_the_run_shows(tmp_path: Path) -> None:
    """The estimate errs on the side of reach: the kick, solved, stays at least that far off."""
    with build_simulation(load_scenario(far_kick(tmp_path))) as sim:
        (estimate,) = sim.feasibility()
        table, closest = sim.constraints, np.inf
        for _ in range(45):
            sim.step()
            if table.weight[0] >= 1.0:
                closest = min(closest, float(table.error[0]))
    assert estimate.short_m - SHORT_TOLERANCE_M <= closest < estimate.short_m + 0.15


def test_the_shipped_fight_has_no_false_alarm() -> None:
    """Every kick, ward-off and punch of the fight is within reach (its kicks reach the chest's
    surface within 3 mm in the run); the dodges' keep-out areas are not a question of reach."""
    with build_simulation(load_scenario(SCENARIOS_DIR / "fight_training.yaml")) as sim:
        estimates = sim.feasibility()
    assert len(estimates) == 16
    assert all(e.reachable for e in estimates), [e.line for e in estimates if not e.reachable]
    assert sorted(e.constraint for e in estimates if not e.checked) == ["lean_back"] * 4
    kick_4 = next(e for e in estimates if e.character == "kicker_4" and e.constraint == "kick_torso")
    assert kick_4.line == ("kick_torso of kicker_4 (1.65 m, leg_r 0.70 m) can reach defender_4's "
                           f"spine_upper: {-kick_4.short_m:.2f} m to spare")


@pytest.mark.parametrize("name, out_of_reach", [
    ("grasp_com.yaml", {"out_of_reach.grasp"}),
    ("reach_and_touch.yaml", {"reacher.elbow_out", "friend.pat_head"}),
    ("wrist_elbow_priority.yaml", {"elbow_unreachable.elbow"}),
    ("wrists_above_table.yaml", set()),
])
def test_the_shipped_scenarios_say_what_their_comments_say(name: str, out_of_reach: set[str]) -> None:
    """The constraints each scenario's comment calls out of reach, and only those."""
    with build_simulation(load_scenario(SCENARIOS_DIR / name)) as sim:
        said = {f"{e.character}.{e.constraint}" for e in sim.feasibility() if not e.reachable}
        assert said == out_of_reach
        assert sim.unreachable() == {e.uid for e in sim.feasibility() if not e.reachable}


def test_a_body_change_that_puts_a_target_out_of_reach_warns_once() -> None:
    with build_simulation(load_scenario(SCENARIOS_DIR / "fight_training.yaml")) as sim:
        sim.feasibility()
        kicker = sim.entity("kicker_1")
        sim.set_body(kicker, Morphology.from_stature(1.0))
        sim.set_body(kicker, Morphology.from_stature(0.98))  # still out: said once
        said = [m for m in sim.messages if "kick_torso of kicker_1" in m]
        assert len(said) == 1 and "(1.00 m, leg_r 0.48 m) cannot reach defender_1's spine_upper" \
            in said[0], sim.messages
        assert sim.constraint_index(kicker, "kick_torso") in sim.unreachable()


def test_chain_reach_is_the_bones_from_the_anchor() -> None:
    lengths = Morphology.preset("adult_male").lengths
    points = [("ankle_r", ("leg_r",)), ("wrist_l", ("arm_l",)), ("wrist_l", ("arm_l", "trunk")),
              ("head", ("head",)), ("forearm_r", ("arm_r",))]
    bodies = [body_point(name) for name, _ in points]
    masks = np.array([sum(1 << GROUP_INDEX[g] for g in chain) for _, chain in points])
    reach, _ = chain_reach(np.tile(lengths, (len(points), 1)),
                           np.array([b.segment for b in bodies]),
                           np.array([b.fraction for b in bodies]),
                           np.array([b.offset_m for b in bodies]), masks)
    arm = lengths[L["upper_arm_l"]] + lengths[L["forearm_l"]]
    spine = lengths[L["spine_lower"]] + lengths[L["spine_middle"]] + lengths[L["spine_upper"]]
    np.testing.assert_allclose(reach, [
        lengths[L["thigh_r"]] + lengths[L["shank_r"]], arm,
        spine + lengths[L["clavicle_l"]] + arm, lengths[L["neck"]],
        lengths[L["upper_arm_r"]] + 0.5 * lengths[L["forearm_r"]]], rtol=0, atol=1e-12)


#: A 0.95 m step 2 m ahead of a 1.2 m child and an adult (issue 35: a rise of metres was
#: accepted silently, and walked into: penetration up to 25 m).
WALL = f"""\
duration_s: 5.0
fps: 30
motions:
  walk: {MOTIONS_DIR / "walk.bvh"}
ground: {{type: stairs, rise_m: 0.95, run_m: 0.4, steps: 1, start_m: 2.0}}
characters:
  - name: child
    morphology: child
    motion: walk
  - name: adult
    morphology: adult_male
    position_m: [0.0, 1.0]
    motion: walk
"""


def test_run_says_a_rise_no_leg_can_step_up_before_the_first_tick(tmp_path: Path, capsys) -> None:
    path = tmp_path / "wall.yaml"
    path.write_text(WALL)
    report = tmp_path / "wall.json"
    assert main(["run", str(path), "--report", str(report)]) == 0
    first = capsys.readouterr().out.splitlines()[0]
    assert first == ("ground: a rise of 0.95 m, more than child can step up (0.26 m, half its "
                     "leg): a character walking into it stops there")
    figures = json.loads(report.read_text())
    assert figures["ground_problems"] == [first]
    for character in figures["characters"]:  # they stop in front of it: nothing sinks
        assert character["floating_mm_max"] <= 1.0 and character["ground_penetration_mm_max"] <= 1.0
        assert character["foot_sliding_mm_per_frame"]["max"] <= 1.0


def test_walkers_stop_in_front_of_a_rise_they_cannot_step_up(tmp_path: Path) -> None:
    path = tmp_path / "wall.yaml"
    path.write_text(WALL)
    scenario = load_scenario(path)
    with build_simulation(scenario) as sim:
        front = np.zeros(2)
        for _ in range(round(scenario.duration_s * scenario.fps)):
            sim.step()
            front = np.maximum(front, sim.store.positions[:, :, 0].max(axis=1))
        assert np.all(front < 2.0) and np.all(front > 1.5), front  # at the riser, x = 2 m


@pytest.mark.parametrize(("ground", "sheer"), [
    (Stairs(rise_m=0.15, run_m=0.3), (0.15, 0.0)),
    (Slope(grade_x=0.6, grade_y=0.8), (0.0, 1.0)),
    (Bumps(amplitude_m=0.04, wavelength_x_m=2.0, wavelength_y_m=4.0), (0.0, 0.04 * np.pi)),
    (HeightGrid(np.array([[0.0, 0.1], [0.5, 0.2]]), cell_m=0.25), (0.5, 2.0)),
    (Combined((Stairs(rise_m=-0.2), Slope(grade_x=0.5))), (0.2, 0.5)),
])
def test_the_sheerest_rise_and_grade_of_each_ground(ground, sheer) -> None:
    assert sheerest(ground) == pytest.approx(sheer)


@pytest.mark.parametrize("name", sorted(p.stem for p in SCENARIOS_DIR.glob("*.yaml")))
def test_the_shipped_grounds_can_be_walked_by_their_characters(name: str) -> None:
    with build_simulation(load_scenario(SCENARIOS_DIR / f"{name}.yaml")) as sim:
        assert ground_lines(sim) == []


def test_say_unreachable_estimates_again_only_what_changed(monkeypatch) -> None:
    """A moved target is estimated again alone, and said once when it goes out of reach; back
    in reach it leaves ``unreachable()``, and out again it is said again. Nothing changed:
    nothing is estimated."""
    asked: list[list[int]] = []
    estimate = feasibility

    def counted(sim, constraints=None):
        asked.append(list(constraints) if constraints is not None else [-1])
        return estimate(sim, constraints)

    monkeypatch.setattr("ecs_anim.runtime.simulation.feasibility", counted)
    with build_simulation(load_scenario(SCENARIOS_DIR / "grasp_com.yaml")) as sim:
        before = {e.uid: e for e in sim.feasibility()}
        for _ in range(3):
            sim.step()
        table = sim.constraints
        reachable = next(uid for uid, e in before.items() if e.reachable and e.checked)
        row = int(table.rows_of(np.array([reachable]))[0])
        owner = int(table.owner[row])
        near = tuple(table.target_world[row])
        far = tuple(sim.store.positions[owner, 0] + (5.0, 0.0, 0.0))
        asked.clear()
        sim.say_unreachable()  # nothing changed since the estimate: nothing estimated again
        assert asked == [[]]
        sim.set_target(reachable, far)
        sim.say_unreachable()
        sim.say_unreachable()
        assert asked[1:] == [[row], []]
        said = [m for m in sim.messages if before[reachable].constraint in m]
        (full,) = [e for e in estimate(sim) if e.uid == reachable]
        assert len(said) == 1 and said[0].endswith(full.line) and "cannot reach" in full.line
        assert reachable in sim.unreachable()
        assert sim.unreachable() == {e.uid for e in estimate(sim) if not e.reachable}
        sim.set_target(reachable, near)
        sim.say_unreachable()
        assert reachable not in sim.unreachable()
        sim.set_target(reachable, far)
        sim.say_unreachable()
        assert len([m for m in sim.messages if before[reachable].constraint in m]) == 2


def test_the_estimate_of_some_constraints_is_the_full_ones() -> None:
    """``feasibility(sim, rows)`` (what say_unreachable asks) gives, for those rows, what every
    constraint's estimate gives them: body targets, self targets and keep-out areas of the
    fight, at the start and mid-kick (to 1e-12 m; the same lines)."""
    with build_simulation(load_scenario(SCENARIOS_DIR / "fight_training.yaml")) as sim:
        for ticks in (0, 30):
            for _ in range(ticks):
                sim.step()
            full = feasibility(sim)
            for rows in [np.array([k]) for k in range(len(full))] + [np.arange(len(full))[::-3]]:
                some = feasibility(sim, rows)
                assert [e.line for e in some] == [full[k].line for k in rows]
                np.testing.assert_allclose([e.short_m for e in some],
                                           [full[k].short_m for k in rows], rtol=0, atol=1e-12)


def test_a_body_change_estimates_again_the_constraints_on_or_at_that_body(monkeypatch) -> None:
    """set_body: the constraints its character owns or aims at are estimated again, the others
    keep their estimate; a second say with nothing changed estimates nothing."""
    asked: list[list[int]] = []

    def counted(sim, constraints=None):
        asked.append(list(constraints) if constraints is not None else [-1])
        return feasibility(sim, constraints)

    monkeypatch.setattr("ecs_anim.runtime.simulation.feasibility", counted)
    with build_simulation(load_scenario(SCENARIOS_DIR / "fight_training.yaml")) as sim:
        sim.feasibility()
        kicker = sim.entity("kicker_2")
        row, table = sim.row(kicker), sim.constraints
        involved = np.flatnonzero((table.owner == row) | ((table.target_kind != TARGET_WORLD)
                                                          & (table.target_row == row)))
        asked.clear()
        sim.set_body(kicker, Morphology.from_stature(1.2))
        sim.say_unreachable()
        assert asked == [involved.tolist(), []] and 0 < involved.size < table.m
        assert sim.unreachable() == {e.uid for e in feasibility(sim) if not e.reachable}
