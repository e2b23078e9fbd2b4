"""What the viewer draws, as numpy arrays built from a simulation's store: no OpenGL here.

Every body part, constraint target, centre of mass and restricted area is a *capsule instance*:
two end points ``a`` and ``b`` (a sphere when they coincide), a radius and a colour, packed as
one float32 row. Rows for all characters are built with array operations (no per-character
Python loop), so thousands of characters cost one instanced draw. Read-only (STYLE 8).
"""

from __future__ import annotations

import colorsys
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import esper
import numpy as np
from numpy.typing import NDArray

from ecs_anim.apps.viewer.constraint_view import (
    ConstraintMarks,
    RestrictedAreas,
    constraint_marks,
    max_constraint_error_m,
    restricted_areas,
    unreachable_uids,
)
from ecs_anim.core.ground import Combined, Ground, HeightGrid, Stairs
from ecs_anim.core.morphology import centres_of_mass, leg_length
from ecs_anim.core.skeleton import JOINT_INDEX
from ecs_anim.runtime.simulation import Simulation

F32 = NDArray[np.float32]
F64 = NDArray[np.float64]

#: Floats per instance: a (3), b (3), radius (1), rgba (4).
INSTANCE_FLOATS = 11

# Body capsules: (from joint, to joint, start fraction, end fraction, radius per leg length,
# shade). The radius scales with each character's leg length; shade darkens the left side so
# a character's facing reads at a glance.
_J = JOINT_INDEX
BODY_CAPSULES: tuple[tuple[str, str, float, float, float, float], ...] = (
    ("hip_l", "hip_r", 0.0, 1.0, 0.115, 1.0),
    ("pelvis", "spine_1", 0.0, 1.0, 0.135, 1.0),
    ("spine_1", "spine_2", 0.0, 1.0, 0.145, 1.0),
    ("spine_2", "neck", 0.0, 0.8, 0.14, 1.0),
    ("shoulder_l", "shoulder_r", 0.0, 1.0, 0.075, 1.0),
    ("neck", "head", 0.0, 1.0, 0.055, 1.12),
    ("head", "head_top", 0.42, 0.58, 0.12, 1.18),
    ("hip_l", "knee_l", 0.0, 1.0, 0.085, 0.78),
    ("knee_l", "ankle_l", 0.0, 1.0, 0.062, 0.78),
    ("ankle_l", "toe_l", 0.0, 1.0, 0.048, 0.7),
    ("hip_r", "knee_r", 0.0, 1.0, 0.085, 1.0),
    ("knee_r", "ankle_r", 0.0, 1.0, 0.062, 1.0),
    ("ankle_r", "toe_r", 0.0, 1.0, 0.048, 0.9),
    ("shoulder_l", "elbow_l", 0.0, 1.0, 0.06, 0.78),
    ("elbow_l", "wrist_l", 0.0, 1.0, 0.05, 0.78),
    ("wrist_l", "hand_l", 0.0, 1.0, 0.04, 0.7),
    ("shoulder_r", "elbow_r", 0.0, 1.0, 0.06, 1.0),
    ("elbow_r", "wrist_r", 0.0, 1.0, 0.05, 1.0),
    ("wrist_r", "hand_r", 0.0, 1.0, 0.04, 0.9),
)
_FROM = np.array([_J[c[0]] for c in BODY_CAPSULES])
_TO = np.array([_J[c[1]] for c in BODY_CAPSULES])
_T0 = np.array([c[2] for c in BODY_CAPSULES])[None, :, None]
_T1 = np.array([c[3] for c in BODY_CAPSULES])[None, :, None]
_RADIUS_PER_LEG = np.array([c[4] for c in BODY_CAPSULES])
_SHADE = np.array([c[5] for c in BODY_CAPSULES])

#: The head capsule's radius follows the head segment (skull base to top) rather than the leg.
_HEAD = next(i for i, c in enumerate(BODY_CAPSULES) if c[:2] == ("head", "head_top"))
HEAD_RADIUS_PER_HEAD_LENGTH = 0.5

