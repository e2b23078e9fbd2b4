"""The pyglet side of the viewer: an interactive window and one-frame screenshots.

The simulation runs at its fixed step; the Render system (``systems/render.py``) only tells the
:class:`SceneSource` that a new posture is in the store, and drawing reads that posture
(STYLE 8: rendering never writes to the simulation).
"""

from __future__ import annotations

import math
import os
import sys
import time
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from ..errors import EcsAnimError
from ..files import output_problem
from ..ground import Ground
from ..scenario import Scenario, build_simulation
from ..simulation import Simulation
from .camera import OrbitCamera, frame_points, spread_yaw
from .scene import NEAR_MARGIN_M, SceneFrame, ground_patches, snapshot

INSTALL_HINT = ("on Debian/Ubuntu install libegl1 and libgl1-mesa-dri (headless EGL), "
                "or run under xvfb-run (package xvfb)")
#: Supersampling of screenshots: rendered this many times larger, then averaged down.
SUPERSAMPLE = 2


class SceneSource:
    """The renderer the Render system hands the simulation to (``sim.renderer``).

    ``draw(sim)`` is called once per tick and only notes that the store holds a new posture;
    :meth:`latest` builds the drawable frame when someone draws (so ticks without a redraw
    cost nothing).
    """

    def __init__(self) -> None:
        self._sim: Simulation | None = None
        self._frame: SceneFrame | None = None

    def draw(self, sim: Simulation) -> None:
        self._sim, self._frame = sim, None

    def latest(self) -> SceneFrame | None:
        if self._frame is None and self._sim is not None:
            self._frame = snapshot(self._sim)
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


def offscreen_mode() -> bool:
    """Whether screenshots use pyglet's headless (EGL) mode: yes, unless ``PYGLET_HEADLESS``
    says otherwise, or there is a display and no EGL library (then a hidden X window)."""
    import ctypes.util

    explicit = os.environ.get("PYGLET_HEADLESS")
    if explicit:
        return explicit in ("true", "TRUE", "True", "1")
    has_display = bool(os.environ.get("DISPLAY"))
    return not (has_display and ctypes.util.find_library("EGL") is None)


def _pyglet(headless: bool) -> Any:
    """Import pyglet for drawing, headless (EGL, no screen) or not. One-line errors."""
    try:
        import pyglet
    except ImportError as exc:  # pragma: no cover - a dependency
        raise EcsAnimError(f"pyglet is not installed ({exc}); pip install 'pyglet>=2,<3'") from None
    if "pyglet.window" not in sys.modules:  # the mode is fixed once pyglet.window is imported
        pyglet.options["headless"] = headless
        pyglet.options["shadow_window"] = False
    try:
        import pyglet.window
        from pyglet import gl  # noqa: F401
    except Exception as exc:
        raise EcsAnimError(f"cannot load OpenGL ({type(exc).__name__}: {exc}); {INSTALL_HINT}") from None
    return pyglet


def _gl_config(pyglet: Any, samples: int) -> list[Any]:
    gl = pyglet.gl
    extra = {"sample_buffers": 1, "samples": samples} if samples else {}
    return [gl.Config(major_version=3, minor_version=3, forward_compatible=True, depth_size=24,
                      double_buffer=True, **extra),
            gl.Config(major_version=3, minor_version=3, forward_compatible=True, depth_size=24),
            None]


def _make_window(pyglet: Any, width: int, height: int, visible: bool, samples: int = 0,
                 cls: type | None = None, **kwargs: Any) -> Any:
    """A window with an OpenGL >= 3.3 core context; the first config that works."""
    window_cls = cls or pyglet.window.Window
    last: Exception | None = None
    for config in _gl_config(pyglet, samples):
        try:
            window = window_cls(width=width, height=height, visible=visible, config=config, **kwargs)
        except Exception as exc:
            last = exc
            continue
        version = tuple(int(v) for v in pyglet.gl.gl_info.get_version()[:2])
        if version < (3, 3):
            window.close()
            raise EcsAnimError(f"OpenGL 3.3 is needed, this context offers {version[0]}.{version[1]} "
                               f"({pyglet.gl.gl_info.get_renderer()}); {INSTALL_HINT}")
        return window
    raise EcsAnimError(f"cannot open an OpenGL 3.3 context ({type(last).__name__}: "
                       f"{str(last).strip() or 'no details'}); {INSTALL_HINT}")


