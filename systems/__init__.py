"""ECS systems, one esper processor per file (installed as ``ecs_anim.systems``)."""

from .com_control import COMControl
from .constraint_solve import ConstraintSolve
from .ground_adapt import GroundAdapt
from .morphology_adapt import MorphologyAdapt
from .motion_playback import MotionPlayback
from .posture_convert import PostureConvert
from .render import Render

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
