"""The frame budget's last resort: characters played, grounded and posed every k-th tick
(:mod:`ecs_anim.runtime.update_rate`). The rate's model is given (``UpdateRate.given``), as the
solve's is (``SolverSettings.cost_model``), so the cut does not depend on the machine."""

from __future__ import annotations

import dataclasses
import itertools
from pathlib import Path

import numpy as np
import pytest

from ecs_anim import (
    Morphology,
    MotionPlayer,
    Placement,
    Simulation,
    SolverSettings,
    Stairs,
    import_bvh,
)
from ecs_anim.runtime import kernels
from ecs_anim.runtime.bench_scene import BenchScene
from ecs_anim.runtime.metrics import MetricsRecorder
from ecs_anim.runtime.update_rate import CALM_TICKS, UPDATE_INTERVALS, intervals_by_rank
from ecs_anim.solver.budget import SolverCostModel, solve_intervals

REPO = Path(__file__).resolve().parents[2]
#: Characters of the scenes below (walkers on bumps, in lanes 1.5 m apart: none touches another).
N = 12


def _scene(budget_ms: float | None, constrained: bool = False) -> BenchScene:
    scene = BenchScene(N, constrained=constrained, budget_ms=budget_ms)
    if not scene.sim.compiled:
        pytest.skip("the update rate works on the compiled kernels (they compile aside here)")
    return scene


def test_intervals_by_rank_gives_each_tier_its_size_nearest_first():
    rng = np.random.default_rng(7)
    key = rng.uniform(0.0, 50.0, 1000)
    tiers = solve_intervals(1000, 300.0, UPDATE_INTERVALS)
    tiers[tiers == 0] = UPDATE_INTERVALS[-1]
    interval = intervals_by_rank(key, tiers)
    for every in UPDATE_INTERVALS:  # as many at each interval as the tiers say
        assert (interval == every).sum() == (tiers == every).sum()
    for faster, slower in itertools.pairwise(UPDATE_INTERVALS):
        if (interval == faster).any() and (interval == slower).any():
            assert key[interval == faster].max() <= key[interval == slower].min()
    assert (intervals_by_rank(key, np.ones(1000, np.int64)) == 1).all()


def test_without_a_budget_every_character_is_updated_every_tick():
    scene = _scene(None)
    sim = scene.sim
    sim.update_rate.given = (1.0, 100.0)  # (would rest every one, but there is no budget)
    rows = np.arange(N, dtype=np.int64)
    for _ in range(5):
        scene.tick()
        assert not sim.update_rate.resting and sim.update_rate.counts() == {}
        assert sim.update_rate.due_rows(sim, rows) is rows


def test_resting_characters_keep_their_posture_and_catch_up_with_their_clip():
    """A budget of 10 ms where the rest of the tick takes 6 and an update 1: 4 updates a tick
    for 12 characters. Those not due keep last tick's posture to the bit; every one is updated
    at least every 8th tick, and then is about where the unbudgeted twin is (the same clock:
    the motion sampled where it is then), its soles on the bumps and not sliding."""
    scene, twin = _scene(10.0), _scene(None)
    sim = scene.sim
    sim.update_rate.given = (1.0, 6.0)
    metrics = MetricsRecorder(sim)
    scene.tick()
    twin.tick()
    metrics.record()
    last_updated = np.zeros(N, np.int64)
    pelvis_mm: list[float] = []
    for tick in range(1, 41):
        before = sim.store.positions.copy()
        scene.tick()
        twin.tick()
        metrics.record()
        rate = sim.update_rate
        assert rate.resting
        due = np.flatnonzero(rate.updated)
        assert 0 < due.size < N and sum(rate.counts().values()) > 0
        resting = np.setdiff1d(np.arange(N), due)
        assert np.array_equal(sim.store.positions[resting], before[resting])
        assert not np.array_equal(sim.store.positions[due], before[due])
        last_updated[due] = tick
        assert (tick - last_updated < UPDATE_INTERVALS[-1]).all()
        # the clocks run on for every character
        np.testing.assert_array_equal(sim.store.clip_time_s, twin.sim.store.clip_time_s)
        pelvis_mm.extend(np.linalg.norm(
            sim.store.positions[due, 0] - twin.sim.store.positions[due, 0], axis=1) * 1e3)
    # (a contact begun between two updates is laid where the motion has its sole at the next,
    # after a heel roll maybe: the pelvis follows those legs)
    assert np.median(pelvis_mm) < 1.0 and max(pelvis_mm) < 30.0
    assert np.isfinite(sim.store.positions).all()
    for figures in metrics.report()["characters"]:
        assert figures["floating_mm_max"] < 1.0 and figures["ground_penetration_mm_max"] < 1.0
        assert figures["foot_sliding_mm_per_frame"]["max"] < 1.0
        assert figures["bone_length_error_m_max"] < 1e-6


