"""ECS systems, one esper processor per file (installed as ``ecs_anim.systems``)."""

from ecs_anim.systems.apply_reactions import ApplyReactions
from ecs_anim.systems.collision_separate import CollisionSeparate
from ecs_anim.systems.com_control import COMControl
from ecs_anim.systems.constraint_solve import ConstraintSolve
from ecs_anim.systems.detect_events import DetectEvents
from ecs_anim.systems.ground_adapt import GroundAdapt
from ecs_anim.systems.morphology_adapt import MorphologyAdapt
from ecs_anim.systems.motion_playback import MotionPlayback
from ecs_anim.systems.posture_convert import PostureConvert
from ecs_anim.systems.queued_clips import QueuedClips
from ecs_anim.systems.render import Render
from ecs_anim.systems.steering import Steering

#: The tick, declared once: the design card's seven (DESIGN §6) with what chooses the clips
#: before MotionPlayback (triggers due, queued clips, steering), the bodies pushed apart on the
#: posture (DESIGN §8b) and the clock and the events after PostureConvert. esper priorities
#: derive from this order.
SCHEDULE = (ApplyReactions, QueuedClips, Steering, MotionPlayback, MorphologyAdapt, GroundAdapt,
            ConstraintSolve, COMControl, PostureConvert, CollisionSeparate, DetectEvents, Render)
HEADLESS = SCHEDULE[:-1]

__all__ = [
    "HEADLESS",
    "SCHEDULE",
    "ApplyReactions",
    "COMControl",
    "CollisionSeparate",
    "ConstraintSolve",
    "DetectEvents",
    "GroundAdapt",
    "MorphologyAdapt",
    "MotionPlayback",
    "PostureConvert",
    "QueuedClips",
    "Render",
    "Steering",
]
