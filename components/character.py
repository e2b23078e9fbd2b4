"""Per-character components. Data only; each field says its shape, frame and unit.

Body, MotionPlayer, Placement and Constraints are specifications: what a character was given
when it was spawned (Body is replaced by ``Simulation.set_body``). The live state the systems
work on, every tick and for all characters at once, is the simulation's structure-of-arrays
store (``Simulation.store``, STYLE 12): NormalizedPose and Posture name a character's row in it,
and MotionPlayback advances clips and queues there, not in these components.
"""

from __future__ import annotations

from dataclasses import dataclass, field

from ecs_anim.constraints import ConstraintSpec
from ecs_anim.morphology import Morphology


@dataclass(frozen=True)
class Body:
    """The character's morphology (segment lengths in metres, masses). Replace to resize."""

    morphology: Morphology


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
class Constraints:
    """Constraints added to the character's motion by the scenario (the solver issue)."""

    specs: tuple[ConstraintSpec, ...] = ()


@dataclass(frozen=True)
class CharacterRow:
    """The character's row in the simulation's structure-of-arrays store."""

    row: int


@dataclass(frozen=True)
class NormalizedPose:
    """This tick's normalized pose: ``Simulation.store.poses`` at ``row`` (see
    :class:`ecs_anim.normalized.NormalizedPoses` for every field's shape and frame)."""

    row: int


@dataclass(frozen=True)
class Posture:
    """This tick's world posture: ``Simulation.store.positions[row]`` (N_JOINTS, 3) metres,
    world Z up, and ``Simulation.store.local_rotations[row]`` (n_export_joints, 3, 3) local
    rotation matrices (BVH axes) of the export skeleton (:data:`ecs_anim.exporting.EXPORT_NAMES`)."""

    row: int


@dataclass
class Name:
    """A character's name, for reports and exports."""

    name: str
    team: str = field(default="")
