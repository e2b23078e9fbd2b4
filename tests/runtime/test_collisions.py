"""Bodies for collisions (issue 32, items 1-3): capsules, targets on the surface, overlaps."""

from __future__ import annotations

import numpy as np
import pytest

from conftest import SCENARIOS_DIR
from ecs_anim.core.morphology import Morphology
from ecs_anim.core.skeleton import JOINT_INDEX as J
from ecs_anim.core.skeleton import N_JOINTS
from ecs_anim.runtime.kernels.capsules import (
    Capsules,
    bounds,
    capsules,
    closest_between,
    grid_of,
    overlaps,
    touching,
)
from ecs_anim.scenario import load_scenario, measured_run
from ecs_anim.solver.capsules import (
    CAPSULE_INDEX,
    N_CAPSULES,
    capsule_radii,
    capsules_from_positions,
    closest_between_segments,
    surface_points,
)
from support.scenarios import run


def test_compiled_capsules_match_the_numpy_reference():
    rng = np.random.default_rng(3201)
    positions = rng.normal(size=(7, N_JOINTS, 3))
    lengths = np.stack([Morphology.preset(p).lengths for p in
                        ("child", "adult_female", "adult_male", "tall", "child", "tall",
                         "adult_male")])
    ends, radii = capsules_from_positions(positions, lengths)
    body = capsules(positions, lengths)
    np.testing.assert_allclose(body.ends, ends, atol=1e-12)
    np.testing.assert_allclose(body.radii, radii, atol=1e-12)
    assert body.ends.shape == (7, N_CAPSULES, 2, 3)
    # An adult's girths (the module's table): trunk 106 mm, shank 51 mm.
    adult = capsule_radii(Morphology.preset("adult_male").lengths)
    assert adult[CAPSULE_INDEX["trunk"]] == pytest.approx(0.106, abs=2e-3)
    assert adult[CAPSULE_INDEX["shank_r"]] == pytest.approx(0.051, abs=2e-3)


def test_nearest_points_of_two_segments_batch_and_single_agree():
    rng = np.random.default_rng(3202)
    p1, q1, p2, q2 = rng.normal(size=(4, 50, 3))
    q1[0] = p1[0]  # a degenerate segment: a point
    a, b = closest_between_segments(p1, q1, p2, q2)
    for k in range(50):
        sa, sb = closest_between(tuple(p1[k]), tuple(q1[k]), tuple(p2[k]), tuple(q2[k]))
        np.testing.assert_allclose(sa, a[k], atol=1e-12)
        np.testing.assert_allclose(sb, b[k], atol=1e-12)
    # Crossing segments: the nearest points are where they cross.
    a, b = closest_between_segments(np.array([[-1.0, 0, 0]]), np.array([[1.0, 0, 0]]),
                                    np.array([[0.0, -1, 0.2]]), np.array([[0.0, 1, 0.2]]))
    np.testing.assert_allclose(a, [[0, 0, 0]], atol=1e-12)
    np.testing.assert_allclose(b, [[0, 0, 0.2]], atol=1e-12)


def test_a_target_on_a_capsule_goes_out_to_its_surface_square_to_the_axis():
    axis_a, axis_b = np.array([[0.0, 0, 1.0]]), np.array([[0.0, 0, 1.5]])
    target = np.array([[0.0, 0, 1.2]])
    # The effector comes from in front and below: the goal is square to the axis, 0.16 m out.
    goal = surface_points(target, axis_a, axis_b, np.array([0.16]), np.array([[0.8, 0, 0.9]]))
    np.testing.assert_allclose(goal, [[0.16, 0, 1.2]], atol=1e-12)


