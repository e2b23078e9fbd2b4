"""World-level components, held by one environment entity per simulation."""

from __future__ import annotations

from dataclasses import dataclass

from ecs_anim.ground import Ground


@dataclass(frozen=True)
class GroundQuery:
    """The ground under everyone: anything with ``height(xy (..., 2)) -> (...)`` in metres."""

    ground: Ground
