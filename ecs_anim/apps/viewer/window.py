"""The viewer's interactive window: the simulation, the camera, toggles, the clock, picking and
dragging targets, and saving the edits (one-frame screenshots are :mod:`.screenshot`).

The simulation runs at its fixed step; the Render system (``systems/render.py``) only tells the
:class:`~ecs_anim.apps.viewer.scene_view.SceneSource` that a new posture is in the store, and
drawing reads that posture (STYLE 8: rendering never writes to the simulation).
"""

from __future__ import annotations

import math
import os
import sys
import time
from dataclasses import dataclass, replace
from typing import Any

import numpy as np
from numpy.typing import NDArray

from ecs_anim.apps.viewer.authoring import Timeline, drag_in_view_plane, pick_capsule
from ecs_anim.apps.viewer.camera import OrbitCamera
from ecs_anim.apps.viewer.edits import Edit, EditLog, apply_edit, copy_name
from ecs_anim.apps.viewer.gl_setup import load_pyglet, make_window, text_label
from ecs_anim.apps.viewer.scene import BODY_CAPSULES, NEAR_MARGIN_M, SceneFrame, ground_patches
from ecs_anim.apps.viewer.scene_view import (
    SceneSource,
    default_camera,
    ground_patch_half_m,
    status_line,
)
from ecs_anim.core.errors import EcsAnimError
from ecs_anim.core.skeleton import JOINT_INDEX
from ecs_anim.runtime.simulation import Simulation
from ecs_anim.scenario import Scenario, build_simulation, load_scenario


def _centroid(frame: SceneFrame) -> NDArray[np.float64]:
    """(3,) mean pelvis position (NaN without characters)."""
    if frame.joints.shape[0] == 0:
        return np.full(3, np.nan)
    return np.asarray(frame.joints[:, 0].mean(axis=0), dtype=np.float64)


#: Every key and mouse action of the window, as the help overlay (H) lists them.
CONTROLS: tuple[tuple[str, str], ...] = (
    ("click", "pick a character (its name shows in the status line; click empty space: none)"),
    ("drag a target sphere", "move it in the view plane (facing the camera); the solve follows"),
    ("drag", "orbit"),
    ("right-drag, shift-drag", "pan"),
    ("wheel", "zoom"),
    ("click or drag the timeline", "set the time (going back re-simulates from the start)"),
    ("space", "play / pause"),
    ("right arrow", "one tick"),
    ("up / down", "speed x2 / /2"),
    ("+ / -", "the picked character 5 % taller / shorter"),
    ("A", "add a copy of the picked character (its motion, in step, 1 m to its left)"),
    ("Delete, Backspace", "remove the picked character"),
    ("N", "names over the characters"),
    ("R", "restart (your edits replay at their times)"),
    ("Ctrl+R", "reload the YAML now (it also reloads by itself when a file changes)"),
    ("L", "loop at the scenario's end"),
    ("T", "targets and areas"),
    ("C", "centres of mass"),
    ("F", "frame and follow"),
    ("H", "this help"),
    ("Esc", "quit"),
)
HELP = "\n".join(f"{keys}: {action}" for keys, action in CONTROLS)

#: Names are drawn over at most this many characters (beyond, only the picked one's).
MAX_LABELS = 50
#: Height of a name above the head's top (m).
LABEL_LIFT_M = 0.12
#: The grow and shrink keys scale the picked character's body by this factor (+ then - is
#: the body it had).
STATURE_STEP = 1.05
#: A left press that moves less than this before its release is a click (pixels).
CLICK_SLOP_PX = 3.0
#: How often the scenario's files are checked for a change, and how long a notice shows (s).
POLL_S, NOTICE_S = 1.0, 6.0
NOTICE_COLOUR = (170, 20, 20, 255)


