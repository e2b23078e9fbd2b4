"""ecs_anim: morphology-independent motion for many characters.

The public API (docs/api.md): make a :class:`Simulation` from motions (or from a scenario file
with :func:`load_scenario` and :func:`build_simulation`), spawn characters on bodies
(:class:`Morphology`) playing clips (:class:`MotionPlayer`, :class:`QueuedClip`) from a
:class:`Placement`, constrain them (``Simulation.add_constraint``, :class:`Activation`,
:class:`Area`), step it and read ``Simulation.store``. Z up, metres, seconds, radians.
"""

from ecs_anim.components import MotionPlayer, Placement, QueuedClip
from ecs_anim.core.body_points import body_point
from ecs_anim.core.errors import EcsAnimError, InputError
from ecs_anim.core.ground import Bumps, Combined, Ground, HeightGrid, Plane, Slope, Stairs
from ecs_anim.core.morphology import Morphology, load_morphology_yaml, with_lengths_m
from ecs_anim.core.skeleton import JOINT_INDEX, JOINTS, LENGTHS
from ecs_anim.io.export import (
    EXPORT_NAMES,
    Rig,
    bvh_from_rotations,
    export_motion,
    glb_bytes,
    load_rig,
    write_npz,
)
from ecs_anim.io.importing import import_bvh
from ecs_anim.io.positions import PositionOptions, import_positions
from ecs_anim.motion.clip import NormalizedMotion, load_nmo, save_nmo
from ecs_anim.motion.constraint_table import Area
from ecs_anim.motion.constraints import Activation
from ecs_anim.runtime.actions import switched_off
from ecs_anim.runtime.allocator import keep_freed_memory
from ecs_anim.runtime.kernels import set_threads, threads
from ecs_anim.runtime.metrics import MetricsRecorder
from ecs_anim.runtime.recorder import RecordedCharacter, Recorder
from ecs_anim.runtime.simulation import Simulation
from ecs_anim.runtime.steering import GAITS, SteeringSettings
from ecs_anim.runtime.system_base import System
from ecs_anim.runtime.triggers import (
    Arm,
    Arrived,
    AtTime,
    ClipEnded,
    ClipStarted,
    ContactBegan,
    Event,
    MoveTarget,
    Near,
    Play,
    Reached,
    Remove,
    Removed,
    SetBody,
    SwitchOff,
    SwitchOn,
    Trigger,
)
from ecs_anim.scenario import Scenario, build_simulation, load_scenario
from ecs_anim.solver.budget import SolverCostModel, SolverReport
from ecs_anim.solver.shell import SolverSettings

__all__ = [
    "EXPORT_NAMES",
    "GAITS",
    "JOINTS",
    "JOINT_INDEX",
    "LENGTHS",
    "Activation",
    "Area",
    "Arm",
    "Arrived",
    "AtTime",
    "Bumps",
    "ClipEnded",
    "ClipStarted",
    "Combined",
    "ContactBegan",
    "EcsAnimError",
    "Event",
    "Ground",
    "HeightGrid",
    "InputError",
    "MetricsRecorder",
    "Morphology",
    "MotionPlayer",
    "MoveTarget",
    "Near",
    "NormalizedMotion",
    "Placement",
    "Plane",
    "Play",
    "PositionOptions",
    "QueuedClip",
    "Reached",
    "RecordedCharacter",
    "Recorder",
    "Remove",
    "Removed",
    "Rig",
    "Scenario",
    "SetBody",
    "Simulation",
    "Slope",
    "SolverCostModel",
    "SolverReport",
    "SolverSettings",
    "Stairs",
    "SteeringSettings",
    "SwitchOff",
    "SwitchOn",
    "System",
    "Trigger",
    "body_point",
    "build_simulation",
    "bvh_from_rotations",
    "export_motion",
    "glb_bytes",
    "import_bvh",
    "import_positions",
    "keep_freed_memory",
    "load_morphology_yaml",
    "load_nmo",
    "load_rig",
    "load_scenario",
    "save_nmo",
    "set_threads",
    "switched_off",
    "threads",
    "with_lengths_m",
    "write_npz",
]
