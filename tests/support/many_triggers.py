"""A scenario with many triggers, to measure loading and building them (docs/performance.md,
"Loading a scenario"): ``.venv/bin/python tests/support/many_triggers.py 100000`` writes it to
``out/many_triggers.yaml`` and prints the CPU seconds to load it and to build its simulation."""

from __future__ import annotations

import sys
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[2]


def many_triggers_yaml(count: int) -> str:
    """Four walkers, each with a reach switched by triggers; ``count`` triggers, a third each
    at a time, on a wrist near another's head, and on a foot landing (repeating)."""
    lines = ["description: many triggers", "duration_s: 1.0", "fps: 30", "motions:",
             f"  walk: {REPO / 'scenarios' / 'motions' / 'walk.bvh'}", "characters:"]
    for i in range(4):
        lines += [f"  - name: c{i}", "    morphology: adult_male", f"    position_m: [0.0, {1.5 * i}]",
                  "    motion: walk", "    constraints:", "      - name: reach",
                  "        point: wrist_r", "        target: {world_m: [0.5, 0.0, 1.0]}",
                  "        activation: {start_s: 100.0, stop_s: 200.0}"]
    lines.append("triggers:")
    for k in range(count):
        i, j = k % 4, (k + 1) % 4
        when = (f"{{at_s: {0.01 * (k % 500):.2f}}}", f"{{near: c{i}.wrist_r, to: c{j}.head, "
                "within_m: 0.3}", f"{{contact_began: c{i}}}")[k % 3]
        lines += [f"  - name: t{k}", f"    when: {when}", f"    repeat: {str(k % 3 > 0).lower()}",
                  "    then:", f"      - switch_on: c{j}.reach", "        for_s: 0.1"]
    return "\n".join(lines) + "\n"


if __name__ == "__main__":
    from ecs_anim.scenario import build_simulation, load_scenario

    count = int(sys.argv[1]) if len(sys.argv) > 1 else 100_000
    path = REPO / "out" / "many_triggers.yaml"
    path.parent.mkdir(exist_ok=True)
    path.write_text(many_triggers_yaml(count), encoding="utf-8")
    start = time.process_time()
    scenario = load_scenario(path)
    loaded = time.process_time()
    with build_simulation(scenario) as sim:
        built = time.process_time()
        sim.step()
        print(f"{count:,} triggers: load {loaded - start:.1f} s, build {built - loaded:.1f} s, "
              f"first tick {time.process_time() - built:.2f} s of CPU")