def file_stamps(paths: tuple[str, ...]) -> tuple[tuple[str, int, int], ...]:
    """(path, mtime_ns, size) of each file, (path, -1, -1) for one that cannot be read: the
    viewer reloads when any of them changes."""
    stamps = []
    for path in paths:
        try:
            st = os.stat(path)
            stamps.append((path, st.st_mtime_ns, st.st_size))
        except OSError:
            stamps.append((path, -1, -1))
    return tuple(stamps)


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
    pyglet = load_pyglet(headless=headless)
    from ecs_anim.apps.viewer.gl_render import SceneRenderer

    app = ViewerApp(scenario, pyglet)
    app.show_targets, app.show_com = show_targets, show_com
    window = make_window(pyglet, width, height, visible=True, samples=0 if headless else 4,
                         resizable=True, caption=f"ecs-anim view {scenario.path}")
    app.attach(window, SceneRenderer())
    return app


@dataclass
class _Press:
    """What the left button went down on: ``kind`` "timeline", "target" (``uid``, its
    ``owner``'s and its own ``constraint`` name, and the target's ``point`` (3,) then) or
    "view" (an orbit, or a click if it hardly moves); ``moved_px`` since."""

    kind: str
    moved_px: float = 0.0
    owner: str = ""
    constraint: str = ""
    point: NDArray[np.float64] | None = None