def test_constraints_come_back_only_once_every_character_is_updated_again():
    """The strict order: the solve's budget drops every character (its given model's floor is
    over the budget), then the update rate rests some; a cheaper model would bring constraints
    back, but not while any character rests, nor for CALM_TICKS ticks after the last did."""
    scene = _scene(10.0, constrained=True)
    sim = scene.sim
    sim.solver_settings = dataclasses.replace(
        sim.solver_settings, cost_model=SolverCostModel(ms_per_iteration=0.01, fixed_ms=12.0))
    sim.update_rate.given = (1.0, 6.0)
    for _ in range(15):  # (the dropped characters go back to their motion first)
        scene.tick()
    report = sim.solver_report()
    assert report is not None and len(report.dropped_characters) == N and report.characters == 0
    assert sim.update_rate.resting and report.update_intervals and report.cut
    sim.solver_settings = dataclasses.replace(
        sim.solver_settings, cost_model=SolverCostModel(ms_per_iteration=0.01, fixed_ms=1.0))
    for _ in range(5):  # the solve's model would have them back; the update rate still rests
        scene.tick()
        report = sim.solver_report()
        assert report is not None and report.characters == 0 and sim.update_rate.resting
    sim.update_rate.given = (0.1, 1.0)  # every update fits: none rests from the next tick
    solved = []
    for _ in range(CALM_TICKS + 2):
        scene.tick()
        report = sim.solver_report()
        assert report is not None and not report.update_intervals
        solved.append(report.characters)
    # the CALM_TICKS-th tick without a rest solves them again
    assert solved == [0] * (CALM_TICKS - 1) + [N] * 3


def test_the_quickstart_update_rate_example_prints_what_it_says(capsys, monkeypatch):
    """docs/quickstart.md's last resort example (the fourth "From Python" block), as written
    there: 2 updates a tick for 8 characters, one every tick, one every 4th, six every 8th."""
    if not kernels.load_kernels():
        pytest.skip("the update rate works on the compiled kernels (they compile aside here)")
    text = (REPO / "docs" / "quickstart.md").read_text(encoding="utf-8")
    section = text.split("## From Python", 1)[1].split("\n## ", 1)[0]
    block = section.split("```python\n")[4].split("```", 1)[0]
    monkeypatch.chdir(REPO)
    exec(compile(block, "docs/quickstart.md", "exec"), {})
    assert capsys.readouterr().out.splitlines() == ["{4: 1, 8: 6} 2 updated this tick"]


def _walkers_facing_a_step(budget_ms: float | None) -> Simulation:
    """8 adults walking along +x, 1.5 m apart, towards a 0.6 m step at x = 2.5 (too tall)."""
    walk = import_bvh(REPO / "scenarios" / "motions" / "walk.bvh")
    sim = Simulation({"walk": walk}, ground=Stairs(rise_m=0.6, run_m=5.0, steps=1, start_m=2.5),
                     solver_settings=SolverSettings(budget_ms=budget_ms))
    if not sim.compiled:
        pytest.skip("the update rate works on the compiled kernels (they compile aside here)")
    for i in range(8):
        sim.spawn(f"w{i}", Morphology.preset("adult_male"), MotionPlayer("walk", loop=True),
                  Placement((0.0, 1.5 * i)))
    return sim


