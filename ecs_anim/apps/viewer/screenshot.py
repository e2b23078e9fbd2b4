"""One-frame screenshots: a scenario simulated to a time and that frame rendered without a screen
(headless EGL), supersampled, written as a PNG."""

from __future__ import annotations

import os
import sys
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from ecs_anim.apps.viewer.camera import OrbitCamera
from ecs_anim.apps.viewer.gl_setup import load_pyglet, make_window, text_label
from ecs_anim.apps.viewer.scene import SceneFrame, ground_patches
from ecs_anim.apps.viewer.scene_view import (
    SceneSource,
    default_camera,
    ground_patch_half_m,
    status_line,
)
from ecs_anim.core.errors import EcsAnimError
from ecs_anim.core.files import output_problem
from ecs_anim.core.ground import Ground
from ecs_anim.scenario import Scenario, build_simulation

#: Supersampling of screenshots: rendered this many times larger, then averaged down.
SUPERSAMPLE = 2


def offscreen_mode() -> bool:
    """Whether screenshots use pyglet's headless (EGL) mode: yes, unless ``PYGLET_HEADLESS``
    says otherwise, or there is a display and no EGL library (then a hidden X window)."""
    import ctypes.util

    explicit = os.environ.get("PYGLET_HEADLESS")
    if explicit:
        return explicit in ("true", "TRUE", "True", "1")
    has_display = bool(os.environ.get("DISPLAY"))
    return not (has_display and ctypes.util.find_library("EGL") is None)


@dataclass(frozen=True)
class Screenshot:
    """One rendered frame: rgb (height, width, 3) uint8 (top row first), the camera and the
    frame it shows (``camera.project(frame.joints, width, height)`` gives joint pixels)."""

    rgb: NDArray[np.uint8]
    camera: OrbitCamera
    frame: SceneFrame


def render_screenshot(scenario: Scenario, at_s: float, width: int = 1280, height: int = 720,
                      camera: OrbitCamera | None = None, show_targets: bool = True,
                      show_com: bool = True, status: bool = True,
                      only: frozenset[str] | None = None) -> Screenshot:
    """Simulate ``scenario`` up to ``at_s`` seconds and render that frame without a screen;
    ``only``: the names of the characters drawn and framed (None: all; every one is simulated)."""
    if not (1 <= width <= 8192 and 1 <= height <= 8192):
        raise EcsAnimError(f"--size: width and height must be 1-8192 pixels, got {width}x{height}")
    ticks = max(round(at_s * scenario.fps), 0) + 1  # the posture at t = at_s
    source = SceneSource(only)
    with build_simulation(scenario, window=True) as sim:
        sim.renderer = source
        for _ in range(ticks):
            sim.step()
        frame = source.latest()
        assert frame is not None
        camera = camera or default_camera(frame, width / height, scenario.camera)
        return render_frame(frame, sim.ground, width, height, camera, show_targets, show_com,
                            status)


def render_frame(frame: SceneFrame, ground: Ground, width: int, height: int,
                 camera: OrbitCamera | None = None, show_targets: bool = True,
                 show_com: bool = True, status: bool = True) -> Screenshot:
    """Render one frame offscreen (no window shown); the camera frames it when not given."""
    cam = camera or default_camera(frame, width / height)
    near, far = ground_patches(ground, frame.joints, ground_patch_half_m(cam))
    pyglet = load_pyglet(headless=offscreen_mode())
    from ecs_anim.apps.viewer.gl_render import OffscreenTarget, SceneRenderer

    window = make_window(pyglet, 16, 16, visible=False)
    try:
        window.switch_to()
        big_w, big_h = width * SUPERSAMPLE, height * SUPERSAMPLE
        target = OffscreenTarget(big_w, big_h)
        renderer = SceneRenderer()
        renderer.set_ground(near, far)
        target.bind()
        renderer.draw(frame, cam, big_w, big_h, show_targets, show_com)
        if status:
            _draw_status(pyglet, window, status_line(frame), width, height)
        rgb = target.read_rgb()
        target.release()
    finally:
        window.close()
    small = rgb.reshape(height, SUPERSAMPLE, width, SUPERSAMPLE, 3).mean(axis=(1, 3))
    return Screenshot(np.round(small).astype(np.uint8), cam, frame)


def _draw_status(pyglet: Any, window: Any, text: str, width: int, height: int) -> None:
    """The status line in the top-left corner, in ``width`` x ``height`` logical pixels.
    Without fonts (a bare machine) the frame goes without it, with a warning."""
    from pyglet.math import Mat4

    try:
        window.projection = Mat4.orthogonal_projection(0, width, 0, height, -255, 255)
        label = text_label(pyglet, text, 10, height - 8, 11)
        label.draw()
    except Exception as exc:
        print(f"warning: no status line ({type(exc).__name__}: {exc})", file=sys.stderr)


def write_screenshot(scenario: Scenario, out: str | Path, at_s: float, width: int, height: int,
                     force: bool, show_targets: bool = True, show_com: bool = True,
                     only: frozenset[str] | None = None) -> Screenshot:
    """Render and write ``out`` (PNG). What :func:`~ecs_anim.core.files.output_problem` refuses (an
    existing file without ``force``, a folder, an unwritable place, ...) is an
    :class:`EcsAnimError` before rendering."""
    from ecs_anim.apps.viewer.png import write_png

    problem = output_problem(out, force)
    if problem is not None:
        raise EcsAnimError(problem)
    shot = render_screenshot(scenario, at_s, width, height, show_targets=show_targets,
                             show_com=show_com, only=only)
    write_png(out, shot.rgb, force)
    return shot
