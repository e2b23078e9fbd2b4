"""Compiled ground heights equal the numpy grounds (every kind, and combinations), and the
compiled GroundAdapt equals its numpy reference on terrain scenes."""

from dataclasses import dataclass

import numpy as np
import pytest

from conftest import shipped_motion
from ecs_anim.components import MotionPlayer, Placement, QueuedClip
from ecs_anim.core.ground import (
    Bumps,
    Combined,
    Ground,
    HeightGrid,
    Plane,
    Slope,
    Stairs,
    describe,
)
from ecs_anim.core.morphology import Morphology
from ecs_anim.core.normalized import QUATERNION_FIELDS
from ecs_anim.runtime.kernels.ground import (
    NEAR_M,
    SINE_DOMAIN,
    height_at,
    height_near,
    sine,
    smooth,
)
from ecs_anim.runtime.simulation import Simulation
from ecs_anim.systems import GroundAdapt


def _grid(seed: int) -> HeightGrid:
    rng = np.random.default_rng(seed)
    return HeightGrid(rng.uniform(-0.2, 0.3, (7, 11)), 0.45, -1.3, 0.7)


GROUNDS: dict[str, Ground] = {
    "plane": Plane(0.12),
    "slope": Slope(0.08, -0.05, 0.3),
    "stairs": Stairs(rise_m=0.13, run_m=0.31, steps=5, start_m=0.4, heading_deg=37.0, z_m=0.02),
    "bumps": Bumps(0.04, 2.3, 1.7, -0.01),
    "grid": _grid(3),
    "combined": Combined((Bumps(0.03, 2.5, 3.0), Stairs(0.12, 0.40, 6, 5.0))),
    "nested": Combined((_grid(5), Combined((Slope(0.02, 0.01), _grid(6))), Plane(-0.1))),
}


def _compiled(ground: Ground, xy: np.ndarray) -> np.ndarray:
    d = describe(ground)
    assert d is not None
    return np.array([height_at(x, y, d.kinds, d.params, d.grid) for x, y in xy])


@pytest.mark.parametrize("name", list(GROUNDS))
def test_compiled_height_equals_numpy(name: str) -> None:
    rng = np.random.default_rng(1301)
    ground = GROUNDS[name]
    xy = rng.uniform(-4.0, 9.0, (500, 2))
    np.testing.assert_allclose(_compiled(ground, xy), ground.height(xy), rtol=0, atol=1e-12)


def test_grid_border_and_cell_corners_equal_numpy() -> None:
    ground = _grid(7)
    xs = -1.3 + 0.45 * np.arange(-2, 14)
    ys = 0.7 + 0.45 * np.arange(-2, 10)
    xy = np.stack(np.meshgrid(xs, ys), -1).reshape(-1, 2)
    np.testing.assert_allclose(_compiled(ground, xy), ground.height(xy), rtol=0, atol=1e-12)


def test_stair_edges_equal_numpy() -> None:
    ground = Stairs(rise_m=0.15, run_m=0.30, steps=8, start_m=1.0)
    x = 1.0 + 0.30 * np.arange(-2, 12)
    xy = np.stack([np.concatenate([x, x - 1e-9, x + 1e-9]), np.zeros(3 * x.size)], -1)
    np.testing.assert_allclose(_compiled(ground, xy), ground.height(xy), rtol=0, atol=1e-12)


def test_the_bumps_sine_is_within_an_ulp_of_the_c_librarys() -> None:
    """``sine`` (the bumps' sines, a polynomial that runs on the vector units) is within one
    unit in the last place of ``math.sin`` wherever its callers use it, its bits most of the
    time; far out, where it is not used, the bumps take the C library's sines."""
    import math

    rng = np.random.default_rng(1302)
    special = [0.0, -0.0, 1e-300, -1e-300, 0.5, math.pi / 4, math.pi / 2, math.pi, 3 * math.pi / 2,
               1e3 * math.pi, -1e3 * math.pi / 2, 7e5, -1e6, np.nextafter(SINE_DOMAIN, 0.0)]
    x = np.concatenate([rng.uniform(-1.0, 1.0, 20_000), rng.uniform(-300.0, 300.0, 20_000),
                        rng.uniform(-SINE_DOMAIN, SINE_DOMAIN, 20_000), special])
    ours, theirs = np.array([sine(v) for v in x]), np.sin(x)
    ulps = np.abs(ours.view(np.int64) - theirs.view(np.int64))
    assert ulps.max() <= 1 and np.mean(ulps == 0) > 0.8
    assert math.isnan(sine(math.nan))
    bumps = describe(Bumps(0.04, 2.5, 3.0))
    assert bumps is not None
    far = np.array([[1e6, 3.0], [-0.4, -2e6], [math.nan, 1.0]])
    np.testing.assert_array_equal(_compiled(Bumps(0.04, 2.5, 3.0), far),
                                  Bumps(0.04, 2.5, 3.0).height(far))


