"""OpenSim joint angles (``.mot``, ``.sto``) on the model they were computed on (``.osim``):
``ecs-anim import walk.mot --body-model subject_scaled.osim``.

A ``.mot`` holds a model's generalized coordinates over time (``pelvis_tilt``,
``hip_flexion_r``, ``knee_angle_r``, ...): a header ending at ``endheader`` (``inDegrees=yes``,
``nRows``, ``nColumns``), a line of column labels starting with ``time``, then one row a frame.
Where the joints are follows from those angles only through the model: its bodies' frames, its
joints' offsets and the functions that couple a knee's translation to its angle. So the model
is read (:mod:`.opensim_model`), its forward kinematics places every body, and the joint centres
it gives (hips, knees, ankles, the toes' joint, the lumbar joint, the torso's frame) enter the
import as measured joints; the parts the model lacks or import does not read (head, arms) take
the neutral pose a C3D's absent parts take. Without a model the file is refused in one line
saying so; a malformed file in one line naming the file and line.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from ecs_anim.core.errors import EcsAnimError, InputError, listed, quoted
from ecs_anim.core.files import read_text
from ecs_anim.core.rotations import frame_from_axes
from ecs_anim.core.skeleton import JOINT_INDEX as J
from ecs_anim.core.skeleton import JOINTS, N_JOINTS
from ecs_anim.io.bvh import rate_of_step
from ecs_anim.io.c3d.centre_build import JointCentreBuild, adult_length, heading_frame, set_joint
from ecs_anim.io.c3d.joint_centres import fill_absent, flat_toe
from ecs_anim.io.contacts import ContactThresholds
from ecs_anim.io.importing import UP_AXES, CanonicalClip, FrameRange, import_canonical
from ecs_anim.io.joint_map import JointMap
from ecs_anim.io.opensim_model import GROUND, OsimModel, body_frames, read_osim
from ecs_anim.motion.clip import NormalizedMotion

F64 = NDArray[np.float64]


@dataclass
class MotCoordinates:
    """An OpenSim coordinates file: ``labels`` of the columns after ``time``, ``values``
    (n_frames, len(labels)) as written (degrees where ``in_degrees``), ``time_s`` (n_frames,)."""

    labels: list[str]
    values: F64
    time_s: F64
    in_degrees: bool
    path: str


def read_mot(path: str | Path) -> MotCoordinates:
    """Read an OpenSim ``.mot``/``.sto``. Raises :class:`InputError` naming the file and line:
    no ``endheader``, no ``time`` column, a row whose count of values is not the labels', a value
    that is no number, no frame, a column with no finite value."""
    path = str(path)
    lines = read_text(path).splitlines()
    end = next((k for k, line in enumerate(lines) if line.strip().lower() == "endheader"), None)
    if end is None:
        raise InputError(path, "no 'endheader' line: not an OpenSim .mot/.sto file", len(lines) or 1)
    header = {k.strip().lower(): v.strip().lower() for k, _, v in
              (line.partition("=") for line in lines[:end] if "=" in line)}
    rows = [(k, line.split()) for k, line in enumerate(lines[end + 1:], start=end + 2) if line.strip()]
    if not rows or rows[0][1][0].lower() != "time":
        raise InputError(path, "expected a line of column labels starting with 'time' after "
                               "endheader", rows[0][0] if rows else end + 1)
    label_line, labels = rows[0]
    data: list[F64] = []
    for line_no, cells in rows[1:]:
        if len(cells) != len(labels):
            raise InputError(path, f"a row of {len(cells)} values where the labels (line "
                                   f"{label_line}) name {len(labels)}", line_no)
        try:
            data.append(np.array([float(c) for c in cells]))
        except ValueError:
            bad = next(c for c in cells if not _is_number(c))
            raise InputError(path, f"expected a number, found {quoted(bad)}", line_no) from None
    if not data:
        raise InputError(path, "the file holds no frame (no row after the labels)", label_line)
    values = np.stack(data)
    empty = [labels[k] for k in range(values.shape[1]) if not np.isfinite(values[:, k]).any()]
    if empty:
        raise InputError(path, f"no finite value in any frame for {listed(empty, 3)}")
    return MotCoordinates(labels[1:], values[:, 1:], values[:, 0],
                          header.get("indegrees", "yes") != "no", path)


def _is_number(text: str) -> bool:
    try:
        float(text)
    except ValueError:
        return False
    return True


def refuse_mot(path: str | Path) -> EcsAnimError:
    """The one-line error for an OpenSim coordinates file given without its model (read first,
    so a malformed file is named with its line instead): which coordinates it holds and what
    import needs."""
    mot = read_mot(path)
    return InputError(path, f"OpenSim joint angles ({len(mot.labels)} coordinates: "
                            f"{listed(mot.labels, 3)}; {len(mot.values)} frames) need the model "
                            "they were computed on: give --body-model MODEL.osim, or import the "
                            "trial's markers (.trc)")


#: OpenSim's body axes (x forward, y up, z right) as ours (x forward, y left, z up): the columns
#: are our axes in OpenSim's.
OSIM_BODY_AXES = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, 1.0], [0.0, -1.0, 0.0]])
#: OpenSim's ground is Y up.
OSIM_TO_WORLD = UP_AXES["y"]
#: Frame times may wander by this share of a frame (rounded times) and still be one rate.
TIME_TOLERANCE = 0.01


def import_mot(path: str | Path, model_path: str | Path,
               thresholds: ContactThresholds = ContactThresholds(),
               trim: FrameRange | None = None, treadmill: bool = True) -> NormalizedMotion:
    """Read an OpenSim ``.mot``/``.sto`` and pose the ``.osim`` model at ``model_path`` by it,
    then normalize the joint centres as any import does (:func:`canonical_clip_mot`).
    ``info.opensim`` names the model, the coordinates read and those left at their defaults.
    Raises :class:`InputError` naming the file (and line) on bad input."""
    path = Path(path)
    model = read_osim(model_path)
    mot = read_mot(path)
    details: dict[str, object] = {}

    def make_clip() -> CanonicalClip:
        clip, found = canonical_clip_mot(mot, model)
        details.update(found)
        return clip

    motion = import_canonical(path, make_clip, trim, thresholds, treadmill)
    motion.info["format_in"] = "mot"
    motion.info["opensim"] = details
    return motion


def coordinate_values(mot: MotCoordinates, model: OsimModel
                      ) -> tuple[Callable[[str], F64], list[str], list[str]]:
    """Each model coordinate's values (radians or metres) over the file's frames: the file's
    column (a label may be a state path, ``/jointset/hip_r/hip_flexion_r/value``), degrees
    turned to radians for rotations where the file says ``inDegrees=yes``; the model's default
    where the file has no column. Returns (values by name, coordinates read, coordinates left at
    their default). Raises :class:`InputError` where the file gives none of the model's."""
    columns: dict[str, int] = {}
    for k, label in enumerate(mot.labels):
        parts = [p for p in label.split("/") if p]
        name = parts[-2] if len(parts) > 1 and parts[-1] == "value" else parts[-1] if parts else ""
        if name in model.defaults:
            columns.setdefault(name, k)
    if not columns:
        raise InputError(mot.path, f"none of the columns ({listed(mot.labels, 3)}) is a "
                                   f"coordinate of the model {model.path} "
                                   f"({listed(list(model.defaults), 3)}): another model's motion?")
    n = len(mot.values)

    def values(name: str) -> F64:
        if name not in columns:
            return np.full(n, model.defaults[name])
        column = mot.values[:, columns[name]]
        if np.isnan(column).any():
            frames = np.arange(n)
            good = np.isfinite(column)
            column = np.interp(frames, frames[good], column[good])
        out: F64 = np.radians(column) if mot.in_degrees and model.rotational[name] else column
        return out

    return values, list(columns), [c for c in model.defaults if c not in columns]