#: Team colours (RGB 0-1): saturated hues kept away from the targets' red and blue and the
#: centre of mass's yellow, so each reads as a character.
TEAM_PALETTE: tuple[tuple[float, float, float], ...] = tuple(
    colorsys.hsv_to_rgb(h, 0.8, 0.9) for h in (0.08, 0.36, 0.78, 0.48, 0.90, 0.27, 0.56, 0.13)
)
TARGET_HIGH = (0.9, 0.1, 0.1)   # highest priority
TARGET_LOW = (0.15, 0.3, 0.95)  # lowest priority
COM_COLOUR = (1.0, 0.9, 0.1)
AREA_COLOUR = (0.9, 0.2, 0.6)


def character_teams(sim: Simulation) -> list[str]:
    """Each row's team label (``""`` when none), in store order."""
    from ecs_anim.components import CharacterRow, Name

    with sim._active():
        by_row = {r.row: n.team for _, (r, n) in esper.get_components(CharacterRow, Name)}
    return [by_row.get(i, "") for i in range(sim.store.n)]


def team_colours(teams: list[str]) -> F64:
    """(n, 3) RGB per character: one palette colour per team (in order of first appearance);
    characters without a team get their own colour each, by index."""
    keys: dict[str, int] = {}
    index = []
    for i, team in enumerate(teams):
        key = team if team else f"\0{i}"
        index.append(keys.setdefault(key, len(keys)))
    palette = np.array(TEAM_PALETTE)
    return np.asarray(palette[np.array(index, dtype=np.int64) % len(palette)].reshape(-1, 3),
                      dtype=np.float64)


def pack_instances(a: F64, b: F64, radius: F64, rgba: F64) -> F32:
    """(k, INSTANCE_FLOATS) float32 rows from a (k, 3), b (k, 3), radius (k,), rgba (k, 4)."""
    return np.concatenate([a, b, radius[:, None], rgba], axis=1).astype(np.float32)


def body_instances(positions: F64, lengths: F64, colours: F64) -> F32:
    """Capsules of all bodies: positions (n, N_JOINTS, 3), lengths (n, N_LENGTHS) metres,
    colours (n, 3) -> (n * len(BODY_CAPSULES), INSTANCE_FLOATS)."""
    n = positions.shape[0]
    p0, p1 = positions[:, _FROM], positions[:, _TO]
    a, b = p0 + _T0 * (p1 - p0), p0 + _T1 * (p1 - p0)
    radius = leg_length(lengths)[:, None] * _RADIUS_PER_LEG[None, :]
    head = np.linalg.norm(positions[:, _J["head_top"]] - positions[:, _J["head"]], axis=-1)
    radius[:, _HEAD] = HEAD_RADIUS_PER_HEAD_LENGTH * head
    rgb = np.clip(colours[:, None, :] * _SHADE[None, :, None], 0.0, 1.0)
    rgba = np.concatenate([rgb, np.ones(rgb.shape[:-1] + (1,))], axis=-1)
    return pack_instances(a.reshape(-1, 3), b.reshape(-1, 3), radius.reshape(-1),
                          rgba.reshape(-1, 4)) if n else np.zeros((0, INSTANCE_FLOATS), np.float32)


def priority_colours(priority: F64) -> F64:
    """(m, 3): red for the highest priority, blue for the lowest, blended in between (all red
    when they are equal)."""
    if priority.size == 0:
        return np.zeros((0, 3))
    lo, hi = float(priority.min()), float(priority.max())
    t = np.ones_like(priority) if hi <= lo else (priority - lo) / (hi - lo)
    rgb: F64 = t[:, None] * np.array(TARGET_HIGH) + (1 - t[:, None]) * np.array(TARGET_LOW)
    return rgb