def _label(pyglet: Any, text: str, x: float, y: float, size: float) -> Any:
    return pyglet.text.Label(text, x=x, y=y, anchor_x="left", anchor_y="top", font_size=size,
                             color=(25, 25, 30, 255))


def _patch_half_m(camera: OrbitCamera) -> float:
    """Half size of the ground patch to draw: out to where the fog hides it (capped)."""
    return float(min(max(15.0, camera.distance * 4.0 + 10.0), 400.0))


def _centroid(frame: SceneFrame) -> NDArray[np.float64]:
    """(3,) mean pelvis position (NaN without characters)."""
    if frame.joints.shape[0] == 0:
        return np.full(3, np.nan)
    return np.asarray(frame.joints[:, 0].mean(axis=0), dtype=np.float64)


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


# --- screenshots --------------------------------------------------------------------------


@dataclass(frozen=True)
class Screenshot:
    """One rendered frame: rgb (height, width, 3) uint8 (top row first), the camera and the
    frame it shows (``camera.project(frame.joints, width, height)`` gives joint pixels)."""

    rgb: NDArray[np.uint8]
    camera: OrbitCamera
    frame: SceneFrame


def render_screenshot(scenario: Scenario, at_s: float, width: int = 1280, height: int = 720,
                      camera: OrbitCamera | None = None, show_targets: bool = True,
                      show_com: bool = True, status: bool = True) -> Screenshot:
    """Simulate ``scenario`` up to ``at_s`` seconds and render that frame without a screen."""
    if not (1 <= width <= 8192 and 1 <= height <= 8192):
        raise EcsAnimError(f"--size: width and height must be 1-8192 pixels, got {width}x{height}")
    ticks = max(round(at_s * scenario.fps), 0) + 1  # the posture at t = at_s
    source = SceneSource()
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
    near, far = ground_patches(ground, frame.joints, _patch_half_m(cam))
    pyglet = _pyglet(headless=offscreen_mode())
    from .gl_render import OffscreenTarget, SceneRenderer

    window = _make_window(pyglet, 16, 16, visible=False)
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
        label = _label(pyglet, text, 10, height - 8, 11)
        label.draw()
    except Exception as exc:
        print(f"warning: no status line ({type(exc).__name__}: {exc})", file=sys.stderr)


def write_screenshot(scenario: Scenario, out: str | Path, at_s: float, width: int, height: int,
                     force: bool, show_targets: bool = True, show_com: bool = True) -> Screenshot:
    """Render and write ``out`` (PNG). What :func:`~ecs_anim.files.output_problem` refuses (an
    existing file without ``force``, a folder, an unwritable place, ...) is an
    :class:`EcsAnimError` before rendering."""
    from .png import write_png

    problem = output_problem(out, force)
    if problem is not None:
        raise EcsAnimError(problem)
    shot = render_screenshot(scenario, at_s, width, height, show_targets=show_targets,
                             show_com=show_com)
    write_png(out, shot.rgb, force)
    return shot


# --- the interactive window ---------------------------------------------------------------

HELP = ("drag: orbit  right/shift-drag: pan  wheel: zoom  space: play/pause  right arrow: step  "
        "up/down: speed  R: restart  L: loop at the end  T: targets  C: COM  F: frame and follow  "
        "H: help")


def run_viewer(scenario: Scenario, width: int = 1280, height: int = 720,
               show_targets: bool = True, show_com: bool = True) -> None:
    """Open the window and run until it is closed."""
    if sys.platform.startswith("linux") and not (os.environ.get("DISPLAY")
                                                 or os.environ.get("WAYLAND_DISPLAY")):
        raise EcsAnimError("no screen to open a window on (DISPLAY is not set); use "
                           "--screenshot OUT.png to render a frame without one, or run under xvfb-run")
    open_viewer(scenario, width, height, show_targets, show_com, headless=False)
    import pyglet

    pyglet.app.run()