@pytest.mark.parametrize("name", list(GROUNDS))
def test_a_blocks_heights_equal_each_points(name: str) -> None:
    """``heights_lanes`` answers a block's queries at once (on the vector units on a lone plane,
    slope or bumps) with the bits of ``height_at`` at each point: any number of them, NaN
    points, and points far enough out for the bumps to take the C library's sines."""
    from ecs_anim.runtime.kernels.ground_adapt import (
        _S_Q_HEIGHT,
        _S_Q_X,
        _S_Q_Y,
        QUERIES_PER_ROW,
        ground_scratch,
    )
    from ecs_anim.runtime.kernels.ground_adapt import heights_lanes as heights
    from ecs_anim.runtime.kernels.lanes import BLOCK

    d = describe(GROUNDS[name])
    assert d is not None
    rng = np.random.default_rng(1303)
    most = QUERIES_PER_ROW * BLOCK  # a block's every row asking its most
    for count, far in ((0, False), (1, False), (5, False), (most, False), (37, True)):
        scratch = ground_scratch(BLOCK)[0]
        xy = rng.uniform(-4.0, 9.0, (count, 2))
        if count > 3:
            xy[3] = np.nan
        if far:
            xy[7] = (3e6, 1.0)
        scratch[_S_Q_X * BLOCK:_S_Q_X * BLOCK + count] = xy[:, 0]
        scratch[_S_Q_Y * BLOCK:_S_Q_Y * BLOCK + count] = xy[:, 1]
        heights(scratch, 0, count, d.kinds, d.params, d.grid)
        np.testing.assert_array_equal(scratch[_S_Q_HEIGHT * BLOCK:_S_Q_HEIGHT * BLOCK + count],
                                      _compiled(GROUNDS[name], xy))


