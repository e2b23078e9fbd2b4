"""The constraint solver (paper §9): the goals of a tick (:mod:`.goals`), the shell that owns
priorities, iterations, tolerance and the frame budget (:mod:`.shell`, :mod:`.budget`) and the
analytic limb and CCD steps (:mod:`.steps`), as the numpy reference the compiled tick mirrors."""

from ecs_anim.solver.budget import SolverCostModel, SolverReport
from ecs_anim.solver.goals import TickGoals
from ecs_anim.solver.shell import SolverSettings, constrain

__all__ = ["SolverCostModel", "SolverReport", "SolverSettings", "TickGoals", "constrain"]
