"""Repairing bad samples: marker gaps filled, cluster samples that break the cluster's shape, and
joint centres that break their bone lengths.

Gaps: a sample is invalid when its residual is negative, its coordinates are all zero or it is
not finite. Runs of at most ``max_gap`` frames (default :data:`DEFAULT_MAX_GAP_S` worth: 10
at 100 Hz, whatever the rate the same stretch of time) are interpolated linearly; longer
runs are interpolated as well (so no NaN ever reaches the output) and reported. Runs at the
trial's start or end are held from the nearest sample, so they are unreliable at any length:
the frames at the ends where a body part's own markers are missing are trimmed, with one line
each in ``info.parts_frames_trimmed``, as are those where the pelvis markers are
(:mod:`ecs_anim.io.c3d.trimming`).

Joint centres whose bones change length by more than 15 % for at most ``MAX_GLITCH_S``
(0.05 s; marker swaps or ghost markers in fast motion) are replaced by interpolation and reported
(:func:`reject_joint_outliers`).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from ecs_anim.core.skeleton import JOINT_INDEX as J
from ecs_anim.core.skeleton import JOINTS
from ecs_anim.io.contacts import true_runs

F64 = NDArray[np.float64]
BOOL = NDArray[np.bool_]


#: Longest marker gap filled without a warning, in seconds (``--max-gap`` gives frames).
DEFAULT_MAX_GAP_S = 0.1


MAX_GLITCH_S = 0.05  # joint-centre outliers are replaced only in runs this short (seconds)


def fill_gaps(positions: F64, valid: BOOL, max_gap: int) -> tuple[F64, BOOL]:
    """Interpolate invalid samples of each marker linearly (held at the clip's ends).

    positions (F, M, 3), valid (F, M). Returns (filled positions, ``unreliable``): True (F, M)
    on samples in runs of more than ``max_gap`` invalid frames (filled too, but a guess), on
    runs at the trial's start or end of any length (held from the nearest sample: nothing
    brackets them, so a moving marker is simply wrong there) and on markers never seen. The
    loop runs over markers and gaps, never over frames.
    """
    out = positions.copy()
    unreliable = np.zeros(valid.shape, dtype=bool)
    frames = np.arange(valid.shape[0])
    last = valid.shape[0] - 1
    for m in range(valid.shape[1]):
        ok = valid[:, m]
        if ok.all():
            continue
        if not ok.any():
            unreliable[:, m] = True
            continue
        bad = ~ok
        for axis in range(3):
            out[bad, m, axis] = np.interp(frames[bad], frames[ok], positions[ok, m, axis])
        for a, b in true_runs(bad):
            if b - a + 1 > max_gap or a == 0 or b == last:
                unreliable[a:b + 1, m] = True
    return out, unreliable


def cluster_outliers(points: F64, valid: BOOL, tolerance_m: float = 0.015,
                     tolerance_fraction: float = 0.1) -> BOOL:
    """Samples of a rigid cluster that break its shape (mislabelled or swapped markers).

    points (F, K, 3) metres, valid (F, K). A sample is an outlier when more than half of its
    distances to the cluster's other valid markers differ from their median over the trial by
    more than ``tolerance_m + tolerance_fraction * median``. Returns (F, K) bool.
    """
    k = points.shape[1]
    dist = np.linalg.norm(points[:, :, None] - points[:, None], axis=-1)  # (F, K, K)
    pair_ok = valid[:, :, None] & valid[:, None, :]
    median = np.array([[np.median(dist[pair_ok[:, a, b], a, b]) if pair_ok[:, a, b].any() else 0.0
                        for b in range(k)] for a in range(k)])
    off = np.abs(dist - median) > tolerance_m + tolerance_fraction * median
    bad_pairs = (off & pair_ok).sum(axis=2)
    pairs = np.maximum(pair_ok.sum(axis=2) - 1, 0)  # the diagonal counts itself
    out: BOOL = valid & (bad_pairs * 2 > pairs) & (pairs > 0)
    return out


def reject_joint_outliers(positions: F64, measured: BOOL, longest: int, tolerance: float = 0.15
                          ) -> dict[str, int]:
    """Replace limb joint centres that break their bone lengths (marker swaps, ghost markers
    in fast motion) by interpolation from the neighbouring frames, in place.

    positions (F, N_JOINTS, 3). A bone is off in a frame when its length differs from its
    median over the trial by more than ``tolerance`` of it; only runs of at most ``longest``
    frames (:data:`MAX_GLITCH_S` at the file's rate) are replaced (longer runs are motion, or
    the model).
    Along hip-knee-ankle-toe and shoulder-elbow-wrist-hand, the middle joint (knee, elbow) is
    the culprit where the shank (forearm) is off and so is the thigh (upper arm), or the foot
    (hand) beyond it is not; the end joint (ankle, wrist) where the shank (forearm) is still
    off after that; then the toe (hand end) where the foot (hand) is off. Returns joint -> replaced frame count (only joints with some).
    """
    frames = np.arange(positions.shape[0])
    out: dict[str, int] = {}

    def off(p: int, q: int) -> BOOL:
        length = np.linalg.norm(positions[:, q] - positions[:, p], axis=-1)
        median = np.median(length)
        bad: BOOL = np.abs(length - median) > tolerance * median
        return bad

    for s in "lr":
        for top, middle, end, tip in (("hip", "knee", "ankle", "toe"),
                                      ("shoulder", "elbow", "wrist", "hand")):
            a, b, c, d = (J[f"{n}_{s}"] for n in (top, middle, end, tip))
            if not measured[[a, b, c]].all():
                continue
            lower = off(b, c)
            tip_fine = ~off(c, d) if measured[d] else np.zeros_like(lower)
            _interpolate_frames(positions, b, lower & (off(a, b) | tip_fine), frames, longest,
                                out)
            _interpolate_frames(positions, c, off(b, c), frames, longest, out)  # after the fix
            if measured[d]:
                _interpolate_frames(positions, d, off(c, d), frames, longest, out)
    return out


def _interpolate_frames(positions: F64, joint: int, bad: BOOL, frames: NDArray[np.int_],
                        longest: int, counts: dict[str, int]) -> None:
    bad = bad.copy()
    for a, b in true_runs(bad):  # a long run is the motion (or the model), not a glitch
        if b - a + 1 > longest:
            bad[a:b + 1] = False
    if bad.any() and not bad.all():
        for axis in range(3):
            positions[bad, joint, axis] = np.interp(frames[bad], frames[~bad],
                                                    positions[~bad, joint, axis])
        counts[JOINTS[joint]] = counts.get(JOINTS[joint], 0) + int(bad.sum())
