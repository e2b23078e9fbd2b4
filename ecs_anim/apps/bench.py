"""``ecs-anim bench``: performance figures, printed (tests never assert them).

The pipeline benchmark runs the bench scene (:func:`walkers_on_bumps`) at several sizes, each in
a process of its own, and fits ``t(N) = fixed + per_character * N`` by least squares to the
wall time and to the CPU time per tick; each process also reports its peak memory
(``ru_maxrss``), fitted the same way. Two more processes time a start from nothing: one with an
empty kernel cache (numba compiles every kernel), one with that cache filled (numba loads
them), each from the interpreter's start to the end of its first tick.

One more child times local avoidance alone (:func:`time_avoidance`: µs of CPU per agent per
tick at 2,000 walkers).

``python -m ecs_anim.apps.bench size N ...``, ``... first-tick`` and ``... avoidance`` are those
child processes.
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import NDArray

from ecs_anim.core.errors import EcsAnimError

if TYPE_CHECKING:
    pass
from ecs_anim.runtime.bench_scene import BenchScene, first_tick, peer_task

#: ``bench --characters`` above this would take minutes to set up (and gigabytes).
MAX_BENCH_CHARACTERS = 100_000
#: The default sizes: N divided by these.
SIZE_DIVISORS = (8, 4, 2, 1)
#: A tick at 30 Hz, ms.
TICK_BUDGET_MS = 1000.0 / 30.0
#: Ticks run before timing (the first ones load the kernels, fill caches).
WARM_UP_TICKS = 10
#: Ticks run before timing with a frame budget: a second at 30 Hz. Its model is made on the
#: first ticks (which load the kernels: 2-5 x a later tick), and the characters its first cut
#: drops go back to their motion's pose over the next ticks within the joint speed bound (at
#: 19,000 dropped at once, 3 us a character a tick, for about ten ticks). The slowest of these
#: ticks is printed apart (``warm_up_cpu_ms_max``).
BUDGET_WARM_UP_TICKS = 30
#: The marker a child prints when its first tick is done.
FIRST_TICK_DONE = "first tick done"
#: Longest wait for one child process, s (a first compilation takes about half a minute).
CHILD_TIMEOUT_S = 1800.0


def time_size(n: int, seconds: float, rotations: bool = False,
              constrained: bool = False, budget_ms: float | None = None,
              crossing: bool = False, threads: int = 1) -> dict[str, Any]:
    """One size, in this process: after :data:`WARM_UP_TICKS` ticks, ``seconds`` simulated at
    30 Hz. Returns ms per tick per system (wall), of the whole step (wall and CPU: every
    thread of the process), and the process's peak memory (MB); with ``budget_ms``, ``budget``:
    how much further from its target the budget left the top priority than a twin scene solved
    without a budget, stepped alongside (untimed; the largest difference of a constraint over
    the timed ticks, mm: the error the cut cost, measured only over the constraints both solved
    at the same weight this tick: neither held between two solves, dropped nor fading back in),
    the characters cut per tick and the ticks that cut anything, and each tick's figures
    (:class:`BudgetTicks`); with ``constrained``, ``errors_mm``: the errors the solve reached
    (:meth:`BenchScene.errors_mm`; the means over the timed ticks, and the largest). With
    ``threads`` above 1 (the kernels already on that many), ``thread_comparison``: the same
    scene then ticked on one thread and on ``threads`` in turn, as many ticks each
    (:func:`ecs_anim.runtime.kernels.thread_comparison`)."""
    scene = BenchScene(n, rotations, constrained, budget_ms, crossing)
    twin = None if budget_ms is None else BenchScene(n, rotations, constrained, crossing=crossing)
    sim = scene.sim
    warm_up_cpu_ms = []
    for _ in range(WARM_UP_TICKS if budget_ms is None else BUDGET_WARM_UP_TICKS):
        c0 = time.process_time()
        scene.tick()
        warm_up_cpu_ms.append((time.process_time() - c0) * 1e3)
        if twin is not None:
            twin.tick()
    before = sim.system_seconds()
    ticks = max(1, round(seconds * 30.0))
    wall = cpu = 0.0
    cost_m = 0.0
    cut_characters = ticks_cut = 0
    top = sim.constraints.priority == sim.constraints.priority.max(initial=0.0)
    reached: list[dict[str, float]] = []
    per_tick = BudgetTicks()
    for _ in range(ticks):
        w0, c0 = time.perf_counter(), time.process_time()
        sim.step()
        wall_s, cpu_s = time.perf_counter() - w0, time.process_time() - c0
        wall += wall_s
        cpu += cpu_s
        if constrained:
            reached.append(scene.errors_mm())
        report = sim.solver_report()
        if twin is not None and report is not None:
            twin.tick()
            same = top & (sim.constraints.weight == twin.sim.constraints.weight)
            extra = sim.constraints.error[same] - twin.sim.constraints.error[same]
            cost_m = max(cost_m, float(np.nanmax(extra, initial=0.0)))
            cut_characters += len(report.cut_characters)
            ticks_cut += report.cut
            per_tick.add(report, wall_s, cpu_s, separate_cut(sim), tick_parts(sim))
    after = sim.system_seconds()
    comparison = None
    if threads > 1:
        from ecs_anim.runtime import kernels

        comparison = kernels.thread_comparison(scene.tick, threads, ticks)
    sim.close()
    if twin is not None:
        twin.sim.close()
    result: dict[str, Any] = {
        "characters": n, "ticks": ticks,
        "ms_per_tick": {k: (after[k] - before[k]) / ticks * 1e3 for k in after},
        "wall_ms_per_tick": wall / ticks * 1e3, "cpu_ms_per_tick": cpu / ticks * 1e3,
        "peak_memory_mb": peak_memory_mb()}
    if comparison is not None:
        result["thread_comparison"] = comparison
    if reached:
        result["errors_mm"] = errors_over_ticks(reached)
    if budget_ms is not None:
        result["budget"] = {"top_priority_cost_mm": cost_m * 1e3,
                            "characters_cut_per_tick": cut_characters / ticks,
                            "ticks_cut": ticks_cut, **per_tick.figures(budget_ms),
                            "warm_up_ticks": len(warm_up_cpu_ms),
                            "warm_up_cpu_ms_max": max(warm_up_cpu_ms[WARM_UP_TICKS:],
                                                      default=0.0)}
    return result


def errors_over_ticks(reached: list[dict[str, float]]) -> dict[str, float | None]:
    """The errors the solve reached over the timed ticks, from each tick's
    (:meth:`BenchScene.errors_mm`, NaN where it solved no character): the mean of the ticks'
    means and the largest of their maxima, over the ticks that solved a character; None where
    none did (a frame budget that held or dropped every one on every tick: no error to tell)."""
    out: dict[str, float | None] = {}
    for key in reached[0]:
        values = np.array([tick[key] for tick in reached])
        values = values[np.isfinite(values)]
        out[key] = None if values.size == 0 else float(values.max() if key.endswith("_max")
                                                          else values.mean())
    return out


# --- the frame budget, tick by tick (issue 36 item 4) ---------------------------------------


def separate_cut(sim: Any) -> bool:
    """Whether the frame budget ended CollisionSeparate's rounds this tick."""
    from ecs_anim.systems import CollisionSeparate

    return any(s.rounds_cut for s in sim.systems if isinstance(s, CollisionSeparate))


