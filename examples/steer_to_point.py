"""A game loop: a character follows a moving ground point (a simulated mouse), every tick.

Run it from any folder (headless, a few seconds):

    .venv/bin/python examples/steer_to_point.py

Each tick the "mouse" moves (a slow circle, then a jump behind the character), the loop asks the
character to walk to it at a speed that grows with the distance (it runs when far, stands when
there), steps the simulation, and reads the posture back. At the end it prints how closely the
pelvis followed the point, the feet's sliding and the time per tick.
"""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np

from ecs_anim import GAITS, Bumps, MetricsRecorder, Morphology, MotionPlayer, Simulation, import_bvh

#: The project's own motions, found beside this file so that the example runs from any folder.
MOTIONS = Path(__file__).resolve().parents[1] / "scenarios" / "motions"

SECONDS = 24.0


def mouse_point(t: float) -> tuple[float, float]:
    """Where the simulated mouse points on the ground at time ``t`` (x, y metres): round a
    4 m circle in 20 s, then, from 16 s, a point behind where the character goes."""
    if t < 16.0:
        a = 2 * np.pi * t / 20.0
        return 4.0 * np.cos(a), 4.0 * np.sin(a)
    return 1.0, -5.0


def main() -> None:
    motions = {name: import_bvh(MOTIONS / f"{name}.bvh")
               for name in ("idle", "walk", "run")}
    sim = Simulation(motions, Bumps(amplitude_m=0.03, wavelength_x_m=2.5, wavelength_y_m=3.0))
    hero = sim.spawn("hero", Morphology.preset("adult_female"), MotionPlayer("idle"))
    sim.set_locomotion(hero, walk="walk", idle="idle", run="run")
    metrics = MetricsRecorder(sim)
    gaits_seen = [GAITS[sim.store.gait[sim.row(hero)]]]
    gap = []
    started = time.perf_counter()
    for _ in range(int(SECONDS * sim.fps)):
        point = mouse_point(sim.time_s)
        pelvis = sim.posture(hero).positions[0, :2] if sim.tick else np.zeros(2)
        distance = float(np.linalg.norm(np.asarray(point) - pelvis))
        # Farther means faster: walk up close, run when more than about 2.5 m away; the walk
        # ends on the idle motion at the point.
        sim.walk_to(hero, point, speed_m_s=min(0.5 + 0.5 * distance, 3.0))
        sim.step()
        metrics.record()
        gait = GAITS[sim.store.gait[sim.row(hero)]]
        if gaits_seen[-1] != gait:
            gaits_seen.append(gait)
        gap.append(float(np.linalg.norm(np.asarray(point) - sim.posture(hero).positions[0, :2])))
    wall = time.perf_counter() - started
    report = metrics.report()["characters"][0]
    following = np.array(gap[int(4 * sim.fps):int(16 * sim.fps)])
    print(f"{len(gap)} ticks ({SECONDS:g} s at {sim.fps:g} Hz) in {wall:.2f} s wall, "
          f"{wall / len(gap) * 1e3:.2f} ms a tick")
    print(f"gaits: {' -> '.join(gaits_seen)}")
    print(f"pelvis to the moving point, 4-16 s: median {np.median(following):.2f} m, "
          f"max {following.max():.2f} m")
    print(f"after the jump behind it: {gap[-1]:.2f} m from the point at the end, "
          f"arrived: {sim.arrived(hero)}")
    print(f"foot sliding while planted: max {report['foot_sliding_mm_per_frame']['max']:.3f} mm "
          f"a frame; sole below the ground: {report['ground_penetration_mm_max']:.3f} mm")


if __name__ == "__main__":
    main()
