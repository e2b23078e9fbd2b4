"""The viewer: camera math and scene arrays (no GL), then real headless screenshots.

Screenshots need an OpenGL 3.3 context without a screen (pyglet's headless EGL mode with Mesa);
where that is missing the rendering tests skip, saying what to install (CI installs it).
"""

from __future__ import annotations

import math
import os
import struct
import subprocess
import sys
import zlib
from dataclasses import dataclass, replace
from functools import cache
from pathlib import Path

import numpy as np
import pytest

from conftest import REPO, SCENARIOS_DIR
from ecs_anim.apps.cli.main import main
from ecs_anim.apps.viewer.camera import OrbitCamera, frame_points, look_at, perspective, spread_yaw
from ecs_anim.apps.viewer.png import SIGNATURE, encode_png
from ecs_anim.apps.viewer.scene import (
    BODY_CAPSULES,
    INSTANCE_FLOATS,
    UNREACHABLE_COLOUR,
    UNREACHABLE_PIN_M,
    ground_mesh,
    priority_colours,
    snapshot,
    team_colours,
)
from ecs_anim.core.skeleton import JOINT_INDEX, N_JOINTS
from ecs_anim.scenario import build_simulation, load_scenario
from support.gl import need_gl

PELVIS = JOINT_INDEX["pelvis"]


# --- camera math ---------------------------------------------------------------------------


def test_look_at_puts_the_target_straight_ahead():
    eye, target = np.array([3.0, -4.0, 2.0]), np.array([0.5, 1.0, 1.0])
    world2view = look_at(eye, target)
    assert np.allclose(world2view[:3, :3] @ world2view[:3, :3].T, np.eye(3))
    in_view = world2view @ np.append(target, 1.0)
    assert np.allclose(in_view[:2], 0.0, atol=1e-12)
    assert in_view[2] == pytest.approx(-np.linalg.norm(target - eye))
    assert np.allclose(world2view @ np.append(eye, 1.0), [0, 0, 0, 1])


def test_perspective_maps_the_frustum_corners():
    view2clip = perspective(math.radians(90), 2.0, 1.0, 10.0)
    for z, depth in ((-1.0, -1.0), (-10.0, 1.0)):
        corner = view2clip @ np.array([2.0 * -z, -z, z, 1.0])  # right-top edge at distance -z
        assert np.allclose(corner[:3] / corner[3], [1.0, 1.0, depth])


def test_project_known_points():
    # Eye on +x looking at the origin (towards -x): world +y is to the right, +z up.
    cam = OrbitCamera(target=(0.0, 0.0, 0.0), distance=5.0, yaw_rad=0.0, pitch_rad=0.0,
                      fov_y_rad=math.radians(90))
    w, h = 200, 100
    px = cam.project(np.array([[0.0, 0.0, 0.0], [0.0, 0.0, 2.5], [0.0, 2.5, 0.0],
                               [10.0, 0.0, 0.0]]), w, h)
    assert np.allclose(px[0], [100, 50])          # the target: centre of the image
    assert np.allclose(px[1], [100, 25])          # up: half-way to the top (tan 45° = 1)
    assert np.allclose(px[2], [100 + 25, 50])     # +y: right, same scale in x as in y
    assert np.all(np.isnan(px[3]))                # behind the eye


def test_project_batched_equals_one_by_one():
    rng = np.random.default_rng(5)
    cam = OrbitCamera(target=(1.0, 2.0, 0.5), distance=7.0, yaw_rad=0.3, pitch_rad=0.4)
    points = rng.uniform(-2, 2, (4, 5, 3))
    batched = cam.project(points, 640, 480)
    single = np.array([[cam.project(p, 640, 480) for p in row] for row in points])
    assert batched.shape == (4, 5, 2)
    assert np.allclose(batched, single)


def test_orbit_zoom_pan_keep_the_camera_sane():
    cam = OrbitCamera()
    assert cam.orbit(0.0, 10.0).pitch_rad < math.pi / 2
    assert cam.zoom(1e-9).distance == pytest.approx(0.2)
    moved = cam.pan(100.0, 0.0, 500)
    # dragging right moves the target left in the image, i.e. the scene follows the mouse
    px = moved.project(np.array(cam.target), 500, 500)
    assert px[0] > 250 and px[1] == pytest.approx(250)
    assert np.linalg.norm(np.subtract(moved.eye, cam.eye) - np.subtract(moved.target, cam.target)) < 1e-9


