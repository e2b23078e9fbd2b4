"""ECS systems, one esper processor per file (installed as ``ecs_anim.systems``)."""

from ecs_anim.systems.com_control import COMControl
from ecs_anim.systems.constraint_solve import ConstraintSolve
from ecs_anim.systems.ground_adapt import GroundAdapt
from ecs_anim.systems.morphology_adapt import MorphologyAdapt
from ecs_anim.systems.motion_playback import MotionPlayback
from ecs_anim.systems.posture_convert import PostureConvert
from ecs_anim.systems.render import Render

#: The tick, declared once (DESIGN §6). esper priorities derive from this order.
SCHEDULE = (MotionPlayback, MorphologyAdapt, GroundAdapt, ConstraintSolve, COMControl,
            PostureConvert, Render)
HEADLESS = SCHEDULE[:-1]

__all__ = [
            "HEADLESS",
            "SCHEDULE",
            "COMControl",
            "ConstraintSolve",
            "GroundAdapt",
            "MorphologyAdapt",
            "MotionPlayback",
            "PostureConvert",
            "Render",
]
