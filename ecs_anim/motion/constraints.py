"""Constraint specifications stored with a motion (paper §5, DESIGN §5).

``C = {point, type, chain, priority, activation}``. This module holds the data and the activation
ramp; solving them is the solver's job. Foot contacts are detected at import; other constraints
come from a YAML file given at import (``ecs-anim import --constraints``).
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray

from ecs_anim.core.errors import UsageError

KINDS = ("foot_contact", "position", "orientation", "distance", "area")


@dataclass(frozen=True)
class Activation:
    """When a constraint acts: weight 0 before ``start_s``, ramps linearly to 1 over
    ``ease_in_s``, stays 1, ramps back to 0 over ``ease_out_s`` ending at ``stop_s`` (seconds
    in motion time)."""

    start_s: float
    stop_s: float
    ease_in_s: float = 0.0
    ease_out_s: float = 0.0

    def __post_init__(self) -> None:
        values = (self.start_s, self.stop_s, self.ease_in_s, self.ease_out_s)
        if not all(np.isfinite(v) for v in values):
            raise UsageError(f"activation times must be finite, got {values}")
        if self.stop_s < self.start_s:
            raise UsageError(f"activation stop_s {self.stop_s} is before start_s {self.start_s}")
        if self.ease_in_s < 0 or self.ease_out_s < 0:
            raise UsageError("activation ease_in_s and ease_out_s must be >= 0")
        if self.ease_in_s + self.ease_out_s > self.stop_s - self.start_s + 1e-9:
            raise UsageError("activation ease_in_s + ease_out_s is longer than stop_s - start_s")

    def weight(self, time_s: NDArray[np.float64] | float, smooth: bool = True) -> NDArray[np.float64]:
        """Weight in [0, 1] at the given times (any shape); see :func:`ramp_weight`."""
        return ramp_weight(np.asarray(time_s, dtype=np.float64), self.start_s, self.stop_s,
                           self.ease_in_s, self.ease_out_s, smooth)


def ramp_weight(time_s: NDArray[np.float64] | float, start_s: NDArray[np.float64] | float,
                stop_s: NDArray[np.float64] | float, ease_in_s: NDArray[np.float64] | float,
                ease_out_s: NDArray[np.float64] | float, smooth: bool = True) -> NDArray[np.float64]:
    """The activation ramp 0 -> 1 -> 0 (paper fig. 8), broadcast over any of its arguments: up
    over ``ease_in_s`` from ``start_s``, 1, back to 0 over ``ease_out_s`` ending at ``stop_s``; a
    zero ease is a step. With ``smooth`` each ease is a quintic smoothstep
    (``6x^5 - 15x^4 + 10x^3``): the weight's rate and acceleration are 0 at both ends, so a
    constraint starts and stops moving a body as gently as the motion itself moves (a straight
    line would set every joint it moves going at full speed in the first tick). Without, a
    straight line (foot contacts: their short ramps only blend a footprint in and out)."""
    ease_in, ease_out = np.asarray(ease_in_s, dtype=np.float64), np.asarray(ease_out_s, dtype=np.float64)
    up = np.where(ease_in > 0, (time_s - start_s) / np.maximum(ease_in, 1e-12),
                  np.where(np.greater_equal(time_s, start_s), 1.0, 0.0))
    down = np.where(ease_out > 0, (stop_s - time_s) / np.maximum(ease_out, 1e-12),
                    np.where(np.less_equal(time_s, stop_s), 1.0, 0.0))
    x = np.clip(np.minimum(up, down), 0.0, 1.0)
    return x * x * x * (x * (6.0 * x - 15.0) + 10.0) if smooth else x


@dataclass(frozen=True)
class ConstraintSpec:
    """One constraint of a motion.

    Attributes
    ----------
    name : unique within the motion, e.g. ``"contact_l_3"``.
    kind : one of :data:`KINDS`.
    segment : the constrained point: a joint (``"wrist_r"``) or a segment (``"forearm_r"``) with
        ``fraction`` along it (None: the joint, or a segment's middle) and ``offset_m`` (3,) in
        its frame (:mod:`ecs_anim.core.body_points`). Foot contacts name the ankle joint.
    chain : body groups allowed to move (``leg_l``, ``leg_r``, ``head``, ``arm_l``, ``arm_r``,
        ``trunk``); empty: the point's own group.
    priority : higher is solved first.
    activation : see :class:`Activation`.
    params : kind-specific values (target, distance, area), JSON-compatible.
    """

    name: str
    kind: str
    segment: str
    activation: Activation
    chain: tuple[str, ...]
    priority: float = 0.0
    fraction: float | None = None
    offset_m: tuple[float, float, float] = (0.0, 0.0, 0.0)
    params: dict[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        if self.kind not in KINDS:
            raise UsageError(f"constraint {self.name!r}: unknown kind {self.kind!r}; kinds: "
                             f"{', '.join(KINDS)}")

    def to_dict(self) -> dict[str, Any]:
        d = asdict(self)
        d["chain"] = list(self.chain)
        d["offset_m"] = list(self.offset_m)
        return d

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> ConstraintSpec:
        return cls(
            name=str(d["name"]), kind=str(d["kind"]), segment=str(d["segment"]),
            activation=Activation(**d["activation"]), chain=tuple(d["chain"]),
            priority=float(d.get("priority", 0)),
            fraction=None if d.get("fraction") is None else float(d["fraction"]),
            offset_m=tuple(float(x) for x in d.get("offset_m", (0, 0, 0))),  # type: ignore[arg-type]
            params=dict(d.get("params", {})),
        )


def contacts_from_constraints(constraints: list[ConstraintSpec], n_frames: int,
                              fps: float) -> NDArray[np.bool_]:
    """Frames where each foot's contact constraint has full weight. -> bool (n_frames, 2)."""
    t = np.arange(n_frames) / fps
    out = np.zeros((n_frames, 2), dtype=bool)
    for c in constraints:
        if c.kind == "foot_contact":
            side = 0 if c.segment.endswith("_l") else 1
            out[:, side] |= c.activation.weight(t) >= 1.0 - 1e-9
    return out