@pytest.mark.parametrize("name", list(GROUNDS))
def test_a_blocks_pitches_equal_each_feet(name: str) -> None:
    """``pitch_lanes`` takes a block's feet too low through ``pitched_from``'s secant passes at
    once (each pass on the vector units over the feet still too low) with the bits of
    ``pitched_from`` for each foot: both feet of every row of a block, some needing several
    passes, some one, some none, feet with NaN, turning about the ankle or the ball; and with
    no pass allowed, one, or the system's four."""
    import math

    from ecs_anim.runtime.kernels.ground_adapt import (
        _S_PITCHED,
        _S_PITCHED_GROUND,
        _to_pitch,
        ground_scratch,
        pitch_lanes,
        pitched_from,
    )
    from ecs_anim.runtime.kernels.lanes import BLOCK, Column

    d = describe(GROUNDS[name])
    assert d is not None
    rng = np.random.default_rng(1304)
    feet = []
    for _ in range(2 * BLOCK):
        x, y = rng.uniform(-2.0, 8.0, 2)
        origin = (x, y, height_at(x, y, d.kinds, d.params, d.grid) + rng.uniform(0.0, 0.25))
        heading, dz = rng.uniform(-math.pi, math.pi), float(rng.uniform(-0.6, 0.3))
        along = math.sqrt(1.0 - dz * dz)
        foot, sign = float(rng.uniform(0.12, 0.25)), float(rng.choice([1.0, -1.0]))
        feet.append((origin, (along * math.cos(heading), along * math.sin(heading), dz), foot,
                     sign, float(rng.uniform(0.02, 0.09))))
    feet[5] = ((math.nan, 1.0, 0.1), *feet[5][1:])
    feet[6] = (feet[6][0], (math.nan, 0.0, -0.3), *feet[6][2:])
    pitches = {}
    for passes in (0, 1, 4):
        scratch = ground_scratch(BLOCK)[0]
        count, expected, turned = 0, [], 0
        for k, (origin, direction, foot, sign, clearance) in enumerate(feet):
            end = np.add(origin, np.multiply(direction, sign * foot))
            first = height_at(end[0], end[1], d.kinds, d.params, d.grid)
            count = _to_pitch(scratch, count, Column(k // 2), k % 2, origin, direction, foot,
                              sign, clearance, first)
            pitched, ground = pitched_from(origin, direction, foot, sign, clearance, first,
                                           d.kinds, d.params, d.grid, passes)
            expected.append((*pitched, ground))
            turned += pitched != direction
        assert 5 < count < 2 * BLOCK - 5 and (passes == 0 or turned > 5)
        pitch_lanes(scratch, count, d.kinds, d.params, d.grid, passes)
        got = [(*(scratch[(_S_PITCHED + 3 * (k % 2) + a) * BLOCK + k // 2] for a in range(3)),
                scratch[(_S_PITCHED_GROUND + k % 2) * BLOCK + k // 2]) for k in range(len(feet))]
        np.testing.assert_array_equal(np.array(got), np.array(expected))
        pitches[passes] = np.array(expected)
    if name not in ("plane", "stairs"):  # (where flat under the feet, one pass lands them)
        assert not np.array_equal(pitches[1], pitches[4], equal_nan=True)  # several passes


@pytest.mark.parametrize("n", [32, 29])  # a block (lanes.BLOCK), one short of it
def test_a_blocks_planted_feet_enter_their_pitch_as_each_foot(n: int) -> None:
    """``pitch_planted_lanes`` takes the first step of a block's planted feet on the vector
    units (every foot turned, in a lane or the loop's scalar remainder) and ``planted_entries``
    keeps those in contact still too low: the same ``pitch_lanes`` entries, in the same order,
    and the same directions and grounds as ``_to_pitch`` foot by foot; feet not in contact,
    with NaN, on their heel or their ball, a whole block and one short of it."""
    import math

    from ecs_anim.runtime.kernels.ground_adapt import (
        _PITCH_STATE,
        _S_DIR,
        _S_P_CLEARANCE,
        _S_P_FOOT,
        _S_P_ORIGIN,
        _S_P_RISE,
        _S_PITCHED,
        _S_PITCHED_GROUND,
        _S_Q_END,
        _S_Q_HEIGHT,
        _STAGED,
        _to_pitch,
        ground_scratch,
        pitch_planted_lanes,
        planted_entries,
    )
    from ecs_anim.runtime.kernels.lanes import BLOCK, Column

    assert n <= BLOCK
    rng = np.random.default_rng(2207)
    lanes, expected = ground_scratch(BLOCK)[0], ground_scratch(BLOCK)[0]
    count = 0
    for k in range(2 * n):
        j, s = k // 2, k % 2
        heading, dz = rng.uniform(-math.pi, math.pi), float(rng.uniform(-0.6, 0.3))
        along = math.sqrt(1.0 - dz * dz)
        d = (along * math.cos(heading), along * math.sin(heading), dz)
        origin = tuple(rng.uniform(-1.0, 1.0, 3))
        foot, sign = float(rng.uniform(0.12, 0.25)), float(rng.choice([1.0, -1.0]))
        clearance, ground = float(rng.uniform(0.02, 0.09)), float(rng.uniform(-0.2, 0.2))
        if k == 5:
            d = (math.nan, 0.0, -0.3)
        if k == 8:
            origin = (0.0, math.nan, 0.1)
        in_contact = k % 7 != 3
        for scratch in (lanes, expected):
            scratch[(_S_DIR + 3 * s + np.arange(3)) * BLOCK + j] = d
            scratch[(_S_Q_END + s) * BLOCK + j] = k if in_contact else -1.0
            scratch[_S_Q_HEIGHT * BLOCK + k] = ground
        entry = j + BLOCK * s
        lanes[(_S_P_ORIGIN + _STAGED + 2 * np.arange(3)) * BLOCK + entry] = origin
        lanes[(_S_P_RISE + _STAGED) * BLOCK + entry] = sign * foot
        lanes[(_S_P_CLEARANCE + _STAGED) * BLOCK + entry] = clearance
        lanes[(_S_P_FOOT + _STAGED) * BLOCK + entry] = k
        if in_contact:
            count = _to_pitch(expected, count, Column(j), s, origin, d, foot, sign, clearance,
                              ground)
    pitch_planted_lanes(lanes, Column(0), Column(n))
    assert planted_entries(lanes, n) == count and 5 < count < 2 * n - 5
    fields = np.array(_PITCH_STATE)[:, None] * BLOCK + np.arange(count)
    np.testing.assert_array_equal(lanes[fields], expected[fields])
    feet = [(j, s) for j in range(n) for s in range(2) if (2 * j + s) % 7 != 3]
    for j, s in feet:
        for rows in (_S_PITCHED + 3 * s + np.arange(3), [_S_PITCHED_GROUND + s]):
            np.testing.assert_array_equal(lanes[np.array(rows) * BLOCK + j],
                                          expected[np.array(rows) * BLOCK + j])


@dataclass(frozen=True)
class _Ripples:
    def height(self, xy: np.ndarray) -> np.ndarray:
        return 0.01 * np.cos(xy[..., 0])


def test_a_known_height_is_reused_only_near_it_on_a_smooth_ground() -> None:
    """Planes, slopes and bumps are smooth (a point 1e-10 m off takes the known height: they
    differ by the grade times that); stairs and grids are not (an edge may lie in between)."""
    assert [smooth(describe(g).kinds) for g in GROUNDS.values()] == [  # type: ignore[union-attr]
        True, True, False, True, False, False, False]
    d = describe(GROUNDS["bumps"])
    assert d is not None
    x, y = 0.37, -0.81
    exact = height_at(x, y, d.kinds, d.params, d.grid)
    off = x + NEAR_M / 2
    near = height_near(off, y, (x, y, exact), True, d.kinds, d.params, d.grid)
    assert near == exact and abs(height_at(off, y, d.kinds, d.params, d.grid) - near) < NEAR_M
    far = height_near(x + 1e-3, y, (x, y, exact), True, d.kinds, d.params, d.grid)
    assert far == height_at(x + 1e-3, y, d.kinds, d.params, d.grid)
    # Not smooth, or nothing known (NaN): asked.
    assert height_near(off, y, (x, y, 99.0), False, d.kinds, d.params, d.grid) != 99.0
    nothing = (float("nan"),) * 3
    assert height_near(x, y, nothing, True, d.kinds, d.params, d.grid) == exact


def test_a_ground_of_ones_own_has_no_compiled_form() -> None:
    assert describe(_Ripples()) is None
    assert describe(Combined((Plane(), _Ripples()))) is None


# --- GroundAdapt: the compiled system against its numpy reference ---------------------------

TERRAINS: dict[str, Ground] = {
    "bumps_and_stairs": Combined((Bumps(0.03, 2.5, 3.0), Stairs(0.12, 0.40, 6, 2.0))),
    "steep_stairs": Stairs(rise_m=0.17, run_m=0.28, steps=10, start_m=0.8, heading_deg=15.0),
    "slope": Combined((Slope(0.12, -0.05), Bumps(0.05, 1.5, 1.2))),
    "grid": Combined((_grid(11), Plane(0.05))),
    # Alone, each takes heights_lanes' loop on the vector units.
    "lone_plane": Plane(),
    "lone_slope": Slope(0.1, -0.04, 0.02),
    "lone_bumps": Bumps(0.04, 2.5, 3.0),
}
BODIES = [Morphology.preset("child"), Morphology.preset("adult_male"), Morphology.preset("tall"),
          Morphology.from_stature(1.62, "female")]


@pytest.fixture(scope="module")
def motions() -> dict:
    """The shipped walk, idle and kick (in place of conftest's locomotion set)."""
    return {name: shipped_motion(name) for name in ("walk", "idle", "kick")}


def _sim(motions: dict, ground: Ground, seed: int) -> Simulation:
    rng = np.random.default_rng(seed)
    sim = Simulation(motions, ground)
    for k in range(8):
        player = MotionPlayer("walk", speed=float(rng.uniform(0.8, 1.2)),
                              start_s=float(rng.uniform(0, 2)),
                              queue=(QueuedClip("idle", 0.4), QueuedClip("kick", 0.3)) if k % 3 == 2
                              else ())
        if k % 3 == 2:
            player = MotionPlayer("walk", loop=False, queue=player.queue, speed=player.speed)
        sim.spawn(f"c{k}", BODIES[k % len(BODIES)], player,
                  Placement((float(rng.uniform(-1, 1)), 1.1 * k - 4.0),
                            float(rng.uniform(-0.3, 0.3))))
    return sim


def _ground_adapt(sim: Simulation) -> GroundAdapt:
    return next(s for s in sim.systems if isinstance(s, GroundAdapt))


def _assert_same_state(a: Simulation, b: Simulation, tick: int) -> None:
    for name, va in a.store.poses.arrays().items():
        vb = getattr(b.store.poses, name)
        if name in QUATERNION_FIELDS:  # q and -q are one rotation
            vb = vb * np.where(np.sum(va * vb, axis=-1, keepdims=True) < 0.0, -1.0, 1.0)
        np.testing.assert_allclose(va, vb, rtol=0, atol=1e-9, err_msg=f"{name} at tick {tick}")
    for name in ("footprint", "ground_ref", "positions"):
        np.testing.assert_allclose(getattr(a.store, name), getattr(b.store, name), rtol=0,
                                   atol=1e-9, err_msg=f"{name} at tick {tick}")
    for name in ("locked", "pivot"):
        np.testing.assert_array_equal(getattr(a.store, name), getattr(b.store, name),
                                      err_msg=f"{name} at tick {tick}")


@pytest.mark.parametrize("terrain", list(TERRAINS))
def test_compiled_ground_adapt_equals_numpy(motions: dict, terrain: str) -> None:
    compiled = _sim(motions, TERRAINS[terrain], 1321)
    reference = _sim(motions, TERRAINS[terrain], 1321)
    system = _ground_adapt(reference)
    system.run = system.run_numpy  # type: ignore[method-assign]
    for tick in range(240):
        compiled.step()
        reference.step()
        _assert_same_state(compiled, reference, tick)


def test_a_ground_of_ones_own_goes_through_numpy(motions: dict) -> None:
    mine = _sim(motions, Combined((Bumps(0.03, 2.5, 3.0), _Ripples())), 1322)
    assert _ground_adapt(mine)._description(mine.ground) is None
    reference = _sim(motions, Combined((Bumps(0.03, 2.5, 3.0), _Ripples())), 1322)
    system = _ground_adapt(reference)
    system.run = system.run_numpy  # type: ignore[method-assign]
    for tick in range(30):
        mine.step()
        reference.step()
        _assert_same_state(mine, reference, tick)


def test_a_rows_ground_adaptation_does_not_depend_on_its_block(
        monkeypatch: pytest.MonkeyPatch) -> None:
    """``ground_adapt_rows`` decodes and re-aims the legs by blocks of ``lanes.BLOCK`` rows on
    the vector units (a row in a vector lane or in a loop's scalar remainder) and answers a
    block's ground queries at once: three blocks and five rows of the bench's walkers in one
    call, in two uneven chunks and row by row give the same bits; so do they with every foot
    ramping in (the most queries a row asks: six, and a blend's each), and with rows of NaN
    (a root, a foot's direction) among them."""
    import copy
    import itertools

    import ecs_anim.systems.ground_adapt as system_module
    from ecs_anim.runtime.bench_scene import walkers_on_bumps
    from ecs_anim.runtime.kernels import over_chunks
    from ecs_anim.runtime.kernels.ground_adapt import ground_adapt_rows
    from ecs_anim.runtime.kernels.lanes import BLOCK

    sim, _ = walkers_on_bumps(3 * BLOCK + 5, crossing=False)
    calls: list = []

    def spy(kernel: object, n: int, *args: object, **options: int) -> None:
        calls.append(copy.deepcopy((n, args)))
        over_chunks(kernel, n, *args, **options)  # type: ignore[arg-type]

    monkeypatch.setattr(system_module, "over_chunks", spy)
    for _ in range(8):
        sim.step()
    n, args = calls[-1]
    assert n == 3 * BLOCK + 5

    def run(bounds: list[int]) -> list[np.ndarray]:
        a = copy.deepcopy(args)
        for lo, hi in itertools.pairwise(bounds):
            ground_adapt_rows(lo, hi, *a)
        return [np.array(x) for x in a[1]] + [a[k] for k in (8, 9, 10, 11)]  # footprint, locked, pivot, ground_ref

    for case in ("walking", "ramping", "nan"):
        if case == "ramping":
            args[4][:] = 0.5  # contact_weight
        if case == "nan":
            args[4][:] = 1.0
            args[1].root_position[args[0][3]] = np.nan  # (pose, rows)
            args[1].foot_dir[args[0][BLOCK + 2], 1] = np.nan
        whole = run([0, n])
        for other in (run([0, BLOCK + 7, n]), run(list(range(n + 1)))):
            for x, y in zip(whole, other, strict=True):
                np.testing.assert_array_equal(x, y)