def frame_rate(mot: MotCoordinates) -> float:
    """Frames per second from the ``time`` column; :class:`InputError` naming the row where
    times do not step evenly (or do not increase)."""
    if len(mot.time_s) < 2:
        raise InputError(mot.path, "one frame: a motion needs two or more to have a frame rate")
    steps = np.diff(mot.time_s)
    step = float(np.median(steps))
    uneven = np.flatnonzero(~(np.abs(steps - step) <= TIME_TOLERANCE * step))
    if step <= 0 or len(uneven):
        k = int(uneven[0]) + 1 if len(uneven) else 1
        raise InputError(mot.path, f"time {mot.time_s[k]:g} s at frame {k + 1}: the times must "
                                   f"increase in even steps (most are {step:g} s)")
    return rate_of_step(step)


def canonical_clip_mot(mot: MotCoordinates, model: OsimModel
                       ) -> tuple[CanonicalClip, dict[str, object]]:
    """The canonical clip (metres, Z up) of ``mot`` posed on ``model``, and how it was read.

    The pelvis is the body the ground's joint moves; its chains of bodies (each body followed
    into its child with the deepest subtree) whose first joint lies below the pelvis's origin
    at the model's default pose and that go down from it are the legs, left and right by the
    side their hip lies on (OpenSim's z is right); one whose first joint lies above is the
    trunk (its arms may hang lower). Along a leg the joints of its first three bodies are the
    hip, knee and ankle, that of its fifth (the toes' joint, after the calcaneus) the toe; a
    leg of four bodies gets a foot lying flat (:func:`~ecs_anim.io.c3d.joint_centres.flat_toe`). The trunk's first joint is the lumbar
    (spine_1), its first body's frame the thorax's, the spine above it at adult proportions of
    the legs. Head and arms take the neutral pose (as a C3D's absent parts)."""
    fps = frame_rate(mot)
    values, read, defaulted = coordinate_values(mot, model)
    n = len(mot.values)
    frames = body_frames(model, values, n)
    rest = body_frames(model, lambda name: np.array([model.defaults[name]]), 1)
    legs, trunk = _chains(model, rest)
    build = JointCentreBuild(np.zeros((n, N_JOINTS, 3)), np.zeros(N_JOINTS, dtype=bool))
    names: dict[str, str | None] = dict.fromkeys(JOINTS)

    def place(joint: str, body: str) -> None:
        set_joint(build, joint, frames[body][2] @ OSIM_TO_WORLD.T, f"joint of body {body}")
        names[joint] = f"{body}'s joint"

    for side, chain in legs.items():
        for joint, body in zip(("hip", "knee", "ankle", "", "toe"), chain, strict=False):
            if joint:
                place(f"{joint}_{side}", body)
    p = build.positions
    set_joint(build, "pelvis", 0.5 * (p[:, J["hip_l"]] + p[:, J["hip_r"]]),
              "midpoint of the hip centres")
    names["pelvis"] = "midpoint of the hips"
    pelvis_forward = np.einsum("ij,fj->fi", OSIM_TO_WORLD, frames[_pelvis(model)][0][:, :, 0])
    build.pelvis2world = frame_from_axes(p[:, J["hip_l"]] - p[:, J["hip_r"]], pelvis_forward, 1, 0)
    leg = float(np.median(np.linalg.norm(p[:, J["knee_l"]] - p[:, J["hip_l"]], axis=-1)
                          + np.linalg.norm(p[:, J["ankle_l"]] - p[:, J["knee_l"]], axis=-1)))
    for side, chain in legs.items():
        if len(chain) < 5:  # no toes' joint: a foot lying flat, as a filled one does
            p[:, J[f"toe_{side}"]] = flat_toe(p[:, J[f"ankle_{side}"]],
                                              heading_frame(build.pelvis2world), leg)
    present = ["leg_l", "leg_r"]
    if trunk:
        place("spine_1", trunk[0])
        thorax2world = OSIM_TO_WORLD @ frames[trunk[0]][0] @ OSIM_BODY_AXES
        build.thorax2world = thorax2world
        thorax_up = thorax2world[:, :, 2]
        p[:, J["spine_2"]] = p[:, J["spine_1"]] + thorax_up * adult_length("spine_middle", leg)
        p[:, J["neck"]] = p[:, J["spine_2"]] + thorax_up * adult_length("spine_upper", leg)
        present.append("trunk")
    fill_absent(build, present)
    if not np.all(np.isfinite(p)):
        raise InputError(mot.path, "the model's forward kinematics gives non-finite joint "
                                   "positions (a coordinate or spline out of range?)")
    assert build.thorax2world is not None and build.head2world is not None
    clip = CanonicalClip(
        positions=p, pelvis2world=build.pelvis2world, thorax2world=build.thorax2world,
        head2world=build.head2world, measured=build.measured, fps=fps, unit="m",
        unit_reason="an OpenSim model is in metres",
        joint_map=JointMap(source={}, thorax=-1, how=f"OpenSim model {model.name or model.path}",
                           names=names),
        up_axis="y", up_reason="OpenSim's ground is Y up",
        toes_follow_ankle=any(len(chain) < 5 for chain in legs.values()))
    details: dict[str, object] = {
        "model": model.path, "model_name": model.name, "coordinates_read": read,
        "coordinates_at_default": defaulted,
        "legs": {s: list(c) for s, c in legs.items()}, "trunk": list(trunk),
        "neutral_pose": ["head", "arms"] + ([] if trunk else ["trunk"]),
    }
    return clip, details


