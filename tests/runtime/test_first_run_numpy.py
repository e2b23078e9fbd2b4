"""Issue 36, item 6: a first run ticks on the systems' numpy references while the kernels compile
aside, then on the kernels from a tick on. Every system's numpy path calls no kernel, and a run
that switches (or never does) ends as one on the kernels throughout, to 1e-9 m."""

from __future__ import annotations

import subprocess
import sys

import numpy as np
import pytest

from conftest import REPO, SCENARIOS_DIR
from ecs_anim.runtime import capsule_overlaps as reference
from ecs_anim.runtime import kernels
from ecs_anim.runtime.kernels import capsules as compiled
from support.scenarios import run

FIGHT_TICKS = 90  # fight_training: 3 s at 30 Hz


@pytest.fixture(scope="module")
def on_kernels():
    return run("fight_training")


@pytest.mark.parametrize("numpy_ticks", [FIGHT_TICKS, 40])
def test_the_fight_on_numpy_ends_as_on_the_kernels(on_kernels, numpy_ticks):
    """Every tick on numpy, or the first 40 (then the kernels, as when they are compiled
    aside): every joint, constraint error and weight within 1e-9 m of the run on the kernels
    throughout, the same events, and every figure of the report within 1e-9."""
    result = run("fight_training", numpy_ticks=numpy_ticks)
    for key in ("positions", "errors", "weights", "com"):
        np.testing.assert_allclose(result[key], on_kernels[key], rtol=0, atol=1e-9)
    assert [(e.kind, e.entity, e.tick) for e in result["events"]] == \
        [(e.kind, e.entity, e.tick) for e in on_kernels["events"]]
    assert_same_figures(result["report"], on_kernels["report"])


#: The report's keys of time taken, which no two runs share.
TIMES = ("ms_per_tick", "timing")


@pytest.mark.parametrize("name", sorted(p.stem for p in SCENARIOS_DIR.glob("*.yaml")
                                         if p.stem not in ("fight_training", "steered_crowd")))
def test_every_scenario_on_numpy_ends_as_on_the_kernels(name):
    """Every other shipped scenario but the steered crowd (it waits for the kernels: see
    :func:`test_a_first_run_steering_characters_waits_for_the_kernels`), all on numpy: joints,
    errors and centres of mass within 1e-9 m of the kernels' run, the report's figures within
    1e-9."""
    on_numpy, kernels_run = run(name, numpy_ticks=10**9), run(name)
    for key in ("positions", "errors", "com"):
        np.testing.assert_allclose(on_numpy[key], kernels_run[key], rtol=0, atol=1e-9)
    assert_same_figures(on_numpy["report"], kernels_run["report"])


def assert_same_figures(a, b, where="report"):
    """``a`` and ``b`` (a report's JSON values) equal, numbers within 1e-9 (but times)."""
    if isinstance(a, dict):
        assert sorted(a) == sorted(b), where
        for key in a:
            if key not in TIMES:
                assert_same_figures(a[key], b[key], f"{where}.{key}")
    elif isinstance(a, list | tuple):
        assert len(a) == len(b), where
        for k, (x, y) in enumerate(zip(a, b, strict=True)):
            assert_same_figures(x, y, f"{where}[{k}]")
    elif isinstance(a, float) and isinstance(b, float):
        assert (np.isnan(a) and np.isnan(b)) or abs(a - b) <= 1e-9, (where, a, b)
    else:
        assert a == b, where


def crowded_postures(on_kernels, seed=3):
    """The fight's eight postures at several ticks, each body moved to a seeded place within
    0.5 m of the others (bodies in each other), and their lengths."""
    rng = np.random.default_rng(seed)
    for tick in (5, 30, 60, 85):
        positions = on_kernels["positions"][tick].copy()
        pelvis = positions[:, 0, :2].copy()
        positions[..., :2] += rng.uniform(-0.25, 0.25, (len(pelvis), 2))[:, None] - pelvis[:, None]
        yield positions, on_kernels["lengths"]


@pytest.mark.parametrize("block", [None, 3])
def test_capsules_and_overlaps_in_numpy_equal_the_kernels(on_kernels, monkeypatch, block):
    """Capsules (ends, radii, centre, bounds), each body's deepest overlap (depth, whom,
    which capsules, the way out, the point) and the bodies near some: within 1e-9 m, on bodies
    in each other, for every row and for some rows; also a few rows and pairs at a time."""
    if block is not None:
        monkeypatch.setattr(reference, "ROWS_PER_BLOCK", block)
        monkeypatch.setattr(reference, "PAIRS_PER_BLOCK", block)
    checked = 0
    for positions, lengths in crowded_postures(on_kernels):
        n = positions.shape[0]
        body = compiled.capsules(positions, lengths)
        mine = reference.capsules(positions, lengths, compiled.Capsules.empty(n))
        for a, b in zip(mine, body, strict=True):
            np.testing.assert_allclose(a, b, rtol=0, atol=1e-9)
        found = compiled.overlaps(body, compiled.grid_of(body))
        ours = reference.overlaps(mine)
        assert (found.depth > 0.01).sum() >= n // 2  # deep overlaps to compare
        for field_numpy, field_kernel in zip(ours, found, strict=True):
            np.testing.assert_allclose(field_numpy, field_kernel, rtol=0, atol=1e-9)
        some = np.array([1, 4, 6])
        kept = compiled.overlaps(body)._replace(depth=np.full(n, 7.0))
        again = reference.overlaps(mine, some, kept)
        assert (again.depth[np.setdiff1d(np.arange(n), some)] == 7.0).all()
        np.testing.assert_allclose(again.depth[some], found.depth[some], rtol=0, atol=1e-9)
        grid = compiled.grid_of(body)
        assert list(reference.near_rows(mine, some)) == list(compiled.near_rows(body, grid, some))
        checked += 1
    assert checked == 4


