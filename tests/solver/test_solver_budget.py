"""The solver's frame budget (issue 13 item 5): driven by a fixed cost model, so every number is
the model's, never the clock's; the cut solve equals the numpy reference's."""

from __future__ import annotations

import numpy as np
import pytest

from conftest import REPO
from ecs_anim.components import MotionPlayer, Placement
from ecs_anim.core.errors import EcsAnimError
from ecs_anim.core.morphology import Morphology
from ecs_anim.core.skeleton import JOINT_INDEX as J
from ecs_anim.runtime.simulation import Simulation
from ecs_anim.solver.budget import SolverCostModel
from ecs_anim.solver.shell import SolverSettings
from support.solve import Capture, assert_same_solve

ONE_MS = SolverCostModel(ms_per_iteration=1.0)
ADULT = Morphology.preset("adult_male")


def four_reachers(idle, settings, elbow_only=(), ticks=1):
    """Four adults 2 m apart along y, each with a reachable wrist target (priority 10) or, for
    the rows in ``elbow_only``, an elbow target (priority 1) instead; returns the simulation
    and the entities, after ``ticks`` ticks."""
    sim = Simulation({"idle": idle}, solver_settings=settings)
    entities = []
    for i in range(4):
        e = sim.spawn(f"c{i}", ADULT, MotionPlayer("idle"), Placement((0.0, 2.0 * i)))
        entities.append(e)
        if i in elbow_only:
            sim.add_constraint(e, "elbow", "elbow_r", 1, target_in_world=(0.1, 2.0 * i - 0.35, 1.0))
        else:
            sim.add_constraint(e, "reach", "wrist_r", 10, target_in_world=(0.4, 2.0 * i - 0.3, 1.1))
    for _ in range(ticks):
        sim.step()
    return sim, entities


def test_no_budget_cuts_nothing(idle):
    sim, _ = four_reachers(idle, SolverSettings(cost_model=ONE_MS))
    report = sim.solver_report()
    assert report is not None and not report.cut
    assert report.budget_ms is None and report.model is None and np.isnan(report.expected_ms)
    assert report.characters == 4 and set(report.errors) == {10.0}
    assert report.errors[10.0].count == 4 and report.errors[10.0].max_error_m < 1e-4


def test_the_lowest_priority_is_cut_first(idle):
    """The first tick expects 6 iterations of each of 4 characters: 24 ms at 1 ms each. A 16 ms
    budget cuts the elbows (priority 1; the only goal of two characters) to 2 iterations:
    2 x 6 + 2 x 2 = 16 ms; the wrists (priority 10) keep theirs."""
    settings = SolverSettings(budget_ms=16.0, cost_model=ONE_MS)
    sim, _ = four_reachers(idle, settings, elbow_only=(0, 1))
    report = sim.solver_report()
    assert report is not None and report.cut
    assert report.expected_ms == 24.0 and report.cut_ms == 16.0
    assert report.priority_iterations == {1.0: 2} and report.cut_characters == ()
    assert report.errors[1.0].cut == 2 and report.errors[10.0].cut == 0
    assert report.errors[10.0].max_error_m < 1e-3  # the top priority within 1 mm
    # The elbow characters stopped at their cut: the whole tick used at most 2 x 2 + 2 x 6.
    assert report.iterations <= 16


def test_then_the_characters_furthest_from_the_focus(idle):
    """Every goal at one priority: nothing to cut by priority. A 14 ms budget cuts the two
    characters furthest from the focus (beside c0) to one iteration: 24 - 2 x 5 = 14 ms."""
    settings = SolverSettings(budget_ms=14.0, cost_model=ONE_MS, focus_in_world=(0.0, 0.0, 1.0))
    sim, entities = four_reachers(idle, settings)
    report = sim.solver_report()
    assert report is not None
    assert report.priority_iterations == {}
    assert report.cut_characters == (entities[3], entities[2])  # 6 m, then 4 m away
    assert report.expected_ms == 24.0 and report.cut_ms == 14.0
    assert report.errors[10.0].count == 4 and report.errors[10.0].cut == 2
    # One iteration and the final re-aim still meet a reachable wrist: within 1 mm.
    assert report.errors[10.0].max_error_m < 1e-3