class ViewerApp:
    """State of the interactive viewer: the simulation, the camera, toggles, the clock, and
    the authoring state (the picked character, the edits made, the files watched).

    Render-only state stays here (STYLE: the renderer keeps its own table keyed by entity):
    the name labels by entity, the picked character's name; the simulation is changed only
    through :mod:`ecs_anim.apps.viewer.edits`, whose log replays the edits whenever the
    simulation is rebuilt (scrubbing back, restart, loop, reload).
    """

    MAX_STEPS_PER_FRAME = 8

    def __init__(self, scenario: Scenario, pyglet: Any) -> None:
        self.scenario, self.pyglet = scenario, pyglet
        self.paused, self.speed = False, 1.0
        self.loop = True  # start again at the scenario's end (its duration_s), camera kept
        self.show_targets, self.show_com, self.show_help = True, True, False
        self.show_labels = True
        self.accumulator = 0.0
        self.fps = 0.0
        self._last_draw = time.perf_counter()
        self.camera: OrbitCamera | None = None
        self.follow = True  # the camera's target moves with the characters' mean position
        self._followed: NDArray[np.float64] | None = None
        self.edits = EditLog()
        self._live: list[Edit] = []  # edits made on this simulation at its current tick
        self.picked: str | None = None
        self.notice = ""  # a message under the status line (a reload error stays until fixed)
        self._notice_until: float | None = None
        self._press: _Press | None = None
        self._seek_to: float | None = None  # a timeline drag's time, sought once a frame
        self._labels: dict[int, Any] = {}  # entity -> its name label
        self._ground_stale = False
        self._stamps = file_stamps(scenario.input_files)
        self.sim: Simulation | None = None
        self._start()

    # simulation ----------------------------------------------------------------------------

    def _build(self, scenario: Scenario, until_tick: int) -> tuple[Simulation, SceneSource]:
        """A new simulation of ``scenario`` stepped (edits replayed) up to ``until_tick``."""
        source = SceneSource()
        source.picked = self.picked
        sim = build_simulation(scenario, window=True)
        try:
            sim.renderer = source
            while sim.tick < until_tick:
                self._step(sim)
        except BaseException:
            sim.close()
            raise
        return sim, source

    def _step(self, sim: Simulation | None = None) -> None:
        """One tick, after the edits made at this tick (those not made live on it already)."""
        sim = sim or self.sim
        assert sim is not None
        for problem in self.edits.replay(sim, skip=self._live if sim is self.sim else ()):
            self._say(problem)
        if sim is self.sim:
            self._live.clear()
        sim.step()

    def _use(self, sim: Simulation, source: SceneSource) -> None:
        if self.sim is not None:
            self.sim.close()
        self.sim, self.source = sim, source
        self.accumulator = 0.0
        # the edits of the tick it stopped before are made now, as they were when made live
        for problem in self.edits.replay(sim):
            self._say(problem)
        self._live = list(self.edits.by_tick.get(sim.tick, ()))
        source.unposed.update(e.value for e in self._live if e.kind == "copy")
        for label in self._labels.values():
            label.delete()
        self._labels.clear()
        if self.picked not in sim.names():
            self.picked = source.picked = None

    def _start(self) -> None:
        self._use(*self._build(self.scenario, 1))

    def _restart(self) -> None:
        """From the scenario's start again, the camera where the user left it."""
        self._start()
        self._followed = None

    def seek(self, time_s: float) -> None:
        """Show the posture at ``time_s`` (clamped to the scenario): forward by stepping on,
        back by re-simulating from the start (deterministic: the same ticks, the edits replayed
        at theirs, give the same postures)."""
        assert self.sim is not None
        end_tick = round(self.scenario.duration_s * self.scenario.fps)
        tick = min(max(round(time_s * self.scenario.fps), 0), end_tick) + 1
        if tick < self.sim.tick:
            self._start()
        while self.sim.tick < tick:
            self._step()
        self.accumulator = 0.0

    def reload(self) -> bool:
        """Read the scenario's YAML again and rebuild it at the same time (its edits replayed),
        keeping the camera. On an error the old scene goes on and the status line shows the
        one-line error. Returns whether it reloaded."""
        assert self.sim is not None
        try:
            scenario = load_scenario(self.scenario.path)
            end_tick = round(scenario.duration_s * scenario.fps) + 1
            built = self._build(scenario, min(self.sim.tick, end_tick))
        except EcsAnimError as exc:
            self._say(f"reload failed (still showing the previous version): {exc}", sticky=True)
            return False
        self.scenario = scenario
        self._stamps = file_stamps(scenario.input_files)
        self._use(*built)
        self._ground_stale = True
        self._say(f"reloaded {scenario.path} at t = {self.sim.posture_time_s:.2f} s")
        return True

    def check_files(self, dt: float = 0.0) -> None:
        """Reload when the scenario or a motion it reads changed (called every POLL_S)."""
        stamps = file_stamps(self.scenario.input_files)
        if stamps != self._stamps:
            self._stamps = stamps  # a broken file is tried again only once it changes again
            self.reload()

    def _say(self, text: str, sticky: bool = False) -> None:
        """A one-line notice under the status line (and on stderr): for NOTICE_S seconds, or
        until the next notice when ``sticky``."""
        self.notice = text.replace("\n", " ")
        self._notice_until = None if sticky else time.perf_counter() + NOTICE_S
        print(self.notice, file=sys.stderr)

    # edits ---------------------------------------------------------------------------------

    def _edit(self, kind: str, character: str, value: Any = None) -> bool:
        """Make a change now and log it at this tick (:mod:`ecs_anim.apps.viewer.edits`)."""
        assert self.sim is not None
        edit = Edit(self.sim.tick, kind, character, value)
        try:
            apply_edit(self.sim, edit)
        except EcsAnimError as exc:
            self._say(str(exc))
            return False
        self.edits.record(edit)
        self._live.append(edit)
        self.source.changed()
        return True

    def picked_entity(self) -> int | None:
        """The picked character's entity (None when none is picked, or it is gone: removed by
        an edit replayed while scrubbing, say)."""
        assert self.sim is not None
        if self.picked is not None and self.picked not in self.sim.names():
            self._pick(None)
        return None if self.picked is None else self.sim.entity(self.picked)

    def _pick(self, name: str | None) -> None:
        self.picked = self.source.picked = name
        self.source.changed()

    def _picked_or_say(self) -> str | None:
        """The picked character's name, or None (saying how to pick one)."""
        if self.picked_entity() is None or self.picked is None:
            self._say("pick a character first (click it)")
            return None
        return self.picked

    def scale_picked(self, factor: float) -> None:
        """The picked character's body (all lengths) times ``factor``, live."""
        picked = self._picked_or_say()
        if picked is not None:
            self._edit("scale", picked, factor)

    def copy_picked(self) -> None:
        """Add a character playing the picked one's motion in step, beside it; pick the copy."""
        assert self.sim is not None
        picked = self._picked_or_say()
        if picked is None:
            return
        name = copy_name(self.sim, picked)
        if self._edit("copy", picked, name):
            self.source.unposed.add(name)  # drawn from the next tick, when it has a posture
            self._pick(name)

    def remove_picked(self) -> None:
        picked = self._picked_or_say()
        if picked is not None and self._edit("remove", picked):
            self._pick(None)

    def _move_target(self, press: _Press, x: float, y: float) -> None:
        assert self.camera is not None and press.point is not None
        w, h = self.window.get_size()
        point = drag_in_view_plane(self.camera, press.point, x, h - y, w, h)
        self._edit("target", press.owner, (press.constraint, tuple(float(v) for v in point)))

    def _target_under(self, frame: SceneFrame, x: float, y: float) -> _Press | None:
        """The world target sphere under window (x, y), as a press that drags it."""
        marks = frame.marks
        if not self.show_targets or marks is None or not marks.in_world.any() or self.camera is None:
            return None
        w, h = self.window.get_size()
        m = marks.target.shape[0]
        radius = frame.targets[:m, 6].astype(np.float64)
        movable = np.flatnonzero(marks.in_world)
        hit = pick_capsule(self.camera, marks.target[movable], marks.target[movable], radius[movable],
                           w, h, x, h - y)
        if hit < 0:
            return None
        assert self.sim is not None
        table = self.sim.constraints
        k = int(table.rows_of(np.array([marks.uid[movable[hit]]]))[0])
        return _Press("target", owner=self.sim.names()[int(table.owner[k])],
                      constraint=table.names[k], point=marks.target[movable[hit]].copy())

    def character_at(self, x: float, y: float) -> str | None:
        """The name of the front-most character under window (x, y) (pyglet's pixels), or None."""
        frame = self.source.latest()
        if frame is None or self.camera is None or frame.rows.size == 0:
            return None
        w, h = self.window.get_size()
        rows = frame.bodies.astype(np.float64)
        hit = pick_capsule(self.camera, rows[:, 0:3], rows[:, 3:6], rows[:, 6], w, h, x, h - y)
        if hit < 0:
            return None
        assert self.sim is not None
        return self.sim.names()[int(frame.rows[hit // len(BODY_CAPSULES)])]

    # clock ---------------------------------------------------------------------------------

    def attach(self, window: Any, renderer: Any) -> None:
        self.window, self.renderer = window, renderer
        pyglet = self.pyglet
        self.label = text_label(pyglet, "", 10, window.height - 8, 11)
        self.notice_label = pyglet.text.Label("", x=10, y=window.height - 26, anchor_y="top",
                                              font_size=10, color=NOTICE_COLOUR)
        self.help = pyglet.text.Label(HELP, x=10, y=self.timeline_top() + 8, anchor_y="bottom",
                                      font_size=10, multiline=True,
                                      width=max(window.width - 20, 200), color=(25, 25, 30, 255))
        self._help_panel = pyglet.shapes.Rectangle(4, self.timeline_top() + 4, 1, 1,
                                                   color=(250, 250, 250, 215))
        self._label_batch = pyglet.graphics.Batch()
        self._bar_batch = pyglet.graphics.Batch()
        timeline = Timeline(self.scenario.duration_s)
        self._bar = pyglet.shapes.Rectangle(timeline.margin_px, timeline.margin_px, 1,
                                            timeline.height_px, color=(90, 90, 96, 160),
                                            batch=self._bar_batch)
        self._bar_done = pyglet.shapes.Rectangle(timeline.margin_px, timeline.margin_px, 1,
                                                 timeline.height_px, color=(40, 40, 48, 220),
                                                 batch=self._bar_batch)
        self._bar_cursor = pyglet.shapes.Rectangle(0, timeline.margin_px - 3, 3,
                                                   timeline.height_px + 6, color=(230, 230, 235, 255),
                                                   batch=self._bar_batch)
        self._frame_camera()
        window.push_handlers(self)
        pyglet.clock.schedule_interval(self.update, 1 / 120)
        pyglet.clock.schedule_interval(self.check_files, POLL_S)

    @property
    def timeline(self) -> Timeline:
        return Timeline(self.scenario.duration_s)

    def timeline_top(self) -> float:
        t = self.timeline
        return t.margin_px + t.height_px

    def _frame_camera(self) -> None:
        frame = self.source.latest()
        if frame is not None:
            w, h = self.window.get_size()
            self.camera = default_camera(frame, w / max(h, 1), self.scenario.camera)
            self.follow, self._followed = True, _centroid(frame)
            self._ground(frame, force=True)

    def _ground(self, frame: SceneFrame, force: bool = False) -> None:
        assert self.sim is not None and self.camera is not None
        wanted = ground_patch_half_m(self.camera)
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

    def update(self, dt: float) -> None:
        assert self.sim is not None
        if self._seek_to is not None:
            self.seek(self._seek_to)
            self._seek_to = None
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
            self._step()
            self.accumulator -= self.sim.dt
            steps += 1
        if steps == self.MAX_STEPS_PER_FRAME:
            self.accumulator = 0.0  # cannot keep up: slow down rather than spiral

    # drawing -------------------------------------------------------------------------------

    def status(self, frame: SceneFrame) -> str:
        """The status line, with the picked character and its stature."""
        text = status_line(frame, self.fps, self.speed, self.paused)
        entity = self.picked_entity()
        if entity is not None:
            assert self.sim is not None
            text += f"  |  picked {self.picked} ({self.sim.body(entity).stature:.2f} m)"
        return text

    def _draw_labels(self, frame: SceneFrame) -> None:
        """Each character's name over its head (all of them up to MAX_LABELS, else only the
        picked one's), from the labels table kept by entity."""
        assert self.sim is not None and self.camera is not None
        names = self.sim.names()
        rows = frame.rows
        shown = np.arange(rows.size)
        if not self.show_labels:
            shown = shown[:0]
        elif rows.size > MAX_LABELS:
            shown = np.array([i for i in shown if names[int(rows[i])] == self.picked], np.int64)
        w, h = self.window.get_size()
        heads = frame.joints[shown, JOINT_INDEX["head_top"]] + [0.0, 0.0, LABEL_LIFT_M]
        pixels = self.camera.project(heads, w, h)
        keep: dict[int, Any] = {}
        for i, (x, y) in zip(shown, pixels, strict=True):
            if not (np.isfinite(x) and np.isfinite(y)):
                continue
            row = int(rows[i])
            entity, name = int(self.sim.store.entity[row]), names[row]
            label = self._labels.pop(entity, None) or self.pyglet.text.Label(
                name, anchor_x="center", anchor_y="bottom", font_size=10,
                color=(25, 25, 30, 255), batch=self._label_batch)
            label.text, label.bold = name, name == self.picked
            label.position = (float(x), float(h - y), 0.0)
            keep[entity] = label
        for label in self._labels.values():
            label.delete()
        self._labels = keep
        self._label_batch.draw()

    def _draw_timeline(self, frame: SceneFrame) -> None:
        w = self.window.get_size()[0]
        timeline = self.timeline
        left, right = timeline.span(w)
        now = timeline.x_of(frame.time_s, w)
        self._bar.x, self._bar.width = left, right - left
        self._bar_done.x, self._bar_done.width = left, max(now - left, 1.0)
        self._bar_cursor.x = now - 1.5
        self._bar_batch.draw()

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
        self._ground(frame, force=self._ground_stale)
        self._ground_stale = False
        fw, fh = self.window.get_framebuffer_size()
        self.renderer.draw(frame, self.camera, fw, fh, self.show_targets, self.show_com)
        self._draw_labels(frame)
        self._draw_timeline(frame)
        self.label.y = self.window.height - 8
        self.label.text = self.status(frame)
        self.label.draw()
        if self._notice_until is not None and now > self._notice_until:
            self.notice, self._notice_until = "", None
        if self.notice:
            self.notice_label.y = self.window.height - 26
            self.notice_label.text = self.notice
            self.notice_label.draw()
        if self.show_help:
            self._help_panel.width = self.help.content_width + 12
            self._help_panel.height = self.help.content_height + 8
            self._help_panel.draw()
            self.help.draw()

    def screenshot(self) -> NDArray[np.uint8]:
        """Draw the window now and read it back: (height, width, 3) uint8, top row first."""
        import ctypes

        from pyglet import gl

        self.window.switch_to()
        self.on_draw()
        w, h = self.window.get_framebuffer_size()
        out = np.empty((h, w, 4), np.uint8)
        gl.glPixelStorei(gl.GL_PACK_ALIGNMENT, 1)
        gl.glReadPixels(0, 0, w, h, gl.GL_RGBA, gl.GL_UNSIGNED_BYTE,
                        out.ctypes.data_as(ctypes.c_void_p))
        return np.ascontiguousarray(out[::-1, :, :3])

    # events --------------------------------------------------------------------------------

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
            self._step()
        elif symbol == key.UP:
            self.speed = min(self.speed * 2, 16.0)
        elif symbol == key.DOWN:
            self.speed = max(self.speed / 2, 1 / 16)
        elif symbol in (key.PLUS, key.EQUAL, key.NUM_ADD):
            self.scale_picked(STATURE_STEP)
        elif symbol in (key.MINUS, key.NUM_SUBTRACT):
            self.scale_picked(1 / STATURE_STEP)
        elif symbol == key.A:
            self.copy_picked()
        elif symbol in (key.DELETE, key.BACKSPACE):
            self.remove_picked()
        elif symbol == key.N:
            self.show_labels = not self.show_labels
        elif symbol == key.R and modifiers & key.MOD_CTRL:
            self.reload()
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

    def on_mouse_press(self, x: int, y: int, button: int, modifiers: int) -> None:
        mouse, key = self.pyglet.window.mouse, self.pyglet.window.key
        self._press = None
        if button != mouse.LEFT or modifiers & key.MOD_SHIFT:
            return
        if self.timeline.contains(x, y, self.window.get_size()[0]):
            self._press = _Press("timeline")
            self.seek(self.timeline.time_at(x, self.window.get_size()[0]))
            return
        frame = self.source.latest()
        target = None if frame is None else self._target_under(frame, x, y)
        self._press = target or _Press("view")

    def on_mouse_drag(self, x: int, y: int, dx: int, dy: int, buttons: int, modifiers: int) -> None:
        mouse, key = self.pyglet.window.mouse, self.pyglet.window.key
        if self.camera is None:
            return
        press = self._press
        if buttons & (mouse.RIGHT | mouse.MIDDLE) or (buttons & mouse.LEFT and modifiers & key.MOD_SHIFT):
            self.camera = self.camera.pan(dx, dy, self.window.height)
            self.follow = False  # panned by hand: stay there (F frames and follows again)
        elif buttons & mouse.LEFT and press is not None and press.kind == "timeline":
            # sought at the next update: going back re-simulates, so once a frame at most
            self._seek_to = self.timeline.time_at(x, self.window.get_size()[0])
        elif buttons & mouse.LEFT and press is not None and press.kind == "target":
            self._move_target(press, x, y)
        elif buttons & mouse.LEFT:
            if press is not None:
                press.moved_px += math.hypot(dx, dy)
            self.camera = self.camera.orbit(-dx * 0.006, -dy * 0.006)

    def on_mouse_release(self, x: int, y: int, button: int, modifiers: int) -> None:
        press, self._press = self._press, None
        if self._seek_to is not None:
            self.seek(self._seek_to)
            self._seek_to = None
        if press is not None and press.kind == "view" and press.moved_px < CLICK_SLOP_PX:
            self._pick(self.character_at(x, y))

    def on_mouse_scroll(self, x: int, y: int, scroll_x: float, scroll_y: float) -> None:
        if self.camera is not None:
            self.camera = self.camera.zoom(math.pow(0.88, scroll_y))

    def on_close(self) -> None:
        self.pyglet.clock.unschedule(self.update)
        self.pyglet.clock.unschedule(self.check_files)
        if self.sim is not None:
            self.sim.close()


__all__ = ["CONTROLS", "ViewerApp", "file_stamps", "open_viewer", "run_viewer"]