def target_instances(marks: ConstraintMarks, scale_m: float = 1.0) -> F32:
    """A sphere at every active target (bigger as its weight grows) and a thin rod from the
    constrained point to it: (2 m, INSTANCE_FLOATS)."""
    m = marks.target.shape[0]
    if m == 0:
        return np.zeros((0, INSTANCE_FLOATS), np.float32)
    rgb = priority_colours(marks.priority)
    rgba = np.concatenate([rgb, np.ones((m, 1))], axis=1)
    spheres = pack_instances(marks.target, marks.target, scale_m * (0.025 + 0.025 * marks.weight), rgba)
    rods = pack_instances(marks.point, marks.target, np.full(m, 0.006 * scale_m), rgba)
    return np.concatenate([spheres, rods])


#: A constraint whose target its body cannot reach (``Simulation.feasibility``): a dark pin
#: standing on the target, its head this high above it (m).
UNREACHABLE_COLOUR = (0.08, 0.08, 0.08)
UNREACHABLE_PIN_M = 0.3


def unreachable_instances(marks: ConstraintMarks, unreachable: frozenset[int],
                          scale_m: float = 1.0) -> F32:
    """A pin (a rod up from the target, a ball on top) on every drawn target its body cannot
    reach (``unreachable``: constraint ids): (2 k, INSTANCE_FLOATS)."""
    out = np.isin(marks.uid, np.fromiter(unreachable, np.int64, len(unreachable)))
    k = int(out.sum())
    if k == 0:
        return np.zeros((0, INSTANCE_FLOATS), np.float32)
    foot = marks.target[out]
    head = foot + np.array([0.0, 0.0, UNREACHABLE_PIN_M * scale_m])
    rgba = np.tile([*UNREACHABLE_COLOUR, 1.0], (k, 1))
    return np.concatenate([pack_instances(foot, head, np.full(k, 0.008 * scale_m), rgba),
                           pack_instances(head, head, np.full(k, 0.035 * scale_m), rgba)])


_BOX_CORNERS = np.array([[i & 1, (i >> 1) & 1, (i >> 2) & 1] for i in range(8)], dtype=np.float64)
_BOX_EDGES = np.array([(a, b) for a in range(8) for b in range(a + 1, 8)
                       if (a ^ b).bit_count() == 1])  # (12, 2) corners one axis apart
AREA_LINE_M = 0.008
PLANE_HALF_SIZE_M = 1.0


def area_instances(areas: RestrictedAreas) -> F32:
    """Restricted areas: a translucent sphere per sphere, the 12 edges of each box, and for a
    half-space a 2 m square outline in its boundary plane with a rod along its normal (the
    allowed side)."""
    rows = []
    k = areas.sphere_centre.shape[0]
    rows.append(pack_instances(areas.sphere_centre, areas.sphere_centre, areas.sphere_radius,
                               np.tile([*AREA_COLOUR, 0.25], (k, 1))))
    low, high = areas.box_low, areas.box_high
    corners = low[:, None, :] + _BOX_CORNERS[None] * (high - low)[:, None, :]  # (b, 8, 3)
    a, b = corners[:, _BOX_EDGES[:, 0]].reshape(-1, 3), corners[:, _BOX_EDGES[:, 1]].reshape(-1, 3)
    rows.append(pack_instances(a, b, np.full(a.shape[0], AREA_LINE_M),
                               np.tile([*AREA_COLOUR, 1.0], (a.shape[0], 1))))
    point, normal = areas.plane_point, areas.plane_normal
    if point.shape[0]:
        n = normal / np.maximum(np.linalg.norm(normal, axis=1, keepdims=True), 1e-12)
        helper = np.where((np.abs(n[:, 2]) < 0.9)[:, None], [0.0, 0.0, 1.0], [1.0, 0.0, 0.0])
        u = np.cross(n, helper)
        u /= np.linalg.norm(u, axis=1, keepdims=True)
        v = np.cross(n, u)
        h = PLANE_HALF_SIZE_M
        square = np.stack([point + h * (su * u + sv * v)
                           for su, sv in ((-1, -1), (1, -1), (1, 1), (-1, 1))], axis=1)  # (c, 4, 3)
        a = square.reshape(-1, 3)
        b = np.roll(square, -1, axis=1).reshape(-1, 3)
        a = np.concatenate([a, point])
        b = np.concatenate([b, point + 0.3 * n])
        rows.append(pack_instances(a, b, np.full(a.shape[0], AREA_LINE_M),
                                   np.tile([*AREA_COLOUR, 1.0], (a.shape[0], 1))))
    return np.concatenate(rows)


