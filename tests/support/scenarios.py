"""A shipped scenario run headless to its end, with what each tick left behind."""

from __future__ import annotations

from contextlib import contextmanager

import numpy as np

from conftest import SCENARIOS_DIR
from ecs_anim.core.morphology import centres_of_mass
from ecs_anim.runtime import kernels
from ecs_anim.runtime.metrics import MetricsRecorder
from ecs_anim.scenario import build_simulation, load_scenario


def run(name, drop=(), drop_triggers="", numpy_ticks=0):
    """Run a scenario to its end; per tick: positions (n, J, 3), constraint errors and weights;
    the events. ``drop``: constraints left out; ``drop_triggers``: triggers whose name starts so;
    ``numpy_ticks``: the first ticks on the systems' numpy references (as while the kernels
    compile aside on a first run), the others on the kernels."""
    scenario = load_scenario(SCENARIOS_DIR / f"{name}.yaml")
    for c in scenario.characters:
        c.constraints = [k for k in c.constraints if k.name not in drop]
    if drop_triggers:
        scenario.triggers = [t for t in scenario.triggers if not t.name.startswith(drop_triggers)]
    with build_simulation(scenario) as sim:
        metrics = MetricsRecorder(sim)
        ticks = round(scenario.duration_s * scenario.fps)
        positions, errors, weights, com, events = [], [], [], [], []
        for tick in range(ticks):
            sim.compiled = tick >= numpy_ticks
            with on_numpy_until_told(tick < numpy_ticks):
                sim.step()
            events += sim.events()
            metrics.record()
            st = sim.store
            positions.append(st.positions.copy())
            errors.append(sim.constraints.error.copy())
            weights.append(sim.constraints.weight.copy())
            com.append(centres_of_mass(st.positions, st.segment_mass_kg, st.segment_com_fraction))
        index = {f"{sim.names()[o]}.{n}": k for k, (o, n) in
                 enumerate(zip(sim.constraints.owner, sim.constraints.names, strict=True))}
        return {"names": sim.names(), "positions": np.array(positions), "errors": np.array(errors),
                "weights": np.array(weights), "com": np.array(com), "index": index,
                "report": metrics.report(), "leg": sim.leg_length(), "events": events,
                "lengths": sim.store.lengths.copy()}


@contextmanager
def on_numpy_until_told(on: bool):
    """While ``on``: a simulation with ``compiled`` off stays on its numpy references (no
    kernels found ready between two ticks)."""
    if not on:
        yield
        return
    saved = kernels.poll_kernels
    kernels.poll_kernels = lambda wait=False: False
    try:
        yield
    finally:
        kernels.poll_kernels = saved


def clip_on_body(motion, stature_m: float, ground):
    """A scenario of one character (adult proportions, ``stature_m`` tall) playing ``motion``
    once from the origin over ``ground``, at the clip's rate for its length (a batch job's)."""
    from ecs_anim.apps.batch.plan_parts import body_from_text
    from ecs_anim.scenario import clip_scenario

    return clip_scenario(motion, body_from_text(f"stature_{stature_m}").morphology, ground,
                         path="clip_on_body")
