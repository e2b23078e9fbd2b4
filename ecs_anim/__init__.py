"""ecs_anim: morphology-independent motion for many characters.

The public API (docs/api.md): make a :class:`Simulation` from motions (or from a scenario file
with :func:`load_scenario` and :func:`build_simulation`), spawn characters on bodies
(:class:`Morphology`) playing clips (:class:`MotionPlayer`, :class:`QueuedClip`) from a
:class:`Placement`, constrain them (``Simulation.add_constraint``, :class:`Activation`,
:class:`Area`), step it and read ``Simulation.store``. Z up, metres, seconds, radians.
"""

from .allocator import keep_freed_memory
from .components import MotionPlayer, Placement, QueuedClip
from .constraint_table import Area
from .constraints import Activation
from .errors import EcsAnimError, InputError
from .exporting import EXPORT_NAMES, bvh_from_rotations, export_motion, write_npz
from .gltf import glb_bytes
from .ground import Bumps, Combined, Ground, HeightGrid, Plane, Slope, Stairs
from .importing import import_bvh
from .kernels import set_threads, threads
from .metrics import MetricsRecorder
from .morphology import Morphology, load_morphology_yaml, with_lengths_m
from .motion import NormalizedMotion, load_nmo, save_nmo
from .scenario import Scenario, build_simulation, load_scenario
from .simulation import Simulation
from .skeleton import JOINT_INDEX, JOINTS, LENGTHS
from .solver_shell import SolverSettings

__all__ = [
    "EXPORT_NAMES",
    "JOINTS",
    "JOINT_INDEX",
    "LENGTHS",
    "Activation",
    "Area",
    "Bumps",
    "Combined",
    "EcsAnimError",
    "Ground",
    "HeightGrid",
    "InputError",
    "MetricsRecorder",
    "Morphology",
    "MotionPlayer",
    "NormalizedMotion",
    "Placement",
    "Plane",
    "QueuedClip",
    "Scenario",
    "Simulation",
    "Slope",
    "SolverSettings",
    "Stairs",
    "build_simulation",
    "bvh_from_rotations",
    "export_motion",
    "glb_bytes",
    "import_bvh",
    "keep_freed_memory",
    "load_morphology_yaml",
    "load_nmo",
    "load_scenario",
    "save_nmo",
    "set_threads",
    "threads",
    "with_lengths_m",
    "write_npz",
]
