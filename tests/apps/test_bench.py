"""The benchmark command, ``--threads``, and the first run's compile notice (issue 13, items 6
and 8). Figures are printed, never asserted: only their presence and consistency are checked."""

from __future__ import annotations

import json
import shlex
from pathlib import Path
from typing import Any, ClassVar

import numpy as np
import pytest

from conftest import REPO
from ecs_anim.apps.bench import capacity_fit, errors_over_ticks, linear_fit
from ecs_anim.apps.cli.main import main
from ecs_anim.runtime import kernels
from ecs_anim.runtime.bench_scene import BenchScene, arm_targets, peer_task

SCENARIO = str(REPO / "scenarios" / "reach_and_touch.yaml")
#: Makes any bench example quick: two small sizes, a few ticks, no timed cold start.
QUICK = ["--sizes", "4,8", "--seconds", "0.1", "--no-compile-timing"]
#: Every key ``bench --json`` had before issue 13 (kept), then the new ones.
OLD_KEYS = {"characters", "rotations", "constrained", "ms_per_tick", "ms_per_tick_total",
            "ms_per_character", "ms_fixed_per_tick", "max_characters_at_30hz"}
NEW_KEYS = {"threads", "cpu_ms_per_character", "cpu_ms_fixed_per_tick",
            "max_characters_at_30hz_cpu", "wall_ms_per_tick", "cpu_ms_per_tick", "sizes",
            "peak_memory_mb", "peak_memory_kb_per_character", "peak_memory_mb_fixed", "compile",
            "kernel_cache"}


def test_bench_json_keeps_its_keys_and_adds_cpu_wall_memory_and_threads(capsys):
    assert main(["bench", "--constrained", "--json", *QUICK]) == 0
    result = json.loads(capsys.readouterr().out)
    assert OLD_KEYS | NEW_KEYS <= set(result)
    assert result["characters"] == 8 and result["threads"] == 1 and result["constrained"]
    assert [s["characters"] for s in result["sizes"]] == [4, 8]
    assert all(s["ticks"] == 3 and s["peak_memory_mb"] > 0 for s in result["sizes"])
    assert "ConstraintSolve" in result["ms_per_tick"] and result["compile"] is None
    # Figures only (tests never assert speed), but they must be the fit's own: the characters
    # that hold 33.3 ms a tick at the fitted cost.
    for prefix, key in (("", "max_characters_at_30hz"), ("cpu_", "max_characters_at_30hz_cpu")):
        fixed, per_character = result[f"{prefix}ms_fixed_per_tick"], result[f"{prefix}ms_per_character"]
        assert per_character > 0 and fixed >= 0
        assert result[key] == int(max((1000.0 / 30.0 - fixed) / per_character, 0)) or \
            abs(result[key] - (1000.0 / 30.0 - fixed) / per_character) <= 1 + 1e-3 * result[key]


def test_bench_text_names_the_threads_and_every_size(capsys):
    assert main(["bench", *QUICK]) == 0
    out = capsys.readouterr().out
    assert "1 thread," in out and "characters hold 30 Hz" in out and "kB per character" in out
    rows = [line.split() for line in out.splitlines() if line.strip().split(" ")[0] in ("4", "8")]
    assert [r[0] for r in rows] == ["4", "8"]