def test_a_resting_walker_stops_at_a_rise_as_the_others_do():
    """Updated every 8th tick, a walker advances 8 ticks' worth at once: still a walk into the
    rise, which stops it in front of it (not on top), as every walker every tick."""
    free, rested = _walkers_facing_a_step(None), _walkers_facing_a_step(5.0)
    rested.update_rate.given = (1.0, 3.0)  # 2 updates a tick for 8: six every 8th tick
    for _ in range(150):
        free.step()
        rested.step()
    assert rested.update_rate.counts().get(8, 0) >= 5
    pelvis_x_free = free.store.positions[:, 0, 0]
    pelvis_x_rested = rested.store.positions[:, 0, 0]
    assert (pelvis_x_free < 2.5).all() and (pelvis_x_rested < 2.5).all(), pelvis_x_rested
    assert (rested.store.positions[:, 0, 2] < 1.2).all()  # (not on the 0.6 m step)


def test_a_recorder_started_while_characters_rest_gets_every_rotation():
    """``sim.record()`` turns joint rotations on: the tick that makes them fills every row,
    those resting too (not the rest pose's identities)."""
    scene = _scene(10.0)
    sim = scene.sim
    sim.update_rate.given = (1.0, 6.0)
    for _ in range(5):
        scene.tick()
    sim.record()
    scene.tick()
    assert sim.update_rate.resting and not sim.update_rate.updated.all()
    identity = np.all(np.abs(sim.store.local_rotations - np.eye(3)) < 1e-12, axis=(2, 3))
    assert not identity.all(axis=1).any()  # (no row left all at the identity)


def test_the_ground_smoothing_is_given_the_ticks_since_each_update(monkeypatch):
    """GroundAdapt's kernel is called per group of rows last updated k ticks ago with k x dt:
    when the rate changes (down to every tick again), the rows that rested catch up."""
    import ecs_anim.systems.ground_adapt as ground_adapt

    calls: list[tuple[np.ndarray, float]] = []
    real = ground_adapt.over_chunks  # type: ignore[attr-defined]

    def spy(kernel, n, rows, *args, **kwargs):
        calls.append((rows.copy(), float(args[12])))  # (the 13th after rows: dt)
        return real(kernel, n, rows, *args, **kwargs)
    monkeypatch.setattr(ground_adapt, "over_chunks", spy)
    scene = _scene(10.0)
    sim = scene.sim
    sim.update_rate.given = (1.0, 6.0)
    last = np.full(N, -1)
    for tick in range(30):
        if tick == 20:
            sim.update_rate.given = (0.1, 1.0)  # every update fits again
        calls.clear()
        scene.tick()
        for rows, dt_s in calls:
            np.testing.assert_allclose(dt_s, (tick - last[rows]) * sim.dt, rtol=1e-12)
        updated = np.concatenate([rows for rows, _ in calls])
        assert np.unique(updated).size == updated.size
        last[updated] = tick
    assert (last == 29).all()


def test_a_constraint_switched_on_while_characters_rest_is_not_solved_on_a_stale_pose():
    """Constraints that switch on at 0.3 s while characters rest: on that tick only the rows
    updated are solved; from the next, no character rests (the solve keeps some)."""
    scene = _scene(10.0, constrained=True)
    sim = scene.sim
    table = sim.constraints
    table.activation[:, 0] = 0.3  # (the wrist and elbow targets: off until then)
    sim.solver_settings = dataclasses.replace(
        sim.solver_settings, cost_model=SolverCostModel(ms_per_iteration=0.01, fixed_ms=1.0))
    sim.update_rate.given = (1.0, 6.0)
    switched_on = round(0.3 / sim.dt)
    for tick in range(switched_on + 3):
        scene.tick()
        report = sim.solver_report()
        if tick < switched_on:
            assert report is None or report.characters == 0
            continue
        if tick == switched_on:
            assert sim.update_rate.resting and report is not None and report.characters > 0
            solved = np.asarray(sim.store.goals.rows)  # type: ignore[attr-defined]
            assert sim.update_rate.updated[solved].all()
        else:
            assert not sim.update_rate.resting


@pytest.mark.parametrize("model", [(float("nan"), 3.0), (0.0, 3.0), (1.0, -1.0), (1.0, float("inf"))])
def test_a_given_model_that_is_not_one_is_refused_in_one_line(model):
    from ecs_anim.core.errors import UsageError
    from ecs_anim.runtime.update_rate import UpdateRate

    rate = UpdateRate()
    with pytest.raises(UsageError, match=r"update_rate.given must be \(ms an update > 0"):
        rate.given = model
    assert rate.given is None
    rate.given = (1, 3)
    assert rate.given == (1.0, 3.0)
