"""Data-only ECS components (installed as ``ecs_anim.components``)."""

from ecs_anim.components.character import (
    BodyBlend,
    CharacterRow,
    Constraint,
    Morphology,
    MotionPlayer,
    Name,
    NormalizedPose,
    Placement,
    Posture,
    QueuedClip,
)
from ecs_anim.components.environment import GroundQuery

__all__ = [
    "BodyBlend",
    "CharacterRow",
    "Constraint",
    "GroundQuery",
    "Morphology",
    "MotionPlayer",
    "Name",
    "NormalizedPose",
    "Placement",
    "Posture",
    "QueuedClip",
]