#: A tick over the budget was the machine's when the systems before the solve and those after
#: it (which the budget does not change) each took at least this times their median.
SLOWED_ALIKE = 1.15


def tick_parts(sim: Any) -> tuple[float, float, float, float]:
    """This tick's CPU ms of the systems before ConstraintSolve, of ConstraintSolve, of the
    systems after it, and the frame budget's margin factor on the model's cost of the last two
    (:attr:`~ecs_anim.solver.budget.FrameBudget.margin_factor`)."""
    from ecs_anim.systems import ConstraintSolve

    systems = sim.systems
    solve = next(s for s in systems if isinstance(s, ConstraintSolve))
    mine = systems.index(solve)
    return (sum(s.last_cpu_seconds for s in systems[:mine]) * 1e3,
            solve.last_cpu_seconds * 1e3,
            sum(s.last_cpu_seconds for s in systems[mine + 1:]) * 1e3,
            solve.budget.margin_factor)


def _median_counts(ticks: list[dict[int, int]]) -> dict[str, float]:
    """Each interval's median count of characters over ``ticks`` (a tick without it: 0)."""
    every = sorted({k for counts in ticks for k in counts})
    return {str(k): float(np.median([counts.get(k, 0) for counts in ticks])) for k in every}


class BudgetTicks:
    """Each timed tick of a budgeted run: the characters solved, those the budget cut to one
    iteration, those it solves every 2nd tick or less often (the level of detail) and those it
    dropped, whether
    it ended the rounds of separation, the tick's CPU and wall time (the step alone: the twin
    scene stepped beside it is not counted), and its parts (:func:`tick_parts`)."""

    def __init__(self) -> None:
        self.solved: list[int] = []
        self.cut: list[int] = []
        self.dropped: list[int] = []
        self.slowed: list[int] = []
        self.intervals: list[dict[int, int]] = []
        self.update_intervals: list[dict[int, int]] = []
        self.separate_cut: list[bool] = []
        self.cpu_ms: list[float] = []
        self.wall_ms: list[float] = []
        self.floor_ms = float("nan")
        self.parts: list[tuple[float, float, float, float]] = []

    def add(self, report: Any, wall_s: float, cpu_s: float, separate_cut: bool = False,
            parts: tuple[float, float, float, float] = (0.0, 0.0, 0.0, 1.0)) -> None:
        self.solved.append(report.characters)
        self.cut.append(len(report.cut_characters))
        self.dropped.append(len(report.dropped_characters))
        self.slowed.append(report.characters_slowed)
        self.intervals.append(dict(report.intervals))
        self.update_intervals.append(dict(report.update_intervals))
        self.separate_cut.append(separate_cut)
        self.wall_ms.append(wall_s * 1e3)
        self.cpu_ms.append(cpu_s * 1e3)
        self.floor_ms = report.floor_ms
        self.parts.append(parts)

    def figures(self, budget_ms: float) -> dict[str, Any]:
        """The characters solved each tick, and their min / median / max and largest change from
        one tick to the next; min / median / max of the characters cut (to one iteration, solved
        less often than every tick, and dropped); the median number at each solve interval, and
        at each interval of the update rate above 1 (played, grounded and posed less often:
        :mod:`ecs_anim.runtime.update_rate`); the tick's CPU ms
        (min, median, 95th percentile, max); how many ticks went over ``budget_ms`` (CPU, and
        wall); the largest change of the characters cut (cut + slowed + dropped) from one tick
        to the next; the ticks whose separation the budget ended; the budget's margin factor
        (min, median, max); of the ticks over by CPU, those whose systems before the solve and
        after it both took at least :data:`SLOWED_ALIKE` times their median (the machine
        slowed: other processes on the core, or on the other one sharing its memory)."""
        cut, dropped, slowed = np.array(self.cut), np.array(self.dropped), np.array(self.slowed)
        cpu, wall = np.array(self.cpu_ms), np.array(self.wall_ms)
        parts = np.array(self.parts).reshape(-1, 4)
        unbudgeted = parts[:, [0, 2]]  # (before the solve, after it)
        alike = (unbudgeted >= SLOWED_ALIKE * np.median(unbudgeted, axis=0)).all(axis=1) \
            if cpu.size else np.zeros(0, bool)

        def spread(a: NDArray[Any]) -> list[float]:
            return [float(a.min()), float(np.median(a)), float(a.max())] if a.size else [0.0] * 3
        both = cut + dropped + slowed
        solved = np.array(self.solved)
        return {"solved_each_tick": self.solved, "solved_per_tick": spread(solved),
                "largest_change_of_solved": int(np.abs(np.diff(solved)).max(initial=0)),
                "cut_per_tick": spread(cut), "dropped_per_tick": spread(dropped),
                "slowed_per_tick": spread(slowed),
                "characters_at_interval": _median_counts(self.intervals),
                "characters_at_update_interval": _median_counts(self.update_intervals),
                "largest_change_of_cut": int(np.abs(np.diff(both)).max(initial=0)),
                "cpu_ms_per_tick_spread": spread(cpu),
                "cpu_ms_per_tick_p95": float(np.percentile(cpu, 95)) if cpu.size else 0.0,
                "ticks_over_budget_cpu": int((cpu > budget_ms).sum()),
                "ticks_over_budget_wall": int((wall > budget_ms).sum()),
                "ticks_separation_cut": int(np.sum(self.separate_cut)),
                "floor_ms": self.floor_ms,
                "margin_factor_spread": spread(parts[:, 3]),
                "ticks_over_slowed_alike": int((alike & (cpu > budget_ms)).sum())}


