"""Which frames of a trial the markers place: the pelvis' span, the frames where every body part
is placed too (the others are trimmed, one line each in ``info.parts_frames_trimmed``), and
the pelvis repaired inside where its own markers are missing."""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from ecs_anim.core.errors import EcsAnimError, listed
from ecs_anim.core.rotations import matrix_from_quat, quat_from_matrix, slerp
from ecs_anim.core.skeleton import JOINT_INDEX as J
from ecs_anim.io.c3d.centre_build import JointCentreBuild, MarkersByRole
from ecs_anim.io.c3d.clusters import cluster_key
from ecs_anim.io.c3d.marker_sets import GROUP_WORDS, MarkerMap, part_roles
from ecs_anim.io.contacts import true_runs

BOOL = NDArray[np.bool_]


def trimmed_part_lines(mk: MarkersByRole, mmap: MarkerMap, present: list[str], labels: list[str],
                       root: slice, kept: slice) -> list[str]:
    """One line per end of the pelvis' span trimmed because a part's markers did not place it
    (:func:`kept_frames`), naming those parts and their markers unseen or unreliable there."""
    placed = parts_placed(mk, mmap, present)
    out = []
    for first, stop in ((root.start, kept.start), (kept.stop, root.stop)):
        if first >= stop:
            continue
        parts = []
        for group, where in placed.items():
            unplaced = ~where[first:stop]
            markers = [labels[mk.found[r]] for r in part_roles(mmap.preset, group)
                       if r in mk.found and (mk.unreliable[first:stop, mk.found[r]] & unplaced).any()]
            if unplaced.any():
                parts.append(f"{GROUP_WORDS[group]} ({listed(markers, 4)})")
        frames = f"frame {first}" if stop - first == 1 else f"frames {first}-{stop - 1}"
        out.append(f"{frames} of the file trimmed: the markers of the {listed(parts, 3)} are "
                   "unseen or in a long gap there")
    return out


#: A part whose markers are missing at the trial's start or end gets those frames trimmed,
#: unless that keeps less than this share of the frames the pelvis markers place (then the
#: frames are kept and reported with the long gaps).
MIN_KEPT_SHARE = 0.5


def parts_placed(mk: MarkersByRole, mmap: MarkerMap, present: list[str]) -> dict[str, BOOL]:
    """Per present body part but the pelvis (``root_trusted`` places it), the frames (F,) bool
    where its own markers place it: none of its markers unreliable
    (:func:`~ecs_anim.io.c3d.repair.fill_gaps`: in a long gap, or held at the trial's start or
    end where it is not seen); in a cluster set, each of its clusters with three reliable markers
    (what a rigid fit needs). Elsewhere its joints are a guess."""
    out: dict[str, BOOL] = {}
    for group in (g for g in present if g != "pelvis"):
        roles = [r for r in part_roles(mmap.preset, group) if r in mk.found]
        reliable = ~mk.unreliable[:, [mk.found[r] for r in roles]]
        if mmap.preset.method == "functional":
            clusters: dict[str, list[int]] = {}
            for k, role in enumerate(roles):
                clusters.setdefault(cluster_key(role), []).append(k)
            out[group] = np.all([reliable[:, ks].sum(axis=1) >= 3 for ks in clusters.values()],
                                axis=0)
        else:
            out[group] = np.asarray(reliable.all(axis=1))
    return out


def kept_frames(root_trusted: BOOL | None, placed: dict[str, BOOL], n: int) -> tuple[slice, slice]:
    """(the pelvis' span, the frames kept), file frames: the pelvis' span runs from the first to
    the last frame whose pelvis frame the markers determine (``root_trusted`` (n,), None: all);
    the frames kept, from the first to the last of those where every part is ``placed`` too
    (:func:`parts_placed`), unless that would keep less than :data:`MIN_KEPT_SHARE` of the
    pelvis' span or nothing (then the pelvis' span). Raises :class:`EcsAnimError` when the
    pelvis is placed nowhere."""
    trusted = np.ones(n, dtype=bool) if root_trusted is None else root_trusted
    good = np.flatnonzero(trusted)
    if len(good) == 0:
        raise EcsAnimError(f"the pelvis markers place the pelvis in none of the {n} frames "
                           "(a cluster needs three of its markers seen, landmarks all of theirs); "
                           "nothing to import")
    root = slice(int(good[0]), int(good[-1]) + 1)
    everything = np.flatnonzero(trusted & np.all(list(placed.values()), axis=0)) if placed else good
    if len(everything) and everything[-1] + 1 - everything[0] >= MIN_KEPT_SHARE * (root.stop - root.start):
        return root, slice(int(everything[0]), int(everything[-1]) + 1)
    return root, root


def trust_root(build: JointCentreBuild, kept: slice) -> list[list[int]]:
    """Keep only the frames ``kept`` (:func:`kept_frames`) and repair those inside whose pelvis
    frame the markers do not determine, in place.

    Where the pelvis markers are missing (a cluster with fewer than three seen, a landmark in a
    long gap), the computed pelvis frame is noise: it flipped the body upside down from one
    frame to the next, and every part filled in or taken from a default motion followed it.
    Such runs at the start and end of the trial are trimmed (the capture had not started yet);
    inside it, the pelvis frame is interpolated along the shorter arc, and the pelvis and hip
    centres (placed from it) linearly, between the trusted frames on either side (``kept``
    starts and ends on such frames). Joints that their own markers place are kept.

    Returns the repaired runs as ``[first, last]`` pairs in the kept frames' numbering (the
    motion's).
    """
    assert build.pelvis2world is not None, "every pelvis builder sets the pelvis frame"
    n = build.positions.shape[0]
    trusted = np.ones(n, dtype=bool) if build.root_trusted is None else build.root_trusted
    repaired = [[a, b] for a, b in true_runs(~trusted[kept])]
    frames = [f for f in ("pelvis2world", "thorax2world", "head2world") if getattr(build, f) is not None]
    build.positions = build.positions[kept]
    for name in frames:
        setattr(build, name, getattr(build, name)[kept])
    for first, last in repaired:
        before, after = first - 1, last + 1
        t = (np.arange(first, last + 1) - before) / (after - before)
        root = [J["pelvis"], J["hip_l"], J["hip_r"]]
        build.positions[before + 1:after, root] = (1.0 - t[:, None, None]) * build.positions[before, root] \
            + t[:, None, None] * build.positions[after, root]
        quats = quat_from_matrix(build.pelvis2world[[before, after]])
        build.pelvis2world[before + 1:after] = matrix_from_quat(slerp(quats[0], quats[1], t))
    build.root_trusted = None
    return repaired
