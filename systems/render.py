"""Render: hand the posture to a viewer; scheduled only when a window is open.

Reads: store.positions (and whatever the viewer draws). Writes: nothing in the simulation.
The viewer plugs in as ``sim.renderer``: an object with ``draw(sim)``, called once per tick
(``ecs_anim.apps.viewer.scene_view.SceneSource`` notes that a new posture is ready; the window draws it
at its own rate, reading the store: STYLE 8).
"""

from __future__ import annotations

from ecs_anim.runtime.system_base import System


class Render(System):
    reads = ("positions",)

    def run(self, dt: float) -> None:
        renderer = getattr(self.sim, "renderer", None)
        if renderer is not None:
            renderer.draw(self.sim)