def test_frame_points_shows_every_point():
    rng = np.random.default_rng(1)
    points = rng.uniform([-5, -1, 0], [5, 1, 2], (50, 3))
    for aspect in (16 / 9, 0.5):
        cam = frame_points(points, aspect)
        w, h = 1000, int(1000 / aspect)
        px = cam.project(points, w, h)
        assert np.all((px >= 0) & (px <= [w, h]))
        # and it uses the view: points reach at least half-way to an edge
        assert np.max(np.abs(px / [w, h] * 2 - 1)) > 0.5


def test_spread_yaw_spreads_a_row_of_characters_across_the_image():
    row = np.stack([np.zeros(5), np.linspace(0, 4, 5)], axis=1)  # along y
    yaw = spread_yaw(row)
    cam = frame_points(np.column_stack([row, np.ones(5)]), 16 / 9, OrbitCamera(yaw_rad=yaw))
    px = cam.project(np.column_stack([row, np.ones(5)]), 1600, 900)
    assert np.all(np.diff(np.sort(px[:, 0])) > 100)  # well apart on screen
    assert abs(math.remainder(yaw - OrbitCamera.yaw_rad, 2 * math.pi)) <= math.pi / 2
    assert spread_yaw(np.zeros((3, 2))) == OrbitCamera.yaw_rad


# --- scene arrays --------------------------------------------------------------------------


@cache
def _scenario(name: str):
    return load_scenario(SCENARIOS_DIR / name)


def test_snapshot_has_one_capsule_row_per_body_part():
    scenario = _scenario("reach_and_touch.yaml")
    with build_simulation(scenario) as sim:
        for _ in range(40):
            sim.step()
        frame = snapshot(sim)
        n = sim.store.n
        assert frame.bodies.shape == (n * len(BODY_CAPSULES), INSTANCE_FLOATS)
        assert frame.bodies.dtype == np.float32 and np.all(np.isfinite(frame.bodies))
        assert frame.com.shape == (n, INSTANCE_FLOATS)
        # the 3 constraints are active at t = 1.3 s: a sphere and a rod each, and a pin (a rod
        # and a ball) on the 2 their bodies cannot reach (elbow_out, pat_head)
        assert frame.targets.shape == (6 + 4, INSTANCE_FLOATS)
        assert {sim.constraints.names[int(k)] for k in
                sim.constraints.rows_of(np.array(sorted(sim.unreachable())))} == {
                    "elbow_out", "pat_head"}
        pins = frame.targets[6:]
        assert np.allclose(pins[:, 7:10], UNREACHABLE_COLOUR)
        assert np.allclose(pins[:2, 5] - pins[:2, 2], UNREACHABLE_PIN_M)  # rods stand up
        assert frame.joints.shape == (n, N_JOINTS, 3)
        assert frame.time_s == pytest.approx(39 / 30)
        # the status line's figure: the largest error (m) of the fully active constraints
        table = sim.constraints
        full = (table.weight >= 1.0 - 1e-9) & np.isfinite(table.error)
        assert full.any() and frame.max_error_m == pytest.approx(table.error[full].max(), abs=1e-12)


def test_body_instances_batched_equal_one_character_at_a_time():
    from ecs_anim.apps.viewer.scene import body_instances

    rng = np.random.default_rng(3)
    n = 7
    positions = rng.normal(size=(n, N_JOINTS, 3))
    lengths = rng.uniform(0.1, 0.5, (n, 23))
    colours = rng.uniform(0, 1, (n, 3))
    batched = body_instances(positions, lengths, colours)
    single = np.concatenate([body_instances(positions[i:i + 1], lengths[i:i + 1], colours[i:i + 1])
                             for i in range(n)])
    assert np.array_equal(batched, single)
    assert body_instances(positions[:0], lengths[:0], colours[:0]).shape == (0, INSTANCE_FLOATS)