def _pelvis(model: OsimModel) -> str:
    """The body the ground's joint moves (of several, the one with most bodies below it)."""
    roots = [j.child for j in model.joints if j.parent == GROUND]
    return max(roots, key=lambda body: len(_below(model, body)))


def _below(model: OsimModel, body: str) -> list[str]:
    """The bodies below ``body`` in the tree (not itself)."""
    out: list[str] = []
    for joint in model.joints:  # parents come before children
        if joint.parent == body or joint.parent in out:
            out.append(joint.child)
    return out


def _chains(model: OsimModel, rest: dict[str, tuple[F64, F64, F64]]
            ) -> tuple[dict[str, list[str]], list[str]]:
    """The legs ({"l": bodies, "r": bodies} from the thigh down) and the trunk (bodies from the
    lumbar up, or none) below the pelvis (:func:`canonical_clip_mot`); :class:`InputError` where
    there is not one leg on each side of three or more bodies."""
    pelvis = _pelvis(model)
    pelvis_r, pelvis_p, _ = rest[pelvis]
    legs: dict[str, list[str]] = {}
    trunk: list[str] = []
    for joint in (j for j in model.joints if j.parent == pelvis):
        chain = [joint.child]
        while True:
            children = [j.child for j in model.joints if j.parent == chain[-1]]
            if not children:
                break
            chain.append(max(children, key=lambda body: len(_below(model, body))))
        end = pelvis_r[0].T @ (rest[chain[-1]][2][0] - pelvis_p[0])  # in the pelvis's frame
        hip = pelvis_r[0].T @ (rest[chain[0]][2][0] - pelvis_p[0])
        # A leg hangs from below the pelvis's origin and goes down; the trunk starts above it
        # (its arms, hanging, may end lower).
        if hip[1] < 0 and end[1] < hip[1] and len(chain) >= 3:
            side = "r" if hip[2] > 0 else "l"
            if side in legs:
                raise InputError(model.path, f"two legs on the {'right' if side == 'r' else 'left'} "
                                             f"of body {quoted(pelvis)} ({legs[side][0]}, "
                                             f"{chain[0]}): which is the leg?")
            legs[side] = chain
        elif hip[1] >= 0 and len(chain) > len(trunk):
            trunk = chain
    if set(legs) != {"l", "r"}:
        raise InputError(model.path, f"expected a left and a right leg (three or more bodies "
                                     f"each, going down) below the pelvis {quoted(pelvis)}, "
                                     f"found {listed([c[0] for c in legs.values()]) or 'none'}")
    return legs, trunk


__all__ = ["MotCoordinates", "canonical_clip_mot", "import_mot", "read_mot", "refuse_mot"]