def open_viewer(scenario: Scenario, width: int = 1280, height: int = 720,
                show_targets: bool = True, show_com: bool = True,
                headless: bool = False) -> ViewerApp:
    """Make the viewer's window and state (``pyglet.app.run()`` then runs it). ``headless``:
    an offscreen window, for tests."""
    pyglet = _pyglet(headless=headless)
    from .gl_render import SceneRenderer

    app = ViewerApp(scenario, pyglet)
    app.show_targets, app.show_com = show_targets, show_com
    window = _make_window(pyglet, width, height, visible=True, samples=0 if headless else 4,
                          resizable=True, caption=f"ecs-anim view {scenario.path}")
    app.attach(window, SceneRenderer())
    return app


class ViewerApp:
    """State of the interactive viewer: the simulation, the camera, toggles, the clock."""

    MAX_STEPS_PER_FRAME = 8

    def __init__(self, scenario: Scenario, pyglet: Any) -> None:
        self.scenario, self.pyglet = scenario, pyglet
        self.paused, self.speed = False, 1.0
        self.loop = True  # start again at the scenario's end (its duration_s), camera kept
        self.show_targets, self.show_com, self.show_help = True, True, False
        self.accumulator = 0.0
        self.fps = 0.0
        self._last_draw = time.perf_counter()
        self.camera: OrbitCamera | None = None
        self.follow = True  # the camera's target moves with the characters' mean position
        self._followed: NDArray[np.float64] | None = None
        self.sim: Simulation | None = None
        self._start()

    def _start(self) -> None:
        if self.sim is not None:
            self.sim.close()
        self.source = SceneSource()
        self.sim = build_simulation(self.scenario, window=True)
        self.sim.renderer = self.source
        self.sim.step()
        self.accumulator = 0.0

    def _restart(self) -> None:
        """From the scenario's start again, the camera where the user left it."""
        self._start()
        self._followed = None

    def attach(self, window: Any, renderer: Any) -> None:
        self.window, self.renderer = window, renderer
        self.label = _label(self.pyglet, "", 10, window.height - 8, 11)
        self.help = self.pyglet.text.Label(HELP, x=10, y=10, anchor_y="bottom", font_size=10,
                                           multiline=True, width=max(window.width - 20, 200),
                                           color=(25, 25, 30, 255))
        self._frame_camera()
        window.push_handlers(self)
        self.pyglet.clock.schedule_interval(self.update, 1 / 120)

    def _frame_camera(self) -> None:
        frame = self.source.latest()
        if frame is not None:
            w, h = self.window.get_size()
            self.camera = default_camera(frame, w / max(h, 1), self.scenario.camera)
            self.follow, self._followed = True, _centroid(frame)
            self._ground(frame, force=True)

    def _ground(self, frame: SceneFrame, force: bool = False) -> None:
        assert self.sim is not None and self.camera is not None
        wanted = _patch_half_m(self.camera)
        xy = frame.joints[:, 0, :2] if frame.joints.size else np.zeros((0, 2))
        if not force and len(self.renderer.ground_bounds) == 2 and xy.size:
            (x0, y0, x1, y1), far = self.renderer.ground_bounds
            edge = NEAR_MARGIN_M / 2
            inside = ((xy[:, 0] > x0 + edge) & (xy[:, 0] < x1 - edge) & (xy[:, 1] > y0 + edge)
                      & (xy[:, 1] < y1 - edge))
            far_half = (far[2] - far[0]) / 2
            if inside.all() and wanted * 0.8 <= far_half <= wanted * 3:
                return
        self.renderer.set_ground(*ground_patches(self.sim.ground, frame.joints, wanted))

    # clock -------------------------------------------------------------------------------

    def update(self, dt: float) -> None:
        assert self.sim is not None
        if self.paused:
            return
        self.accumulator += dt * self.speed
        if self.camera is not None:  # the solver's frame budget cuts far from the eye first
            self.sim.set_solver_focus(self.camera.eye)
        steps = 0
        while self.accumulator >= self.sim.dt and steps < self.MAX_STEPS_PER_FRAME:
            if self.loop and self.sim.time_s > self.scenario.duration_s + 1e-9:
                self._restart()  # its first tick stands for this one
                break
            self.sim.step()
            self.accumulator -= self.sim.dt
            steps += 1
        if steps == self.MAX_STEPS_PER_FRAME:
            self.accumulator = 0.0  # cannot keep up: slow down rather than spiral

    # events ------------------------------------------------------------------------------

    def on_draw(self) -> None:
        now = time.perf_counter()
        elapsed, self._last_draw = now - self._last_draw, now
        if elapsed > 0:
            self.fps = 1 / elapsed if self.fps == 0 else 0.9 * self.fps + 0.1 / elapsed
        frame = self.source.latest()
        if frame is None or self.camera is None:
            return
        centroid = _centroid(frame)
        if self.follow and self._followed is not None and np.all(np.isfinite(centroid)):
            shift = centroid - self._followed
            moved = np.asarray(self.camera.target) + shift
            self.camera = replace(self.camera, target=(float(moved[0]), float(moved[1]),
                                                       float(moved[2])))
        self._followed = centroid
        self._ground(frame)
        fw, fh = self.window.get_framebuffer_size()
        self.renderer.draw(frame, self.camera, fw, fh, self.show_targets, self.show_com)
        self.label.y = self.window.height - 8
        self.label.text = status_line(frame, self.fps, self.speed, self.paused)
        self.label.draw()
        if self.show_help:
            self.help.draw()

    def on_resize(self, width: int, height: int) -> None:
        self.label.y = height - 8
        self.help.width = max(width - 20, 200)

    def on_key_press(self, symbol: int, modifiers: int) -> bool | None:
        key = self.pyglet.window.key
        assert self.sim is not None
        if symbol == key.SPACE:
            self.paused = not self.paused
        elif symbol in (key.RIGHT, key.PERIOD):
            self.paused = True
            self.sim.step()
        elif symbol in (key.UP, key.PLUS, key.EQUAL, key.NUM_ADD):
            self.speed = min(self.speed * 2, 16.0)
        elif symbol in (key.DOWN, key.MINUS, key.NUM_SUBTRACT):
            self.speed = max(self.speed / 2, 1 / 16)
        elif symbol == key.R:
            self._restart()
        elif symbol == key.L:
            self.loop = not self.loop
        elif symbol == key.T:
            self.show_targets = not self.show_targets
        elif symbol == key.C:
            self.show_com = not self.show_com
        elif symbol == key.F:
            self._frame_camera()
        elif symbol == key.H:
            self.show_help = not self.show_help
        else:
            return None
        return True

    def on_mouse_drag(self, x: int, y: int, dx: int, dy: int, buttons: int, modifiers: int) -> None:
        mouse, key = self.pyglet.window.mouse, self.pyglet.window.key
        if self.camera is None:
            return
        if buttons & (mouse.RIGHT | mouse.MIDDLE) or (buttons & mouse.LEFT and modifiers & key.MOD_SHIFT):
            self.camera = self.camera.pan(dx, dy, self.window.height)
            self.follow = False  # panned by hand: stay there (F frames and follows again)
        elif buttons & mouse.LEFT:
            self.camera = self.camera.orbit(-dx * 0.006, -dy * 0.006)

    def on_mouse_scroll(self, x: int, y: int, scroll_x: float, scroll_y: float) -> None:
        if self.camera is not None:
            self.camera = self.camera.zoom(math.pow(0.88, scroll_y))

    def on_close(self) -> None:
        self.pyglet.clock.unschedule(self.update)
        if self.sim is not None:
            self.sim.close()


__all__ = ["SceneSource", "Screenshot", "ViewerApp", "default_camera", "open_viewer",
           "render_frame", "render_screenshot", "run_viewer", "status_line", "write_screenshot"]