#: Agents of the avoidance kernel's figure, and its ticks timed.
AVOIDANCE_AGENTS = 2000
AVOIDANCE_TICKS = 60


def time_avoidance(n: int = AVOIDANCE_AGENTS, ticks: int = AVOIDANCE_TICKS,
                   seed: int = 32) -> dict[str, Any]:
    """CPU time (``process_time``) of local avoidance (ORCA: the grid and every agent's linear
    program, :func:`ecs_anim.runtime.kernels.avoidance.orca_velocities`, called as Steering
    calls it: facings, legs' stadiums, slowest steps) over ``n`` walkers, µs per agent per
    tick: walkers of the default radii and steering settings, legs of 0.75-1.0 m walking at
    1.4 m/s, 0.5 a square metre, each heading for a random point across the square and moved
    by the velocity it chose, ``ticks`` ticks at 30 Hz after one untimed (compile or load)."""
    from ecs_anim.runtime.kernels.avoidance import orca_velocities
    from ecs_anim.runtime.steering import DEFAULT_STEERING as S

    rng = np.random.default_rng(seed)
    side = float(np.sqrt(n / 0.5))
    position = rng.uniform(0.0, side, (n, 2))
    goal = rng.uniform(0.0, side, (n, 2))
    radius = rng.uniform(0.22, 0.33, n)
    leg = rng.uniform(0.75, 1.0, n)
    walk_m_s = 1.4
    max_speed = np.full(n, walk_m_s)
    velocity = np.zeros((n, 2))
    active = np.ones(n, bool)
    cpu = 0.0
    for tick in range(ticks + 1):
        to_goal = goal - position
        preferred = to_goal * (walk_m_s / np.maximum(np.linalg.norm(to_goal, axis=1), 1e-9))[:, None]
        speed = np.linalg.norm(velocity, axis=1)
        facing = np.where((speed > 1e-6)[:, None], velocity / np.maximum(speed, 1e-9)[:, None],
                          preferred / walk_m_s)
        striding = np.clip(speed / (S.rate_min * walk_m_s), 0.0, 1.0)
        c0 = time.process_time()
        velocity = orca_velocities(position, velocity, preferred, radius, max_speed, active,
                                   range_m=S.avoid_neighbour_m,
                                   time_horizon_s=S.avoid_time_horizon_s,
                                   max_neighbours=S.avoid_neighbours, dt=1.0 / 30.0,
                                   facing=facing, cone_rad=S.avoid_cone_rad,
                                   stride_m=S.avoid_stride_legs * leg * striding,
                                   feet_m=S.avoid_feet_legs * leg,
                                   min_speed=np.full(n, S.rate_min * walk_m_s))
        if tick:
            cpu += time.process_time() - c0
        position += velocity / 30.0
    return {"agents": n, "ticks": ticks, "us_per_agent_per_tick": cpu / ticks / n * 1e6}