def test_numpy_ticks_call_no_kernel():
    """A first run's numpy ticks, numba made unimportable: the fight ticks through its kicks,
    ward-offs and punches without a kernel (any would import numba)."""
    code = (
        "import sys\n"
        "sys.modules['numba'] = None\n"
        "from ecs_anim.runtime import kernels\n"
        "kernels.compile_aside()\n"
        "kernels.uncompiled_kernels = lambda: ['all']\n"
        "kernels._start_compiling_aside = lambda start: "
        "kernels._background.update(process=None, start=start) or True\n"
        "kernels.compiling_elsewhere = lambda: 1\n"
        "from ecs_anim.scenario import build_simulation, load_scenario\n"
        f"scenario = load_scenario({str(REPO / 'scenarios' / 'fight_training.yaml')!r})\n"
        "with build_simulation(scenario, rotations=True) as sim:\n"
        "    sim.vertebrae = 5\n"
        f"    for _ in range({FIGHT_TICKS}):\n"
        "        sim.step()\n"
        "    print(sim.compiled, sim.tick, 'numba' in sys.modules and sys.modules['numba'])\n")
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                          timeout=600, check=False)
    assert done.returncode == 0, done.stderr
    assert done.stdout.split() == ["False", str(FIGHT_TICKS), "None"]


def test_a_first_run_ticks_on_numpy_until_the_child_is_done(monkeypatch, tmp_path):
    """With the kernels to compile and ``compile_aside`` on: the simulation is built at once,
    ticks on numpy while the child runs (its marker names it) and while a thread loads the
    kernels once it ended, then on the kernels (switched between two ticks); a child standing
    in for the compile, ended when the test says."""
    from ecs_anim.scenario import build_simulation, load_scenario

    done = tmp_path / "done"
    monkeypatch.setattr(kernels, "load_figures", {})
    monkeypatch.setattr(kernels, "_background", {})
    monkeypatch.setattr(kernels, "_cache_subfolder", lambda: tmp_path)
    monkeypatch.setattr(kernels, "uncompiled_kernels", lambda: ["decode"])
    monkeypatch.setattr(kernels, "COMPILE_COMMAND", (
        sys.executable, "-c",
        f"import pathlib, time\nwhile not pathlib.Path({str(done)!r}).exists(): time.sleep(0.02)",
        "ecs_anim.runtime.kernels"))  # (in its command line: the marker's check reads it)
    kernels.compile_aside()
    try:
        scenario = load_scenario(REPO / "scenarios" / "fight_training.yaml")
        with build_simulation(scenario) as sim:
            for _ in range(3):
                sim.step()
                assert not sim.compiled
            child = kernels._background["process"]
            assert kernels.compiling_elsewhere() == child.pid and kernels.kernels_pending()
            done.touch()
            child.wait()
            sim.step()  # a thread loads the kernels from the cache while the ticks go on
            kernels._background["loader"].join()
            sim.step()
            assert sim.compiled and kernels.load_figures["aside"]
            assert not kernels.kernels_pending()
    finally:
        kernels.compile_aside(False)


def test_a_first_run_steering_characters_waits_for_the_kernels(monkeypatch, tmp_path):
    """Local avoidance has no numpy reference, and on the references a crowd's paths part (1e-15
    differences deciding a walker's way round another): a simulation steering characters waits
    for the compiling child (a stand-in here, 0.3 s) before its first tick, on the kernels."""
    from ecs_anim.scenario import build_simulation, load_scenario

    monkeypatch.setattr(kernels, "load_figures", {})
    monkeypatch.setattr(kernels, "_background", {})
    monkeypatch.setattr(kernels, "_cache_subfolder", lambda: tmp_path)
    monkeypatch.setattr(kernels, "uncompiled_kernels", lambda: ["avoidance"])
    monkeypatch.setattr(kernels, "COMPILE_COMMAND",
                        (sys.executable, "-c", "import time; time.sleep(0.3)"))
    kernels.compile_aside()
    try:
        scenario = load_scenario(REPO / "scenarios" / "steered_crowd.yaml")
        with build_simulation(scenario) as sim:
            assert not sim.compiled
            sim.step()
            assert sim.compiled and kernels.load_figures["aside"]
    finally:
        kernels.compile_aside(False)


def test_the_compiling_marker_names_a_running_compiler_only(monkeypatch, tmp_path):
    """The marker a compiling child leaves names it while it runs, and nothing once it ended
    (a zombie too) or when its id is another program's: no run waits for a child long gone."""
    import os

    monkeypatch.setattr(kernels, "_cache_subfolder", lambda: tmp_path)
    marker = tmp_path / kernels.COMPILING_MARKER
    assert kernels.compiling_elsewhere() is None  # no marker
    marker.write_text(f"{os.getpid()}\n")  # this test's process: no compiler
    assert kernels.compiling_elsewhere() is None
    child = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(30)",
                              "ecs_anim.runtime.kernels"])
    try:
        marker.write_text(f"{child.pid}\n")
        assert kernels.compiling_elsewhere() == child.pid
    finally:
        child.kill()
        child.wait()
    assert kernels.compiling_elsewhere() is None
