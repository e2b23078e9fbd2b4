"""The tick reuses the memory it frees (ecs_anim.runtime.allocator): no page is faulted in anew on a
steady tick of a large constrained scene (before, glibc handed the tick's large arrays back to
the kernel: about 950 faults a tick at 3,200 characters)."""

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
    before = resource.getrusage(resource.RUSAGE_SELF).ru_minflt
    for _ in range(3):
        scene.tick()
    faults_per_tick = (resource.getrusage(resource.RUSAGE_SELF).ru_minflt - before) / 3
    scene.sim.close()
    assert faults_per_tick < 20, faults_per_tick