def budget_capacity(budget_ms: float, runs: list[dict[str, Any]]) -> dict[str, Any]:
    """How many constrained characters a frame budget holds: the largest size none of whose
    ticks took more than ``budget_ms`` of CPU time (the budget's clock) with the top priority
    of the characters it solved within 1 mm of where the solve without a budget leaves it (0:
    none did); and the figures of each size."""
    held = [r["characters"] for r in runs
            if r["budget"]["ticks_over_budget_cpu"] == 0 and r["budget"]["top_priority_cost_mm"] <= 1.0]
    return {"budget_ms": budget_ms, "characters_held": max(held, default=0),
            "sizes": [{"characters": r["characters"], "wall_ms_per_tick": round(r["wall_ms_per_tick"], 3),
                       **{k: round(v, 4) if isinstance(v, float) else v
                          for k, v in r["budget"].items()}} for r in runs]}


def peak_memory_mb() -> float:
    """This process's peak resident memory so far, MB (``ru_maxrss``: kB on Linux)."""
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    return float(peak) / (1024.0 * 1024.0 if sys.platform == "darwin" else 1024.0)


# --- the parent: child processes, fits ------------------------------------------------------


def _child_command(*args: str) -> list[str]:
    return [sys.executable, "-m", "ecs_anim.apps.bench", *args]


def _run_child(args: list[str], env: dict[str, str] | None = None) -> str:
    """Run a child to its end; its stdout. A failure is an EcsAnimError with its last line."""
    done = subprocess.run(_child_command(*args), capture_output=True, text=True, env=env,
                          timeout=CHILD_TIMEOUT_S, check=False)
    if done.returncode != 0:
        last = (done.stderr.strip().splitlines() or ["no message"])[-1]
        raise EcsAnimError(f"bench: the process timing {' '.join(args)} failed: {last}")
    return done.stdout


def timed_start(cache: str, threads: int) -> dict[str, float]:
    """Seconds from launching a child (``python -m ecs_anim.apps.bench first-tick``) to the end
    of its first tick, with ``NUMBA_CACHE_DIR=cache``; and its phases."""
    env = os.environ | {"NUMBA_CACHE_DIR": cache}
    start = time.perf_counter()
    child = subprocess.Popen(_child_command("first-tick", "--threads", str(threads)),
                             stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env)
    assert child.stdout is not None
    line = child.stdout.readline()
    until_first_tick = time.perf_counter() - start
    _, errors = child.communicate(timeout=CHILD_TIMEOUT_S)
    if child.returncode != 0 or not line.startswith(FIRST_TICK_DONE):
        last = (errors.strip().splitlines() or ["no message"])[-1]
        raise EcsAnimError(f"bench: the process timing a first tick failed: {last}")
    phases: dict[str, float] = json.loads(line[len(FIRST_TICK_DONE):])
    return {"seconds": until_first_tick} | phases


def compile_timing(threads: int) -> dict[str, float]:
    """A first start with an empty kernel cache (numba compiles every kernel), then a second
    one with the cache the first filled (numba loads them): seconds from the interpreter's
    start to the end of the first tick, each."""
    with tempfile.TemporaryDirectory(prefix="ecs_anim_numba_") as cache:
        cold = timed_start(cache, threads)
        warm = timed_start(cache, threads)
    return {"first_compile_s": round(cold["seconds"], 3),
            "cached_load_s": round(warm["seconds"], 3),
            "cached_import_s": round(warm["import_s"], 3),
            "cached_first_tick_s": round(warm["first_tick_s"], 3)}


def warm_up(threads: int = 1) -> float:
    """Compile (or load) every kernel the tick uses into the user's cache, in a child process;
    the seconds it took."""
    start = time.perf_counter()
    _run_child(["first-tick", "--threads", str(threads)])
    return time.perf_counter() - start


def linear_fit(sizes: list[int], values: list[float]) -> tuple[float, float]:
    """Least-squares ``value = fixed + slope * size``: (fixed, slope)."""
    slope, fixed = np.polyfit(np.asarray(sizes, float), np.asarray(values, float), 1)
    return float(fixed), float(slope)


def capacity_fit(sizes: list[int], ms: list[float]) -> dict[str, float]:
    """The fit of ms per tick over the sizes and the characters it says hold 30 Hz. Timing
    noise can make the slope tiny or negative on small runs: it is never taken below a quarter
    of the largest run's average cost per character, nor the fixed cost below 0."""
    fixed, slope = linear_fit(sizes, ms)
    largest = int(np.argmax(sizes))
    per_char = max(slope, ms[largest] / sizes[largest] / 4)
    fixed = max(fixed, 0.0)
    return {"ms_fixed_per_tick": round(fixed, 4), "ms_per_character": round(per_char, 6),
            "max_characters_at_30hz": int(max((TICK_BUDGET_MS - fixed) / per_char, 0))}


