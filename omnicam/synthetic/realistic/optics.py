"""The pure math of the independent tracer, sharing nothing with the estimator: the camera's
numbers, camera rays (eq. 6, ``D`` undone by OpenCV on an identity camera), the first hit on the
mirror sheet (eqs. 1, 8-12), its normal (eq. 14) and the reflection (eq. 15); small linear
algebra without BLAS (an (N, 3) @ (3, 3) product is slow under load)."""

from __future__ import annotations

import math

import cv2
import numpy as np

_CRITERIA = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 100, 1e-14)


def lin(v, M):
    """``v @ M.T`` for (N, k) ``v`` and (m, k) ``M``, column by column."""
    M = np.asarray(M, np.float64)
    out = v[:, :1] * M[:, 0]
    for j in range(1, M.shape[1]):
        out = out + v[:, j : j + 1] * M[:, j]
    return out


def dot(v, n):
    """``v @ n`` for (N, 3) ``v`` and a (3,) vector ``n``."""
    return v[:, 0] * n[0] + v[:, 1] * n[1] + v[:, 2] * n[2]


# -- the camera's numbers --------------------------------------------------------------------
class CameraNumbers:
    """The truth camera read as numbers only (no method of it is called)."""

    def __init__(self, camera):
        for name in ("K", "R", "tvec", "mirror", "image_size"):
            if not hasattr(camera, name):
                raise ValueError(f"camera must be a MisalignedHyperbolicCamera, got {camera!r}")
        if camera.image_size is None:
            raise ValueError("camera has no image_size; construct it with image_size=(w, h)")
        self.K = np.array(camera.K, np.float64)
        self.Kinv = np.linalg.inv(self.K)
        self.D = None if camera.D is None else np.array(camera.D, np.float64).ravel()
        self.R = np.array(camera.R, np.float64)
        self.t = np.array(camera.tvec, np.float64)
        self.C = -self.R.T @ self.t  # camera centre in the mirror frame (eq. 17)
        self.a = float(camera.mirror.a)
        self.b = float(camera.mirror.b)
        self.rim = float(camera.mirror.rim_radius)
        self.z_rim = self.b * math.sqrt(1.0 + (self.rim / self.a) ** 2)
        self.size = tuple(int(v) for v in camera.image_size)


# -- the pure math: camera rays, the mirror, the reflection ------------------------------------
def camera_rays(K, D, pixels):
    """Unit camera rays ``V_C`` of pixels (camera frame), eq. 6 with OpenCV's distortion undone.

    Parameters
    ----------
    K : (3, 3) array_like
        Camera matrix (skew allowed: ``inv(K)`` is applied here).
    D : array_like or None
        OpenCV distortion coefficients, undone with ``cv2.undistortPointsIter`` on an identity
        camera with tight criteria (100 iterations, 1e-14).
    pixels : (N, 2) array_like

    Returns
    -------
    (N, 3) float64 ndarray
    """
    pix = np.asarray(pixels, np.float64).reshape(-1, 2)
    Kinv = np.linalg.inv(np.asarray(K, np.float64))
    xn = lin(pix, Kinv[:2, :2]) + Kinv[:2, 2]
    if D is not None:
        src = np.ascontiguousarray(xn.reshape(-1, 1, 2))
        Dn = np.asarray(D, np.float64)
        if hasattr(cv2, "undistortPointsIter"):  # OpenCV 4
            und = cv2.undistortPointsIter(src, np.eye(3), Dn, None, None, _CRITERIA)
        else:  # OpenCV 5 takes the criteria in undistortPoints
            und = cv2.undistortPoints(src, np.eye(3), Dn, R=None, P=None, criteria=_CRITERIA)
        xn = und.reshape(-1, 2)
    v = np.concatenate([xn, np.ones((len(xn), 1))], axis=1)
    return v / np.linalg.norm(v, axis=1, keepdims=True)


def intersect_mirror(a, b, rim, origins, dirs):
    """First hit of rays ``o + t v`` (t > 0) on the sheet ``Z > 0`` of eq. 1, inside the rim.

    Solves ``A t^2 + 2 B t + G = 0`` (eqs. 8-11) with
    ``A = (vx^2 + vy^2)/a^2 - vz^2/b^2``, ``B = (ox vx + oy vy)/a^2 - oz vz/b^2``,
    ``G = (ox^2 + oy^2)/a^2 - oz^2/b^2 + 1``, keeping the smallest positive root with
    ``Z > 0`` (eq. 12's choice for a ray from outside the sheet).

    Returns
    -------
    t : (N,) float64 ndarray
        NaN where the ray misses the sheet or hits it outside the rim.
    """
    o = np.asarray(origins, np.float64)
    v = np.asarray(dirs, np.float64)
    ia2, ib2 = 1.0 / (a * a), 1.0 / (b * b)
    A = (v[:, 0] ** 2 + v[:, 1] ** 2) * ia2 - v[:, 2] ** 2 * ib2
    B = (o[:, 0] * v[:, 0] + o[:, 1] * v[:, 1]) * ia2 - o[:, 2] * v[:, 2] * ib2
    G = (o[:, 0] ** 2 + o[:, 1] ** 2) * ia2 - o[:, 2] ** 2 * ib2 + 1.0
    disc = B * B - A * G
    with np.errstate(invalid="ignore", divide="ignore"):
        sq = np.sqrt(disc)
        q = -(B + np.copysign(sq, B))  # stable roots: q / A and G / q
        t1 = q / A
        t2 = G / q
    best = np.full(len(o), np.inf)
    for t in (t1, t2):
        with np.errstate(invalid="ignore"):
            z = o[:, 2] + t * v[:, 2]
            ok = np.isfinite(t) & (t > 0) & (z > 0)
        best = np.where(ok & (t < best), t, best)
    with np.errstate(invalid="ignore"):
        X = o + best[:, None] * v
        inside = (X[:, 0] ** 2 + X[:, 1] ** 2 <= rim * rim) & np.isfinite(best)
    return np.where(inside & (disc >= 0), best, np.nan)


def mirror_normal(a, b, points):
    """Unit normal of eq. 1 at ``points``: the gradient ``(X/a^2, Y/a^2, -Z/b^2)`` (eq. 14),
    normalised (docs/conventions.md erratum to eq. 15)."""
    p = np.asarray(points, np.float64)
    n = np.stack([p[:, 0] / (a * a), p[:, 1] / (a * a), -p[:, 2] / (b * b)], axis=1)
    return n / np.linalg.norm(n, axis=1, keepdims=True)


def reflect(dirs, normals):
    """Mirror reflection ``V_out = V - 2 N (N, V)`` (eq. 15, unit ``N``)."""
    v = np.asarray(dirs, np.float64)
    n = np.asarray(normals, np.float64)
    return v - 2.0 * np.einsum("ij,ij->i", n, v)[:, None] * n
