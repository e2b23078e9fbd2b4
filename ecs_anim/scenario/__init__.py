"""Scenario files (YAML): who plays what, on which ground, for how long, and what reacts to what.

:func:`load_scenario` reads and checks a file (every error says ``file:line: path.to.key``), and
:func:`build_simulation` makes a :class:`~ecs_anim.runtime.simulation.Simulation` of it. The
schema is documented in ``docs/scenarios.md``.
"""

from ecs_anim.scenario.build import apply_steering, build_simulation, measured_run
from ecs_anim.scenario.grounds import read_ground
from ecs_anim.scenario.loader import load_motion_constraints, load_scenario
from ecs_anim.scenario.motions import read_motion
from ecs_anim.scenario.reader import (
    MAX_GRID_CELLS,
    MAX_GROUND_PARTS,
    MAX_YAML_VALUES,
    YamlReader,
    read_tree,
)
from ecs_anim.scenario.spec import (
    CharacterSpec,
    ConstraintEntry,
    Scenario,
    SteeringSpec,
    Table,
    clip_scenario,
)

__all__ = [
    "MAX_GRID_CELLS",
    "MAX_GROUND_PARTS",
    "MAX_YAML_VALUES",
    "CharacterSpec",
    "ConstraintEntry",
    "Scenario",
    "SteeringSpec",
    "Table",
    "YamlReader",
    "apply_steering",
    "build_simulation",
    "clip_scenario",
    "load_motion_constraints",
    "load_scenario",
    "measured_run",
    "read_ground",
    "read_motion",
    "read_tree",
]