TABLE_COLOUR = (0.62, 0.58, 0.53)  # pale wood: unsaturated, so never taken for a character
TABLE_TOP_RADIUS_M = 0.02
TABLE_LEG_RADIUS_M = 0.025


def table_instances(tables: Sequence[Any], ground: Ground) -> F32:
    """Capsules drawing each table: its top as rods side by side along its length, touching
    (0.04 m thick), and a leg at each corner down to the ground. ``tables``: scenario tables
    (``centre_m``, ``size_m``, ``height_m``, ``heading_rad``)."""
    rows = [np.zeros((0, INSTANCE_FLOATS), np.float32)]
    r = TABLE_TOP_RADIUS_M
    for t in tables:
        along = np.array([np.cos(t.heading_rad), np.sin(t.heading_rad), 0.0])
        across = np.array([-along[1], along[0], 0.0])
        centre_xy = np.asarray(t.centre_m, dtype=np.float64)
        floor = float(ground.height(centre_xy))
        top = np.array([centre_xy[0], centre_xy[1], floor + t.height_m - r])
        half_l, half_w = 0.5 * t.size_m[0] - r, 0.5 * t.size_m[1] - r
        offsets = np.linspace(-half_w, half_w, max(round(2 * half_w / (2 * r)) + 1, 2))
        a = top + offsets[:, None] * across - half_l * along
        b = top + offsets[:, None] * across + half_l * along
        corners = np.array([top + sl * (half_l - 0.03) * along + sw * (half_w - 0.03) * across
                            for sl in (-1, 1) for sw in (-1, 1)])
        feet = corners.copy()
        feet[:, 2] = ground.height(corners[:, :2]) + TABLE_LEG_RADIUS_M
        starts, ends = np.concatenate([a, corners]), np.concatenate([b, feet])
        radius = np.concatenate([np.full(len(a), r), np.full(4, TABLE_LEG_RADIUS_M)])
        rows.append(pack_instances(starts, ends, radius, np.tile([*TABLE_COLOUR, 1.0], (len(radius), 1))))
    return np.concatenate(rows)


def com_instances(com: F64, radius_m: F64) -> F32:
    """A yellow sphere per centre of mass: com (n, 3), radius (n,)."""
    rgba = np.tile(np.array([*COM_COLOUR, 1.0]), (com.shape[0], 1))
    return pack_instances(com, com, radius_m, rgba)


@dataclass(frozen=True)
class SceneFrame:
    """One drawable snapshot of a simulation.

    bodies, targets, com, areas, props : (k, INSTANCE_FLOATS) float32 instance rows (areas
    are drawn last, blended, without writing depth; props are the scenario's tables);
    joints (n, N_JOINTS, 3) world metres (for framing and labels); time_s the posture's
    simulation time; max_error_m the largest error (m) of the fully active constraints, all
    kinds but orientations (None without any); n_characters; rows (n,) the store row of each
    drawn character (those with a finite posture); marks the point constraints drawn as
    ``targets`` (their first ``m`` rows are the target spheres, in the marks' order).
    """

    bodies: F32
    targets: F32
    com: F32
    areas: F32
    joints: F64
    time_s: float
    max_error_m: float | None
    n_characters: int
    props: F32 = field(default_factory=lambda: np.zeros((0, INSTANCE_FLOATS), np.float32))
    rows: NDArray[np.int64] = field(default_factory=lambda: np.zeros(0, np.int64))
    marks: ConstraintMarks | None = None


