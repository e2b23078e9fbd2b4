"""COMControl: passes poses through unchanged until the solver issue adds adaptRoot (paper §9).

Reads: nothing yet. Writes: nothing yet.
"""

from __future__ import annotations

from ecs_anim.system_base import System


class COMControl(System):
    def run(self, dt: float) -> None:
        return None
