"""Data-only ECS components (installed as ``ecs_anim.components``)."""

from .character import (
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
from .environment import GroundQuery

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
