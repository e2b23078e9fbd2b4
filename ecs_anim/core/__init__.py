"""The bottom layer: the canonical skeleton, rotations, bodies and the normalized pose (paper
§4, eq. 2), points on a body, grounds and ground adaptation, user-facing errors and safe file
writing. Imports nothing else of ecs_anim."""

from ecs_anim.core.body_points import BodyPoint, body_point
from ecs_anim.core.errors import EcsAnimError, InputError, MappingError
from ecs_anim.core.ground import Bumps, Combined, Ground, HeightGrid, Plane, Slope, Stairs
from ecs_anim.core.morphology import Morphology
from ecs_anim.core.normalized import DecodedPose, NormalizedPoses, decode, encode
from ecs_anim.core.skeleton import JOINT_INDEX, JOINTS, LENGTHS

__all__ = ["JOINTS", "JOINT_INDEX", "LENGTHS", "BodyPoint", "Bumps", "Combined", "DecodedPose",
           "EcsAnimError", "Ground", "HeightGrid", "InputError", "MappingError", "Morphology",
           "NormalizedPoses", "Plane", "Slope", "Stairs", "body_point", "decode", "encode"]
