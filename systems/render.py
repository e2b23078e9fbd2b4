"""Render: hand the posture to a viewer; scheduled only when a window is open.

Reads: store.positions (and whatever the viewer draws). Writes: nothing in the simulation.
The pyglet viewer (scenario issue) plugs in as ``sim.renderer``: an object with ``draw(sim)``.
"""

from __future__ import annotations

from ecs_anim.system_base import System


class Render(System):
    def run(self, dt: float) -> None:
        renderer = getattr(self.sim, "renderer", None)
        if renderer is not None:
            renderer.draw(self.sim)
