"""Per-character components. Data only; each field says its shape, frame and unit.

A character's components decide which systems process it (DESIGN §7b): each system's
:attr:`~ecs_anim.runtime.system_base.System.query` names the components it needs, and its rows are the
characters that have them all. Specifications (Morphology, MotionPlayer, Placement, Constraint,
a GroundQuery of the character's own) are frozen and replaced, never mutated; replacing one is a
structural change (the systems' cached rows are recomputed once, not per tick).

The live state the systems work on, every tick and for all characters at once, is the
simulation's structure-of-arrays store (``Simulation.store``, STYLE 12). A character has one
handle into it, :class:`CharacterRow`; :class:`NormalizedPose` and :class:`Posture` are views of
its row (``Simulation.pose(entity)``, ``Simulation.posture(entity)``), made on request and
valid until the next tick replaces the store's arrays.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from ecs_anim.core.morphology import Morphology
from ecs_anim.core.normalized import NormalizedPoses

__all__ = [
    "BodyBlend",
    "CharacterRow",
    "Constraint",
    "Morphology",
    "MotionPlayer",
    "Name",
    "NormalizedPose",
    "Placement",
    "Posture",
    "QueuedClip",
]

# ``Morphology`` (ecs_anim.core.morphology) is itself the component: the body spec, a frozen
# dataclass of segment lengths (metres), total mass (kg) and sex (the de Leva mass table).
# ``Simulation.set_body`` replaces it; MorphologyAdapt takes the new body into the store.


@dataclass(frozen=True)
class QueuedClip:
    """A clip to play after the current one, faded in over ``crossfade_s`` seconds."""

    clip: str
    crossfade_s: float = 0.3
    loop: bool = False


@dataclass(frozen=True)
class MotionPlayer:
    """What the character plays: ``clip`` (a loaded motion's name) from ``start_s`` seconds,
    at ``speed`` (1 = as captured), looping or holding its last pose, then ``queue`` in order."""

    clip: str
    speed: float = 1.0
    loop: bool = True
    start_s: float = 0.0
    queue: tuple[QueuedClip, ...] = ()


@dataclass(frozen=True)
class Placement:
    """Where the motion's origin is in the world: ``position_m`` (x, y) metres and
    ``heading_rad`` (anticlockwise about Z). The motion's own root path is laid out from it."""

    position_m: tuple[float, float] = (0.0, 0.0)
    heading_rad: float = 0.0


@dataclass(frozen=True)
class Constraint:
    """The character's constraints: ``uids`` (ids as ``Simulation.add_constraint`` returns
    them, in the order added) and their ``names``; the specs live in the simulation's constraint
    table (``table.rows_of(uids)``). Present while the character has at least one constraint (its
    own, or stored with a clip it plays); a character without it is not in the solve."""

    uids: tuple[int, ...]
    names: tuple[str, ...]


@dataclass(frozen=True)
class CharacterRow:
    """The character's row in the simulation's structure-of-arrays store: its one handle to
    its per-tick state (renumbered when a character before it is removed)."""

    row: int


@dataclass(frozen=True)
class NormalizedPose:
    """This tick's normalized pose of one character: views of ``Simulation.store.poses`` at its
    row, batch shape (1,) (see :class:`ecs_anim.core.normalized.NormalizedPoses` for every field's
    shape and frame). Not attached to the entity: ``Simulation.pose(entity)`` makes one."""

    row: int
    pose: NormalizedPoses


@dataclass(frozen=True)
class Posture:
    """This tick's world posture of one character, views of the store at its row:
    ``positions`` (N_JOINTS, 3) metres, world Z up; ``local_rotations`` (n_export_joints, 3, 3)
    local rotation matrices (BVH axes) of the export skeleton (:data:`ecs_anim.io.export.skeleton.
    EXPORT_NAMES`), empty (0, 3, 3) unless the simulation makes rotations. Not attached to the
    entity: ``Simulation.posture(entity)`` makes one."""

    row: int
    positions: NDArray[np.float64]
    local_rotations: NDArray[np.float64]


@dataclass(frozen=True)
class Name:
    """A character's name, for reports and exports."""

    name: str
    team: str = field(default="")


@dataclass(frozen=True)
class BodyBlend:
    """A body change in progress (``Simulation.set_body(..., blend_s=...)``): the character's
    segment lengths (metres, N_LENGTHS), segment masses (kg) and centre-of-mass fractions (per
    de Leva segment) when it began, at simulation time ``start_s``; over ``blend_s`` seconds they
    blend into those of its Morphology component (MorphologyAdapt, every tick)."""

    from_lengths: tuple[float, ...]
    from_mass_kg: tuple[float, ...]
    from_com_fraction: tuple[float, ...]
    start_s: float
    blend_s: float
