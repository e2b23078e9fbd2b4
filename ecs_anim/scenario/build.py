"""A simulation made from a loaded :class:`~ecs_anim.scenario.spec.Scenario`."""

from __future__ import annotations

import dataclasses
from typing import Any

from ecs_anim.core.errors import (
    EcsAnimError,
)
from ecs_anim.runtime.simulation import Simulation
from ecs_anim.runtime.triggers import constraints_named
from ecs_anim.scenario.spec import Scenario, SteeringSpec
from ecs_anim.scenario.triggers import bind_trigger


def apply_steering(sim: Simulation, entity: int, spec: SteeringSpec, heading_rad: float) -> None:
    """Give a spawned character its scenario steering: its locomotion set, then its path, or
    its speed along ``heading_rad`` (without ``speed_m_s`` nor a path it stands on its idle
    motion, or walks on at its own speed if it has none)."""
    loco = spec.locomotion
    sim.set_locomotion(entity, loco["walk"], loco.get("idle"), loco.get("run"))
    if not spec.avoid:
        sim.set_avoidance(entity, False)
    if spec.path_m:
        sim.follow_path(entity, spec.path_m, spec.speed_m_s)
    elif spec.speed_m_s is not None or "idle" not in loco:
        sim.steer(entity, heading_rad, spec.speed_m_s)


def build_simulation(scenario: Scenario, window: bool = False,
                     rotations: bool = False) -> Simulation:
    """A :class:`~ecs_anim.runtime.simulation.Simulation` with the scenario's characters spawned."""
    sim = Simulation(scenario.motions, scenario.ground, scenario.fps, window=window,
                     rotations=rotations)
    sim.tables = tuple(scenario.tables)
    if scenario.solver:
        sim.solver_settings = dataclasses.replace(sim.solver_settings, **scenario.solver)
    entities = {c.name: sim.spawn(c.name, c.morphology, c.player, c.placement, c.team,
                                  c.com_control, c.com_target_xy)
                for c in scenario.characters}
    added: dict[tuple[int, str], int] = {}
    for i, c in enumerate(scenario.characters):
        for k in c.constraints:
            clock = -1 if k.clock_motion is None else sim.bank.index(k.clock_motion)
            uid = sim.add_constraint(entities[c.name], k.name, k.point, k.priority, k.activation,
                                     k.target_in_world,
                                     None if k.target_character is None else entities[k.target_character],
                                     k.target_point, **k.options, clock=clock)
            added[i, k.name] = uid
            if k.target_keyframes is not None:
                sim.add_target_track(uid, *k.target_keyframes)
    for c in scenario.characters:
        if c.steering is not None:
            apply_steering(sim, entities[c.name], c.steering, c.placement.heading_rad)
    order = [entities[c.name] for c in scenario.characters]
    uids = {placeholder: added[ref] for placeholder, ref in enumerate(scenario.trigger_constraints)
            if ref in added}
    for trigger in scenario.triggers:
        missing = [scenario.trigger_constraints[u] for x in (trigger.when, *trigger.then)
                   for u in constraints_named(x) if u not in uids]
        if missing:
            who, name = missing[0]
            raise EcsAnimError(f"trigger {trigger.name!r} names constraint "
                               f"{scenario.characters[who].name}.{name}, which is not in the scenario")
        sim.add_trigger(bind_trigger(trigger, order, uids))
    return sim


def measured_run(scenario: Scenario) -> dict[str, Any]:
    """The scenario played headless to its end (``duration_s`` at ``fps``), and ``run``'s
    figures of it: :meth:`~ecs_anim.runtime.metrics.MetricsRecorder.report`."""
    from ecs_anim.runtime.metrics import MetricsRecorder

    with build_simulation(scenario) as sim:
        metrics = MetricsRecorder(sim)
        for _ in range(round(scenario.duration_s * scenario.fps)):
            sim.step()
            metrics.record()
        return metrics.report()