def _grid_free_overlap(ends, radii):
    n = ends.shape[0]
    depth = np.zeros(n)
    for i in range(n):
        for j in range(n):
            if i == j:
                continue
            a, b = closest_between_segments(
                np.repeat(ends[i, :, None, 0], N_CAPSULES, 1), np.repeat(ends[i, :, None, 1], N_CAPSULES, 1),
                np.repeat(ends[j, None, :, 0], N_CAPSULES, 0), np.repeat(ends[j, None, :, 1], N_CAPSULES, 0))
            d = radii[i, :, None] + radii[j, None, :] - np.linalg.norm(a - b, axis=-1)
            depth[i] = max(depth[i], d.max())
    return depth


def test_the_grid_finds_every_overlap_a_search_of_all_pairs_finds():
    rng = np.random.default_rng(3203)
    n = 40
    standing = np.zeros((N_JOINTS, 3))
    lengths = np.tile(Morphology.preset("adult_male").lengths, (n, 1))
    # A crude standing body: joints scattered about the pelvis within a body's size.
    standing = rng.normal(scale=0.25, size=(n, N_JOINTS, 3))
    standing[:, J["pelvis"]] = 0.0
    spots = rng.uniform(0, 4.0, size=(n, 3)) * [1, 1, 0]
    body = capsules(standing + spots[:, None], lengths)
    found = overlaps(body)
    np.testing.assert_allclose(found.depth, _grid_free_overlap(body.ends, body.radii), atol=1e-12)
    assert (found.depth > 0).sum() > 5
    hit = np.flatnonzero(found.depth > 0)
    assert np.all(found.other[hit] >= 0) and np.all(found.other[hit] != hit)
    np.testing.assert_allclose(np.linalg.norm(found.normal[hit], axis=1), 1.0)


