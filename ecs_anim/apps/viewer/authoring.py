"""The viewer's authoring math, pure numpy (no OpenGL): picking what is under the mouse,
dragging a point in the view plane, and the timeline's geometry.

Pixels here are the camera's (top-left origin, y down: :mod:`ecs_anim.apps.viewer.camera`); the
window converts pyglet's mouse coordinates (bottom-left origin, y up) before calling.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from ecs_anim.apps.viewer.camera import OrbitCamera

F64 = NDArray[np.float64]

#: A click picks what lies within this many pixels of the mouse (beyond a capsule's edge).
PICK_TOLERANCE_PX = 4.0


def pick_capsule(camera: OrbitCamera, a: F64, b: F64, radius_m: F64, width: int, height: int,
                 x_px: float, y_px: float, tolerance_px: float = PICK_TOLERANCE_PX) -> int:
    """The capsule under pixel (x_px, y_px): the index of the front-most capsule whose
    projected outline passes within ``tolerance_px`` of it, or -1 for none.

    ``a``, ``b`` (k, 3) end points and ``radius_m`` (k,) in world metres (a sphere when a = b),
    as the viewer draws them. The ray through the mouse is tested in the image: the distance
    from the mouse to each projected axis, less the radius seen at that depth.
    """
    k = a.shape[0]
    if k == 0:
        return -1
    world2view = camera.world2view()
    depth_a = -(a @ world2view[:3, :3].T + world2view[:3, 3])[:, 2]
    depth_b = -(b @ world2view[:3, :3].T + world2view[:3, 3])[:, 2]
    pa, pb = camera.project(a, width, height), camera.project(b, width, height)
    mouse = np.array([x_px, y_px])
    axis = pb - pa
    along = np.einsum("ij,ij->i", mouse - pa, axis) / np.maximum(np.einsum("ij,ij->i", axis, axis), 1e-12)
    t = np.clip(along, 0.0, 1.0)
    gap_px = np.linalg.norm(mouse - (pa + t[:, None] * axis), axis=1)
    depth = depth_a + t * (depth_b - depth_a)
    focal_px = 0.5 * height / math.tan(camera.fov_y_rad / 2.0)
    radius_px = radius_m * focal_px / np.maximum(depth, 1e-9)
    hit = (depth_a > 0) & (depth_b > 0) & np.isfinite(gap_px) & (gap_px <= radius_px + tolerance_px)
    if not hit.any():
        return -1
    return int(np.flatnonzero(hit)[np.argmin(depth[hit])])


def drag_in_view_plane(camera: OrbitCamera, point_in_world: F64, x_px: float, y_px: float,
                       width: int, height: int) -> F64:
    """(3,) where the ray through pixel (x_px, y_px) meets the plane through
    ``point_in_world`` (3,) facing the camera: where a dragged point goes. A ray parallel to
    that plane (it cannot be, from a perspective eye) leaves the point where it is."""
    origin, direction = camera.pixel_ray(x_px, y_px, width, height)
    normal = camera.world2view()[2, :3]  # the view's +z: from the target towards the eye
    point = np.asarray(point_in_world, dtype=np.float64)
    facing = float(direction @ normal)
    if abs(facing) < 1e-12:
        return point
    distance = float((point - origin) @ normal) / facing
    return np.asarray(origin + distance * direction, dtype=np.float64)


@dataclass(frozen=True)
class Timeline:
    """The scrub bar along the bottom of the window, in pyglet's window pixels (origin at the
    bottom-left, y up): ``margin_px`` from the sides and the bottom, ``height_px`` tall,
    covering 0 to ``duration_s``."""

    duration_s: float
    margin_px: float = 10.0
    height_px: float = 14.0

    def span(self, width: int) -> tuple[float, float]:
        """The bar's left and right ends (x, pixels)."""
        return self.margin_px, max(width - self.margin_px, self.margin_px + 1.0)

    def contains(self, x: float, y: float, width: int) -> bool:
        """Whether (x, y) is on the bar (a few pixels of slack above and below)."""
        left, right = self.span(width)
        bottom, top = self.margin_px - 4.0, self.margin_px + self.height_px + 4.0
        return left - 4.0 <= x <= right + 4.0 and bottom <= y <= top

    def time_at(self, x: float, width: int) -> float:
        """The time (s) at window x, clamped to the bar."""
        left, right = self.span(width)
        return float(np.clip((x - left) / (right - left), 0.0, 1.0) * self.duration_s)

    def x_of(self, time_s: float, width: int) -> float:
        """Window x of a time (s), clamped to the bar."""
        left, right = self.span(width)
        return left + float(np.clip(time_s / max(self.duration_s, 1e-12), 0.0, 1.0)) * (right - left)
