"""Far-line pixels of the room's straight edges by the tracer's own bisection
(:func:`far_line_pixels`): the ground truth of far lines in the renders."""

from __future__ import annotations

import numpy as np

from .optics import CameraNumbers, camera_rays, dot, intersect_mirror, lin, mirror_normal, reflect
from .render import rim_box


def reflected_directions(num, pixels):
    """Unit reflected directions of pixels (mirror frame, NaN off the mirror): eqs. 6-15 only."""
    v = lin(camera_rays(num.K, num.D, pixels), num.R.T)
    t = intersect_mirror(num.a, num.b, num.rim, np.broadcast_to(num.C, v.shape), v)
    P = num.C + t[:, None] * v
    with np.errstate(invalid="ignore"):
        d = reflect(v, mirror_normal(num.a, num.b, P))
        return d / np.linalg.norm(d, axis=1, keepdims=True)


def mirror_grid(camera):
    """Integer pixels of the rim's bounding box and their reflected directions (h, w, 3)."""
    num = CameraNumbers(camera)
    lo, hi = rim_box(num)
    xs = np.arange(lo[0], hi[0] + 1)
    ys = np.arange(lo[1], hi[1] + 1)
    gx, gy = np.meshgrid(xs, ys)
    d = reflected_directions(num, np.stack([gx.ravel(), gy.ravel()], axis=1))
    return xs, ys, d.reshape(len(ys), len(xs), 3)


def far_line_pixels(camera, p1, p2, n_points=40, valid=None, margin=2, _grid=None):
    """Pixels on the image of the straight line at infinity through ``p1, p2`` (own tracer).

    The line's directions form the great-circle arc ``alpha p1 + beta p2`` (alpha, beta >= 0)
    of the plane with normal ``n = p1 x p2``. Every integer pixel of the mirror is traced;
    where ``n . d`` changes sign between horizontal or vertical neighbours, the crossing is
    found by bisection on that segment (to 1e-9 px, 30 halvings) and kept if its direction
    lies on the arc.

    Parameters
    ----------
    camera : MisalignedHyperbolicCamera
    p1, p2 : (3,) array_like
        Two points of the line, mirror frame (any unit: only directions count).
    n_points : int
        Points returned, evenly spread along the arc that is seen.
    valid : (h, w) bool ndarray or None
        Pixels where a point may be taken (e.g. the scene is seen around it); points whose
        nearest pixel is not valid, or that lie within ``margin`` px of the frame edge, are
        dropped.

    Returns
    -------
    (M, 2) float64 ndarray
        ``M <= n_points`` pixels, ordered along the line (empty when the line is not seen).
    """
    num = CameraNumbers(camera)
    p1 = np.asarray(p1, np.float64)
    p2 = np.asarray(p2, np.float64)
    nrm = np.cross(p1, p2)
    nrm /= np.linalg.norm(nrm)
    xs, ys, dgrid = _grid if _grid is not None else mirror_grid(camera)

    def side(px):
        return dot(reflected_directions(num, px), nrm)

    f = dot(dgrid.reshape(-1, 3), nrm).reshape(dgrid.shape[:2])
    found = []
    for axis in (0, 1):
        fa = f[:, :-1] if axis == 0 else f[:-1, :]
        fb = f[:, 1:] if axis == 0 else f[1:, :]
        cross = np.isfinite(fa) & np.isfinite(fb) & (np.sign(fa) != np.sign(fb))
        iy, ix = np.nonzero(cross)
        if not len(iy):
            continue
        a = np.stack([xs[ix], ys[iy]], axis=1).astype(np.float64)
        step = np.array([1.0, 0.0]) if axis == 0 else np.array([0.0, 1.0])
        fa0 = fa[iy, ix]
        lo_t = np.zeros(len(a))
        hi_t = np.ones(len(a))
        for _ in range(30):
            mid = 0.5 * (lo_t + hi_t)
            fm = side(a + mid[:, None] * step)
            same = np.sign(fm) == np.sign(fa0)
            lo_t = np.where(same, mid, lo_t)
            hi_t = np.where(same, hi_t, mid)
        found.append(a + (0.5 * (lo_t + hi_t))[:, None] * step)
    if not found:
        return np.zeros((0, 2))
    pts = np.concatenate(found)
    d = reflected_directions(num, pts)
    good = np.isfinite(d[:, 0])
    on_arc = (dot(np.cross(p1, d), nrm) >= 0) & (dot(np.cross(d, p2), nrm) >= 0)
    w, h = num.size
    inside = (
        (pts[:, 0] >= margin)
        & (pts[:, 0] <= w - 1 - margin)
        & (pts[:, 1] >= margin)
        & (pts[:, 1] <= h - 1 - margin)
    )
    keep = good & on_arc & inside
    if valid is not None:
        ri = np.clip(np.round(pts[:, 1]).astype(int), 0, h - 1)
        ci = np.clip(np.round(pts[:, 0]).astype(int), 0, w - 1)
        keep &= np.asarray(valid, bool)[ri, ci]
    pts, d = pts[keep], d[keep]
    if not len(pts):
        return np.zeros((0, 2))
    u1 = p1 / np.linalg.norm(p1)
    ang = np.arctan2(dot(np.cross(u1, d), nrm), dot(d, u1))
    order = np.argsort(ang)
    pts, ang = pts[order], ang[order]
    if len(pts) > n_points:
        pick = np.searchsorted(ang, np.linspace(ang[0], ang[-1], n_points))
        pts = pts[np.unique(np.clip(pick, 0, len(pts) - 1))]
    return pts