#: A picked character is drawn this far from its colour towards white.
HIGHLIGHT_MIX = 0.6


def highlighted(colours: F64, rows: NDArray[np.int64]) -> F64:
    """``colours`` (n, 3) with the characters at ``rows`` lightened (:data:`HIGHLIGHT_MIX`
    of the way to white): how the viewer shows the picked character."""
    out = np.array(colours, dtype=np.float64)
    out[rows] = (1.0 - HIGHLIGHT_MIX) * out[rows] + HIGHLIGHT_MIX
    return out


def snapshot(sim: Simulation, colours: F64 | None = None,
             hidden_rows: NDArray[np.int64] | None = None) -> SceneFrame:
    """Build the frame for the posture now in ``sim.store`` (after at least one step).

    ``colours`` (n, 3) RGB per character; default: by team (:func:`team_colours`).
    Characters whose posture is not finite are left out, and those at ``hidden_rows`` (ones
    spawned since the last tick: they have no posture yet).
    """
    st = sim.store
    positions = st.positions
    if colours is None:
        colours = team_colours(character_teams(sim))
    if positions.shape[0] != st.n:  # nothing stepped yet
        positions = np.full((st.n, len(JOINT_INDEX), 3), np.nan)
    ok = np.all(np.isfinite(positions), axis=(1, 2))
    if hidden_rows is not None:
        ok[hidden_rows] = False
    bodies = body_instances(positions[ok], st.lengths[ok], colours[ok])
    # the constraints of hidden characters are hidden with them (--only)
    shown = None if hidden_rows is None or hidden_rows.size == 0 else ok
    marks = constraint_marks(sim, shown)
    targets = np.concatenate([target_instances(marks),
                              unreachable_instances(marks, unreachable_uids(sim))])
    if ok.any():
        com = centres_of_mass(positions[ok], st.segment_mass_kg[ok], st.segment_com_fraction[ok])
        com_rows = com_instances(com, 0.06 * leg_length(st.lengths[ok]))
    else:
        com_rows = np.zeros((0, INSTANCE_FLOATS), np.float32)
    return SceneFrame(bodies, targets, com_rows, area_instances(restricted_areas(sim, shown)),
                      positions[ok].copy(),
                      sim.posture_time_s, max_constraint_error_m(sim), int(ok.sum()),
                      table_instances(getattr(sim, "tables", ()), sim.ground),
                      np.flatnonzero(ok).astype(np.int64), marks)


# --- the ground --------------------------------------------------------------------------


@dataclass(frozen=True)
class GroundMesh:
    """A height-field patch of the ground: vertices (k, 6) float32 (position, normal) world
    metres, triangles (t, 3) uint32, and the xy rectangle it covers ``(x0, y0, x1, y1)``."""

    vertices: F32
    triangles: NDArray[np.uint32]
    bounds: tuple[float, float, float, float]


