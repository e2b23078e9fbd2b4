"""ConstraintSolve: passes poses through unchanged until the solver issue lands (paper §9).

Reads: nothing yet. Writes: nothing yet.
"""

from __future__ import annotations

from ecs_anim.system_base import System


class ConstraintSolve(System):
    def run(self, dt: float) -> None:
        return None
