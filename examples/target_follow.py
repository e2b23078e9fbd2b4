"""A game loop: a character's right wrist follows a point that moves every tick.

The character stands playing the idle clip; the game moves a point round a circle in front of
its right shoulder, and every tick hands it to the solver (``Simulation.set_target``) before
stepping. Each simulated second it prints how far the wrist was from the point (the solver's
error, and the same distance measured on the output posture), in millimetres.

    .venv/bin/python examples/target_follow.py [--seconds 6] [--radius-m 0.15] [--realtime]

Exit status 0 when the wrist kept within ``--tolerance-mm`` of the point on every tick; 1 when
it did not (try ``--radius-m 0.8``: out of reach), a pose went non-finite, or the simulation
warned; 2 on a bad argument. Runs from any folder (the motions are found beside this file).
"""

from __future__ import annotations

import argparse
import math
import sys
import time
from pathlib import Path

import numpy as np

from ecs_anim import (
    JOINT_INDEX,
    EcsAnimError,
    Morphology,
    MotionPlayer,
    Placement,
    Simulation,
    import_bvh,
)

MOTIONS = Path(__file__).resolve().parents[1] / "scenarios" / "motions"
#: The circle the point goes round, in the character's frame (x forward, y left, z up), metres.
CIRCLE_CENTRE_IN_BODY_M = (0.38, -0.22, 1.15)
CIRCLE_HZ = 0.5


def point_in_world(time_s: float, radius_m: float, placement: Placement) -> tuple[float, float, float]:
    """The moving point at ``time_s``: a vertical circle across the character's front."""
    angle = 2.0 * math.pi * CIRCLE_HZ * time_s
    forward, left, up = CIRCLE_CENTRE_IN_BODY_M
    left += radius_m * math.cos(angle)
    up += radius_m * math.sin(angle)
    c, s = math.cos(placement.heading_rad), math.sin(placement.heading_rad)
    x0, y0 = placement.position_m
    return (x0 + c * forward - s * left, y0 + s * forward + c * left, up)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--seconds", type=float, default=6.0, help="simulated seconds (6)")
    parser.add_argument("--radius-m", type=float, default=0.15, help="the circle's radius (0.15 m)")
    parser.add_argument("--tolerance-mm", type=float, default=1.0,
                        help="the largest wrist-to-point distance that passes (1 mm)")
    parser.add_argument("--realtime", action="store_true", help="pace the loop at 30 ticks a second")
    args = parser.parse_args(argv)
    if not (0 < args.seconds <= 600 and 0 <= args.radius_m <= 2):
        parser.error("--seconds must be in (0, 600] and --radius-m in [0, 2]")

    placement = Placement(position_m=(1.0, 2.0), heading_rad=math.radians(30.0))
    sim = Simulation({"idle": import_bvh(MOTIONS / "idle.bvh")}, fps=30.0)
    hero = sim.spawn("hero", Morphology.preset("adult_female"), MotionPlayer("idle"), placement)
    reach = sim.add_constraint(hero, "follow", "wrist_r", priority=1.0,
                               target_in_world=point_in_world(0.0, args.radius_m, placement),
                               chain=("arm_r", "trunk"))
    table_row = int(sim.constraints.rows_of(np.array([reach]))[0])
    wrist = JOINT_INDEX["wrist_r"]

    print(f"hero's right wrist follows a point round a {args.radius_m:.2f} m circle at "
          f"{CIRCLE_HZ:g} Hz ({2 * math.pi * args.radius_m * CIRCLE_HZ:.2f} m/s)")
    print(f"  {'second':>6s} {'solver error mm':>16s} {'wrist to point mm':>18s}")
    worst_mm, failed = 0.0, False
    second_errors: list[float] = []
    second_distances: list[float] = []
    ticks = round(args.seconds * sim.fps)
    started = time.perf_counter()
    for tick in range(ticks):
        target = point_in_world(sim.time_s, args.radius_m, placement)  # where it is this tick
        sim.set_target(reach, target)
        sim.step()
        posture = sim.store.positions[sim.row(hero)]
        if not np.isfinite(posture).all() or sim.store.frozen.any():
            print(f"  t={sim.posture_time_s:.3f} s: a non-finite pose", file=sys.stderr)
            return 1
        second_errors.append(float(sim.constraints.error[table_row]) * 1e3)
        second_distances.append(float(np.linalg.norm(posture[wrist] - target)) * 1e3)
        if (tick + 1) % round(sim.fps) == 0 or tick + 1 == ticks:
            error_mm, distance_mm = max(second_errors), max(second_distances)
            print(f"  {math.ceil(sim.tick / sim.fps):6d} {error_mm:16.2f} {distance_mm:18.2f}")
            worst_mm = max(worst_mm, error_mm, distance_mm)
            failed |= not (math.isfinite(error_mm) and math.isfinite(distance_mm))
            second_errors.clear()
            second_distances.clear()
        if args.realtime:
            time.sleep(max(0.0, started + sim.tick * sim.dt - time.perf_counter()))
    sim.close()
    if sim.messages:
        print("the simulation warned: " + "; ".join(sim.messages), file=sys.stderr)
        return 1
    verdict = "kept" if worst_mm <= args.tolerance_mm and not failed else "did not keep"
    print(f"worst {worst_mm:.2f} mm over {ticks} ticks: the wrist {verdict} within "
          f"{args.tolerance_mm:g} mm of the point")
    return 0 if verdict == "kept" else 1


if __name__ == "__main__":
    try:
        sys.exit(main())
    except EcsAnimError as exc:
        print(f"error: {exc}", file=sys.stderr)
        sys.exit(1)
