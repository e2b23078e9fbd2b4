"""The library as a library: every API mistake is an EcsAnimError of one line, events come in
time order, warnings go through logging, and importing the package changes no global state."""

from __future__ import annotations

import subprocess
import sys

import pytest

from conftest import MOTIONS_DIR
from ecs_anim import (
    Activation,
    ClipStarted,
    EcsAnimError,
    Morphology,
    MotionPlayer,
    Placement,
    Remove,
    Simulation,
    SolverSettings,
    Stairs,
    Trigger,
    import_bvh,
)


@pytest.mark.parametrize("call, message", [
    (lambda: Morphology.preset("tal"), "unknown morphology preset 'tal' (did you mean 'tall'?)"),
    (lambda: Morphology.from_stature(175), "stature must be between 0.3 and 3 m, got 175 "
                                           "(centimetres? statures are in metres)"),
    (lambda: Morphology.from_stature(1.7, proportions="teen"), "proportions must be 'adult' or "
                                                               "'child', got 'teen'"),
    (lambda: Stairs(run_m=-1.0), "stairs: run_m must be > 0"),
    (lambda: Activation(2.0, 1.0), "activation stop_s 1.0 is before start_s 2.0"),
    (lambda: SolverSettings(budget_ms=-1.0), "budget_ms must be a positive number"),
])
def test_api_mistakes_are_one_line_ecs_anim_errors(call, message):
    with pytest.raises(EcsAnimError) as caught:
        call()
    assert str(caught.value).startswith(message) and "\n" not in str(caught.value)
    assert isinstance(caught.value, ValueError)  # code that checks values keeps working


def test_one_steps_events_are_in_time_order():
    """A trigger that removes a character when another's clip starts: the removal is stamped
    with the posture it is first missing from, and listed after the clip starts of this one."""
    sim = Simulation({"walk": import_bvh(MOTIONS_DIR / "walk.bvh")})
    a = sim.spawn("a", Morphology.preset("child"), MotionPlayer("walk"))
    b = sim.spawn("b", Morphology.preset("child"), MotionPlayer("walk"), Placement((0.0, 2.0)))
    sim.add_trigger(Trigger("drop_b", ClipStarted(a), (Remove(b),)))
    sim.step()
    events = sim.events()
    kinds = [(e.kind, e.character) for e in events]
    assert kinds[:2] == [("clip_started", "a"), ("clip_started", "b")]
    assert kinds[-1] == ("removed", "b") and ("removed", "b") not in kinds[:-1]
    times = [e.time_s for e in events]
    assert times == sorted(times) and times[-1] == pytest.approx(sim.dt) and times[0] == 0.0


def run_python(code: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                          timeout=120, check=False)


def test_importing_the_package_changes_no_global_state():
    done = run_python(
        "import os, resource, sys\n"
        "env = dict(os.environ)\n"
        "import ecs_anim, ecs_anim.systems, ecs_anim.runtime.kernels.decode\n"
        "no_numba = 'numba' not in sys.modules\n"
        "from ecs_anim.runtime.kernels.vec import with_numba\n"
        "with_numba()\n"
        "print(dict(os.environ) == env, no_numba, 'numba' in sys.modules)\n")
    assert done.returncode == 0, done.stderr
    # No variable set (numba: the kernels' own); numba imported only once a kernel is needed.
    assert done.stdout.split() == ["True", "True", "True"]


def test_a_warning_reaches_stderr_through_logging_when_nothing_configured_it():
    done = run_python(
        "import numpy as np\n"
        f"from ecs_anim import Morphology, MotionPlayer, Simulation, import_bvh\n"
        f"sim = Simulation({{'idle': import_bvh({str(MOTIONS_DIR / 'idle.bvh')!r})}})\n"
        "e = sim.spawn('a', Morphology.preset('child'), MotionPlayer('idle'))\n"
        "k = sim.add_constraint(e, 'reach', 'wrist_r', 1.0, target_in_world=(0.3, -0.2, 0.9))\n"
        "sim.step(); sim.set_target(k, (np.nan, 0.0, 1.0)); sim.step()\n")
    assert done.returncode == 0, done.stderr
    assert done.stderr.strip() == ("warning: t=0.033 s: constraint 'reach' has a target that is "
                                   "not finite or beyond 1,000 km and is switched off until a "
                                   "new target is set; the others go on")
