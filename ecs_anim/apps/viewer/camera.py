"""The viewer's camera: pure math, no OpenGL, so it can be tested without a screen.

An orbit camera looks at ``target`` from ``distance`` metres, from the direction given by
``yaw_rad`` (azimuth of the eye about Z, anticlockwise from +x) and ``pitch_rad`` (elevation of
the eye above the horizontal). World frame Z up (DESIGN §2). Matrices are OpenGL's: column
vectors, clip space x, y, z in [-1, 1] after the divide, stored as numpy (4, 4) float64 arrays
(``world2view``, ``view2clip``); pixels have their origin at the top-left corner of the image,
x to the right, y down (as in a PNG).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np
from numpy.typing import NDArray

F64 = NDArray[np.float64]

#: Pitch is kept strictly inside (-90°, 90°) so the view never flips over the pole.
MAX_PITCH_RAD = math.radians(89.0)


Z_UP = (0.0, 0.0, 1.0)


def _point(v: F64) -> tuple[float, float, float]:
    return (float(v[0]), float(v[1]), float(v[2]))


def look_at(eye: F64, target: F64, up: tuple[float, float, float] = Z_UP) -> F64:
    """world2view (4, 4): the eye at the origin looking down its -z axis at ``target``."""
    eye, target = np.asarray(eye, dtype=np.float64), np.asarray(target, dtype=np.float64)
    forward = target - eye
    forward = forward / max(float(np.linalg.norm(forward)), 1e-12)
    side = np.cross(forward, np.asarray(up, dtype=np.float64))
    if np.linalg.norm(side) < 1e-9:  # looking straight along up: any side will do
        side = np.cross(forward, np.array([0.0, 1.0, 0.0]))
    side = side / np.linalg.norm(side)
    true_up = np.cross(side, forward)
    world2view = np.eye(4)
    world2view[0, :3], world2view[1, :3], world2view[2, :3] = side, true_up, -forward
    world2view[:3, 3] = -world2view[:3, :3] @ eye
    return world2view


def perspective(fov_y_rad: float, aspect: float, near: float, far: float) -> F64:
    """view2clip (4, 4): OpenGL's symmetric perspective projection (``aspect`` = width/height)."""
    f = 1.0 / math.tan(fov_y_rad / 2.0)
    view2clip = np.zeros((4, 4))
    view2clip[0, 0] = f / aspect
    view2clip[1, 1] = f
    view2clip[2, 2] = (far + near) / (near - far)
    view2clip[2, 3] = 2.0 * far * near / (near - far)
    view2clip[3, 2] = -1.0
    return view2clip


def project_points(points_in_world: F64, world2clip: F64, width: int, height: int) -> F64:
    """Pixel coordinates (..., 2) of world points (..., 3): x right, y down from the top-left.

    Points behind the eye come out as NaN.
    """
    p = np.asarray(points_in_world, dtype=np.float64)
    homogeneous = np.concatenate([p, np.ones(p.shape[:-1] + (1,))], axis=-1)
    clip = homogeneous @ world2clip.T
    w = clip[..., 3]
    ndc = clip[..., :2] / np.where(w > 1e-12, w, np.nan)[..., None]
    x = (ndc[..., 0] + 1.0) * 0.5 * width
    y = (1.0 - ndc[..., 1]) * 0.5 * height
    return np.stack([x, y], axis=-1)