def ground_mesh(ground: Ground, centre_xy: tuple[float, float], half_size_m: float,
                cell_m: float = 0.05, max_cells: int = 300, skirt_m: float = 0.0) -> GroundMesh:
    """Sample ``ground.height`` on a square grid around ``centre_xy`` (at most ``max_cells``
    cells a side; the cell grows for a larger patch). Normals from central differences.

    ``skirt_m`` > 0 hangs a vertical strip that deep from the border, so where this patch meets
    a coarser one no crack shows the sky."""
    cells = int(min(max(np.ceil(2 * half_size_m / cell_m), 2), max_cells))
    cell = 2 * half_size_m / cells
    x = centre_xy[0] + np.linspace(-half_size_m, half_size_m, cells + 1)
    y = centre_xy[1] + np.linspace(-half_size_m, half_size_m, cells + 1)
    gx, gy = np.meshgrid(x, y)  # (rows along y, columns along x)
    xy = np.stack([gx, gy], axis=-1)
    z = ground.height(xy)
    eps = min(cell / 2, 0.01)
    dzdx = (ground.height(xy + [eps, 0]) - ground.height(xy - [eps, 0])) / (2 * eps)
    dzdy = (ground.height(xy + [0, eps]) - ground.height(xy - [0, eps])) / (2 * eps)
    normal = np.stack([-dzdx, -dzdy, np.ones_like(z)], axis=-1)
    normal /= np.linalg.norm(normal, axis=-1, keepdims=True)
    vertices = np.concatenate([gx[..., None], gy[..., None], z[..., None], normal], axis=-1)
    side = cells + 1
    i, j = np.meshgrid(np.arange(cells), np.arange(cells))
    v00 = (j * side + i).reshape(-1)
    v10, v01, v11 = v00 + 1, v00 + side, v00 + side + 1
    triangles = np.concatenate([np.stack([v00, v10, v11], 1), np.stack([v00, v11, v01], 1)])
    vertices = vertices.reshape(-1, 6)
    if skirt_m > 0:
        last = cells
        ring = np.concatenate([np.arange(0, last),                      # bottom row, left to right
                               last + side * np.arange(0, last),         # right column, upwards
                               last * side + np.arange(last, 0, -1),     # top row, right to left
                               side * np.arange(last, 0, -1)])           # left column, downwards
        below = vertices[ring].copy()
        below[:, 2] -= skirt_m
        first = vertices.shape[0]
        dup = first + np.arange(ring.size)
        ring_next, dup_next = np.roll(ring, -1), np.roll(dup, -1)
        skirt = np.concatenate([np.stack([ring, ring_next, dup_next], 1),
                                np.stack([ring, dup_next, dup], 1)])
        vertices = np.concatenate([vertices, below])
        triangles = np.concatenate([triangles, skirt])
    return GroundMesh(vertices.astype(np.float32), triangles.astype(np.uint32),
                      (float(x[0]), float(y[0]), float(x[-1]), float(y[-1])))


#: The near patch reaches this far beyond the characters (m), with at most this many cells a
#: side; its cell size comes from :func:`near_cell_m`.
NEAR_MARGIN_M, NEAR_MAX_CELLS = 6.0, 400


def near_cell_m(ground: Ground) -> float:
    """Cell size that shows this ground's shape near the characters: 4 cm where it has sharp
    edges (stairs keep upright risers), half a height grid's cell, else 15 cm (smooth grounds)."""
    parts = list(ground.parts) if isinstance(ground, Combined) else [ground]
    cell = 0.15
    for part in parts:
        if isinstance(part, Stairs):
            cell = min(cell, 0.04)
        elif isinstance(part, HeightGrid):
            cell = min(cell, max(part.cell_m / 2, 0.04))
        elif isinstance(part, Combined):
            cell = min(cell, near_cell_m(part))
    return cell


def ground_patches(ground: Ground, points_in_world: F64, far_half_size_m: float
                   ) -> tuple[GroundMesh, GroundMesh]:
    """The ground to draw: a fine patch around the points (..., 3) and a coarse one out to
    ``far_half_size_m`` around them (the renderer cuts the fine one's rectangle out of it)."""
    p = np.asarray(points_in_world, dtype=np.float64).reshape(-1, 3)
    p = p[np.all(np.isfinite(p), axis=1)]
    if p.shape[0] == 0:
        p = np.zeros((1, 3))
    lo, hi = p[:, :2].min(axis=0), p[:, :2].max(axis=0)
    centre = (float((lo[0] + hi[0]) / 2), float((lo[1] + hi[1]) / 2))
    near_half = float((hi - lo).max()) / 2 + NEAR_MARGIN_M
    near = ground_mesh(ground, centre, near_half, near_cell_m(ground), NEAR_MAX_CELLS, skirt_m=0.5)
    far = ground_mesh(ground, centre, max(far_half_size_m, near_half * 1.5), 0.25, 200)
    return near, far
