"""Extending the ECS: a component and a system of your own, through the public API only.

Four characters walk past each other. Two of them carry a ``Watcher`` component (plain data, as
esper's components are); the ``LookAtNearest`` system, put into the schedule with
``Simulation.add_system``, processes exactly the characters its query gives: every tick, for all
watchers at once (arrays, no loop over characters), it finds the nearest other character's head
on the last posture, writes that distance into a store column of its own
(``store.columns["nearest_m"]``, added with ``store.add_column``: it grows and shrinks with the
characters) and turns the watcher's head-orientation constraint toward it. Each simulated second
it prints, per watcher, how far the nearest head is and how far (degrees) the head is from
looking at it.

    .venv/bin/python examples/look_at_nearest.py [--seconds 4]

Exit status 0 when every watcher's head kept within ``--tolerance-deg`` of its target once the
look eased in, 1 when not (or on a non-finite pose), 2 on a bad argument.
"""

from __future__ import annotations

import argparse
import math
import sys
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ecs_anim import (
    JOINT_INDEX,
    Activation,
    EcsAnimError,
    Morphology,
    MotionPlayer,
    Placement,
    Simulation,
    System,
    import_bvh,
)
from ecs_anim.systems import ConstraintSolve

MOTIONS = Path(__file__).resolve().parents[1] / "scenarios" / "motions"
HEAD = JOINT_INDEX["head"]


@dataclass(frozen=True)
class Watcher:
    """Data only: this character turns its head toward the nearest other character."""

    look_uid: int  # its head-orientation constraint (Simulation.add_constraint's id)


class LookAtNearest(System):
    """Each watcher's head turned toward the nearest other character's head (last posture).

    Rows: characters with a Watcher.
    Reads: store.positions (the last tick's posture), columns.look_uid.
    Writes: columns.nearest_m, the look constraints' targets.
    """

    query = (Watcher,)
    reads = ("positions", "columns.look_uid")
    writes = ("columns.nearest_m", "constraints.target")

    def run(self, dt: float) -> None:
        st, rows = self.sim.store, self.rows()
        heads = st.positions[:, HEAD]  # (n, 3) metres, world
        apart = np.linalg.norm(heads[rows][:, None] - heads[None], axis=-1)  # (r, n)
        apart[np.arange(rows.size), rows] = np.inf  # not oneself
        nearest = np.argmin(apart, axis=1)
        st.columns["nearest_m"][rows] = apart[np.arange(rows.size), nearest]
        towards = heads[nearest] - heads[rows]
        towards[:, 2] = 0.0  # look level: turn the head, do not nod
        length = np.linalg.norm(towards, axis=1, keepdims=True)
        direction = np.where(length > 1e-6, towards / np.maximum(length, 1e-6), [1.0, 0.0, 0.0])
        self.sim.set_targets(st.columns["look_uid"][rows], direction)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--seconds", type=float, default=4.0)
    parser.add_argument("--tolerance-deg", type=float, default=2.0)
    args = parser.parse_args(argv)
    if not (math.isfinite(args.seconds) and args.seconds > 0):
        parser.error("--seconds must be a positive number")

    walk = import_bvh(MOTIONS / "walk.bvh")
    sim = Simulation({"walk": walk})
    starts = [((0.0, 0.0), 0.0), ((6.0, 0.6), math.pi), ((0.0, 1.5), 0.0), ((6.0, -1.2), math.pi)]
    entities = [sim.spawn(f"walker_{i}", Morphology.from_stature(1.55 + 0.12 * i),
                          MotionPlayer("walk", start_s=0.3 * i), Placement(xy, heading))
                for i, (xy, heading) in enumerate(starts)]
    sim.store.add_column("look_uid", dtype=np.int64, fill=-1)
    sim.store.add_column("nearest_m", fill=np.nan)
    watchers = entities[:2]
    look_in = Activation(0.3, 1e9, ease_in_s=0.3)
    for entity in watchers:
        uid = sim.add_constraint(entity, "look", "head", 5.0, look_in, (1.0, 0.0, 0.0),
                                 kind="orientation", axis=(1.0, 0.0, 0.0))
        sim.add_component(entity, Watcher(uid))
        sim.store.columns["look_uid"][sim.row(entity)] = uid
    sim.add_system(LookAtNearest, before=ConstraintSolve)

    worst_deg = 0.0
    ticks = round(args.seconds * sim.fps)
    print("  s  watcher     nearest   off")
    for tick in range(1, ticks + 1):
        sim.step()
        if not np.all(np.isfinite(sim.store.positions)):
            print("a pose went non-finite", file=sys.stderr)
            return 1
        table = sim.constraints
        errors = table.error[table.rows_of(sim.store.columns["look_uid"][[sim.row(e) for e in watchers]])]
        if sim.time_s > 0.7:  # eased in
            worst_deg = max(worst_deg, float(np.degrees(np.nanmax(errors))))
        if tick % round(sim.fps) == 0:
            for entity, error in zip(watchers, errors, strict=True):
                nearest = sim.store.columns["nearest_m"][sim.row(entity)]
                print(f"{tick / sim.fps:3.0f}  {sim.names()[sim.row(entity)]:10s} "
                      f"{nearest:6.2f} m {math.degrees(error):5.2f} deg")
    print(f"worst {worst_deg:.2f} deg after the look eased in "
          f"(tolerance {args.tolerance_deg:g} deg)")
    return 0 if worst_deg <= args.tolerance_deg else 1


if __name__ == "__main__":
    try:
        sys.exit(main())
    except EcsAnimError as exc:
        print(f"error: {exc}", file=sys.stderr)
        sys.exit(2)
