"""Motions in the normalized form: a clip with its timing, source body and stored constraints,
the ``.nmo`` file, the constraints' table and activation, and sampling clips at any time."""

from ecs_anim.motion.clip import NormalizedMotion, load_nmo, save_nmo
from ecs_anim.motion.constraint_table import Area, ConstraintTable
from ecs_anim.motion.constraints import Activation, ConstraintSpec
from ecs_anim.motion.sampling import ClipBank

__all__ = ["Activation", "Area", "ClipBank", "ConstraintSpec", "ConstraintTable",
           "NormalizedMotion", "load_nmo", "save_nmo"]