@dataclass(frozen=True)
class OrbitCamera:
    """Where the viewer looks from. Replace (``dataclasses.replace``) to move it.

    target : (3,) metres, world point the camera orbits; distance : metres from it;
    yaw_rad : eye azimuth about Z from +x; pitch_rad : eye elevation; fov_y_rad : vertical
    field of view.
    """

    target: tuple[float, float, float] = (0.0, 0.0, 1.0)
    distance: float = 6.0
    yaw_rad: float = math.radians(-105.0)
    pitch_rad: float = math.radians(18.0)
    fov_y_rad: float = math.radians(32.0)

    @property
    def eye(self) -> F64:
        """(3,) the eye's world position, metres."""
        c = math.cos(self.pitch_rad)
        direction = np.array([c * math.cos(self.yaw_rad), c * math.sin(self.yaw_rad),
                              math.sin(self.pitch_rad)])
        return np.asarray(self.target) + self.distance * direction

    def world2view(self) -> F64:
        return look_at(self.eye, np.asarray(self.target))

    def view2clip(self, aspect: float) -> F64:
        near = max(0.01, self.distance * 0.01)
        return perspective(self.fov_y_rad, aspect, near, self.distance * 50.0 + 100.0)

    def world2clip(self, width: int, height: int) -> F64:
        return self.view2clip(width / max(height, 1)) @ self.world2view()

    def project(self, points_in_world: F64, width: int, height: int) -> F64:
        """Pixels (..., 2), top-left origin, of world points (..., 3) in a width x height image."""
        return project_points(points_in_world, self.world2clip(width, height), width, height)

    def pixel_ray(self, x_px: float, y_px: float, width: int, height: int) -> tuple[F64, F64]:
        """The ray from the eye through pixel (x_px, y_px) (top-left origin, y down) of a
        width x height image: its origin (3,) (the eye) and unit direction (3,), world."""
        clip2world = np.linalg.inv(self.world2clip(width, height))
        ndc_x, ndc_y = 2.0 * x_px / width - 1.0, 1.0 - 2.0 * y_px / height
        far = clip2world @ np.array([ndc_x, ndc_y, 1.0, 1.0])
        direction = far[:3] / far[3] - self.eye
        return self.eye, direction / max(float(np.linalg.norm(direction)), 1e-12)

    # --- interaction ---------------------------------------------------------------------

    def orbit(self, d_yaw_rad: float, d_pitch_rad: float) -> OrbitCamera:
        pitch = min(max(self.pitch_rad + d_pitch_rad, -MAX_PITCH_RAD), MAX_PITCH_RAD)
        return replace(self, yaw_rad=self.yaw_rad + d_yaw_rad, pitch_rad=pitch)

    def zoom(self, factor: float) -> OrbitCamera:
        """Distance times ``factor`` (kept between 0.2 m and 10 km)."""
        return replace(self, distance=min(max(self.distance * factor, 0.2), 1e4))

    def pan(self, dx_px: float, dy_px: float, height_px: int) -> OrbitCamera:
        """Slide the target in the view plane so the scene follows a mouse drag of (dx, dy)
        pixels (x right, y up, as pyglet reports them)."""
        world2view = self.world2view()
        side, up = world2view[0, :3], world2view[1, :3]
        metres_per_px = 2.0 * self.distance * math.tan(self.fov_y_rad / 2.0) / max(height_px, 1)
        shift = (-dx_px * side - dy_px * up) * metres_per_px
        return replace(self, target=_point(np.asarray(self.target) + shift))


def frame_points(points_in_world: F64, aspect: float, camera: OrbitCamera = OrbitCamera(),
                 margin: float = 1.3) -> OrbitCamera:
    """The camera (same yaw, pitch, field of view) moved so all points (..., 3) are in view.

    Aims at the centre of the points' bounding box, far enough back that the bounding sphere
    fits the narrower field of view with ``margin``. Non-finite points are ignored; with none
    left, the camera is returned unchanged.
    """
    p = np.asarray(points_in_world, dtype=np.float64).reshape(-1, 3)
    p = p[np.all(np.isfinite(p), axis=1)]
    if p.shape[0] == 0:
        return camera
    lo, hi = p.min(axis=0), p.max(axis=0)
    centre = (lo + hi) / 2.0
    radius = max(float(np.linalg.norm(p - centre, axis=1).max()), 0.5)
    half_fov_y = camera.fov_y_rad / 2.0
    half_fov_x = math.atan(math.tan(half_fov_y) * aspect)
    # The bounding sphere always fits; then come as close as the points allow (bisection on
    # the distance: every point in front of the eye and inside 1 / margin of the view).
    far = margin * radius / math.sin(min(half_fov_x, half_fov_y))
    framed = replace(camera, target=_point(centre), distance=far)
    w, h = 1000, max(round(1000 / aspect), 1)

    def fits(distance: float) -> bool:
        pixels = replace(framed, distance=distance).project(p, w, h)
        ndc = np.abs(pixels / np.array([w, h]) * 2.0 - 1.0)
        return bool(np.all(np.isfinite(ndc)) and ndc.max() <= 1.0 / margin)

    near = radius * 0.5
    if not fits(far):
        return framed
    for _ in range(30):
        middle = (near + far) / 2
        near, far = (near, middle) if fits(middle) else (middle, far)
    return replace(framed, distance=far)


def spread_yaw(points_xy: F64, preferred_yaw_rad: float = OrbitCamera.yaw_rad,
               off_axis_rad: float = math.radians(35.0)) -> float:
    """An eye azimuth from which points spread in (x, y) overlap little.

    The eye looks ``off_axis_rad`` away from the points' minor axis (principal components of
    ``points_xy`` (k, 2)), so their main spread runs across the image (cos 35° ≈ 82 % of it)
    while the view stays oblique; of the four such directions, the one nearest
    ``preferred_yaw_rad``. Too few or too clustered points (< 0.3 m): ``preferred_yaw_rad``.
    """
    p = np.asarray(points_xy, dtype=np.float64).reshape(-1, 2)
    p = p[np.all(np.isfinite(p), axis=1)]
    if p.shape[0] < 2:
        return preferred_yaw_rad
    centred = p - p.mean(axis=0)
    values, vectors = np.linalg.eigh(centred.T @ centred / p.shape[0])
    if math.sqrt(max(values[-1], 0.0)) < 0.15:
        return preferred_yaw_rad
    minor = math.atan2(vectors[1, 0], vectors[0, 0])
    candidates = [minor + sign * off_axis_rad + k * math.pi for sign in (-1, 1) for k in (0, 1)]

    def gap(a: float) -> float:
        return abs(math.remainder(a - preferred_yaw_rad, 2 * math.pi))

    return math.remainder(min(candidates, key=gap), 2 * math.pi)
