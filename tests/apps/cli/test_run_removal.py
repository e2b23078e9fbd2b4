"""``ecs-anim run`` on a scenario whose trigger removes a character mid-run (issue 35)."""

from __future__ import annotations

import json

import numpy as np

from conftest import MOTIONS_DIR
from ecs_anim.apps.cli.main import main


def test_run_exports_every_character_and_ends_the_removed_ones_files_at_its_removal(tmp_path):
    scenario = tmp_path / "leaving.yaml"
    scenario.write_text(f"""\
duration_s: 1.0
fps: 30
motions:
  walk: {MOTIONS_DIR / "walk.bvh"}
  idle: {MOTIONS_DIR / "idle.bvh"}
characters:
  - name: red
    morphology: adult_male
    position_m: [0.0, 0.0]
    motion: walk
  - name: blue
    morphology: adult_female
    position_m: [0.0, 1.5]
    motion: idle
  - name: green
    morphology: adult_male
    position_m: [0.0, 3.0]
    motion: walk
triggers:
  - name: blue_leaves
    when: {{at_s: 0.5}}
    then: [{{remove: blue}}]
""")
    out, report_path = tmp_path / "out", tmp_path / "report.json"
    assert main(["run", str(scenario), "--export", str(out), "--report", str(report_path)]) == 0
    report = json.loads(report_path.read_text())
    assert [c["name"] for c in report["characters"]] == ["red", "blue", "green"]
    removed = {c["name"]: c.get("removed_at_s") for c in report["characters"]}
    assert removed == {"red": None, "blue": 0.5, "green": None}
    for name, frames in (("red", 30), ("blue", 15), ("green", 30)):  # blue: until 0.5 s
        with np.load(out / f"{name}.npz") as npz:
            assert npz["positions"].shape[0] == frames and npz["contacts"].shape[0] == frames
            assert np.all(np.isfinite(npz["positions"]))
        assert f"Frames: {frames}\n" in (out / f"{name}.bvh").read_text()
        assert (out / f"{name}.glb").stat().st_size > 0
    # green's row moved down when blue left: its frames are still its own (walking on at y = 3)
    with np.load(out / "green.npz") as npz:
        assert np.all(np.abs(npz["positions"][:, 0, 1] - 3.0) < 0.5)
