"""``ecs-anim info`` says whether each constraint stored with a clip can reach its target on
the clip's own body (issue 32, item 6; docs/scenarios.md, Constraints stored with a motion)."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from conftest import MOTIONS_DIR
from ecs_anim.apps.cli.main import main
from ecs_anim.core.ground import Plane
from ecs_anim.motion.clip import load_nmo
from ecs_anim.scenario import build_simulation, clip_scenario

STORED = """\
constraints:
  - name: clap
    kind: distance
    point: wrist_l
    target: {point: wrist_r}
    distance_m: 0.0
    priority: 5
    activation: {start_s: 1.2, stop_s: 1.6, ease_in_s: 0.1, ease_out_s: 0.1}
  - name: chin
    point: wrist_r
    chain: [arm_r, trunk]
    target: {point: head, fraction: 0.0}
    activation: {start_s: 0.2, stop_s: 0.6}
"""


def test_info_says_whether_stored_constraints_reach_on_the_own_body(tmp_path: Path,
                                                                      capsys) -> None:
    (tmp_path / "stored.yaml").write_text(STORED)
    assert main(["import", str(MOTIONS_DIR / "walk.bvh"), "-o", str(tmp_path),
                 "--constraints", str(tmp_path / "stored.yaml")]) == 0
    nmo = tmp_path / "walk.nmo"
    capsys.readouterr()
    assert main(["info", str(nmo)]) == 0
    reach = [line for line in capsys.readouterr().out.splitlines() if line.startswith("  reach")]
    assert reach[0].startswith("  reach      body/clip/clap of body (1.75 m, arm_l 0.57 m) "
                               "cannot reach its own wrist_r: "), reach
    # The trunk carries the head: the arm alone brings the wrist nearer.
    assert reach[1].startswith("  reach      body/clip/chin of body (1.75 m, arm_r 0.57 m) can "
                               "reach its own head: "), reach
    assert main(["info", str(nmo), "--json"]) == 0
    written = json.loads(capsys.readouterr().out)["feasibility"]
    assert [e["reachable"] for e in written] == [False, True]
    # The left wrist alone cannot meet the right one while walking: played, it stays as short.
    motion = load_nmo(nmo)
    with build_simulation(clip_scenario(motion, motion.source_morphology, Plane())) as sim:
        closest = np.inf
        for _ in range(motion.n_frames):
            sim.step()
            if sim.constraints.weight[0] >= 1.0:
                closest = min(closest, float(sim.constraints.error[0]))
    assert abs(closest - written[0]["short_m"]) < 0.02
