"""The tick reuses the memory it frees (ecs_anim.runtime.allocator): no page is faulted in anew on a
steady tick of a large constrained scene (before, glibc handed the tick's large arrays back to
the kernel: about 1,000 faults on every other warm tick at 3,200 characters, measured again
2026-12-07).

Each tick is judged against under a third of that: inside the full suite a tick now and then grows
Python's own heap by a few dozen pages (CI once saw 24.7 a tick averaged over three, against 5-14
alone), which is not the tick's arrays and is not what this guards."""

from __future__ import annotations

import resource
import sys

import pytest

from ecs_anim.runtime.allocator import keep_freed_memory
from ecs_anim.runtime.bench_scene import BenchScene


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="glibc's allocator: Linux only")
def test_a_steady_constrained_tick_faults_no_page_in():
    assert keep_freed_memory()  # glibc took it (the command line asks for it, a library never)
    scene = BenchScene(3200, constrained=True)  # at 1,600 glibc faulted little already
    for _ in range(3):
        scene.tick()
    faults_per_tick = []
    for _ in range(9):
        before = resource.getrusage(resource.RUSAGE_SELF).ru_minflt
        scene.tick()
        faults_per_tick.append(resource.getrusage(resource.RUSAGE_SELF).ru_minflt - before)
    scene.sim.close()
    assert max(faults_per_tick) < 300, faults_per_tick
