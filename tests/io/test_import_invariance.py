"""Import invariances (issue 12): the same motion written by another lab or tool gives the same
contacts and the same normalized motion. Copies of dev walks made in tmp_path: yawed about the
vertical and moved 500 m away, at half or double the rate, in another length unit, started
mid-stride or cut to 2 s; each compared with the original's import."""

from __future__ import annotations

import re
from dataclasses import dataclass, field
from functools import cache
from pathlib import Path

import numpy as np
import pytest

from conftest import MOCAP_DIR
from ecs_anim.core.morphology import leg_length
from ecs_anim.core.normalized import decode
from ecs_anim.core.rotations import (
    euler_to_matrix,
    matrix_from_quat,
    matrix_to_euler,
    quat_from_matrix,
    rot_axis,
    slerp,
)
from ecs_anim.core.skeleton import JOINT_INDEX as J
from ecs_anim.io.bvh import parse_bvh
from ecs_anim.io.c3d.importing import import_c3d
from ecs_anim.io.c3d.reading import read_c3d
from ecs_anim.io.contacts import horizontal_speed, true_runs
from ecs_anim.io.importing import import_bvh, unit_scale
from ecs_anim.motion.clip import NormalizedMotion, facing_and_travel
from support.c3d_files import write_c3d

UP_INDEX = {"x": 0, "y": 1, "z": 2}


# --- copies of a BVH as another tool could have written it -------------------------------------

@dataclass(frozen=True)
class Variation:
    """How a copy differs from its source: turned by ``yaw_deg`` about the vertical and moved
    ``shift_m`` metres horizontally, lengths times ``scale`` (another unit), frames
    ``frames`` (a slice of the source's) and, when ``upsample``, a frame put between each two."""

    yaw_deg: float = 0.0
    shift_m: float = 0.0
    scale: float = 1.0
    frames: slice = field(default_factory=lambda: slice(None))
    upsample: bool = False


def _rotation_columns(channels: list[str], first: int) -> tuple[list[int], list[int], str]:
    """Column numbers of a joint's position and rotation channels, and its rotation order."""
    pos = [first + k for k, ch in enumerate(channels) if ch.lower().endswith("position")]
    rot = [first + k for k, ch in enumerate(channels) if ch.lower().endswith("rotation")]
    order = "".join(channels[c - first][0].upper() for c in rot)
    return pos, rot, order


def varied_bvh(src: Path, dst: Path, v: Variation, up: str, metres_per_unit: float) -> Path:
    """A copy of the BVH ``src`` with the variation ``v``: the root's channels (position and
    rotation) turned about the file's ``up`` axis and shifted along another axis; OFFSETs and
    every position channel scaled; frames resampled (rotations by slerp, positions linearly)."""
    text = src.read_text()
    motion = parse_bvh(text, str(src))
    values = motion.channels.copy()
    joints = motion.skeleton.joints
    columns, first = [], 0
    for joint in joints:
        columns.append(_rotation_columns(joint.channels, first))
        first += len(joint.channels)
    root_pos, root_rot, root_order = columns[0]
    assert len(root_pos) == 3 and len(root_rot) == 3, "the root needs 6 channels"
    turn = rot_axis(UP_INDEX[up], np.deg2rad(v.yaw_deg))
    values[:, root_pos] = values[:, root_pos] @ turn.T
    values[:, root_pos[(UP_INDEX[up] + 1) % 3]] += v.shift_m / metres_per_unit
    values[:, root_rot] = matrix_to_euler(turn @ euler_to_matrix(values[:, root_rot], root_order),
                                          root_order)
    for pos, _, _ in columns:
        values[:, pos] *= v.scale
    values = values[v.frames]
    frame_time = motion.frame_time_s
    if v.frames.step:
        frame_time *= v.frames.step
    if v.upsample:
        values, frame_time = _upsampled(values, columns), frame_time / 2
    head = text.split("MOTION", 1)[0]
    head = re.sub(r"(OFFSET)\s+(\S+)\s+(\S+)\s+(\S+)", lambda m: "OFFSET " + " ".join(
        f"{float(x) * v.scale:.6f}" for x in m.groups()[1:]), head)
    rows = "\n".join(" ".join(f"{x:.6f}" for x in row) for row in values)
    dst.write_text(f"{head}MOTION\nFrames: {len(values)}\nFrame Time: {frame_time:.10f}\n{rows}\n")
    return dst


