"""A chessboard's object points and its pose from the rays of its corners."""

from __future__ import annotations

import cv2
import numpy as np
from scipy.optimize import least_squares

from .._typing import FloatArray
from ..gauge import perpendicular_basis
from .intrinsics import check_pattern_size

__all__ = ["board_pose_from_rays", "nearest_point", "object_points", "rodrigues", "start_viewpoint"]

#: Spacing (px) of the pixel grid whose rays give the boards' start viewpoint.
VIEWPOINT_GRID_PX = 8


def object_points(pattern_size, square_size) -> FloatArray:
    """OpenCV's object points of a board: ``(cols * rows, 3)``, ``(i s, j s, 0)`` row by row."""
    cols, rows = check_pattern_size(pattern_size)
    obj = np.zeros((rows * cols, 3))
    obj[:, :2] = np.mgrid[0:cols, 0:rows].T.reshape(-1, 2) * float(square_size)
    return obj


def rodrigues(rvec) -> np.ndarray:
    """The rotation matrix of a Rodrigues vector (``cv2.Rodrigues``)."""
    return cv2.Rodrigues(np.asarray(rvec, np.float64).reshape(3, 1))[0]


def nearest_point(origins, directions) -> FloatArray:
    """The point nearest, in mean squared distance, to the rays ``origins + s directions``
    (unit directions): with ``M_i = I - d_i d_i^T``, ``(sum M_i) p = sum M_i P_i``."""
    A = len(directions) * np.eye(3) - directions.T @ directions
    rhs = origins.sum(axis=0) - directions.T @ np.einsum("ij,ij->i", directions, origins)
    return np.linalg.solve(A, rhs)


def start_viewpoint(camera) -> FloatArray:
    """The viewpoint of the boards' start poses: the point nearest to the rays of the pixels
    of a :data:`VIEWPOINT_GRID_PX` grid over the rim's image that see the mirror (the
    camera's ``best_fit_viewpoint`` takes every pixel, at about 64 times the cost; the start
    pose of :func:`board_pose_from_rays` is refined on the rays themselves)."""
    rim = camera.rim_image_points(360)
    lo, hi = rim.min(axis=0), rim.max(axis=0)
    u, v = np.meshgrid(
        np.arange(lo[0], hi[0], VIEWPOINT_GRID_PX), np.arange(lo[1], hi[1], VIEWPOINT_GRID_PX)
    )
    P, d = camera.unproject(np.stack([u.ravel(), v.ravel()], axis=1))
    ok = np.isfinite(d).all(axis=1)
    if ok.sum() < 3:
        return np.asarray(camera.best_fit_viewpoint()[0], np.float64)
    return nearest_point(P[ok], d[ok])


def board_pose_from_rays(
    origins, directions, obj, viewpoint
) -> tuple[FloatArray, FloatArray, float]:
    """A board's pose ``(rvec_b, tvec_b)`` from its corners' reflected rays (non-central PnP).

    Start: the central approximation from ``viewpoint`` (a virtual pinhole looking along the
    mean ray, ``cv2.solvePnP`` with IPPE on the rays' normalised coordinates); then the pose
    that minimises the distances of the board points ``R X_b + t`` to their rays
    ``P_i + s d_i`` (``scipy.optimize.least_squares``).

    Parameters
    ----------
    origins, directions : (N, 3) ndarray
        Rays in the mirror frame (finite, unit directions).
    obj : (N, 3) ndarray
        Object points on the board's ``z = 0`` plane.
    viewpoint : (3,) ndarray

    Returns
    -------
    rvec, tvec : (3,) float64 ndarray
    rms : float
        RMS point-to-ray distance (mirror units).
    """
    m = directions.mean(axis=0)
    m /= np.linalg.norm(m)
    b1, b2 = perpendicular_basis(m)
    Rv = np.stack([b1, b2, m])  # mirror -> virtual camera
    dv = directions @ Rv.T
    xn = (dv[:, :2] / dv[:, 2:3]).reshape(-1, 1, 2)
    ok, rp, tp = cv2.solvePnP(obj.reshape(-1, 1, 3), xn, np.eye(3), None, flags=cv2.SOLVEPNP_IPPE)
    if not ok:
        ok, rp, tp = cv2.solvePnP(obj.reshape(-1, 1, 3), xn, np.eye(3), None)
    Rb = Rv.T @ rodrigues(rp.ravel())
    tb = Rv.T @ tp.ravel() + viewpoint

    def resid(x):
        X = obj @ rodrigues(x[:3]).T + x[3:]
        w = X - origins
        return (w - directions * np.einsum("ij,ij->i", w, directions)[:, None]).ravel()

    x0 = np.concatenate([cv2.Rodrigues(Rb)[0].ravel(), tb])
    sol = least_squares(resid, x0, method="lm", xtol=1e-15, ftol=1e-15, gtol=1e-15)
    r = resid(sol.x)
    return sol.x[:3].copy(), sol.x[3:].copy(), float(np.sqrt(np.mean(r * r) * 3))