def bench_sizes(n: int, given: list[int] | None) -> list[int]:
    """The sizes timed: ``given``, else N/8, N/4, N/2, N."""
    sizes = sorted(set(given)) if given else sorted({max(1, n // d) for d in SIZE_DIVISORS})
    if len(sizes) < 2:
        raise EcsAnimError(f"bench: --sizes {','.join(map(str, sizes))}: give two sizes or more "
                           "(the figures are a fit over them)")
    if sizes[-1] > MAX_BENCH_CHARACTERS:
        raise EcsAnimError(f"bench: --characters {sizes[-1]}: at most {MAX_BENCH_CHARACTERS:,}")
    return sizes


def size_list(text: str) -> list[int]:
    """argparse type of ``--sizes``: ``100,200,400,800``."""
    try:
        sizes = [int(word) for word in text.split(",") if word.strip()]
    except ValueError:
        sizes = []
    if not sizes or min(sizes) < 1:
        raise argparse.ArgumentTypeError(f"expected whole numbers >= 1 separated by commas "
                                         f"(e.g. 100,200,400,800), got {text!r}")
    return sizes


def bench_pipeline(args: argparse.Namespace) -> dict[str, Any]:
    """Run every size (each in a process of its own) and, unless ``no_compile_timing``, the two
    timed starts; the figures as :func:`cmd_bench_pipeline` prints them."""
    from ecs_anim.runtime import kernels

    n = args.characters
    if n < 8 and not args.sizes:
        raise EcsAnimError("bench: give --characters 8 or more (the figures are a fit over "
                           "N/8, N/4, N/2 and N)")
    if not 0 < args.seconds <= 600:
        raise EcsAnimError(f"bench: --seconds {args.seconds:g}: expected more than 0 and at "
                           "most 600")
    sizes = bench_sizes(n, args.sizes)
    threads = args.threads
    compiled = None if args.no_compile_timing else compile_timing(threads)
    if kernels.uncompiled_kernels():  # so that no size's peak memory holds the compiler's
        warm_up(threads)
    budget_ms = getattr(args, "budget_ms", None)
    if budget_ms is not None and not args.constrained:
        raise EcsAnimError("bench: --budget-ms is the solver's frame budget: give --constrained too")
    crossing = bool(getattr(args, "crossing", False))
    flags = [f for f, on in (("--rotations", args.rotations),
                             ("--constrained", args.constrained), ("--crossing", crossing)) if on]
    if budget_ms is not None:
        flags += ["--budget-ms", repr(budget_ms)]
    runs = [json.loads(_run_child(["size", str(size), "--seconds", repr(args.seconds),
                                   "--threads", str(threads), *flags]))
            for size in sizes]
    avoidance = json.loads(_run_child(["avoidance", "--threads", str(threads)]))
    largest = runs[-1]
    wall = capacity_fit(sizes, [r["wall_ms_per_tick"] for r in runs])
    cpu = capacity_fit(sizes, [r["cpu_ms_per_tick"] for r in runs])
    memory_fixed, memory_slope = linear_fit(sizes, [r["peak_memory_mb"] for r in runs])
    systems = largest["ms_per_tick"]
    return {
        "characters": sizes[-1],
        "rotations": bool(args.rotations),
        "constrained": bool(args.constrained),
        "crossing": crossing,
        "threads": threads,
        "ms_per_tick": {k: round(v, 3) for k, v in systems.items()},
        "ms_per_tick_total": round(sum(systems.values()), 3),
        # The fit of the wall time per tick (what holds 30 Hz):
        "ms_per_character": wall["ms_per_character"],
        "ms_fixed_per_tick": wall["ms_fixed_per_tick"],
        "max_characters_at_30hz": wall["max_characters_at_30hz"],
        # The fit of the CPU time per tick (every thread's; on one thread, what one core holds
        # when nothing else runs on it):
        "cpu_ms_per_character": cpu["ms_per_character"],
        "cpu_ms_fixed_per_tick": cpu["ms_fixed_per_tick"],
        "max_characters_at_30hz_cpu": cpu["max_characters_at_30hz"],
        "wall_ms_per_tick": round(largest["wall_ms_per_tick"], 3),
        "cpu_ms_per_tick": round(largest["cpu_ms_per_tick"], 3),
        "sizes": [{"characters": r["characters"], "ticks": r["ticks"],
                   "wall_ms_per_tick": round(r["wall_ms_per_tick"], 3),
                   "cpu_ms_per_tick": round(r["cpu_ms_per_tick"], 3),
                   "peak_memory_mb": round(r["peak_memory_mb"], 1),
                   **({"thread_comparison": {k: round(v, 3)
                                             for k, v in r["thread_comparison"].items()}}
                      if "thread_comparison" in r else {})} for r in runs],
        "peak_memory_mb": round(largest["peak_memory_mb"], 1),
        "peak_memory_kb_per_character": round(memory_slope * 1024.0, 2),
        "peak_memory_mb_fixed": round(memory_fixed, 1),
        "compile": compiled,
        "kernel_cache": str(kernels.cache_dir()),
        "budget": None if budget_ms is None else budget_capacity(budget_ms, runs),
        "errors_mm": ({k: None if v is None else round(v, 4)
                       for k, v in largest["errors_mm"].items()}
                      if "errors_mm" in largest else None),
        "avoidance_us_per_agent_per_tick": round(avoidance["us_per_agent_per_tick"], 3),
        "avoidance_agents": avoidance["agents"],
    }


def cmd_bench_peer_task(args: argparse.Namespace) -> int:
    """``bench --peer-task``: :func:`~ecs_anim.runtime.bench_scene.peer_task`'s errors."""
    result = peer_task()
    if args.json:
        print(json.dumps({k: round(v, 4) for k, v in result.items()}, indent=2))
        return 0
    print("bench --peer-task: one standing adult, a wrist and an elbow target its right arm takes "
          "exactly, feet planted, centre of mass held (the IK comparisons' task)")
    print(f"  wrist {result['wrist_mm']:.3f} mm, elbow {result['elbow_mm']:.3f} mm from their "
          f"targets; shoulder moved {result['shoulder_moved_mm']:.2f} mm "
          f"({result['shoulder_off_sphere_mm']:.3f} mm off the sphere the elbow target allows)")
    print(f"  centre of mass {result['com_mm']:.3f} mm from its place, feet moved "
          f"{result['feet_moved_mm']:.3f} mm, {result['iterations']:.0f} solver iterations")
    return 0


def cmd_bench_pipeline(args: argparse.Namespace) -> int:
    from ecs_anim.runtime import kernels

    try:
        kernels.set_threads(args.threads)
    except ValueError as exc:
        raise EcsAnimError(f"--threads {args.threads}: {exc}") from None
    if getattr(args, "peer_task", False):
        return cmd_bench_peer_task(args)
    result = bench_pipeline(args)
    if args.json:
        print(json.dumps(result, indent=2))
        return 0
    sizes = result["sizes"]
    n = result["characters"]
    threads = result["threads"]
    crowd = "crossing each other" if result["crossing"] else "in lanes"
    print(f"bench: {n} characters walking on bumps {crowd}, {args.seconds:g} s simulated at 30 Hz, "
          f"{threads} thread{'s' if threads > 1 else ''}, "
          f"{'positions and joint rotations' if args.rotations else 'joint positions'}"
          f"{', wrist + elbow targets the arm takes, on the walker' if args.constrained else ''}")
    for k, v in result["ms_per_tick"].items():
        print(f"  {k:16s} {v:8.2f} ms/tick")
    print(f"  {'total':16s} {result['ms_per_tick_total']:8.2f} ms/tick (the systems at {n})")
    print(f"  {'characters':>10s} {'wall ms/tick':>13s} {'CPU ms/tick':>12s} {'peak MB':>8s}")
    for s in sizes:
        print(f"  {s['characters']:10d} {s['wall_ms_per_tick']:13.2f} {s['cpu_ms_per_tick']:12.2f} "
              f"{s['peak_memory_mb']:8.1f}")
    print_thread_comparison(sizes, threads)
    print(f"  => wall: about {result['max_characters_at_30hz']} characters hold 30 Hz "
          f"(33.3 ms/tick): {result['ms_per_character'] * 1e3:.1f} us per character + "
          f"{result['ms_fixed_per_tick']:.2f} ms per tick")
    print(f"  => CPU:  about {result['max_characters_at_30hz_cpu']} characters: "
          f"{result['cpu_ms_per_character'] * 1e3:.1f} us per character + "
          f"{result['cpu_ms_fixed_per_tick']:.2f} ms per tick")
    print(f"  peak memory {result['peak_memory_mb']:.0f} MB at {n}: "
          f"{result['peak_memory_kb_per_character']:.1f} kB per character + "
          f"{result['peak_memory_mb_fixed']:.0f} MB")
    reached = result["errors_mm"]
    if reached is not None and all(v is None for v in reached.values()):
        print(f"  errors reached at {n}: none solved (the frame budget held or dropped every "
              "character on every timed tick)")
    elif reached is not None:
        def mm(key: str) -> str:
            return "n/a" if reached[key] is None else f"{reached[key]:.3f}"  # (none to tell)
        print(f"  errors reached at {n}: wrist {mm('wrist_mean')} mm mean, "
              f"{mm('wrist_max')} max; elbow {mm('elbow_mean')} mean, "
              f"{mm('elbow_max')} max; centre of mass {mm('com_mean')} mean, "
              f"{mm('com_max')} max")
    print(f"  local avoidance (ORCA, grid + linear programs): "
          f"{result['avoidance_us_per_agent_per_tick']:.2f} us CPU per agent per tick at "
          f"{result['avoidance_agents']} agents")
    budget = result["budget"]
    if budget is not None:
        print(f"  frame budget {budget['budget_ms']:g} ms (the solver cuts iterations to hold it):")
        print(f"  {'characters':>10s} {'wall ms/tick':>13s} {'top priority cost mm':>21s} "
              f"{'characters cut/tick':>20s}")
        for s in budget["sizes"]:
            print(f"  {s['characters']:10d} {s['wall_ms_per_tick']:13.2f} "
                  f"{s['top_priority_cost_mm']:21.3f} {s['characters_cut_per_tick']:20.1f}")
        print(f"  => a {budget['budget_ms']:g} ms budget holds {budget['characters_held']} constrained "
              "characters: no tick over it (CPU time) and the top priority of those it solved "
              "within 1 mm of the unbudgeted solve (the largest size timed that did; how many it "
              "dropped to do so: below)")
        print_budget_ticks(budget)
    compiled = result["compile"]
    if compiled is not None:
        print(f"  start to first tick: {compiled['first_compile_s']:.1f} s compiling the "
              f"kernels (empty cache), {compiled['cached_load_s']:.2f} s from the cache")
    return 0


def print_thread_comparison(sizes: list[dict[str, Any]], threads: int) -> None:
    """With ``--threads N`` above 1: each size's scene ticked on one thread and on N in turn,
    in the same process after its timed ticks (same machine load for both)."""
    if threads <= 1:
        return
    print(f"  {threads} threads against one, the same scene ticked on each in turn:")
    print(f"  {'characters':>10s} {'1 thread ms (wall/CPU)':>24s} "
          f"{f'{threads} threads ms (wall/CPU)':>25s} {'speed-up (wall)':>16s}")
    for s in sizes:
        c = s.get("thread_comparison")
        if c is None:
            continue
        print(f"  {s['characters']:10d} {c['wall_ms_1']:12.2f}/{c['cpu_ms_1']:<11.2f} "
              f"{c[f'wall_ms_{threads}']:13.2f}/{c[f'cpu_ms_{threads}']:<11.2f} "
              f"{c['speedup']:15.2f}x")


def print_budget_ticks(budget: dict[str, Any]) -> None:
    """The frame budget tick by tick, per size: the cut (min / median / max), the level of
    detail (median characters at each solve interval), the CPU ms, the ticks over the budget."""
    print(f"  {'characters':>10s} {'cut to 1 it.':>14s} {'solved less often':>18s} "
          f"{'dropped':>14s} {'largest step':>12s} {'CPU ms/tick':>18s} {'95th %':>7s} "
          f"{'over (CPU/wall)':>15s}")

    def spread(values: list[float], digits: int) -> str:
        return "/".join(f"{v:.{digits}f}" for v in values)
    for s in budget["sizes"]:
        print(f"  {s['characters']:10d} {spread(s['cut_per_tick'], 0):>14s} "
              f"{spread(s['slowed_per_tick'], 0):>18s} "
              f"{spread(s['dropped_per_tick'], 0):>14s} {s['largest_change_of_cut']:12d} "
              f"{spread(s['cpu_ms_per_tick_spread'], 1):>18s} {s['cpu_ms_per_tick_p95']:7.1f} "
              f"{s['ticks_over_budget_cpu']:>7d}/{s['ticks_over_budget_wall']:<7d}")
        print(f"  {'':10s} solved a tick {spread(s['solved_per_tick'], 0)}, at most "
              f"{s['largest_change_of_solved']} more or fewer than the tick before")
        levels = ", ".join(f"{v:.0f} every {k}" if k != "1" else f"{v:.0f} every tick"
                           for k, v in s["characters_at_interval"].items())
        if levels:
            print(f"  {'':10s} solved (median a tick): {levels}"
                  + (f"; separation cut short on {s['ticks_separation_cut']} ticks"
                     if s["ticks_separation_cut"] else ""))
        updated = ", ".join(f"{v:.0f} every {k}"
                            for k, v in s["characters_at_update_interval"].items())
        if updated:
            print(f"  {'':10s} played, grounded and posed less often than every tick (median "
                  f"a tick): {updated}")
        print(f"  {'':10s} the {s['warm_up_ticks']} ticks before timing: the slowest after the "
              f"first {WARM_UP_TICKS} {s['warm_up_cpu_ms_max']:.1f} ms CPU (the budget's first "
              "cut settling)")
        print(f"  {'':10s} margin on the model x{spread(s['margin_factor_spread'], 2)}"
              + (f"; of the {s['ticks_over_budget_cpu']} ticks over, "
                 f"{s['ticks_over_slowed_alike']} slowed alike (the machine)"
                 if s["ticks_over_budget_cpu"] else ""))
        if s["floor_ms"] > budget["budget_ms"]:
            print(f"  {'':10s} even with every character dropped the tick costs "
                  f"{s['floor_ms']:.1f} ms: the budget cannot hold at {s['characters']}")
    print("  (characters per tick min/median/max; ticks over the budget by CPU time, the "
          "budget's clock, and by wall time, which other processes on the core also take; "
          f"slowed alike: the systems before the solve and those after it both at "
          f"{SLOWED_ALIKE:g} x their median or more)")


# --- bench import ---------------------------------------------------------------------------


def default_bench_files() -> list[Path]:
    from ecs_anim.io.library import shipped_motion_paths

    for candidate in (Path("../shared/mocap"),
                      Path(__file__).resolve().parents[3] / "shared" / "mocap"):
        files = sorted(candidate.glob("*.bvh")) + sorted(candidate.glob("*.c3d"))
        if files:
            return files
    return shipped_motion_paths()


def cmd_bench_import(args: argparse.Namespace) -> int:
    files = [Path(f) for f in args.files] or default_bench_files()
    if not files:
        raise EcsAnimError("bench import: no clips found (give BVH or C3D files, or run from "
                           "the repository next to ../shared/mocap)")
    missing = [str(f) for f in files if not f.is_file()]
    if missing:
        raise EcsAnimError(f"bench import: no such file: {', '.join(missing)}")
    other = [str(f) for f in files if f.suffix.lower() not in (".bvh", ".c3d")]
    if other:
        raise EcsAnimError(f"bench import: not a .bvh or .c3d file: {', '.join(other)}")
    bvh_files = [f for f in files if f.suffix.lower() == ".bvh"]
    result: dict[str, Any] = {}
    if bvh_files:
        result = _bench_bvh(max(bvh_files, key=lambda p: p.stat().st_size), args.repeat)
    c3d = [_bench_c3d(f, args.repeat) for f in files if f.suffix.lower() == ".c3d"]
    if c3d:
        result["c3d"] = c3d
    if args.json:
        print(json.dumps(result, indent=2))
        return 0
    if bvh_files:
        best = result["seconds"]
        print(f"bench import: {Path(str(result['file'])).name}, {result['frames']} frames, "
              f"best of {args.repeat}")
        print(f"  parse {best['parse'] * 1e3:8.1f} ms")
        print(f"  FK    {best['fk'] * 1e3:8.1f} ms")
        print(f"  map + FK + encode + contacts {best['map_encode'] * 1e3:8.1f} ms")
        print(f"  total {best['total'] * 1e3:8.1f} ms -> {result['frames_per_second']:.0f} "
              "frames/s")
    for one in c3d:
        print(f"bench import: {Path(str(one['file'])).name}, {one['frames']} frames, best of "
              f"{args.repeat}: read {one['seconds']['read'] * 1e3:.1f} ms, joint centres + "
              f"encode + contacts {one['seconds']['centres_encode'] * 1e3:.1f} ms -> "
              f"{one['frames_per_second']:.0f} frames/s")
    return 0


def _bench_bvh(path: Path, repeat: int) -> dict[str, Any]:
    """Best-of-``repeat`` timings of one BVH import: parse, FK, map + FK + encode + contacts."""
    from ecs_anim.io.bvh import forward_kinematics, read_bvh
    from ecs_anim.io.importing import canonical_clip, normalize_clip

    timings: dict[str, list[float]] = {"parse": [], "fk": [], "map_encode": []}
    n_frames = 0
    for _ in range(repeat):
        t0 = time.perf_counter()
        motion = read_bvh(path)
        t1 = time.perf_counter()
        forward_kinematics(motion)
        t2 = time.perf_counter()
        normalize_clip(canonical_clip(motion), path.stem, str(path))
        t3 = time.perf_counter()
        timings["parse"].append(t1 - t0)
        timings["fk"].append(t2 - t1)
        timings["map_encode"].append(t3 - t2)
        n_frames = motion.n_frames
    best = {k: min(v) for k, v in timings.items()}
    # canonical_clip runs FK again internally; count the pipeline once: parse + (map + FK + encode).
    total = best["parse"] + best["map_encode"]
    return {
        "file": str(path),
        "frames": n_frames,
        "seconds": {k: round(v, 5) for k, v in best.items()} | {"total": round(total, 5)},
        "frames_per_second": round(n_frames / total, 1),
    }


def _bench_c3d(path: Path, repeat: int) -> dict[str, Any]:
    """Best-of-``repeat`` timings of one C3D import: reading the markers, then joint centres,
    encoding and contacts."""
    from ecs_anim.io.c3d.importing import canonical_clip_c3d
    from ecs_anim.io.c3d.reading import read_c3d
    from ecs_anim.io.importing import normalize_clip

    reads, rest = [], []
    n_frames = 0
    for _ in range(repeat):
        t0 = time.perf_counter()
        raw = read_c3d(path)
        t1 = time.perf_counter()
        clip, _ = canonical_clip_c3d(raw)
        motion = normalize_clip(clip, path.stem, str(path))
        t2 = time.perf_counter()
        reads.append(t1 - t0)
        rest.append(t2 - t1)
        n_frames = motion.n_frames
    read_s, rest_s = min(reads), min(rest)
    return {"file": str(path), "frames": n_frames,
            "seconds": {"read": round(read_s, 5), "centres_encode": round(rest_s, 5),
                        "total": round(read_s + rest_s, 5)},
            "frames_per_second": round(n_frames / (read_s + rest_s), 1)}


def cmd_bench(args: argparse.Namespace) -> int:
    if args.what == "pipeline":
        return cmd_bench_pipeline(args)
    return cmd_bench_import(args)


# --- the child processes --------------------------------------------------------------------


def child_main(argv: list[str] | None = None) -> int:
    """``size N [--seconds S] [--threads T] [--rotations] [--constrained] [--crossing]
    [--budget-ms MS]``:
    time one size and print JSON; ``first-tick [--threads T]``: print :data:`FIRST_TICK_DONE`
    and the phases' seconds as soon as the first tick is done; ``avoidance [--threads T]``:
    :func:`time_avoidance` as JSON."""
    from ecs_anim.runtime import kernels
    from ecs_anim.runtime.allocator import keep_freed_memory

    keep_freed_memory()  # as the command line does: the tick's arrays reuse freed memory
    parser = argparse.ArgumentParser(prog="python -m ecs_anim.apps.bench")
    parser.add_argument("what", choices=["size", "first-tick", "avoidance"])
    parser.add_argument("characters", nargs="?", type=int, default=8)
    parser.add_argument("--seconds", type=float, default=1.0)
    parser.add_argument("--threads", type=int, default=1)
    parser.add_argument("--rotations", action="store_true")
    parser.add_argument("--constrained", action="store_true")
    parser.add_argument("--crossing", action="store_true")
    parser.add_argument("--budget-ms", type=float)
    args = parser.parse_args(argv)
    if args.what == "first-tick":
        phases = first_tick(args.threads)
        print(FIRST_TICK_DONE + json.dumps(phases), flush=True)
        return 0
    kernels.set_threads(args.threads)
    if args.what == "avoidance":
        print(json.dumps(time_avoidance()))
        return 0
    print(json.dumps(time_size(args.characters, args.seconds, args.rotations,
                               args.constrained, args.budget_ms, args.crossing, args.threads)))
    return 0


if __name__ == "__main__":
    sys.exit(child_main())