def _upsampled(values: np.ndarray, columns: list[tuple[list[int], list[int], str]]) -> np.ndarray:
    """Frames (F, C) -> (2F - 1, C): a frame between each two, positions halfway, each joint's
    rotation slerped halfway (and written back in its own order)."""
    out = np.empty((2 * len(values) - 1, values.shape[1]))
    out[::2] = values
    out[1::2] = 0.5 * (values[:-1] + values[1:])
    for _, rot, order in columns:
        if len(rot) != 3:
            continue
        q = quat_from_matrix(euler_to_matrix(values[:, rot], order))
        mid = slerp(q[:-1], q[1:], 0.5)
        out[1::2, rot] = matrix_to_euler(matrix_from_quat(mid), order)
    return out


def varied_c3d(src: Path, dst: Path, v: Variation, unit: str) -> Path:
    """A copy of the C3D ``src``'s markers with the variation ``v`` (no upsampling), written in
    ``unit`` (``POINT:UNITS``) at its rate over ``v.frames.step``."""
    raw = read_c3d(src)
    assert raw.units in ("mm", "m", "cm"), raw.units
    to_m = {"mm": 1e-3, "cm": 1e-2, "m": 1.0}
    p = raw.positions * to_m[raw.units]
    turn = rot_axis(2, np.deg2rad(v.yaw_deg))  # these labs' files are Z up
    p = p @ turn.T
    p[..., 0] += v.shift_m
    p = np.where(raw.valid[..., None], p, 0.0) / to_m[unit]
    return write_c3d(dst, raw.labels, p[v.frames], raw.valid[v.frames],
                     raw.rate / (v.frames.step or 1), unit)


# --- the figures compared ---------------------------------------------------------------------

def edges_s(flags: np.ndarray, fps: float) -> list[tuple[list[float], list[float]]]:
    """Per foot, the times (s) of its touch-downs and lift-offs inside the clip."""
    out = []
    for side in range(flags.shape[1]):
        runs = true_runs(flags[:, side])
        out.append(([a / fps for a, _ in runs if a > 0],
                    [(b + 1) / fps for _, b in runs if b < len(flags) - 1]))
    return out


def planted_speeds(motion: NormalizedMotion, frames: slice = slice(None)) -> np.ndarray:
    """The planted part's horizontal speed (m/s) on every planted frame of ``frames`` (as
    test_contacts computes it)."""
    p = decode(motion.poses, motion.source_morphology.lengths, use_stretch=True).positions
    v = horizontal_speed(p[:, [J["ankle_l"], J["ankle_r"], J["toe_l"], J["toe_r"]]], motion.fps)
    heel, ball = motion.planted_part("heel"), motion.planted_part("ball")
    part = np.minimum(np.where(heel, v[:, :2], np.inf), np.where(ball, v[:, 2:], np.inf))[frames]
    return part[np.isfinite(part)]


