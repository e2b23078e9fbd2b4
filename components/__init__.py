"""Data-only ECS components (installed as ``ecs_anim.components``)."""

from .character import (
    Body,
    CharacterRow,
    Constraints,
    MotionPlayer,
    Name,
    NormalizedPose,
    Placement,
    Posture,
    QueuedClip,
)
from .environment import GroundQuery

__all__ = ["Body", "CharacterRow", "Constraints", "GroundQuery", "MotionPlayer", "Name",
           "NormalizedPose", "Placement", "Posture", "QueuedClip"]
