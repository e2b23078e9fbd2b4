"""The ground component: held by the environment entity (the ground under everyone), and by a
character that has a ground of its own (GroundAdapt then adapts it to that one)."""

from __future__ import annotations

from dataclasses import dataclass

from ecs_anim.core.ground import Ground


@dataclass(frozen=True)
class GroundQuery:
    """A ground: anything with ``height(xy (..., 2)) -> (...)`` in metres, world Z up."""

    ground: Ground