def matched_frames(original: NormalizedMotion, copy: NormalizedMotion, v: Variation
                   ) -> tuple[np.ndarray, np.ndarray]:
    """Frame numbers (original's, copy's) of the same instants. A C3D import may have trimmed
    frames at either file's start (``first_file_frame``)."""
    step = v.frames.step or 1
    start = (v.frames.start or 0) + copy.info.get("first_file_frame", 0) * step \
        - original.info.get("first_file_frame", 0)
    every = 2 if v.upsample else 1
    kv = np.arange(0, copy.n_frames, every)
    ko = start + (kv // every) * step
    inside = (ko >= 0) & (ko < original.n_frames)
    return ko[inside], kv[inside]


def figures(original: NormalizedMotion, copy: NormalizedMotion, v: Variation) -> dict[str, float]:
    """How far the copy's import is from the original's over the instants both hold: per foot
    the planted share (``share``, the larger difference), contact edges (``edge_s``: the worst
    distance of a copy's touch-down or lift-off, foot or on-ground, to the original's nearest,
    and ``unmatched``: edges of either with none within 0.1 s in the other, away from the
    copy's ends), the planted part's speed (``median_mps``, ``max_mps``), the decoded joints on
    the source body with the yaw and shift undone (``joints_m``), the root heading less the yaw
    (``heading_deg``), and the facing and straight travel ``info`` reports (``facing_deg``,
    ``travel_m``)."""
    ko, kv = matched_frames(original, copy, v)
    span = slice(int(ko[0]), int(ko[-1]) + 1)
    t0 = ko[0] / original.fps - kv[0] / copy.fps
    out: dict[str, float] = {}
    fo, fv = original.planted_part("foot")[span], copy.planted_part("foot")
    out["share"] = float(np.abs(fo.mean(axis=0) - fv.mean(axis=0)).max())
    worst, unmatched = 0.0, 0
    inner = (t0 + 2 / copy.fps, t0 + (copy.n_frames - 3) / copy.fps)
    for part in ("foot", "on_ground"):
        theirs = edges_s(original.planted_part(part), original.fps)
        ours = edges_s(copy.planted_part(part), copy.fps)
        for side in range(2):
            for kind in range(2):
                a, b = np.array(theirs[side][kind]), np.array(ours[side][kind]) + t0
                for t in b:
                    gap = float(np.abs(a - t).min()) if len(a) else np.inf
                    worst, unmatched = (max(worst, gap), unmatched) if gap < 0.1 \
                        else (worst, unmatched + 1)
                for t in a[(a > inner[0]) & (a < inner[1])]:
                    unmatched += not (len(b) and np.abs(b - t).min() < 0.1)
    out["edge_s"], out["unmatched"] = worst, unmatched
    so, sv = planted_speeds(original, span), planted_speeds(copy)
    out["median_mps"] = abs(float(np.median(so) - np.median(sv)))
    out["max_mps"] = abs(float(so.max() - sv.max()))
    yaw = np.deg2rad(v.yaw_deg)
    turn = rot_axis(2, yaw)
    po = decode(original.poses, original.source_morphology.lengths, use_stretch=True).positions[ko]
    pv = decode(copy.poses, copy.source_morphology.lengths, use_stretch=True).positions[kv]
    back = pv @ turn  # each point turned back by -yaw
    back -= np.median(back[:, J["pelvis"]] - po[:, J["pelvis"]], axis=0)  # the shift
    out["joints_m"] = float(np.linalg.norm(back - po, axis=-1).max())
    turned = copy.poses.root_heading[kv] - original.poses.root_heading[ko] - yaw
    out["heading_deg"] = float(np.degrees(np.abs(np.angle(np.exp(1j * turned))).max()))
    report = facing_and_travel(copy)
    facing = report["facing_deg"] - np.degrees(original.poses.root_heading[ko[0]]) - v.yaw_deg
    out["facing_deg"] = abs((facing + 180.0) % 360.0 - 180.0)
    leg = float(leg_length(original.source_morphology.lengths))
    root = original.poses.root_position[[ko[0], ko[-1]], :2] * leg
    out["travel_m"] = abs(report["straight_m"] - float(np.linalg.norm(root[1] - root[0])))
    return out


# --- the invariances --------------------------------------------------------------------------

#: Dev walks (Y up in cm at 30 Hz, Acclaim names in cm at 120 Hz, Z up in inches at 119.875 Hz)
#: and two C3D walks (Plug-in Gait at 100 Hz, a cluster set at 50 Hz).
BVH_WALKS = ["bandai_walk.bvh", "varied/asf_noneck_walk_speeds_120hz.bvh",
             "varied/fair_zup_walk_inch_120hz.bvh"]
C3D_WALKS = ["varied/vicon_cgm24_events_jc_100hz.c3d", "c3dorg_eb015pi_gait.c3d"]


def variations(fps: float, metres_per_unit: float, bvh: bool) -> dict[str, Variation]:
    """The copies another lab or tool could have written of the same capture."""
    out = {
        "yawed_37_500m_away": Variation(yaw_deg=37.0, shift_m=500.0),
        "yawed_90": Variation(yaw_deg=90.0),
        "half_rate": Variation(frames=slice(None, None, 2)),
        "from_0.37s": Variation(frames=slice(round(0.37 * fps), None)),
        "2s_from_1s": Variation(frames=slice(round(fps), round(3 * fps) + 1)),
        "in_m": Variation(scale=metres_per_unit),
    }
    if bvh:
        out["double_rate"] = Variation(upsample=True)
        out["in_mm"] = Variation(scale=metres_per_unit / 1e-3)
    return out


BVH_CASES = ["yawed_37_500m_away", "yawed_90", "half_rate", "double_rate", "in_mm", "in_m",
             "from_0.37s", "2s_from_1s"]
C3D_CASES = ["yawed_37_500m_away", "half_rate", "in_m", "from_0.37s", "2s_from_1s"]
#: Bounds: planted share per foot (a few percent), edges within one frame at the coarser of the
#: two rates plus 5 ms, planted speed median and max, joints (BVH: the file's 6 decimals;
#: C3D: its float32 samples through the joint-centre fits), heading and facing.
SHARE, EDGE_EXTRA_S, MEDIAN_MPS, MAX_MPS = 0.02, 0.005, 0.005, 0.05
JOINTS_M = {"bvh": 1e-4, "c3d": 5e-3}
HEADING_DEG = {"bvh": 0.01, "c3d": 0.5}
TRAVEL_M = {"bvh": 2e-3, "c3d": 5e-3}
#: Measured where an invariance does not hold yet: the cluster set's functional joint centres
#: (SCoRE) fitted on a 2 s cut differ from the whole trial's (a hinge's axis is fitted on
#: what the cut's frames move it through). (At half the rate, cgm24's lift-off and c3dorg's
#: touch-down came 1.5 and 2 frames late until the contact edges were interpolated between
#: frames: they now hold.)
OPEN = {
    ("c3dorg_eb015pi_gait.c3d", "2s_from_1s"): "joints 42 mm, heading 5.8 deg off",
}


def _source(name: str) -> Path:
    path = MOCAP_DIR / name
    if not path.exists():
        pytest.skip(f"{path} not available")
    return path


@cache
def _original_bvh(name: str) -> NormalizedMotion:
    return import_bvh(_source(name))


def _check(original: NormalizedMotion, copy: NormalizedMotion, v: Variation, kind: str) -> None:
    f = figures(original, copy, v)
    frame_s = max(1.0 / original.fps, 1.0 / copy.fps)
    assert f["share"] <= SHARE, f
    assert f["unmatched"] == 0 and f["edge_s"] <= frame_s + EDGE_EXTRA_S, f
    assert f["median_mps"] <= MEDIAN_MPS and f["max_mps"] <= MAX_MPS, f
    assert f["joints_m"] <= JOINTS_M[kind], f
    assert f["heading_deg"] <= HEADING_DEG[kind] and f["facing_deg"] <= HEADING_DEG[kind] + 0.1, f
    assert f["travel_m"] <= TRAVEL_M[kind], f


def _params(names: list[str], cases: list[str]) -> list[object]:
    return [pytest.param(n, c, id=f"{Path(n).stem}-{c}", marks=[pytest.mark.xfail(
        reason=OPEN[(n, c)], strict=True)] if (n, c) in OPEN else [])
        for n in names for c in cases]


@pytest.mark.parametrize(("name", "case"), _params(BVH_WALKS, BVH_CASES))
def test_a_bvh_written_otherwise_imports_to_the_same_motion(name, case, tmp_path):
    original = _original_bvh(name)
    up, metres = original.info["up_axis"], unit_scale(original.info["unit"])
    v = variations(original.fps, metres, bvh=True)[case]
    copy = import_bvh(varied_bvh(_source(name), tmp_path / f"{case}.bvh", v, up, metres))
    _check(original, copy, v, "bvh")


@pytest.mark.parametrize(("name", "case"), _params(C3D_WALKS, C3D_CASES))
def test_a_c3d_written_otherwise_imports_to_the_same_motion(name, case, tmp_path):
    """Both files written alike (float32 samples, millimetres unless the case says otherwise),
    the original unchanged: the variation is the only difference."""
    src = _source(name)
    raw_rate = read_c3d(src).rate
    v = variations(raw_rate, 1.0, bvh=False)[case]
    original = import_c3d(varied_c3d(src, tmp_path / "original.c3d", Variation(), "mm"))
    copy = import_c3d(varied_c3d(src, tmp_path / f"{case}.c3d", v, "m" if case == "in_m" else "mm"))
    _check(original, copy, v, "c3d")
