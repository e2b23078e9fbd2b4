"""What a scenario file says, once read and checked: characters, their constraints and steering,
tables, triggers (plain data; :mod:`ecs_anim.scenario.build` makes a simulation of it)."""

from __future__ import annotations

from dataclasses import asdict, dataclass, field
from typing import Any

from ecs_anim.components import MotionPlayer, Placement
from ecs_anim.core.ground import Ground
from ecs_anim.core.morphology import Morphology
from ecs_anim.motion.clip import NormalizedMotion
from ecs_anim.motion.constraints import Activation, ConstraintSpec
from ecs_anim.runtime.triggers import Trigger


@dataclass
class ConstraintEntry:
    """A scenario constraint, as :meth:`Simulation.add_constraint` takes it; the target
    character is a name until the simulation is built."""

    name: str
    point: str
    priority: float
    activation: Activation
    target_in_world: tuple[float, float, float] | None = None
    target_character: str | None = None
    target_point: str | None = None
    options: dict[str, Any] = field(default_factory=dict)
    #: ``activation.motion``: the activation runs in this clip's own time while it plays.
    clock_motion: str | None = None
    #: A moving world target: keyframe times (s) and points (m), interpolated linearly.
    target_keyframes: tuple[tuple[float, ...], tuple[tuple[float, float, float], ...]] | None = None

    def aims_at_itself(self) -> bool:
        """Whether the target is the constrained point itself (on its own body)."""
        from ecs_anim.core.body_points import body_point

        if self.target_point is None:
            return False
        o = self.options
        own = body_point(self.point, o.get("fraction"), o.get("offset_m", (0.0, 0.0, 0.0)),
                         segment=o.get("kind") == "orientation")
        aim = body_point(self.target_point, o.get("target_fraction"),
                         o.get("target_offset_m", (0.0, 0.0, 0.0)), as_target=True)
        return (own.segment, own.fraction, tuple(own.offset_m)) == \
            (aim.segment, aim.fraction, tuple(aim.offset_m))

    def to_spec(self) -> ConstraintSpec:
        """The constraint stored with a motion (its target a point of the same body)."""
        o = self.options
        params: dict[str, Any] = {"target_point": self.target_point,
                                  "target_fraction": o.get("target_fraction"),
                                  "target_offset_m": list(o.get("target_offset_m", (0.0, 0.0, 0.0)))}
        for key in ("distance_m", "axis"):
            if key in o:
                params[key] = list(o[key]) if key == "axis" else o[key]
        if "area" in o:
            params["area"] = asdict(o["area"])
        return ConstraintSpec(self.name, o["kind"], self.point, self.activation,
                              tuple(o.get("chain") or ()), self.priority,
                              o.get("fraction"),
                              tuple(o.get("offset_m", (0.0, 0.0, 0.0))), params)


@dataclass(frozen=True)
class SteeringSpec:
    """A character's locomotion set and steering from the scenario (docs/steering.md):
    ``locomotion`` gait -> motion name (``walk`` always, ``idle`` and ``run`` if given),
    ``path_m`` waypoints (x, y) metres walked in order (empty: none), ``speed_m_s`` the speed
    asked for (None: the walk's own), ``avoid`` whether it avoids the other steered
    characters (local avoidance, ORCA)."""

    locomotion: dict[str, str]
    path_m: tuple[tuple[float, float], ...] = ()
    speed_m_s: float | None = None
    avoid: bool = True


@dataclass
class CharacterSpec:
    name: str
    morphology: Morphology
    player: MotionPlayer
    placement: Placement
    team: str = ""
    constraints: list[ConstraintEntry] = field(default_factory=list)
    com_control: bool = True
    com_target_xy: tuple[float, float] | None = None
    steering: SteeringSpec | None = None


@dataclass(frozen=True)
class Table:
    """A table drawn in the scene (a prop: nothing collides with it): its top's centre
    ``centre_m`` (x, y) and size ``size_m`` (along its heading, across), metres; the top's
    height above the ground, metres; heading, radians anticlockwise from +x."""

    centre_m: tuple[float, float]
    size_m: tuple[float, float]
    height_m: float
    heading_rad: float = 0.0


@dataclass
class Scenario:
    """A scenario file as :func:`load_scenario` read it (docs/scenarios.md): ``duration_s`` and
    ``fps`` (Hz), ``motions`` by name, the ``ground``, the ``characters`` to spawn
    (:func:`build_simulation`), viewer hints and props."""

    path: str
    duration_s: float
    fps: float
    motions: dict[str, NormalizedMotion]
    ground: Ground
    characters: list[CharacterSpec] = field(default_factory=list)
    camera: dict[str, Any] = field(default_factory=dict)  # viewer hints (docs/scenarios.md)
    tables: list[Table] = field(default_factory=list)  # props, drawn only
    #: The scenario file and every motion file it read: no output may overwrite one.
    input_files: tuple[str, ...] = ()
    #: Reactions (ecs_anim.runtime.events), naming characters and constraints by scenario index.
    triggers: list[Trigger] = field(default_factory=list)
    #: The constraints triggers name: (character index, constraint name) by placeholder id.
    trigger_constraints: list[tuple[int, str]] = field(default_factory=list)
    #: The solver's settings the scenario gives (``SolverSettings`` fields by name).
    solver: dict[str, Any] = field(default_factory=dict)


def clip_scenario(motion: NormalizedMotion, morphology: Morphology, ground: Ground,
                  clip: str = "clip", character: str = "body", path: str = "") -> Scenario:
    """A scenario of one character, ``character``, with ``morphology``, playing ``motion``
    (named ``clip``) once from the origin facing +x over ``ground``, at the clip's rate for its
    length: a batch job's (docs/batch.md) and ``info``'s check (docs/cli.md)."""
    spec = CharacterSpec(character, morphology, MotionPlayer(clip, loop=False), Placement())
    return Scenario(path or clip, motion.n_frames / motion.fps, motion.fps, {clip: motion},
                    ground, [spec])