def test_the_focus_can_be_moved_between_ticks(idle):
    settings = SolverSettings(budget_ms=14.0, cost_model=ONE_MS)
    sim, entities = four_reachers(idle, settings, ticks=0)
    sim.set_solver_focus((0.0, 6.0, 1.0))  # beside c3: c0 and c1 are cut
    sim.step()
    report = sim.solver_report()
    assert report is not None and report.cut_characters == (entities[0], entities[1])
    with pytest.raises(EcsAnimError, match=r"set_solver_focus: focus_in_world must be a finite"):
        sim.set_solver_focus((float("nan"), 0.0, 0.0))


def test_later_ticks_expect_what_each_character_took_last_tick(idle):
    settings = SolverSettings(budget_ms=100.0, cost_model=ONE_MS)
    sim, _ = four_reachers(idle, settings)
    first = sim.solver_report()
    sim.step()
    second = sim.solver_report()
    assert first is not None and second is not None
    assert first.expected_ms == 24.0 and not second.cut
    assert second.expected_ms == float(first.iterations) < 24.0


def test_the_cut_solve_equals_numpy(idle, monkeypatch):
    """The iteration caps are the same in the compiled solve and the numpy reference."""
    capture = Capture(monkeypatch)
    settings = SolverSettings(budget_ms=14.0, cost_model=ONE_MS, focus_in_world=(0.0, 0.0, 1.0))
    four_reachers(idle, settings, elbow_only=(1,), ticks=3)
    assert len(capture.calls) == 3
    goals = capture.calls[0][2]
    assert goals.row_iterations is not None and goals.row_iterations.min() == 1
    for args in capture.calls:
        assert_same_solve(args)


def test_the_model_is_calibrated_from_measured_times():
    model = SolverCostModel.calibrated(tick_ms=30.0, solve_ms=10.0, iterations=100)
    assert model == SolverCostModel(ms_per_iteration=0.1, fixed_ms=20.0)
    assert model.tick_ms(50) == pytest.approx(25.0)
    assert SolverCostModel.calibrated(30.0, 10.0, 0) is None


def test_without_a_given_model_the_first_tick_cuts_nothing(idle):
    """Nothing measured yet: no model, no cut; a whole tick measured between the first two
    solves, the third tick cuts by that model."""
    sim, _ = four_reachers(idle, SolverSettings(budget_ms=1e-6), ticks=2)
    second = sim.solver_report()
    assert second is not None and second.model is None and not second.cut
    sim.step()
    third = sim.solver_report()
    assert third is not None and third.model is not None and third.cut
    assert third.model.ms_per_iteration > 0 and third.cut_ms < third.expected_ms


def test_bad_budget_settings_say_what():
    with pytest.raises(ValueError, match=r"budget_ms must be a positive number of milliseconds or None, got -1"):
        SolverSettings(budget_ms=-1)
    with pytest.raises(ValueError, match=r"ms_per_iteration must be a positive number, got 0"):
        SolverCostModel(ms_per_iteration=0)


def test_the_readme_budget_example_runs(capsys, monkeypatch):
    """docs/quickstart.md's frame-budget example (the third "From Python" block), as written
    there."""
    text = (REPO / "docs" / "quickstart.md").read_text(
        encoding="utf-8")
    section = text.split("## From Python", 1)[1].split("\n## ", 1)[0]
    block = section.split("```python\n")[3].split("```", 1)[0]
    monkeypatch.chdir(REPO)
    exec(compile(block, "docs/quickstart.md", "exec"), {})
    assert capsys.readouterr().out.splitlines() == [
        "expected 24 ms, cut to 14 ms; priorities cut {1.0: 1}; characters cut ['c3', 'c2']",
        "priority 10: 4 constraints, 2 cut, largest error under 1 mm: True"]


def test_pelvis_is_where_distances_are_measured():
    from ecs_anim.solver.shell import focus_distances

    positions = np.zeros((2, len(J), 3))
    positions[1, J["pelvis"]] = (3.0, 4.0, 1.0)
    np.testing.assert_allclose(focus_distances(positions, (0.0, 0.0, 1.0)), [1.0, 5.0])
    np.testing.assert_array_equal(focus_distances(positions, None), [0.0, 0.0])