def test_snapshot_of_a_crowd():
    from ecs_anim.components import MotionPlayer, Placement
    from ecs_anim.core.morphology import Morphology
    from ecs_anim.runtime.simulation import Simulation

    motions = _scenario("terrain_walk.yaml").motions
    with Simulation({"walk": motions["walk"]}) as sim:
        for i in range(300):
            sim.spawn(f"c{i}", Morphology.from_stature(1.2 + i / 500), MotionPlayer("walk"),
                      Placement((1.5 * (i // 20), 1.5 * (i % 20))), team=f"t{i % 3}")
        sim.step()
        frame = snapshot(sim)
        assert frame.bodies.shape == (300 * len(BODY_CAPSULES), INSTANCE_FLOATS)
        colours = frame.bodies[::len(BODY_CAPSULES), 7:10]
        assert len({tuple(c) for c in np.round(colours, 5)}) == 3  # one colour per team


@dataclass
class _FullTable:
    """A stand-in with the columns of the full constraint table (body points, kinds, areas,
    the solver's residual), to check the viewer's accessors read that shape too."""

    owner: np.ndarray
    kind: np.ndarray
    segment: np.ndarray
    fraction: np.ndarray
    priority: np.ndarray
    target_kind: np.ndarray
    target_world: np.ndarray
    target_row: np.ndarray
    target_segment: np.ndarray
    target_fraction: np.ndarray
    area_shape: np.ndarray
    area_low: np.ndarray
    area_high: np.ndarray
    area_radius: np.ndarray
    area_normal: np.ndarray
    error: np.ndarray

    @property
    def m(self) -> int:
        return int(self.owner.shape[0])

    def weights(self, time_s, clip=None, clip_time_s=None):
        return np.ones(self.m)


def _full_table() -> _FullTable:
    from ecs_anim.core.skeleton import LENGTH_INDEX

    fa, lw = LENGTH_INDEX["forearm_r"], LENGTH_INDEX["head"]
    # 0: wrist_r -> world point (position); 1: wrist_r at the other's head top (distance);
    # 2: orientation (not drawn); 3-5: areas sphere, box, half-space at world points
    return _FullTable(
        owner=np.array([0, 1, 0, 0, 0, 1]), kind=np.array([0, 1, 3, 2, 2, 2]),
        segment=np.array([fa] * 6), fraction=np.array([1.0, 1.0, 1.0, 1.0, 1.0, 1.0]),
        priority=np.array([10.0, 5.0, 1.0, 1.0, 1.0, 1.0]),
        target_kind=np.array([0, 1, 0, 0, 0, 0]),
        target_world=np.array([[0.45, -0.35, 1.25], [0, 0, 0], [0, 0, 1], [0.5, 0.5, 1.0],
                               [1.0, 0.0, 0.0], [0.0, -1.0, 0.0]]),
        target_row=np.array([0, 0, 0, 0, 0, 0]), target_segment=np.array([0, lw, 0, 0, 0, 0]),
        target_fraction=np.array([0.0, 1.0, 0.0, 0.0, 0.0, 0.0]),
        area_shape=np.array([0, 0, 0, 2, 1, 3]),
        area_low=np.array([[0, 0, 0]] * 4 + [[-0.2, -0.2, 0.0], [0, 0, 0]], dtype=float),
        area_high=np.array([[0, 0, 0]] * 4 + [[0.2, 0.2, 1.5], [0, 0, 0]], dtype=float),
        area_radius=np.array([0, 0, 0, 0.3, 0, 0], dtype=float),
        area_normal=np.array([[0, 0, 1]] * 5 + [[0, 1, 0]], dtype=float),
        error=np.array([0.002, np.nan, 0.1, 0.0, 0.0, 0.0]))


def test_accessors_read_the_full_constraint_table():
    from ecs_anim.apps.viewer.constraint_view import constraint_marks, restricted_areas
    from ecs_anim.apps.viewer.scene import area_instances

    with build_simulation(_scenario("reach_and_touch.yaml")) as sim:
        sim.step()
        sim.constraints = _full_table()  # type: ignore[assignment]
        p = sim.store.positions
        marks = constraint_marks(sim)
        assert marks.target.shape == (2, 3)  # orientation and areas are not point targets
        assert np.allclose(marks.point, p[[0, 1], JOINT_INDEX["wrist_r"]])
        assert np.allclose(marks.target[1], p[0, JOINT_INDEX["head_top"]])
        assert marks.error_m[0] == pytest.approx(0.002)  # the solver's residual
        assert marks.error_m[1] == pytest.approx(np.linalg.norm(marks.target[1] - marks.point[1]))
        areas = restricted_areas(sim)
        assert np.allclose(areas.sphere_centre, [[0.5, 0.5, 1.0]])
        assert np.allclose(areas.box_low, [[0.8, -0.2, 0.0]]) and np.allclose(areas.box_high, [[1.2, 0.2, 1.5]])
        assert np.allclose(areas.plane_normal, [[0, 1, 0]])
        rows = area_instances(areas)
        assert rows.shape == (1 + 12 + 5, INSTANCE_FLOATS)
        frame = snapshot(sim)
        assert frame.areas.shape == rows.shape and frame.targets.shape == (4, INSTANCE_FLOATS)


def test_team_colours_share_by_team_and_differ_by_index():
    c = team_colours(["red", "", "red", "", "blue"])
    assert np.allclose(c[0], c[2])
    assert len({tuple(np.round(x, 6)) for x in c}) == 4


def test_priority_colours_run_from_blue_to_red():
    c = priority_colours(np.array([1.0, 10.0, 5.5]))
    assert c[1, 0] > 0.8 and c[1, 2] < 0.2     # highest: red
    assert c[0, 2] > 0.8 and c[0, 0] < 0.2     # lowest: blue
    assert np.allclose(priority_colours(np.array([3.0, 3.0])), priority_colours(np.array([9.0]))[0])


def test_ground_mesh_follows_the_ground():
    scenario = _scenario("terrain_walk.yaml")
    mesh = ground_mesh(scenario.ground, (5.0, 0.0), 3.0, cell_m=0.1)
    xyz = mesh.vertices[:, :3].astype(np.float64)
    # float32 vertices: a point on a step's edge may round to the other side of it
    heights = [scenario.ground.height(xyz[:, :2] + [dx, 0.0]) for dx in (0.0, -1e-5, 1e-5)]
    assert np.all(np.any([np.isclose(xyz[:, 2], h, atol=1e-5) for h in heights], axis=0))
    assert np.allclose(np.linalg.norm(mesh.vertices[:, 3:], axis=1), 1.0, atol=1e-5)
    assert mesh.triangles.max() < mesh.vertices.shape[0]


# --- PNG ----------------------------------------------------------------------------------

def _unfilter(raw: bytes, h: int, w: int, channels: int) -> np.ndarray:
    stride = w * channels
    out = np.zeros((h, stride), np.int32)
    rows = np.frombuffer(raw, np.uint8).reshape(h, stride + 1)
    prev = np.zeros(stride, np.int32)
    for y in range(h):
        kind, line = rows[y, 0], rows[y, 1:].astype(np.int32)
        if kind == 0:
            cur = line
        elif kind == 2:
            cur = (line + prev) & 255
        else:  # 1 (sub), 3 (average), 4 (Paeth) depend on the left pixel: go byte by byte
            cur = np.zeros(stride, np.int32)
            for x in range(stride):
                left = cur[x - channels] if x >= channels else 0
                up, upleft = prev[x], (prev[x - channels] if x >= channels else 0)
                if kind == 1:
                    pred = left
                elif kind == 3:
                    pred = (left + up) // 2
                elif kind == 4:
                    p = left + up - upleft
                    pa, pb, pc = abs(p - left), abs(p - up), abs(p - upleft)
                    pred = left if pa <= pb and pa <= pc else (up if pb <= pc else upleft)
                else:
                    raise ValueError(f"PNG: unknown filter type {kind}")
                cur[x] = (line[x] + pred) & 255
        out[y] = cur
        prev = cur
    return out.astype(np.uint8).reshape(h, w, channels)


def read_png(path: str | Path) -> np.ndarray:
    """(height, width, 3) uint8 of an 8-bit RGB or RGBA non-interlaced PNG (alpha dropped): what
    :func:`ecs_anim.apps.viewer.png.write_png` writes, read back to check it."""
    data = Path(path).read_bytes()
    if not data.startswith(SIGNATURE):
        raise ValueError(f"{path}: not a PNG file")
    pos, idat, header = len(SIGNATURE), b"", None
    while pos < len(data):
        (length,) = struct.unpack(">I", data[pos:pos + 4])
        kind, body = data[pos + 4:pos + 8], data[pos + 8:pos + 8 + length]
        (crc,) = struct.unpack(">I", data[pos + 8 + length:pos + 12 + length])
        if zlib.crc32(kind + body) != crc:
            raise ValueError(f"{path}: PNG chunk {kind!r} has a bad checksum")
        if kind == b"IHDR":
            header = struct.unpack(">IIBBBBB", body)
        elif kind == b"IDAT":
            idat += body
        elif kind == b"IEND":
            break
        pos += 12 + length
    if header is None:
        raise ValueError(f"{path}: PNG without a header")
    w, h, depth, colour, _, _, interlace = header
    if depth != 8 or colour not in (2, 6) or interlace:
        raise ValueError(f"{path}: only 8-bit RGB/RGBA non-interlaced PNGs are read here")
    channels = 3 if colour == 2 else 4
    return _unfilter(zlib.decompress(idat), h, w, channels)[..., :3]


def test_png_round_trip(tmp_path):
    rng = np.random.default_rng(2)
    image = rng.integers(0, 256, (7, 5, 3), dtype=np.uint8)
    path = tmp_path / "a.png"
    path.write_bytes(encode_png(image))
    assert np.array_equal(read_png(path), image)


# --- rendering -----------------------------------------------------------------------------


def _character_mask(rgb: np.ndarray, colour: np.ndarray) -> np.ndarray:
    """Pixels whose chromaticity is that of a character colour (lit or in shade)."""
    px = rgb.astype(np.float64)
    saturation = px.max(axis=-1) - px.min(axis=-1)
    chroma = px / np.maximum(px.sum(axis=-1, keepdims=True), 1.0)
    target = colour / colour.sum()
    return (saturation > 40) & (np.linalg.norm(chroma - target, axis=-1) < 0.06)


def _check_characters_where_they_are(shot, colours: np.ndarray,
                                     extra_points: np.ndarray | None = None) -> None:
    """``extra_points`` (k, 3): other things drawn in colour (restricted areas' corners)."""
    h, w = shot.rgb.shape[:2]
    joints = shot.frame.joints
    pelvis_px = shot.camera.project(joints[:, PELVIS], w, h)
    drawn = joints.reshape(-1, 3) if extra_points is None else np.concatenate(
        [joints.reshape(-1, 3), extra_points])
    all_px = shot.camera.project(drawn, w, h)
    saturated = (shot.rgb.max(axis=-1).astype(int) - shot.rgb.min(axis=-1)) > 40
    # Restricted areas are drawn where the scenario puts them, not on characters.
    from ecs_anim.apps.viewer.scene import AREA_COLOUR
    saturated &= ~_character_mask(shot.rgb, np.array(AREA_COLOUR) * 255)
    yy, xx = np.mgrid[0:h, 0:w]
    for i, (x, y) in enumerate(pelvis_px):
        assert 0 <= x < w and 0 <= y < h, f"character {i}'s pelvis is outside the image"
        near = (xx - x) ** 2 + (yy - y) ** 2 <= (0.03 * h) ** 2
        mine = _character_mask(shot.rgb, colours[i]) & near
        assert mine.sum() >= 10, f"character {i}: {mine.sum()} pixels of its colour at its pelvis"
    # nowhere absurd: every strongly coloured pixel lies near some character's projected joints
    lo, hi = all_px.min(axis=0) - 0.12 * h, all_px.max(axis=0) + 0.12 * h
    inside = (xx >= lo[0]) & (xx <= hi[0]) & (yy >= lo[1]) & (yy <= hi[1])
    stray = saturated & ~inside
    assert stray.sum() == 0, f"{stray.sum()} coloured pixels far from every character"
    assert saturated.sum() > 0.01 * h * w
    # the rest is sky and ground: unsaturated, and both present
    assert (~saturated).sum() > 0.5 * h * w


@pytest.mark.parametrize("name, at_s", [
    ("terrain_walk.yaml", 3.0), ("reach_and_touch.yaml", 2.5), ("fight_training.yaml", 1.2),
    ("wrists_above_table.yaml", 4.0), ("grasp_com.yaml", 1.6), ("wrist_elbow_priority.yaml", 1.5),
    ("dance_morphologies.yaml", 3.0)])
def test_screenshot_shows_the_characters_where_they_are(tmp_path, name, at_s, capsys):
    need_gl()
    out = tmp_path / f"{Path(name).stem}.png"
    assert main(["view", str(SCENARIOS_DIR / name), "--screenshot", str(out), "--at", str(at_s),
                 "--size", "640x360"]) == 0
    assert "wrote" in capsys.readouterr().out
    keep = os.environ.get("ECS_ANIM_SCREENSHOT_DIR")  # CI keeps them for a person to look at
    if keep:
        Path(keep).mkdir(parents=True, exist_ok=True)
        (Path(keep) / out.name).write_bytes(out.read_bytes())
    rgb = read_png(out)
    assert rgb.shape == (360, 640, 3)
    # the same frame rendered in-process gives the camera and joints to check against
    from ecs_anim.apps.viewer.screenshot import render_screenshot

    scenario = _scenario(name)
    shot = render_screenshot(scenario, at_s, 640, 360)
    assert np.abs(shot.rgb.astype(int) - rgb).max() <= 2  # deterministic
    with build_simulation(scenario) as sim:
        from ecs_anim.apps.viewer.scene import character_teams

        colours = team_colours(character_teams(sim))
        table = sim.constraints
        boxes = np.flatnonzero(table.area_shape == 1)
        corners = np.array([table.target_world[k] + np.where(np.array([i >> b & 1 for b in range(3)]) > 0,
                                                               table.area_high[k], table.area_low[k])
                            for k in boxes for i in range(8)]).reshape(-1, 3)
    _check_characters_where_they_are(shot, colours, corners if corners.size else None)


def test_screenshot_without_targets_and_com_hides_them():
    need_gl()
    from ecs_anim.apps.viewer.screenshot import render_screenshot

    scenario = _scenario("reach_and_touch.yaml")
    shown = render_screenshot(scenario, 2.5, 320, 180)
    hidden = render_screenshot(scenario, 2.5, 320, 180, camera=shown.camera, show_targets=False,
                               show_com=False)

    def red_blue_yellow(rgb: np.ndarray) -> int:
        r, g, b = (rgb[..., k].astype(int) for k in range(3))
        return int(((r > 150) & (g < 60) & (b < 60)).sum() + ((b > 150) & (r < 80) & (g < 110)).sum()
                   + ((r > 180) & (g > 160) & (b < 60)).sum())

    assert red_blue_yellow(shown.rgb) > 30
    assert red_blue_yellow(hidden.rgb) < red_blue_yellow(shown.rgb) / 5


def test_restricted_areas_are_drawn():
    need_gl()
    from ecs_anim.apps.viewer.screenshot import render_frame

    with build_simulation(_scenario("reach_and_touch.yaml")) as sim:
        sim.step()
        plain = snapshot(sim)
        sim.constraints = _full_table()  # type: ignore[assignment]
        with_areas = snapshot(sim)
        ground = sim.ground
    shot = render_frame(with_areas, ground, 320, 180, status=False)
    without = render_frame(plain, ground, 320, 180, camera=shot.camera, status=False)
    r, g, b = (shot.rgb[..., k].astype(int) for k in range(3))
    magenta = (r > 150) & (b > 90) & (g < 120) & (r - g > 60)
    r0, g0, b0 = (without.rgb[..., k].astype(int) for k in range(3))
    assert magenta.sum() > 50
    assert ((r0 > 150) & (b0 > 90) & (g0 < 120) & (r0 - g0 > 60)).sum() == 0


def test_viewer_window_controls():
    """The interactive viewer in an offscreen window: clock, keys, mouse, follow, restart."""
    need_gl()
    import pyglet

    from ecs_anim.apps.viewer.window import open_viewer

    app = open_viewer(_scenario("reach_and_touch.yaml"), 320, 180, headless=True)
    key, mouse = pyglet.window.key, pyglet.window.mouse
    try:
        assert app.sim is not None and app.sim.tick == 1 and app.camera is not None
        app.update(0.1)  # 0.1 s at 30 Hz: 3 fixed ticks
        assert app.sim.tick == 4
        app.update(10.0)  # a long stall is not caught up (at most 8 ticks a frame)
        assert app.sim.tick == 4 + app.MAX_STEPS_PER_FRAME
        app.on_key_press(key.SPACE, 0)
        tick = app.sim.tick
        app.update(1.0)
        assert app.paused and app.sim.tick == tick
        app.on_key_press(key.RIGHT, 0)
        assert app.sim.tick == tick + 1
        app.on_key_press(key.UP, 0)
        assert app.speed == 2.0
        app.on_key_press(key.T, 0)
        app.on_key_press(key.C, 0)
        assert not app.show_targets and not app.show_com
        yaw, distance = app.camera.yaw_rad, app.camera.distance
        app.on_mouse_drag(10, 10, 50, 0, mouse.LEFT, 0)
        app.on_mouse_scroll(10, 10, 0, 1)
        assert app.camera.yaw_rad != yaw and app.camera.distance < distance
        app.on_mouse_drag(10, 10, 5, 5, mouse.RIGHT, 0)
        assert not app.follow
        app.on_draw()
        assert "paused" in app.label.text and "speed x2" in app.label.text
        app.on_key_press(key.F, 0)
        assert app.follow
        app.on_key_press(key.R, 0)
        assert app.sim.tick == 1
        app.on_draw()
        # At the scenario's end it starts again (L switches that off).
        app.on_key_press(key.SPACE, 0)
        app.speed = 1.0
        end_tick = round(app.scenario.duration_s * app.scenario.fps)
        while app.sim.tick < end_tick + 1:
            app.update(app.sim.dt)
        assert app.sim.tick == end_tick + 1
        app.update(app.sim.dt)
        assert app.sim.tick == 1
        app.on_key_press(key.L, 0)
        assert not app.loop
        while app.sim.tick < end_tick + 3:
            app.update(app.sim.dt)
        assert app.sim.tick == end_tick + 3
    finally:
        app.on_close()
        app.window.close()


def test_a_side_view_of_one_pair_draws_and_frames_only_that_pair(tmp_path, capsys):
    """docs/viewer.md's side view of the fight's pair 2 at its kick (docs/images/fight_pair2_side.png):
    two characters drawn, the other six (still simulated, as the triggers need them) and their
    targets hidden, seen from the kicker's right; an unknown name is one line."""
    need_gl()
    out = tmp_path / "pair2.png"
    assert main(["view", str(SCENARIOS_DIR / "fight_training.yaml"), "--screenshot", str(out),
                 "--at", "1.2", "--only", "kicker_2,defender_2", "--yaw-deg", "-100",
                 "--pitch-deg", "6", "--size", "320x240"]) == 0
    assert "t = 1.200 s, 2 characters" in capsys.readouterr().out
    from ecs_anim.apps.viewer.screenshot import render_screenshot

    scenario = _scenario("fight_training.yaml")
    scenario.camera = {"yaw_deg": -100.0, "pitch_deg": 6.0}
    shot = render_screenshot(scenario, 1.2, 320, 240, only=frozenset({"kicker_2", "defender_2"}))
    assert np.abs(shot.rgb.astype(int) - read_png(out)).max() <= 2
    assert shot.frame.n_characters == 2 and shot.frame.joints.shape[0] == 2
    assert np.allclose(shot.frame.joints[:, 0, 1], 2.0, atol=0.3)  # pair 2 stands at y = 2 m
    assert shot.frame.marks is not None and shot.frame.marks.target.shape[0] >= 1
    assert np.all(np.abs(shot.frame.marks.target[:, 1] - 2.0) < 0.5)  # its own targets only
    assert math.isclose(math.degrees(shot.camera.yaw_rad), -100.0)
    assert main(["view", str(SCENARIOS_DIR / "fight_training.yaml"), "--screenshot",
                 str(tmp_path / "x.png"), "--only", "kicker_9"]) == 1
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "no character named kicker_9" in err


def test_screenshot_refuses_to_overwrite(tmp_path, capsys):
    out = tmp_path / "x.png"
    out.write_bytes(b"keep")
    assert main(["view", str(SCENARIOS_DIR / "reach_and_touch.yaml"), "--screenshot", str(out)]) == 1
    assert "already exists" in capsys.readouterr().err
    assert out.read_bytes() == b"keep"


def test_view_errors_are_one_line(tmp_path, capsys, monkeypatch):
    monkeypatch.delenv("DISPLAY", raising=False)
    monkeypatch.delenv("WAYLAND_DISPLAY", raising=False)
    if sys.platform.startswith("linux"):
        assert main(["view", str(SCENARIOS_DIR / "reach_and_touch.yaml")]) == 1
        err = capsys.readouterr().err
        assert err.count("\n") == 1 and "--screenshot" in err
    assert main(["view", str(SCENARIOS_DIR / "reach_and_touch.yaml"), "--screenshot",
                 str(tmp_path / "a.png"), "--at", "1000"]) == 1
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "after the scenario's end" in err
    with pytest.raises(SystemExit):
        main(["view", str(SCENARIOS_DIR / "reach_and_touch.yaml"), "--size", "big"])


def test_render_system_only_notes_the_tick():
    """STYLE 8: with a window the Render system hands the store over; the posture is the same
    as headless."""
    from ecs_anim.apps.viewer.scene_view import SceneSource

    scenario = _scenario("reach_and_touch.yaml")
    with build_simulation(scenario, window=True) as windowed, build_simulation(scenario) as headless:
        source = SceneSource()
        windowed.renderer = source
        for _ in range(20):
            windowed.step()
            headless.step()
            frame = source.latest()
        assert frame is not None and frame.time_s == pytest.approx(19 / 30)
        assert np.array_equal(windowed.store.positions, headless.store.positions)
        assert np.allclose(replace(frame).joints, headless.store.positions)


def test_tables_are_drawn_where_the_scenario_puts_them():
    """The table scene's two tables become capsules: a top of touching rods at the table's
    height, and four legs standing on the ground; they are unsaturated (never a character)."""
    from ecs_anim.apps.viewer.scene import TABLE_COLOUR, TABLE_TOP_RADIUS_M, snapshot

    scenario = _scenario("wrists_above_table.yaml")
    assert len(scenario.tables) == 2
    with build_simulation(scenario, window=True) as sim:
        sim.step()
        frame = snapshot(sim)
    rows = frame.props
    top = rows[rows[:, 6] == np.float32(TABLE_TOP_RADIUS_M)]
    legs = rows[rows[:, 6] != np.float32(TABLE_TOP_RADIUS_M)]
    assert len(legs) == 8 and len(top) >= 2 * 20
    np.testing.assert_allclose(top[:, 2] + TABLE_TOP_RADIUS_M, 0.92, atol=1e-6)  # the top's height
    np.testing.assert_allclose(legs[:, 5] - legs[:, 6], 0.0, atol=1e-6)  # legs reach the ground
    for table in scenario.tables:
        near = np.linalg.norm(top[:, :2] - np.array(table.centre_m), axis=1) < 0.7
        assert near.any()
    assert max(TABLE_COLOUR) - min(TABLE_COLOUR) < 40 / 255


FORK_AFTER_SCREENSHOT = """
import gc, multiprocessing, sys
gc.disable()  # the display of the screenshot below stays garbage until a child collects it
from ecs_anim import load_scenario
from ecs_anim.apps.viewer.screenshot import write_screenshot
write_screenshot(load_scenario(sys.argv[1]), sys.argv[2], 0.5, 64, 48, force=True)
with multiprocessing.get_context("fork").Pool(1) as pool:
    print("collected", pool.apply(gc.collect) >= 0)
"""


def test_a_process_forked_after_a_screenshot_can_collect_its_garbage(tmp_path):
    """A batch worker forked after a screenshot used to hang forever in pyglet's
    ``HeadlessDisplay.__del__`` (``eglTerminate`` of the parent's display) when it collected
    the display left behind; now the child leaves the parent's display alone."""
    need_gl()
    done = subprocess.run([sys.executable, "-c", FORK_AFTER_SCREENSHOT,
                           str(REPO / "scenarios" / "reach_and_touch.yaml"),
                           str(tmp_path / "shot.png")],
                          capture_output=True, text=True, timeout=120, check=False)
    assert done.returncode == 0 and "collected True" in done.stdout, done.stderr[-2000:]
