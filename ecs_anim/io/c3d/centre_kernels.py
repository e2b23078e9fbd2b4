"""Joint-centre geometry, batched over frames: the chord rule, a hinge's flexion axis, a rigid
cluster's pose (Kabsch) and the centre of rotation of two segments (SCoRE)."""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from ecs_anim.core.rotations import frame_from_axes, normalize

F64 = NDArray[np.float64]
BOOL = NDArray[np.bool_]


#: SCoRE: weakest / next eigenvalue below this = a hinge (axis undetermined) ...
HINGE_RATIO = 0.2


#: ... and a hinge's axis runs across its segment (a knee's, an ankle's): the weakest direction
#: is taken for a hinge with a prior only when its cosine with the line from the free solution
#: to the prior (the proximal joint, up the segment) is below this (at least 60 degrees apart).
HINGE_ACROSS_COS = 0.5


#: A limb's plane gives its flexion axis in the frames flexed this much of the trial's most.
FLEXED_FRACTION = 0.7


def midpoint(a: F64, b: F64) -> F64:
    """The point halfway between ``a`` and ``b`` (..., 3)."""
    return 0.5 * (a + b)


def chord_centre(proximal: F64, wand: F64, marker: F64, offset: F64 | float) -> F64:
    """Plug-in-Gait chord rule: the joint centre ``c`` at ``offset`` from ``marker``, in the
    plane of (proximal, wand, marker), with (proximal - c) perpendicular to (marker - c), on the
    side away from the wand. All (F, 3) -> (F, 3)."""
    u_vec = proximal - marker
    length = np.linalg.norm(u_vec, axis=-1, keepdims=True)
    u = u_vec / np.maximum(length, 1e-12)
    w = wand - marker
    v = -normalize(w - np.sum(w * u, axis=-1, keepdims=True) * u)
    off = np.asarray(offset, dtype=np.float64)
    off = off[..., None] if off.ndim else off
    cos_t = np.clip(off / np.maximum(length, 1e-12), 0.0, 1.0)
    sin_t = np.sqrt(1.0 - cos_t**2)
    centre: F64 = marker + off * (cos_t * u + sin_t * v)
    return centre


def flexion_axis(proximal: F64, joint: F64, distal: F64, segment_second: F64,
                 use: BOOL | None = None) -> F64:
    """A hinge's flexion axis (unit, world, (F, 3)) as the normal of the proximal-joint-distal
    plane, ``cross(proximal - joint, distal - joint)``, averaged in the proximal segment's frame
    (long axis joint -> proximal, ``segment_second`` a second direction fixed in the segment)
    over the most flexed of the frames ``use`` (F,) (all when None): those whose flexion sine
    is at least :data:`FLEXED_FRACTION` of its 95th percentile. Near straight, the plane is set
    by skin-marker noise and ab/adduction more than by flexion. All inputs (F, 3)."""
    upper, lower = proximal - joint, distal - joint
    flex = np.cross(upper, lower)
    sine = np.linalg.norm(flex, axis=-1) / np.maximum(
        np.linalg.norm(upper, axis=-1) * np.linalg.norm(lower, axis=-1), 1e-12)
    frames = np.ones(len(flex), dtype=bool) if use is None else use
    flexed = frames & (sine >= FLEXED_FRACTION * np.percentile(sine[frames], 95))
    segment2world = frame_from_axes(upper, segment_second, 2, 0)
    axis_local = normalize(np.einsum("fji,fj->i", segment2world[flexed], flex[flexed]))
    axis: F64 = np.einsum("fij,j->fi", segment2world, axis_local)
    return axis


def cluster_poses(points: F64, weights: F64, iterations: int = 2) -> tuple[F64, F64]:
    """Rigid poses of a marker cluster by weighted least squares (Kabsch), batched over frames.

    points (F, K, 3) world, weights (F, K) (0 for missing samples). The cluster's local shape is
    its mean shape (first the first fully seen frame, then refined ``iterations`` times).
    Returns (cluster2world (F, 3, 3), origin (F, 3)) with ``points ≈ R @ shape + origin``.
    """
    full = np.flatnonzero(weights.min(axis=1) > 0)
    if len(full):  # the fully seen frame whose shape is closest to the typical one
        dist = np.linalg.norm(points[full, :, None] - points[full, None], axis=-1)
        ref_frame = int(full[np.argmin(np.abs(dist - np.median(dist, axis=0)).sum(axis=(1, 2)))])
    else:
        ref_frame = int(np.argmax(weights.sum(axis=1)))
    shape = points[ref_frame] - points[ref_frame].mean(axis=0)
    w = weights[..., None]
    wsum = np.maximum(weights.sum(axis=1), 1e-12)[:, None]
    for _ in range(iterations + 1):
        c_ref = np.einsum("fk,ki->fi", weights, shape) / wsum
        c_cur = (w * points).sum(axis=1) / wsum
        a = shape[None] - c_ref[:, None]
        b = points - c_cur[:, None]
        h = np.einsum("fk,fki,fkj->fij", weights, a, b)
        u, _, vt = np.linalg.svd(h)
        d = np.sign(np.linalg.det(np.swapaxes(vt, -1, -2) @ np.swapaxes(u, -1, -2)))
        fix = np.ones(u.shape[:-1])
        fix[:, 2] = d
        rot = np.swapaxes(vt, -1, -2) @ (fix[:, :, None] * np.swapaxes(u, -1, -2))
        origin = c_cur - np.einsum("fij,fj->fi", rot, c_ref)
        local = np.einsum("fji,fkj->fki", rot, points - origin[:, None])  # R^T (p - o)
        shape = (w * local).sum(axis=0) / np.maximum(weights.sum(axis=0), 1e-12)[:, None]
        shape -= shape.mean(axis=0)
    return rot, origin