def test_the_bench_walkers_keep_to_their_lanes_and_crossing_ones_meet(capsys):
    """The bench's crowd walks in lanes (one body a lane, 1.5 m apart, each walker at its own
    time of the walk, starting on its grid point): nobody is in another's body; with
    ``--crossing`` a tenth of the crowd is, every tick."""
    lanes, crossing = BenchScene(100), BenchScene(100, crossing=True)
    starts = lanes.sim.store.clip_time_s.copy()
    assert np.unique(np.round(starts, 9)).size == 100  # no two walkers in step
    lanes.tick()
    grid_xy = np.stack([1.5 * (np.arange(100) // 10), 1.5 * (np.arange(100) % 10)], axis=1)
    posture = lanes.sim.store.posture
    assert posture is not None
    pelvis_xy = posture.positions[:, 0, :2]
    # along the lane exactly (the walk's own path set back), across it the walk's sway
    assert np.abs(pelvis_xy - grid_xy).max(axis=0) == pytest.approx([0.0, 0.008], abs=0.005)
    deepest = {}
    for name, scene in (("lanes", lanes), ("crossing", crossing)):
        worst = 0.0
        for _ in range(30):
            scene.tick()
            worst = max(worst, float(scene.sim.store.overlap_m.max()))
        scene.sim.close()
        deepest[name] = worst
    assert deepest["lanes"] == 0.0 and deepest["crossing"] > 0.01, deepest
    assert main(["bench", "--crossing", "--json", *QUICK]) == 0
    assert json.loads(capsys.readouterr().out)["crossing"] is True
    assert main(["bench", "--crossing", *QUICK]) == 0
    assert "walking on bumps crossing each other" in capsys.readouterr().out


def test_bench_budget_prints_the_cut_tick_by_tick(capsys):
    """A budget nothing could overrun (8 characters, 1 s a tick): nothing cut or dropped, no
    tick over it; the spread of each figure over the timed ticks, per size."""
    assert main(["bench", "--constrained", "--budget-ms", "1000", "--json", *QUICK]) == 0
    budget = json.loads(capsys.readouterr().out)["budget"]
    assert budget["characters_held"] == 8
    for size in budget["sizes"]:
        assert size["cut_per_tick"] == [0, 0, 0] and size["dropped_per_tick"] == [0, 0, 0]
        assert size["slowed_per_tick"] == [0, 0, 0] and size["ticks_separation_cut"] == 0
        assert size["characters_at_interval"] == {"1": float(size["characters"])}
        assert size["characters_at_update_interval"] == {} and size["warm_up_ticks"] == 30
        assert size["ticks_over_budget_cpu"] == 0 and size["largest_change_of_cut"] == 0
        low, median, high = size["cpu_ms_per_tick_spread"]
        assert 0 < low <= median <= high < 1000 and size["floor_ms"] < 1000
        assert low <= size["cpu_ms_per_tick_p95"] <= high
        least, middle, most = size["margin_factor_spread"]
        assert 1.0 <= least <= middle <= most <= 2.0 and size["ticks_over_slowed_alike"] == 0
    assert main(["bench", "--constrained", "--budget-ms", "1000", *QUICK]) == 0
    text = capsys.readouterr().out
    assert "cut to 1 it." in text and "over (CPU/wall)" in text and "cannot hold" not in text
    assert "solved less often" in text and "solved (median a tick): 8 every tick" in text
    assert "margin on the model x" in text and "slowed alike" in text
    assert "the 30 ticks before timing" in text and "played, grounded" not in text


def test_bench_budget_tells_the_ticks_over_the_machine_slowed():
    """Of the ticks over the budget, those whose systems before the solve and after it (which
    the budget does not change) took SLOWED_ALIKE times their median or more: one of two."""
    from ecs_anim.apps.bench import BudgetTicks

    class Report:
        cut_characters = dropped_characters = ()
        characters, characters_slowed, intervals, floor_ms = 8, 0, {1: 8}, 1.0
        update_intervals: ClassVar[dict[int, int]] = {}

    ticks = BudgetTicks()
    for _ in range(10):
        ticks.add(Report(), 0.02, 0.02, parts=(4.0, 10.0, 6.0, 1.1))
    ticks.add(Report(), 0.03, 0.03, parts=(6.0, 15.0, 9.0, 1.5))  # the machine
    ticks.add(Report(), 0.03, 0.03, parts=(4.0, 20.0, 6.0, 1.5))  # the solve alone
    figures = ticks.figures(25.0)
    assert figures["ticks_over_budget_cpu"] == 2 and figures["ticks_over_slowed_alike"] == 1
    assert figures["margin_factor_spread"] == [1.1, 1.1, 1.5]
    assert figures["solved_each_tick"] == [8] * 12 and figures["largest_change_of_solved"] == 0


def test_bench_threads_prints_them_against_one_thread_in_the_same_run(capsys):
    assert main(["bench", "--threads", "2", "--json", *QUICK]) == 0
    result = json.loads(capsys.readouterr().out)
    for size in result["sizes"]:
        figures = size["thread_comparison"]
        assert {"wall_ms_1", "cpu_ms_1", "wall_ms_2", "cpu_ms_2", "speedup"} == set(figures)
    assert main(["bench", "--threads", "2", *QUICK]) == 0
    text = capsys.readouterr().out
    assert "2 threads against one, the same scene ticked on each in turn:" in text
    rows = [line.split() for line in text.splitlines() if line.strip().endswith("x")]
    assert [r[0] for r in rows] == ["4", "8"]
    assert main(["bench", *QUICK]) == 0
    assert "against one" not in capsys.readouterr().out


def test_bench_sizes_default_to_four_and_bad_sizes_are_one_line_errors(capsys):
    from ecs_anim.apps.bench import bench_sizes

    assert bench_sizes(400, None) == [50, 100, 200, 400]
    assert bench_sizes(8, None) == [1, 2, 4, 8]
    cases = [(["bench", "--sizes", "8"], "give two sizes or more"),
             (["bench", "--sizes", "8,200000"], "at most 100,000"),
             (["bench", "--threads", "999", *QUICK], "--threads 999: expected 1 to")]
    for argv, message in cases:
        assert main(argv) == 1, argv
        err = capsys.readouterr().err
        assert message in err and "Traceback" not in err, (argv, err)
    with pytest.raises(SystemExit):
        main(["bench", "--sizes", "4,x"])
    assert "expected whole numbers >= 1" in capsys.readouterr().err


def test_the_fit_is_least_squares_over_every_size():
    sizes = [10, 20, 40, 80]
    fixed, slope = linear_fit(sizes, [2.0 + 0.5 * n for n in sizes])
    np.testing.assert_allclose([fixed, slope], [2.0, 0.5], atol=1e-9)
    fit = capacity_fit(sizes, [2.0 + 0.5 * n for n in sizes])
    assert fit["max_characters_at_30hz"] == int((1000.0 / 30.0 - 2.0) / 0.5)


def test_run_and_view_take_threads(tmp_path, capsys, monkeypatch):
    assert main(["run", SCENARIO, "--seconds", "0.1", "--threads", "1"]) == 0
    assert kernels.threads() == 1
    monkeypatch.setattr(kernels, "available_threads", lambda: 4)
    monkeypatch.setattr("ecs_anim.runtime.kernels.os.getloadavg", lambda: (2.6, 1.0, 1.0))
    assert kernels.default_threads() == 1  # a loaded machine: one thread
    monkeypatch.setattr("ecs_anim.runtime.kernels.os.getloadavg", lambda: (0.2, 1.0, 1.0))
    assert kernels.default_threads() == 4  # idle cores: all of them
    monkeypatch.setattr("ecs_anim.runtime.kernels.os.getloadavg", lambda: (9.0, 1.0, 1.0))
    assert kernels.default_threads() == 1
    monkeypatch.undo()
    assert main(["run", SCENARIO, "--seconds", "0.1"]) == 0  # default: the idle cores
    assert 1 <= kernels.threads() <= kernels.available_threads()
    shot = tmp_path / "v.png"
    assert main(["view", SCENARIO, "--threads", "999", "--screenshot", str(shot)]) == 1
    assert "--threads 999: expected 1 to" in capsys.readouterr().err and not shot.exists()


def test_thread_comparison_times_one_thread_and_n_in_the_same_run():
    ticks: list[int] = []
    kernels.set_threads(1)
    figures = kernels.thread_comparison(lambda: ticks.append(kernels.threads()),
                                        kernels.available_threads(), 3)
    assert ticks == [1, kernels.available_threads()] * 3  # alternating, tick by tick
    assert kernels.threads() == 1  # as it was
    assert {"wall_ms_1", "cpu_ms_1", "speedup"} <= set(figures) and figures["wall_ms_1"] >= 0


@pytest.mark.parametrize("characters, constrained, ticks", [(12, True, 5), (300, False, 3)])
def test_results_do_not_depend_on_the_thread_count(characters: int, constrained: bool,
                                                   ticks: int):
    """Each character is computed by one thread on its own: the bench scene gives the same joint
    positions on one thread as on all, constrained, and with 300 walkers (more than one chunk
    of 32), whose PostureConvert keeps a block scratch for every thread's chunk (the kernel
    indexes it by the chunk's first row, unchecked)."""
    from ecs_anim.runtime.kernels.decode import spine_scratch_fits
    from ecs_anim.systems import PostureConvert

    if kernels.available_threads() < 2:
        pytest.skip("one core available: nothing to compare")
    positions = []
    for n_threads in (1, kernels.available_threads()):
        kernels.set_threads(n_threads)
        scene = BenchScene(characters, constrained=constrained)
        for _ in range(ticks):
            scene.tick()
        posture = next(s for s in scene.sim.systems if isinstance(s, PostureConvert))
        assert spine_scratch_fits(posture._spines, scene.sim.store.n)
        positions.append(scene.sim.store.positions.copy())
        scene.sim.close()
    kernels.set_threads(None)
    np.testing.assert_array_equal(positions[0], positions[1])


def test_over_chunks_splits_the_rows_and_raises_what_a_chunk_raised():
    """Contiguous chunks covering 0..n once, one per thread; a failing chunk's error is raised
    after the others are done."""
    chunks: list[tuple[int, int]] = []

    def record(lo: int, hi: int, tag: str) -> None:
        assert tag == "rows"
        chunks.append((lo, hi))

    kernels.set_threads(kernels.available_threads())
    kernels.over_chunks(record, 101, "rows")
    assert sorted(chunks) == [(101 * i // kernels.threads(), 101 * (i + 1) // kernels.threads())
                              for i in range(kernels.threads())]
    chunks.clear()
    kernels.over_chunks(record, 3, "rows")  # too few rows to share
    assert chunks == [(0, 3)]
    kernels.set_threads(1)
    chunks.clear()
    kernels.over_chunks(record, 101, "rows")
    assert chunks == [(0, 101)]
    kernels.set_threads(None)

    def fail_late(lo: int, hi: int) -> None:
        if hi == 101:
            raise ValueError(f"rows {lo}..{hi}")
        chunks.append((lo, hi))

    chunks.clear()
    with pytest.raises(ValueError, match=r"\.\.101"):
        kernels.over_chunks(fail_late, 101)
    assert len(chunks) == kernels.threads() - 1


def _fake_cache(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Path:
    """An empty kernel cache folder of this package in ``tmp_path`` (NUMBA_CACHE_DIR)."""
    monkeypatch.setenv("NUMBA_CACHE_DIR", str(tmp_path))
    folder = kernels._cache_subfolder()
    assert folder.parent == tmp_path and folder.name.startswith("kernels_")
    return folder


def _index(path: Path, source: bytes) -> None:
    """A numba cache index as numba 0.68 writes it: its version, then (stamp, overloads), the
    stamp being the sha256 of the module's source."""
    import hashlib
    import pickle

    with open(path, "wb") as f:
        pickle.dump("0.68", f)
        f.write(pickle.dumps((hashlib.sha256(source).digest(), {})))


def test_uncompiled_kernels_reads_the_cache_folder(tmp_path, monkeypatch):
    folder = _fake_cache(tmp_path, monkeypatch)
    # The threads' hand-over is not waited for: a tick on one thread never compiles it.
    modules = [p.stem for p in kernels.kernel_sources()
               if "@jit(nogil=True)" in p.read_text(encoding="utf-8") and p.stem != "handover"]
    assert {"decode", "playback", "ground_adapt", "solve", "posture", "com"} <= set(modules)
    assert kernels.uncompiled_kernels() == modules  # nothing compiled yet
    folder.mkdir()
    for source in kernels.kernel_sources():
        _index(folder / f"{source.stem}.some_kernel-10.py311.nbi", source.read_bytes())
    assert kernels.uncompiled_kernels() == [] and kernels.compile_notice() is None
    # A module whose source changed since it was compiled is compiled again (file times do not
    # matter: a fresh checkout of the same source stays compiled).
    first = kernels.kernel_sources()[0]
    _index(folder / f"{first.stem}.some_kernel-10.py311.nbi", first.read_bytes() + b"# edited")
    assert kernels.uncompiled_kernels() == [first.stem]
    (folder / "vec.broken-1.py311.nbi").write_bytes(b"not an index")
    assert kernels.uncompiled_kernels() == [first.stem]


def test_compiled_code_of_other_kernel_sources_is_dropped(tmp_path, monkeypatch):
    """numba checks only a compiled function's own file; a kernel inlining an updated helper
    of another module must not keep running its old code."""
    folder = _fake_cache(tmp_path, monkeypatch)
    folder.mkdir()
    stale = [folder / "solve.solve_rows-130.py311.nbi", folder / "solve.solve_rows-130.py311.1.nbc"]
    for path in stale:
        path.write_bytes(b"old")
    (folder / kernels.SOURCES_MARKER).write_text("0" * 64 + "\n")  # made from other sources
    assert kernels.drop_stale_cache()
    assert not any(path.exists() for path in stale)
    assert (folder / kernels.SOURCES_MARKER).read_text().strip() == kernels.sources_digest()
    stale[0].write_bytes(b"compiled from these sources")
    assert not kernels.drop_stale_cache() and stale[0].exists()  # same sources: kept


def test_a_first_run_says_once_that_it_compiles(tmp_path, monkeypatch, capsys):
    monkeypatch.setattr(kernels, "uncompiled_kernels", lambda: ["decode"])
    assert main(["run", SCENARIO, "--seconds", "0.1"]) == 0
    err = capsys.readouterr().err
    assert err.count("compiling the tick's kernels once (1-3 minutes of CPU); cached in ") == 1
    assert str(kernels.cache_dir()) in err
    assert main(["bench", "import", "nope.bvh"]) == 1  # no tick: nothing said
    assert "compiling" not in capsys.readouterr().err
    assert main(["run", str(tmp_path / "missing.yaml")]) == 1  # refused before a tick: the error alone
    assert capsys.readouterr().err.count("\n") == 1
    monkeypatch.setattr(kernels, "uncompiled_kernels", lambda: [])
    assert main(["run", SCENARIO, "--seconds", "0.1"]) == 0
    assert "compiling" not in capsys.readouterr().err


class _FakeProcess:
    """Stands for the process compiling the solver aside: records the command and the waits."""

    started: ClassVar[list[tuple[str, ...]]] = []

    def __init__(self, command, **_: object) -> None:
        self.started.append(tuple(command))
        self.waited = 0

    def wait(self) -> int:
        self.waited += 1
        return 0

    def poll(self) -> int:
        return 0


def test_a_first_run_compiles_the_solver_in_a_second_process_and_the_solve_waits_for_it(
        monkeypatch):
    monkeypatch.setattr("ecs_anim.runtime.kernels.subprocess.Popen", _FakeProcess)
    monkeypatch.setattr("ecs_anim.runtime.kernels.os.sched_getaffinity", lambda pid: {0, 1}, raising=False)
    _FakeProcess.started = []
    monkeypatch.setattr(kernels, "_solver_compile", {})
    monkeypatch.setattr(kernels, "uncompiled_kernels", lambda: [])
    kernels.compile_solver_aside()  # compiled already: nothing started, not asked again
    monkeypatch.setattr(kernels, "uncompiled_kernels", lambda: ["posture", "solve"])
    kernels.compile_solver_aside()
    assert _FakeProcess.started == []
    monkeypatch.setattr(kernels, "_solver_compile", {})
    monkeypatch.setattr("ecs_anim.runtime.kernels.os.sched_getaffinity", lambda pid: {0}, raising=False)
    kernels.compile_solver_aside()  # one core: this process compiles everything itself
    assert _FakeProcess.started == []
    monkeypatch.setattr(kernels, "_solver_compile", {})
    monkeypatch.setattr("ecs_anim.runtime.kernels.os.sched_getaffinity", lambda pid: {0, 1}, raising=False)
    kernels.compile_solver_aside()
    kernels.compile_solver_aside()  # once per process
    assert _FakeProcess.started == [kernels.SOLVER_COMMAND]
    child = kernels._solver_compile["process"]
    assert isinstance(child, _FakeProcess)
    BenchScene(2, constrained=True).tick()  # the solve waits for the other process, once
    kernels.wait_for_solver()
    assert child.waited == 1 and kernels._solver_compile["process"] is None


def test_the_solver_compiled_aside_is_the_one_a_solve_runs():
    """``python -m ecs_anim.runtime.kernels --solver`` (solving no character) compiles solve_rows for
    the argument types of a real solve: a real solve then finds it (no second compilation)."""
    from ecs_anim.runtime.kernels import solve as solve_module
    from ecs_anim.runtime.kernels.__main__ import compile_solver

    scene = BenchScene(2, constrained=True)
    scene.tick()
    scene.sim.close()
    compile_solver()
    solve_rows: Any = solve_module.solve_rows  # numba's dispatcher, once a simulation is built
    assert len(solve_rows.signatures) == 1


def _doc_commands(page: str, heading: str) -> list[list[str]]:
    """The ``ecs-anim`` command lines of a docs page's section (indented code), as argv: from
    the ``heading`` line (``## ...`` or ``### ...``) to the next heading of any level."""
    text = (REPO / "docs" / page).read_text(encoding="utf-8")
    block = text.split(f"\n{heading}\n", 1)[1].split("\n#", 1)[0]
    commands = []
    for line in block.splitlines():
        words = shlex.split(line.strip(), comments=True) if line.startswith("    ") else []
        if ".venv/bin/ecs-anim" in words:  # an example (the synopsis lines say ecs-anim)
            commands.append(words[words.index(".venv/bin/ecs-anim") + 1:])
    return commands


def test_the_readme_performance_commands_run(capsys):
    """Every command of docs/performance.md's bench commands, made quick (two small sizes, a
    few ticks, no timed cold start); taskset is left out (the figures are not checked)."""
    commands = _doc_commands("performance.md", "### The bench commands")
    assert len(commands) == 7, commands
    flags = {w for argv in commands for w in argv if w.startswith("--")}
    assert {"--constrained", "--threads", "--rotations", "--sizes", "--no-compile-timing",
            "--json", "--characters", "--seconds"} <= flags
    for argv in commands:
        assert argv[0] == "bench", argv
        if "--threads" in argv and int(argv[argv.index("--threads") + 1]) > \
                kernels.available_threads():
            continue  # a one-core machine cannot run the two-thread example
        assert main([*argv, *QUICK]) == 0, argv  # the last --sizes, --seconds count
        assert "characters hold 30 Hz" in capsys.readouterr().out or "--json" in argv


def test_the_readme_threads_examples_run(tmp_path, capsys):
    """docs/cli.md's ``--threads`` examples of run and view (a screenshot: it needs headless
    OpenGL, as tests/apps/viewer/test_viewer.py's do), their outputs in a temporary folder."""
    commands = [c for c in _doc_commands("cli.md", "## Threads") if "--threads" in c]
    assert {c[0] for c in commands} >= {"run", "view"}
    for argv in commands:
        argv = [w.replace("out/", f"{tmp_path}/") for w in argv]
        if "--screenshot" in argv:
            from support.gl import need_gl

            need_gl()
            assert main(argv) == 0, argv
            continue
        assert main([*argv, "--seconds", "0.1"]) == 0, argv


def _one_tick_in_a_child(n: int) -> tuple[int, ...]:
    scene = BenchScene(n)
    scene.tick()
    shape = scene.sim.store.positions.shape
    scene.sim.close()
    return tuple(shape)


def test_a_process_that_ran_the_kernels_can_fork_workers_that_run_them():
    """The batch's pool forks after the kernels ran on this process's threads, which a forked
    child does not have: each process makes its own (:func:`ecs_anim.runtime.kernels.over_chunks`)."""
    import multiprocessing
    import os

    # Every core, not the default (which the machine's load lowers to one: no threads started).
    most = kernels.set_threads(kernels.available_threads())
    try:
        assert _one_tick_in_a_child(16)[0] == 16  # the kernels' threads start in this process
        assert (os.getpid() in kernels._pools) == (most > 1)
        with multiprocessing.get_context("fork").Pool(1) as pool:
            assert pool.map(_one_tick_in_a_child, [12]) == [(12, 22, 3)]
    finally:
        kernels.set_threads(None)


def test_the_constrained_bench_reaches_its_targets_and_prints_the_errors(capsys):
    """The constrained bench's wrist and elbow targets are ones the arm takes (points of the
    walker's own body, fixed to its shoulder): both met, the centre of mass held within the
    tenth of its tolerance the solve stops at."""
    assert main(["bench", "--constrained", "--json", *QUICK]) == 0
    errors = json.loads(capsys.readouterr().out)["errors_mm"]
    assert errors["wrist_max"] < 1e-6 and errors["elbow_max"] < 1e-6
    assert 0.0 <= errors["com_mean"] <= errors["com_max"] <= 0.1
    assert main(["bench", "--constrained", *QUICK]) == 0
    assert "errors reached at 8: wrist 0.000 mm mean" in capsys.readouterr().out


def test_the_errors_over_ticks_leave_out_the_ticks_that_solved_none():
    """A frame budget may solve no character on a tick (its errors NaN) or on every tick: the
    errors are over the ticks that solved some, and None (printed "none solved"), not NaN,
    when none did."""
    nan = float("nan")
    some = errors_over_ticks([{"wrist_mean": 1.0, "wrist_max": 2.0},
                              {"wrist_mean": nan, "wrist_max": nan},
                              {"wrist_mean": 3.0, "wrist_max": 5.0}])
    assert some == {"wrist_mean": 2.0, "wrist_max": 5.0}
    assert errors_over_ticks([{"wrist_mean": nan, "wrist_max": nan}] * 2) == {
        "wrist_mean": None, "wrist_max": None}


def test_a_budget_that_drops_every_character_prints_none_solved(capsys):
    """A budget no tick can hold drops every character on every tick: the bench says none was
    solved (docs/cli.md, bench), not NaN errors, and that the budget cannot hold."""
    assert main(["bench", "--constrained", "--budget-ms", "0.001", "--characters", "8",
                 *QUICK]) == 0
    out = capsys.readouterr().out
    assert "errors reached at 8: none solved" in out and "nan" not in out
    assert "the budget cannot hold at 8" in out
    # its last resort: every character played, grounded and posed every 8th tick only (on the
    # compiled kernels: while they compile aside, the numpy references update every row)
    if kernels.load_kernels():
        assert "played, grounded and posed less often than every tick (median a tick): 8 every 8" \
            in out


def test_the_bench_arm_targets_are_ones_the_arm_takes():
    rng = np.random.default_rng(36)
    upper, fore = rng.uniform(0.15, 0.4, 20), rng.uniform(0.15, 0.4, 20)
    wrist, elbow = arm_targets(upper, fore)
    np.testing.assert_allclose(np.linalg.norm(elbow, axis=1), upper, rtol=0, atol=1e-12)
    np.testing.assert_allclose(np.linalg.norm(wrist - elbow, axis=1), fore, rtol=0, atol=1e-12)
    np.testing.assert_allclose(np.linalg.norm(wrist, axis=1), 0.8 * (upper + fore), rtol=0,
                               atol=1e-12)


def test_the_peer_task_meets_the_elbow_without_moving_the_feet(capsys):
    """The IK comparisons' task: wrist and elbow targets the arm takes from where its shoulder
    stands, feet planted, centre of mass held. The root's move for the centre of mass carries
    the shoulder off the sphere on which the elbow target can be met (17 mm off, and the elbow
    with it, before the trunk could turn it back); the trunk brings it back."""
    result = peer_task()
    assert result["wrist_mm"] < 1e-6 and result["elbow_mm"] < 1.0
    assert result["shoulder_off_sphere_mm"] < 1.0 and result["shoulder_moved_mm"] < 10.0
    assert result["feet_moved_mm"] < 1e-6 and result["com_mm"] <= 0.1
    assert main(["bench", "--peer-task"]) == 0
    out = capsys.readouterr().out
    assert "elbow" in out and "shoulder moved" in out