def _scattered_adults(rng: np.random.Generator, n: int
                      ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``n`` adult males' lengths (n, lengths), random joints about each pelvis (n, joints, 3)
    and spots (n, 3) on the ground within 9 m: a crowd some of whose bodies meet."""
    lengths = np.tile(Morphology.preset("adult_male").lengths, (n, 1))
    standing = rng.normal(scale=0.25, size=(n, N_JOINTS, 3))
    standing[:, J["pelvis"]] = 0.0
    return lengths, standing, rng.uniform(0, 9.0, size=(n, 3)) * [1, 1, 0]


def test_the_search_over_the_bodies_that_touch_finds_what_a_search_of_all_finds():
    """CollisionSeparate searches only the bodies whose bounds meet another's (bounds from the
    joints, no capsule made: wider than the capsules'), the capsules made for those alone: the
    same overlaps as a search of every body with every capsule's bounds, and the bodies left
    out overlap no one."""
    rng = np.random.default_rng(3204)
    n = 60
    lengths, standing, spots = _scattered_adults(rng, n)
    positions = standing + spots[:, None]
    every = overlaps(capsules(positions, lengths))
    body = bounds(positions, lengths, Capsules.empty(n))
    every_box = capsules(positions, lengths).box
    assert np.all(body.box[:, 0] <= every_box[:, 0]) and np.all(body.box[:, 1] >= every_box[:, 1])
    for unmade in (body.ends, body.radii, body.capsule_box):  # never read for a body that
        unmade[:] = np.nan  # touches no one
    grid = grid_of(body)
    near = touching(body, grid)
    capsules(positions, lengths, body, near)
    found = overlaps(body, grid, near)
    assert 5 < near.size < n, near.size
    assert (every.depth > 0).sum() > 3
    for name in every._fields:
        np.testing.assert_array_equal(getattr(found, name), getattr(every, name), err_msg=name)


def test_the_bounds_are_the_joints_least_and_most_widened_by_the_widest_radius():
    """``bounds`` (each body's joints read two at a time, its radii two capsules at a time,
    each a running least or most folded at the end) gives the bits of one running
    least and most over the joints in order and over the radii: a NaN joint or radius skipped
    (a body all NaN unbounded: infinite corners), a zero's sign lost once the radius is added;
    on 1 and 2 threads, in two chunks of rows, and with an odd count of joints."""
    from ecs_anim.runtime import kernels
    from ecs_anim.runtime.kernels.capsules import (
        BOUND_HAIR_M,
        WIDEST_TERMS,
        WIDEST_WEIGHTS,
        bound_rows,
    )

    rng = np.random.default_rng(3207)
    n = 40
    lengths, standing, spots = _scattered_adults(rng, n)
    positions = standing + spots[:, None]
    lengths = lengths * rng.uniform(0.8, 1.2, size=(n, 1))
    positions[1, 5] = np.nan  # one joint not posed
    positions[2, :, 0] = np.nan  # one axis of every joint
    positions[3] = np.nan  # a body not posed
    positions[4, 7:, 1] = -0.0  # zeros of both signs on one axis
    positions[4, :7, 1] = 0.0
    positions[5, -1] = [-50.0, 50.0, -50.0]  # the last joint the widest
    lengths[6, WIDEST_TERMS[5, 1]] = np.nan  # a radius NaN (its weight 0 elsewhere: 0 x NaN)
    lengths[7] = np.nan  # every radius NaN: only the hair
    lengths[8] = 0.0  # zero lengths
    def least_and_most(joints):
        """The reference: one running least and most over ``joints`` (n, J, 3) in order
        (min(a, v) keeps a unless v < a)."""
        low, high = np.full((n, 3), np.inf), np.full((n, 3), -np.inf)
        for j in range(joints.shape[1]):
            v = joints[:, j]
            low, high = np.where(v < low, v, low), np.where(v > high, v, high)
        return low, high

    low, high = least_and_most(positions)
    terms = lengths[:, WIDEST_TERMS] * WIDEST_WEIGHTS  # (n, C, 3)
    radii = terms[..., 0] + terms[..., 1] + terms[..., 2]
    widest = np.zeros(n)
    for k in range(N_CAPSULES):
        widest = np.where(radii[:, k] > widest, radii[:, k], widest)
    widest += BOUND_HAIR_M
    expected = np.stack([low - widest[:, None], high + widest[:, None]], axis=1)
    assert np.isinf(expected[3]).all() and np.isfinite(expected[7]).all()
    try:
        for count in range(1, min(2, kernels.available_threads()) + 1):
            kernels.set_threads(count)
            body = bounds(positions, lengths, Capsules.empty(n))
            np.testing.assert_array_equal(body.box, expected, err_msg=f"{count} threads")
            np.testing.assert_array_equal(body.centre, positions[:, 0])
    finally:
        kernels.set_threads(None)
    split = Capsules.empty(n)
    for lo, hi in ((0, 13), (13, n)):
        bound_rows(lo, hi, positions, lengths, split.centre, split.box)
    np.testing.assert_array_equal(split.box, expected)
    odd_joints = np.ascontiguousarray(positions[:, :N_JOINTS - 1])  # the last read twice
    odd = Capsules.empty(n)
    bound_rows(0, n, odd_joints, lengths, odd.centre, odd.box)
    low, high = least_and_most(odd_joints)
    np.testing.assert_array_equal(odd.box, np.stack([low - widest[:, None],
                                                     high + widest[:, None]], axis=1))


@pytest.mark.parametrize("apart", [False, True])  # some bounds meet; none do
def test_the_search_measures_gaps_only_when_asked_and_they_are_the_least(apart):
    """``touching`` without a clearance (no gap measured) marks the bodies it marks with one;
    with one, where no two bounds meet, each body's clearance is its least gap to another's
    bounds (the largest of the axes' gaps), at most the gap the grid's cells guarantee."""
    from ecs_anim.runtime.kernels.capsules import CELL_SLACK

    rng = np.random.default_rng(3205)
    n = 60
    lengths, standing, spots = _scattered_adults(rng, n)
    if apart:  # on a grid 5 m apart, each within 1 m of its point
        spots = np.stack([5.0 * (np.arange(n) // 8), 5.0 * (np.arange(n) % 8),
                          np.zeros(n)], axis=1) + rng.uniform(0, 1.0, size=(n, 3)) * [1, 1, 0]
    positions = standing + spots[:, None]
    body = bounds(positions, lengths, Capsules.empty(n))
    grid = grid_of(body)
    clearance = np.full(n, np.nan)
    near = touching(body, grid, clearance)
    np.testing.assert_array_equal(touching(body, grid), near)
    if apart:
        assert near.size == 0
        low, high = body.box[:, 0], body.box[:, 1]
        gap = np.maximum(low[None] - high[:, None], low[:, None] - high[None]).max(axis=2)
        np.fill_diagonal(gap, np.inf)
        least = np.minimum(gap.min(axis=1), grid.cell_m * (1.0 - 1.0 / CELL_SLACK))
        np.testing.assert_allclose(clearance, least, rtol=0, atol=1e-12)
    else:
        assert 5 < near.size < n, near.size


@pytest.mark.parametrize("crowd", ["compact", "far", "beyond"])
def test_the_cells_laid_out_by_column_find_what_the_hashed_cells_find(crowd):
    """``grid_of`` lays a crowd's cells out column by column where they fit in the table (the
    compact crowd, across the origin: negative cells), else hashes them as before (a body 30 km
    off, and one not posed: 1 km apart off the plane; a body 1e20 m off, its cell past what an
    integer holds, where a layout's extent would wrap round): the marks, clearances, bodies near
    and overlaps are those of the same bodies on the hashed table, overlaps on 1 and 2 threads."""
    from ecs_anim.runtime import kernels
    from ecs_anim.runtime.kernels.avoidance import build_grid
    from ecs_anim.runtime.kernels.capsules import near_rows

    rng = np.random.default_rng(3206)
    n = 60
    lengths, standing, spots = _scattered_adults(rng, n)
    positions = standing + (spots - [4.5, 4.5, 0.0])[:, None]
    if crowd == "far":
        positions[3] += [3e4, -2e4, 0.0]
        positions[7] = np.nan
    if crowd == "beyond":
        positions[3] += [-1e20, 0.0, 0.0]
    body = bounds(positions, lengths, Capsules.empty(n))
    grid = grid_of(body)
    assert (grid.column_cells > 0) == (crowd == "compact")
    slot, order = np.empty(n, np.int64), np.empty(n, np.int64)
    start = np.empty(grid.mask + 2, np.int64)
    build_grid(grid.plane, grid.cell_m, grid.mask, slot, start, order)
    hashed = grid._replace(origin_x=0, origin_y=0, column_cells=0, start=start, order=order)
    laid, kept = np.empty(n), np.empty(n)
    near = touching(body, grid, laid)
    np.testing.assert_array_equal(near, touching(body, hashed, kept))
    np.testing.assert_array_equal(laid, kept)
    np.testing.assert_array_equal(near, touching(body, grid))
    assert 5 < near.size < n, near.size
    np.testing.assert_array_equal(near_rows(body, grid, near[:4]),
                                  near_rows(body, hashed, near[:4]))
    capsules(positions, lengths, body, near)
    try:
        for count in range(1, min(2, kernels.available_threads()) + 1):
            kernels.set_threads(count)
            found, expected = overlaps(body, grid, near), overlaps(body, hashed, near)
            assert (found.depth > 0).sum() > 3
            for name in found._fields:
                np.testing.assert_array_equal(getattr(found, name), getattr(expected, name),
                                              err_msg=f"{name}, {count} threads")
    finally:
        kernels.set_threads(None)


def test_the_fights_kicks_land_on_the_chest_not_in_it():
    r = run("fight_training")
    e, w, idx, pos = r["errors"], r["weights"], r["index"], r["positions"]
    for pair in (1, 2, 3, 4):
        k, d = r["names"].index(f"kicker_{pair}"), r["names"].index(f"defender_{pair}")
        lengths = r["lengths"]
        shank = capsule_radii(lengths[k])[CAPSULE_INDEX["shank_r"]]
        trunk = capsule_radii(lengths[d])[CAPSULE_INDEX["trunk"]]
        a, b = pos[:, d, J["pelvis"]], pos[:, d, J["neck"]]
        ankle = pos[:, k, J["ankle_r"]]
        t = np.clip(np.sum((ankle - a) * (b - a), 1) / np.sum((b - a) ** 2, 1), 0, 1)
        to_axis = np.linalg.norm(ankle - (a + t[:, None] * (b - a)), axis=1)
        # never closer than its own radius; while the kick is fully on, at the chest's surface
        # (its shank's radius and the trunk's from the axis) as the defender stood last tick:
        # within 30 mm of it as the defender stands now (its ward-off turns its trunk)
        kick = idx[f"kicker_{pair}.kick_torso"]
        full = w[:, kick] >= 1
        assert to_axis.min() > shank, (pair, to_axis.min(), shank)
        assert to_axis[full].min() > shank + trunk - 0.03, (pair, to_axis[full].min())
        if pair < 4:  # pair 4's kicker cannot reach
            assert np.nanmax(e[full, kick]) < 1e-4  # 0.0 mm to the surface
    for c in r["report"]["characters"]:
        # kick, ward-off and punch meet on the surfaces: 44-93 mm deep before each chain that
        # aims at a body could go out to its surface
        assert c["overlap_mm_max"] <= 10.0, c


def test_a_two_against_two_fight_of_a_small_and_a_tall_body_touches_without_overlap():
    """The fight's first two pairs, its first kicker 1.1 m tall (a child's proportions), its
    second defender 2.1 m: the kicks, ward-offs and punches meet on the surfaces (before, 61 and
    102 mm deep), the feet stay planted."""
    scenario = load_scenario(SCENARIOS_DIR / "fight_training.yaml")
    scenario.characters = scenario.characters[:4]
    scenario.characters[0].morphology = Morphology.from_stature(1.1, proportions="child")
    scenario.characters[3].morphology = Morphology.from_stature(2.1)
    scenario.triggers = [t for t in scenario.triggers if t.name.endswith(("_1", "_2"))]
    report = measured_run(scenario)
    for c in report["characters"]:
        assert c["overlap_mm_max"] <= 10.0, c
        assert c["foot_sliding_mm_per_frame"]["max"] < 1.0, c
        assert c["ground_penetration_mm_max"] < 1.0, c
        assert c["floating_mm_max"] < 1.0, c
    errors = {(k["character"], k["name"]): k["error_mm_max_fully_active"]
              for k in report["constraints"]}
    # the 1.1 m kicker cannot reach; the 1.75 m one lands on the 2.1 m chest
    assert errors[("kicker_2", "kick_torso")] < 0.1
    assert errors[("defender_1", "ward_off")] < 0.1 and errors[("defender_2", "ward_off")] < 0.1


def test_stuck_pairs_are_reported_once_each_a_line_a_round_naming_the_first_three():
    """Walkers on the bench's grid ignore each other: many pairs end in each other with both
    feet planted (neither may move). Each pair is reported once; a round's new pairs make one
    line naming at most three and counting the rest (a line each buried the output)."""
    import re

    from ecs_anim.runtime.bench_scene import walkers_on_bumps
    from ecs_anim.systems.collision_separate import STUCK_NAMED, CollisionSeparate

    sim, _ = walkers_on_bumps(200)
    with sim:
        for _ in range(30):
            sim.step()
        separate = next(s for s in sim.systems if isinstance(s, CollisionSeparate))
        lines = [m for m in sim.messages if "neither may move" in m]
    counted = 0
    for line in lines:
        many = re.search(r": (\d+) pairs overlap where neither may move: (.*)$", line)
        if many is None:
            assert re.search(r"'s \w+ and .*'s \w+ overlap by \d+ mm and neither may move$", line)
            counted += 1
            continue
        k = int(many.group(1))
        named = many.group(2).split("; ")
        assert len(named) == min(k, STUCK_NAMED), line
        assert (k > STUCK_NAMED) == named[-1].endswith(f"and {k - STUCK_NAMED} more"), line
        counted += k
    assert counted == len(separate.reported) > STUCK_NAMED
    assert len(lines) < counted  # some lines name several pairs


def test_the_frame_budget_ends_the_rounds_of_separation():
    """The bench's crossing walkers overlap: without a budget the rounds go on while they help
    (several a tick); with one, a clock that says every round costs a second ends them after
    the first (which always runs), and says so."""
    from itertools import count

    from ecs_anim.runtime.bench_scene import walkers_on_bumps
    from ecs_anim.solver.shell import SolverSettings
    from ecs_anim.systems.collision_separate import CollisionSeparate

    sim, _ = walkers_on_bumps(200)
    with sim:
        separate = next(s for s in sim.systems if isinstance(s, CollisionSeparate))
        free = []
        for _ in range(10):
            sim.step()
            free.append((separate.rounds, separate.rounds_cut))
        assert max(r for r, _ in free) > 1 and not any(cut for _, cut in free)
        sim.solver_settings = SolverSettings(budget_ms=33.0)
        seconds = count()
        separate.clock = lambda: float(next(seconds))
        capped = []
        for _ in range(10):
            sim.step()
            capped.append((separate.rounds, separate.rounds_cut))
        assert {r for r, _ in capped} == {1} and all(cut for _, cut in capped)



def _assert_capsules_of_the_bodies_that_touch(st) -> np.ndarray:
    """The store's capsules are those of the bodies whose bounds meet another's (to 1e-12 m),
    NaN for the others, which overlap nobody; returns the rows made (n,) bool."""
    made = np.isfinite(st.capsule_radii).all(axis=1)
    assert np.array_equal(np.isnan(st.capsule_ends).all(axis=(1, 2, 3)), ~made)
    ends, radii = capsules_from_positions(st.positions[made], st.lengths[made])
    np.testing.assert_allclose(st.capsule_ends[made], ends, rtol=0, atol=1e-12)
    np.testing.assert_allclose(st.capsule_radii[made], radii, rtol=0, atol=1e-12)
    # a body left out: its capsules' bounds meet no other body's capsules' bounds
    every = capsules(st.positions, st.lengths)
    low, high = every.box[:, 0], every.box[:, 1]
    meets = np.logical_not(((high[:, None] < low[None])
                            | (high[None] < low[:, None])).any(axis=-1))
    np.fill_diagonal(meets, False)
    assert not meets[~made].any()
    assert not (st.overlap_m[~made] > 0).any()
    return made


def test_the_store_holds_the_capsules_of_the_bodies_that_touch_and_nan_for_the_others():
    """CollisionSeparate makes capsules only for the bodies whose bounds meet another's: their
    rows of ``store.capsule_ends`` and ``capsule_radii`` are the capsules of their postures as
    the tick ends; the rows of a body whose bounds meet no one's are NaN, every tick (a crowd
    that ignores itself: bodies meet and part)."""
    from ecs_anim.runtime.bench_scene import walkers_on_bumps

    sim, _ = walkers_on_bumps(30, crossing=True)
    made_ever = set()
    with sim:
        for _ in range(12):
            sim.step()
            made = _assert_capsules_of_the_bodies_that_touch(sim.store)
            made_ever |= set(np.flatnonzero(made).tolist())
    assert 0 < len(made_ever) < 30, made_ever


def test_the_capsules_kept_follow_their_bodies_when_characters_are_removed():
    """Removing characters renumbers the rows: the capsules kept from the last tick are those of
    the bodies that stay (the viewer's Delete, a removal mid-run), never a row that is gone."""
    from ecs_anim.runtime.bench_scene import walkers_on_bumps

    sim, _ = walkers_on_bumps(30, crossing=True)
    with sim:
        st = sim.store
        for _ in range(4):
            sim.step()
        made = _assert_capsules_of_the_bodies_that_touch(st)
        # every body with capsules goes, and the last half of the others: the rows kept hold
        # none, and fewer rows stay than the highest row that had capsules
        apart = np.flatnonzero(~made)
        gone = np.concatenate([np.flatnonzero(made), apart[apart.size // 2:]])
        for entity in st.entity[gone].tolist():
            sim.remove(entity)
        assert 0 < st.n <= np.flatnonzero(made).max()
        assert np.isnan(st.capsule_radii).all()
        for _ in range(4):
            sim.step()
            _assert_capsules_of_the_bodies_that_touch(sim.store)


@pytest.mark.parametrize(("crossing", "least_skips"), [(False, 5), (True, 1)])
def test_the_ticks_that_skip_the_grid_while_no_bounds_meet_end_as_a_search_would(crossing,
                                                                                  least_skips):
    """While no two bodies' bounds meet, a tick whose bounds each moved less than half their
    clearance skips the grid: postures, overlaps and the store's capsules equal those of the
    same crowd searched on the grid every tick, walkers in lanes (that never meet) and
    crossing (that meet and part), and the skip is tried."""
    from ecs_anim.runtime.bench_scene import walkers_on_bumps
    from ecs_anim.systems.collision_separate import CollisionSeparate

    (skipping, _), (searching, _) = (walkers_on_bumps(16, crossing=crossing) for _ in range(2))
    with skipping, searching:
        mine, every = (next(s for s in sim.systems if isinstance(s, CollisionSeparate))
                       for sim in (skipping, searching))
        skipped = 0
        for _ in range(40):
            skipped += mine._apart is not None
            every._apart = None
            skipping.step()
            searching.step()
            a, b = skipping.store, searching.store
            np.testing.assert_array_equal(a.positions, b.positions)
            np.testing.assert_array_equal(a.overlap_m, b.overlap_m)
            np.testing.assert_array_equal(a.capsule_ends, b.capsule_ends)
    assert skipped >= least_skips, skipped


def test_a_tick_whose_bounds_parted_after_meeting_searches_again_for_the_clearances(
        monkeypatch):
    """Bounds that met last tick likely meet now, so the search measures no gap; when none
    meet after all, it searches again with the gaps: the bounds and half of each body's
    clearance are kept (``_apart``), finite, equal to those of a search with gaps on the same
    joints (``touching`` with a clearance: each body's least gap)."""
    from ecs_anim.runtime.bench_scene import walkers_on_bumps
    from ecs_anim.systems.collision_separate import CollisionSeparate

    sim, _ = walkers_on_bumps(16, crossing=True)
    with sim:
        mine = next(s for s in sim.systems if isinstance(s, CollisionSeparate))
        seen: list[tuple[np.ndarray, np.ndarray]] = []
        run_once = mine.run

        def run_recording(dt):
            seen.append((sim.store.positions.copy(), sim.store.lengths.copy()))
            run_once(dt)

        monkeypatch.setattr(mine, "run", run_recording)
        met_last = parted = False
        for _ in range(120):
            sim.step()
            if met_last and mine._apart is not None:
                parted = True
                break
            met_last = sim.compiled and mine._apart is None  # (on the kernels: bounds met)
    assert parted
    positions, lengths = seen[-1]
    body = bounds(positions, lengths, Capsules.empty(positions.shape[0]))
    clearance = np.full(positions.shape[0], np.nan)
    assert touching(body, grid_of(body), clearance).size == 0
    assert mine._apart is not None
    _, box, slack = mine._apart
    assert np.isfinite(slack).all() and (slack > 0).all()
    np.testing.assert_array_equal(box, body.box)
    np.testing.assert_array_equal(slack, 0.5 * clearance)
