"""The scene as both the window and screenshots show it: the source the Render system feeds
(:class:`SceneSource`), the camera framing it, the ground patch drawn around it and the status
line."""

from __future__ import annotations

import math
from dataclasses import replace
from typing import Any

import numpy as np

from ecs_anim.apps.viewer.camera import OrbitCamera, frame_points, spread_yaw
from ecs_anim.apps.viewer.scene import (
    SceneFrame,
    character_teams,
    highlighted,
    snapshot,
    team_colours,
)
from ecs_anim.runtime.simulation import Simulation


class SceneSource:
    """The renderer the Render system hands the simulation to (``sim.renderer``).

    ``draw(sim)`` is called once per tick and only notes that the store holds a new posture;
    :meth:`latest` builds the drawable frame when someone draws (so ticks without a redraw
    cost nothing). ``picked``: the name of a character to draw highlighted (render-only state,
    kept here and never in a component); ``only``: the names of the characters drawn (None:
    all; the others are still simulated, as a pair's opponent must be).
    """

    def __init__(self, only: frozenset[str] | None = None) -> None:
        self._sim: Simulation | None = None
        self._frame: SceneFrame | None = None
        self.picked: str | None = None
        self.only = only
        #: Characters added since the last tick (no posture yet): not drawn until it comes.
        self.unposed: set[str] = set()

    def draw(self, sim: Simulation) -> None:
        self._sim, self._frame = sim, None
        self.unposed.clear()

    def changed(self) -> None:
        """Something drawn changed between ticks (a target moved, a character picked): the
        next :meth:`latest` builds the frame again."""
        self._frame = None

    def latest(self) -> SceneFrame | None:
        if self._frame is None and self._sim is not None:
            sim = self._sim
            colours = team_colours(character_teams(sim))
            names = sim.names()
            if self.picked in names:
                colours = highlighted(colours, np.array([names.index(str(self.picked))]))
            hidden = np.array([i for i, name in enumerate(names) if name in self.unposed
                               or (self.only is not None and name not in self.only)], np.int64)
            self._frame = snapshot(sim, colours, hidden)
        return self._frame


def status_line(frame: SceneFrame, fps: float | None = None, speed: float = 1.0,
                paused: bool = False) -> str:
    """The on-screen line: time, frames per second, characters, max constraint error."""
    error = "-" if frame.max_error_m is None else f"{frame.max_error_m * 1000:.1f} mm"
    parts = [f"t {frame.time_s:6.2f} s"]
    if fps is not None:
        parts.append(f"{fps:5.1f} fps")
    parts += [f"{frame.n_characters} characters", f"max constraint error {error}"]
    if speed != 1.0:
        parts.append(f"speed x{speed:g}")
    if paused:
        parts.append("paused")
    return "  |  ".join(parts)


def ground_patch_half_m(camera: OrbitCamera) -> float:
    """Half size of the ground patch to draw: out to where the fog hides it (capped)."""
    return float(min(max(15.0, camera.distance * 4.0 + 10.0), 400.0))


def default_camera(frame: SceneFrame, aspect: float,
                   hints: dict[str, Any] | None = None) -> OrbitCamera:
    """Auto-frame all characters (and their constraint targets) from the default direction, or
    from the scenario's camera hints (``yaw_deg``, ``pitch_deg``: the direction; ``target_m``,
    ``distance_m``: where it looks from; what a hint leaves out is framed automatically)."""
    hints = hints or {}
    points = [frame.joints.reshape(-1, 3)]
    if frame.targets.shape[0]:
        points.append(frame.targets[:, 0:3].astype(np.float64))
    yaw = spread_yaw(frame.joints[:, 0, :2]) if frame.joints.shape[0] else OrbitCamera.yaw_rad
    base = OrbitCamera(yaw_rad=math.radians(hints["yaw_deg"]) if "yaw_deg" in hints else yaw)
    if "pitch_deg" in hints:
        base = replace(base, pitch_rad=math.radians(hints["pitch_deg"]))
    camera = frame_points(np.concatenate(points), aspect, base)
    if "target_m" in hints:
        x, y, z = (float(v) for v in hints["target_m"])  # a 3-vector (the scenario checks)
        camera = replace(camera, target=(x, y, z))
    if "distance_m" in hints:
        camera = replace(camera, distance=float(hints["distance_m"]))
    return camera
