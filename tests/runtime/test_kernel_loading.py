"""Issue 36, item 6: every kernel a simulation ticks with is in memory once it is built (no tick
loads or compiles one: the first constraint switched on cost its tick 95-117 ms, the first
cross-fade compiled a second specialisation of the samplers), and numba is imported only then."""

from __future__ import annotations

import subprocess
import sys

from conftest import REPO
from ecs_anim.runtime import kernels
from ecs_anim.scenario import build_simulation, load_scenario


def test_no_tick_loads_a_kernel():
    scenario = load_scenario(REPO / "scenarios" / "fight_training.yaml")  # constraints, fades
    with build_simulation(scenario, rotations=True) as sim:
        called = kernels.called_kernels()
        built = {k.py_func.__qualname__: len(k.overloads) for k in called}
        for _ in range(round(scenario.duration_s * scenario.fps)):
            sim.step()
        assert {k.py_func.__qualname__: len(k.overloads) for k in called} == built
    assert built["sample_rows"] >= 1 and built["solve_rows"] >= 1  # loaded before


def test_numba_is_imported_by_a_simulation_built_not_by_the_package():
    code = ("import sys\n"
            "import ecs_anim\n"
            "from ecs_anim.scenario import load_scenario\n"
            f"scenario = load_scenario({str(REPO / 'scenarios' / 'fight_training.yaml')!r})\n"
            "before = 'numba' in sys.modules\n"
            "from ecs_anim.scenario import build_simulation\n"
            "build_simulation(scenario).close()\n"
            "print(before, 'numba' in sys.modules)\n")
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                          timeout=600, check=False)
    assert done.returncode == 0, done.stderr
    assert done.stdout.split() == ["False", "True"]
