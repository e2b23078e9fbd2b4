"""Shared paths and fixtures: the repository's folders, the real captured clips in
../shared/mocap (never copied into the repo), and the shipped motions imported once per run.

Test files live in folders mirroring the package (tests/core, tests/io/bvh, ...); pytest puts
this folder on sys.path, so every test imports ``conftest`` and the helper modules of
``tests/support`` by their top-level names. No test imports another test file.
"""

from __future__ import annotations

import copy
import os
from functools import cache
from pathlib import Path

import pytest

from ecs_anim.io.importing import import_bvh
from ecs_anim.motion.clip import NormalizedMotion, save_nmo

#: The repository's root, and its folders the tests read.
REPO = Path(__file__).resolve().parents[1]
TESTS_DIR = REPO / "tests"
DATA_DIR = TESTS_DIR / "data"
SCENARIOS_DIR = REPO / "scenarios"
MOTIONS_DIR = SCENARIOS_DIR / "motions"
MOCAP_DIR = Path(os.environ.get("ECS_ANIM_MOCAP", REPO.parent / "shared" / "mocap"))


#: The most workers ``pytest -n auto`` (the README's test command) starts: each loads the
#: kernels and some tests hold a few hundred MB, and past four the longest files (the bench's,
#: the batch's: a file runs on one worker) set the suite's time anyway.
MAX_TEST_WORKERS = 4


@pytest.hookimpl(optionalhook=True)  # (an xdist hook: `-p no:xdist` must still run the tests)
def pytest_xdist_auto_num_workers(config: pytest.Config) -> int:
    """``-n auto``: a worker per core this process may run on, at most :data:`MAX_TEST_WORKERS`."""
    cores = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count()
    return max(1, min(cores or 1, MAX_TEST_WORKERS))


def mocap_files(pattern: str = "*.bvh") -> list[Path]:
    return sorted(MOCAP_DIR.glob(pattern)) if MOCAP_DIR.is_dir() else []


def require_mocap() -> None:
    if not MOCAP_DIR.is_dir():
        pytest.skip(f"real captured clips not found at {MOCAP_DIR} (they live in ../shared/mocap; "
                    "CI always has them)")


def mocap_params(pattern: str = "*.bvh") -> list[object]:
    files = mocap_files(pattern)
    if not files:
        return [pytest.param(None, marks=pytest.mark.skip(
            reason=f"real captured clips not found at {MOCAP_DIR} (../shared/mocap)"))]
    return [pytest.param(f, id=f.name) for f in files]


# --- the shipped motions (scenarios/motions) ----------------------------------------------------


@cache
def _imported(name: str) -> NormalizedMotion:
    return import_bvh(MOTIONS_DIR / f"{name}.bvh")


def shipped_motion(name: str) -> NormalizedMotion:
    """``scenarios/motions/<name>.bvh`` imported: a fresh copy each call (the import itself runs
    once per session), so a test may change what it is given."""
    return copy.deepcopy(_imported(name))


@pytest.fixture(scope="module")
def walk() -> NormalizedMotion:
    """The shipped walk, one copy per test module (its tests share it)."""
    return shipped_motion("walk")


@pytest.fixture(scope="module")
def idle() -> NormalizedMotion:
    """The shipped idle, one copy per test module (its tests share it)."""
    return shipped_motion("idle")


@pytest.fixture(scope="module")
def motions() -> dict[str, NormalizedMotion]:
    """A locomotion set: the shipped idle, walk and run, one copy per test module."""
    return {name: shipped_motion(name) for name in ("idle", "walk", "run")}


@pytest.fixture(scope="session")
def walk_nmo(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The shipped walk saved as ``walk.nmo`` (read only: a test edits a copy of it)."""
    path = tmp_path_factory.mktemp("nmo") / "walk.nmo"
    save_nmo(import_bvh(MOTIONS_DIR / "walk.bvh"), path)
    return path
