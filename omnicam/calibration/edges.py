"""Subpixel edges in images: edge points sampled along curve normals.

Used by the rim detector (:mod:`.rim`) and the camera's-reflection detector: the image gradient
is sampled along the normals of a predicted ellipse, and each normal's strongest (or outermost)
edge is located to a fraction of a pixel.
"""

from __future__ import annotations

import cv2
import numpy as np

from .._typing import FloatArray
from .ellipse import axes_angle

__all__ = ["edge_points_along_normals"]


def edge_points_along_normals(
    G, center, S, half_width, step=0.25, outermost=False, centroid=0.0, absolute=False
) -> tuple[FloatArray, int]:
    """Subpixel rim points: strongest outward intensity drop along the ellipse normals.

    The ellipse is sampled every pixel of arc length; along each outward normal the smoothed
    image ``G`` is sampled (bilinear) over ``+-half_width`` px and differentiated; the maximum of
    the outward drop is located by a parabola through the log of the three samples around it.
    With ``centroid > 0`` that position is then refined to the centroid of the drop under a
    triangular window of that half-width centred on it (four fixed-point steps): the drop of an
    edge blurred by any symmetric kernel is symmetric about the edge, so the centroid is unbiased,
    whereas the peak of a bilinearly interpolated profile is pulled towards pixel centres
    (~0.15 px per point against ~0.02 px with the centroid on rendered rims). Profiles that
    leave the image, whose maximum lies at the window ends or that find no drop are dropped.

    With ``absolute`` a rise counts as much as a drop (edges of either polarity).

    Returns ``(points, n_tried)``: the (M, 2) edge points and the number of normals whose whole
    profile was inside the image.

    The profiles come from one ``cv2.remap`` of all normals: scikit-image's nearest piece,
    ``measure.profile_line``, samples one line per call at fixed 1 px steps (3000 normals of a
    1080p rim: 0.5 ms against 2.1 s; section 7 of ``python benchmarks/bench_ellipse_skimage.py``).
    """
    h, w = G.shape
    axes, _ = axes_angle(S)
    n_pts = int(max(64, min(20000, 2 * np.pi * axes[0])))
    tt = np.linspace(0.0, 2 * np.pi, n_pts, endpoint=False)
    u = np.stack([np.cos(tt), np.sin(tt)], axis=1)
    e = center + u @ S.T
    der = np.stack([-np.sin(tt), np.cos(tt)], axis=1) @ S.T
    nrm = np.stack([der[:, 1], -der[:, 0]], axis=1)
    nrm /= np.linalg.norm(nrm, axis=1, keepdims=True)
    tau = np.arange(-half_width - step, half_width + 1.5 * step, step)
    margin = 2.0
    inside = np.ones(len(e), bool)
    for end in (tau[0], tau[-1]):  # a segment is inside the (convex) frame iff its ends are
        q = e + end * nrm
        inside &= (
            (q[:, 0] >= margin)
            & (q[:, 0] <= w - 1 - margin)
            & (q[:, 1] >= margin)
            & (q[:, 1] <= h - 1 - margin)
        )
    if inside.sum() < 6:
        return np.empty((0, 2)), 0
    e, nrm = e[inside], nrm[inside]
    tau32 = tau.astype(np.float32)
    mx = e[:, :1].astype(np.float32) + nrm[:, :1].astype(np.float32) * tau32
    my = e[:, 1:].astype(np.float32) + nrm[:, 1:].astype(np.float32) * tau32
    prof = cv2.remap(G, mx, my, cv2.INTER_LINEAR).astype(np.float64)
    drop = (prof[:, :-2] - prof[:, 2:]) / (2 * step)  # outward drop at tau[1:-1]
    if absolute:  # a step of either sign (a rim whose contrast changes sign along it)
        drop = np.abs(drop)
    if outermost:
        # the outermost local maximum at least half as strong as the strongest one
        dmax = drop.max(axis=1, keepdims=True)
        locmax = np.zeros_like(drop, bool)
        locmax[:, 1:-1] = (drop[:, 1:-1] >= drop[:, :-2]) & (drop[:, 1:-1] > drop[:, 2:])
        cand = locmax & (drop >= 0.5 * dmax)
        k = np.where(
            cand.any(axis=1),
            drop.shape[1] - 1 - np.argmax(cand[:, ::-1], axis=1),
            np.argmax(drop, axis=1),
        )
    else:
        k = np.argmax(drop, axis=1)
    rows = np.arange(len(k))
    ok = (k > 0) & (k < drop.shape[1] - 1)
    k = np.clip(k, 1, drop.shape[1] - 2)
    d0, d1, d2 = drop[rows, k - 1], drop[rows, k], drop[rows, k + 1]
    strength = d1
    pos = d0 > 0
    pos &= (d2 > 0) & (d1 > 0)  # logs of positive drops only
    l0, l1, l2 = (np.log(np.where(pos, v, 1.0)) for v in (d0, d1, d2))
    den_log = l0 - 2 * l1 + l2
    den_lin = d0 - 2 * d1 + d2
    off = np.where(
        pos & (den_log < 0),
        0.5 * (l0 - l2) / np.where(den_log < 0, den_log, -1.0),
        0.5 * (d0 - d2) / np.where(den_lin < 0, den_lin, -1.0),
    )
    off = np.clip(off, -1.0, 1.0)
    where = tau[1:-1][k] + off * step
    ok &= strength > 0
    if centroid > 0:
        tc = tau[1:-1]
        pos_drop = np.maximum(drop, 0.0)
        for _ in range(4):
            wgt = np.maximum(0.0, 1.0 - np.abs(tc[None, :] - where[:, None]) / centroid) * pos_drop
            total = wgt.sum(axis=1)
            where = np.where(total > 0, (wgt @ tc) / np.where(total > 0, total, 1.0), where)
        ok &= (where - centroid >= tc[0]) & (where + centroid <= tc[-1])
    return e[ok] + where[ok, None] * nrm[ok], int(inside.sum())