def score_centre(parent: tuple[F64, F64], child: tuple[F64, F64], use: BOOL,
                 hinge_prior_in_parent: F64 | None = None,
                 hinge_plane_in_parent: tuple[F64, float] | None = None,
                 hinge_through_in_parent: F64 | None = None) -> tuple[F64, F64, F64]:
    """SCoRE (Ehrig et al. 2006): the point fixed in both segments.

    parent, child : (rotation (F, 3, 3), origin (F, 3)) segment poses; use : (F,) frames to fit.
    For a hinge the point is only defined up to the axis: with ``hinge_prior_in_parent`` (3,),
    when the weakest direction of the normal equations is clearly weaker than the others (by
    :data:`HINGE_RATIO`) and runs across the segment (:data:`HINGE_ACROSS_COS`: along it, it is
    the segment's twist in a joint that is no hinge, and the point nearest the prior would slide
    up the segment), it is dropped from the least-squares solution and the point on it nearest
    the prior is taken; with ``hinge_plane_in_parent`` (unit direction d (3,), offset) instead,
    the point on it with ``d . centre = offset``. ``hinge_through_in_parent`` (3,): a point known
    to lie on the hinge's axis (a landmark on it); the axis keeps SCoRE's direction but passes
    through that point, and the child's centre is refitted to it. Returns (centre in parent
    frame (3,), in child frame (3,), world position (F, 3): the mean of both estimates).
    """
    rp, tp = parent
    rc, tc = child
    a = np.concatenate([rp, -rc], axis=-1)[use]  # (F, 3, 6)
    b = (tc - tp)[use]
    m = np.einsum("fki,fkj->ij", a, a)
    v = np.einsum("fki,fk->i", a, b)
    evals, evecs = np.linalg.eigh(m)
    keep = evals > 1e-9 * evals[-1]
    hinge = (hinge_prior_in_parent is not None or hinge_plane_in_parent is not None) \
        and evals[0] < HINGE_RATIO * evals[1]
    if hinge and hinge_prior_in_parent is not None and hinge_plane_in_parent is None:
        free = evecs @ np.where(keep, (evecs.T @ v) / np.where(keep, evals, 1.0), 0.0)
        up_segment = normalize(hinge_prior_in_parent - free[:3])
        hinge = abs(float(normalize(evecs[:3, 0]) @ up_segment)) < HINGE_ACROSS_COS
    if hinge:
        keep[0] = False
    coeff = np.where(keep, (evecs.T @ v) / np.where(keep, evals, 1.0), 0.0)
    x = evecs @ coeff
    if hinge:
        n = evecs[:, 0]
        n_p = n[:3]
        if hinge_through_in_parent is not None:  # the axis through the landmark, in both frames
            x[:3] = hinge_through_in_parent
            x[3:] = np.mean(np.einsum("fji,fj->fi", rc[use], np.einsum("fij,j->fi", rp[use], x[:3])
                                      + tp[use] - tc[use]), axis=0)
            n = np.concatenate([n_p, np.mean(np.einsum("fji,fj->fi", rc[use],
                                                       np.einsum("fij,j->fi", rp[use], n_p)), axis=0)])
        if hinge_plane_in_parent is not None:
            d, offset = hinge_plane_in_parent
            lam = (offset - float(d @ x[:3])) / float(d @ n_p) if abs(float(d @ n_p)) > 1e-6 else 0.0
        else:
            assert hinge_prior_in_parent is not None
            lam = float(n_p @ (hinge_prior_in_parent - x[:3])) / max(float(n_p @ n_p), 1e-12)
        x = x + lam * n
    c_parent, c_child = x[:3], x[3:]
    world = 0.5 * (np.einsum("fij,j->fi", rp, c_parent) + tp + np.einsum("fij,j->fi", rc, c_child) + tc)
    return c_parent, c_child, world
