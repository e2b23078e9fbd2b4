"""BVH read back independently of the importer, for the tests that check it.

A plain forward kinematics (explicit axis matrices, units as ../shared/mocap/README.md and
../shared/mocap/varied/README.md document them, not the importer's guesses), the import/export
round trip through the CLI, and numpy Euler angles for rewriting a file's channel orders.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from ecs_anim.apps.cli.main import main
from ecs_anim.core.skeleton import JOINT_INDEX
from ecs_anim.io.bvh import read_bvh

CMU_UNIT = 0.0254 / 0.45

#: Metres per file unit and up axis, as the folders' READMEs document them (prefix of the name).
DOCUMENTED = {
    "bandai": (0.01, "y"), "cmu_01": (CMU_UNIT, "y"), "cmubiped": (0.0254, "y"),
    "cmumax": (1.0, "y"), "cmu_walk_120hz": (CMU_UNIT, "y"), "optitrack": (0.01, "y"),
    "neuron": (0.01, "y"), "fair_zup": (0.0254, "z"), "asf_noneck": (0.01, "y"),
    "asf_zup": (0.0254, "z"), "cmudaz": (0.01, "y"),
}


def lookup(table: dict, name: str):
    """The value of ``table`` whose key is the longest prefix of ``name`` (None if none is)."""
    return next((v for k, v in sorted(table.items(), key=lambda kv: -len(kv[0]))
                 if name.startswith(k)), None)


def axis_rotation(axis: str, degrees: np.ndarray) -> np.ndarray:
    """Rotation matrices (..., 3, 3) about ``axis`` ("X", "Y" or "Z") by ``degrees`` (...)."""
    i = "XYZ".index(axis)
    j, k = (i + 1) % 3, (i + 2) % 3
    c, s = np.cos(np.radians(degrees)), np.sin(np.radians(degrees))
    m = np.zeros(np.shape(degrees) + (3, 3))
    m[..., i, i] = 1.0
    m[..., j, j], m[..., k, k], m[..., j, k], m[..., k, j] = c, c, -s, s
    return m


def euler_matrix(degrees: np.ndarray, order: str) -> np.ndarray:
    """BVH channel angles (n, 3), in the channels' ``order`` ("ZXY"), as matrices (n, 3, 3)."""
    m = axis_rotation(order[0], degrees[:, 0])
    for n in (1, 2):
        m = m @ axis_rotation(order[n], degrees[:, n])
    return m


def euler_angles(matrix: np.ndarray, order: str) -> np.ndarray:
    """The inverse of :func:`euler_matrix`: angles (n, 3) in degrees for ``order``."""
    i, j, k = ("XYZ".index(a) for a in order)
    sign = 1.0 if (j - i) % 3 == 1 else -1.0  # XYZ, YZX, ZXY are cyclic
    middle = np.arcsin(np.clip(sign * matrix[:, i, k], -1.0, 1.0))
    first = np.arctan2(-sign * matrix[:, j, k], matrix[:, k, k])
    last = np.arctan2(-sign * matrix[:, i, j], matrix[:, i, i])
    return np.degrees(np.stack([first, middle, last], axis=-1))


def reference_positions(path, file_frame: frozenset[str] = frozenset()
                        ) -> tuple[list[str], np.ndarray]:
    """Independent FK: (joint names incl. '<parent>.end', positions (F, n, 3) in file units).
    Joints named in ``file_frame`` have position channels that give their place in the file's
    frame rather than an offset from their parent."""
    motion = read_bvh(path)  # parsing itself is tested by the bad-input corpus
    sk = motion.skeleton
    values = motion.channels
    n_frames = values.shape[0]
    col = 0
    glob_r, glob_p = [], []
    for joint in sk.joints:
        rot = np.broadcast_to(np.eye(3), (n_frames, 3, 3))
        trans = np.tile(joint.offset, (n_frames, 1))
        for ch in joint.channels:
            axis, kind = ch[0].upper(), ch[1:].lower()
            if kind == "position":
                trans[:, "XYZ".index(axis)] = values[:, col]
            else:
                rot = rot @ axis_rotation(axis, values[:, col])
            col += 1
        if joint.parent < 0:
            glob_r.append(rot)
            glob_p.append(trans)
        else:
            pr, pp = glob_r[joint.parent], glob_p[joint.parent]
            glob_r.append(pr @ rot)
            glob_p.append(trans if joint.name in file_frame
                          else pp + np.einsum("fij,fj->fi", pr, trans))
    return sk.names, np.stack(glob_p, axis=1)


def reference_world(path, scale: float, up: str, file_frame: frozenset[str] = frozenset()
                    ) -> tuple[list[str], np.ndarray]:
    """Independent FK in metres, Z up: (joint names incl. '<parent>.end', (F, n, 3))."""
    names, p = reference_positions(path, file_frame)
    p = p * scale
    if up == "y":
        p = np.stack([p[..., 0], -p[..., 2], p[..., 1]], axis=-1)
    return names, p


def import_and_export(path, tmp_path, extra: list[str] | None = None):
    """Import ``path`` into ``tmp_path`` with the CLI (and ``extra`` flags), export it on its
    source body: (the import's info, joint positions (F, J, 3) in metres, Z up)."""
    args = ["import", str(path), "-o", str(tmp_path)] + (extra or [])
    assert main(args) == 0
    nmo = tmp_path / f"{path.stem}.nmo"
    npz = tmp_path / "source.npz"
    assert main(["export", str(nmo), "--morphology", "source", "-o", str(npz), "--force"]) == 0
    info = json.loads(str(np.load(nmo)["header_json"]))["info"]
    return info, np.load(npz)["positions"]


def errors_m(info: dict, exported: np.ndarray, names: list[str], ref: np.ndarray) -> dict:
    """Each mapped joint's (not filled in) worst distance (m) over the frames between the
    exported joint and the reference joint it maps to (``names``, ``ref`` (F, n, 3))."""
    mapped = {j: s for j, s in info["joints"].items() if s is not None and j not in info["filled_in"]}
    return {j: float(np.linalg.norm(exported[:, JOINT_INDEX[j]] - ref[:, names.index(s)],
                                    axis=-1).max()) for j, s in mapped.items()}


def in_place_copy(source: Path, out_folder: Path, speedup: float = 1.0) -> Path:
    """``source`` (a BVH whose root is its first joint, six channels, Xposition first) on a
    treadmill: the root's mean horizontal velocity (first to last frame) taken away from every
    frame, so the root stays in place, swaying, and the stance foot slides back under it as on a
    belt; played ``speedup`` times faster (its frame time divided). Written to ``out_folder``."""
    head, motion = source.read_text().split("MOTION", 1)
    lines = motion.strip().splitlines()
    first, last = lines[2].split(), lines[-1].split()
    n = len(lines) - 2
    rows = []
    for k, line in enumerate(lines[2:]):
        values = line.split()
        for c in (6, 8):  # Hips' Xpos and Zpos
            drift = (float(last[c]) - float(first[c])) * k / (n - 1)
            values[c] = f"{float(values[c]) - drift:.4f}"
        rows.append(" ".join(values))
    frame_time = float(lines[1].split()[-1]) / speedup
    stem = "walk_in_place" if speedup == 1.0 else f"walk_in_place_x{speedup:g}"
    copy = out_folder / f"{stem}.bvh"
    copy.write_text(head + "MOTION\n" + lines[0] + f"\nFrame Time: {frame_time:.6f}\n"
                    + "\n".join(rows) + "\n")
    return copy
