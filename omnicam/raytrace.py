"""Pixel -> ray by ray tracing, and point -> pixel by the exact non-central inverse (eqs. 6-19).

Pure functions over validated arrays: the camera class (:mod:`omnicam.camera`) checks its
parameters once and calls these. Distortion is handled here with OpenCV's point functions;
the per-point work runs in the numba kernels of :mod:`omnicam._kernels`.
"""

from __future__ import annotations

from collections.abc import Callable

import cv2
import numpy as np

from . import _kernels
from ._jit import notice_if_cold, run_chunks
from ._typing import ArrayLike, FloatArray
from .mirror import Mirror

__all__ = [
    "as_points",
    "undistort_normalized",
    "distort_normalized",
    "normalize",
    "to_pixels",
    "trace",
    "trace_normalized",
    "project",
]

# docs/conventions.md: OpenCV's default 5 iterations of undistortPoints leave up to 0.1 px of error
_UNDISTORT_CRITERIA = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 200, 1e-15)


def as_points(
    points: ArrayLike, name: str, dim: int
) -> tuple[FloatArray, Callable[[FloatArray], FloatArray]]:
    """Validate a point array and return ``(pts, restore)``.

    Parameters
    ----------
    points : (N, dim) or (N, 1, dim) array_like, float32 or float64
    name : str
        Argument name used in error messages.
    dim : int
        2 for pixels, 3 for points.

    Returns
    -------
    pts : (N, dim) float64 C-contiguous ndarray
    restore : callable
        Maps an ``(N, k)`` result back to the caller's layout: ``(N, k)`` or ``(N, 1, k)``.
    """
    arr = np.asarray(points)
    if arr.dtype == object or not (
        np.issubdtype(arr.dtype, np.floating) or np.issubdtype(arr.dtype, np.integer)
    ):
        raise ValueError(
            f"{name} must be a float array of shape (N, {dim}) or (N, 1, {dim}), "
            f"got dtype {arr.dtype}"
        )
    if arr.ndim == 2 and arr.shape[1] == dim:
        layout = 2
    elif arr.ndim == 3 and arr.shape[1] == 1 and arr.shape[2] == dim:
        layout = 3
    else:
        raise ValueError(f"{name} must have shape (N, {dim}) or (N, 1, {dim}), got {arr.shape}")
    pts = np.ascontiguousarray(arr.reshape(-1, dim), dtype=np.float64)

    def restore(result: FloatArray) -> FloatArray:
        return result.reshape(-1, 1, result.shape[-1]) if layout == 3 else result

    return pts, restore


def _f64(x: ArrayLike) -> FloatArray:
    """``x`` as a writable C-contiguous float64 array (a copy only if needed): every kernel call
    has the same argument types, so each kernel compiles and caches one signature."""
    return np.require(x, np.float64, ["C_CONTIGUOUS", "WRITEABLE", "ALIGNED"])


def undistort_normalized(pixels: FloatArray, K: FloatArray, D: ArrayLike) -> FloatArray:
    """Pixels -> undistorted normalised coordinates ``(x, y)`` with ``(x, y, 1) ~ X_C``.

    ``inv(K)`` is applied here (so skew counts) and OpenCV undoes ``D`` on an identity camera with
    tight criteria. Pixels that are not finite (NaN, inf) give NaN, silently.
    """
    Kinv = np.linalg.inv(K)
    ok = np.isfinite(pixels).all(axis=1)  # before inv(K): inf * 0 would warn
    out = np.full(pixels.shape, np.nan)
    if ok.any():
        xd = pixels[ok] @ Kinv[:2, :2].T + Kinv[:2, 2]
        src, D = xd.reshape(-1, 1, 2), np.asarray(D, np.float64)
        if hasattr(cv2, "undistortPointsIter"):  # OpenCV 4
            und = cv2.undistortPointsIter(src, np.eye(3), D, None, None, _UNDISTORT_CRITERIA)
        else:  # OpenCV 5 takes the criteria in undistortPoints
            und = cv2.undistortPoints(
                src, np.eye(3), D, R=None, P=None, criteria=_UNDISTORT_CRITERIA
            )
        out[ok] = und.reshape(-1, 2)
    return out


def distort_normalized(xn: FloatArray, K: FloatArray, D: ArrayLike) -> FloatArray:
    """Undistorted normalised coordinates -> pixels (OpenCV's distortion, then ``K`` with skew).

    ``D = (k1, k2, p1, p2[, k3[, k4, k5, k6]])`` is applied in numpy (the formula of
    ``cv2.projectPoints``, with the rational model's radial factor ``(1 + k1 r^2 + k2 r^4 +
    k3 r^6) / (1 + k4 r^2 + k5 r^4 + k6 r^6)``, without its per-call cost, which the chessboard
    adjustment's rim residuals pay thousands of times); longer models (thin prism, tilt) go
    through ``cv2.projectPoints``."""
    D = np.ravel(np.asarray(D, np.float64))
    ok = np.isfinite(xn).all(axis=1)
    out = np.full_like(xn, np.nan)
    if ok.any() and len(D) in (4, 5, 8):
        x, y = xn[ok, 0], xn[ok, 1]
        k1, k2, p1, p2 = D[:4]
        k3 = D[4] if len(D) >= 5 else 0.0
        r2 = x * x + y * y
        radial = 1.0 + r2 * (k1 + r2 * (k2 + r2 * k3))
        if len(D) == 8:  # the rational model's denominator
            radial = radial / (1.0 + r2 * (D[5] + r2 * (D[6] + r2 * D[7])))
        xd = x * radial + 2.0 * p1 * x * y + p2 * (r2 + 2.0 * x * x)
        yd = y * radial + p1 * (r2 + 2.0 * y * y) + 2.0 * p2 * x * y
        out[ok, 0] = K[0, 0] * xd + K[0, 1] * yd + K[0, 2]
        out[ok, 1] = K[1, 1] * yd + K[1, 2]
    elif ok.any():
        obj = np.concatenate([xn[ok], np.ones((int(ok.sum()), 1))], axis=1)
        xd, _ = cv2.projectPoints(
            obj.reshape(-1, 1, 3), np.zeros(3), np.zeros(3), np.eye(3), np.asarray(D, np.float64)
        )
        xd = xd.reshape(-1, 2)
        out[ok] = xd @ K[:2, :2].T + K[:2, 2]
    return out


def normalize(pixels: FloatArray, K: FloatArray, D: ArrayLike | None = None) -> FloatArray:
    """Pixels ``(N, 2)`` -> undistorted normalised coordinates: ``inv(K)`` (with skew), then
    ``D`` undone (:func:`undistort_normalized`; None: no distortion)."""
    if D is None:
        Ki = np.linalg.inv(K)
        out: FloatArray = pixels @ Ki[:2, :2].T + Ki[:2, 2]
        return out
    return undistort_normalized(np.ascontiguousarray(pixels), K, D)


def to_pixels(xn: FloatArray, K: FloatArray, D: ArrayLike | None = None) -> FloatArray:
    """Undistorted normalised coordinates ``(N, 2)`` -> pixels: ``D``'s distortion (None:
    none), then ``K`` with skew (eq. 6); the inverse of :func:`normalize`."""
    if D is None:
        out: FloatArray = xn @ K[:2, :2].T + K[:2, 2]
        return out
    return distort_normalized(xn, K, D)


def trace(
    pixels: FloatArray,
    K: FloatArray,
    D: FloatArray | None,
    R: FloatArray,
    C: FloatArray,
    mirror: Mirror,
) -> tuple[FloatArray, FloatArray]:
    """Reflected rays of pixels (eqs. 6-19): ``(origins, directions)``, each ``(N, 3)``.

    Parameters
    ----------
    pixels : (N, 2) float64 ndarray
    K : (3, 3) ndarray
        Camera matrix (skew allowed).
    D : ndarray or None
        OpenCV distortion coefficients.
    R : (3, 3) ndarray
        Mirror -> camera rotation (eq. 29).
    C : (3,) ndarray
        Camera centre in the mirror frame (``F_M`` of eq. 17).
    mirror : HyperbolicMirror or AsphericMirror

    Returns
    -------
    origins : (N, 3) ndarray
        Reflection points ``P_M`` on the mirror.
    directions : (N, 3) ndarray
        Unit reflected directions ``V_Mout``. Rows of pixels that do not see the mirror are NaN.
    """
    if D is None:
        uv, Kinv = pixels, np.linalg.inv(K)
    else:
        uv, Kinv = undistort_normalized(pixels, K, D), np.eye(3)
    n = uv.shape[0]
    origins = np.empty((n, 3))
    directions = np.empty((n, 3))
    notice_if_cold(_kernels.trace_rays)
    run_chunks(
        _kernels.trace_rays,
        n,
        _f64(uv),
        _f64(Kinv),
        _f64(R),
        _f64(C),
        mirror.kernel_params(),
        origins,
        directions,
        min_chunk=4096,
    )
    return origins, directions


def trace_normalized(
    xn: ArrayLike, R: ArrayLike, C: ArrayLike, mirror: Mirror
) -> tuple[FloatArray, FloatArray]:
    """Reflected rays of undistorted normalised coordinates, in numpy: the one reference tracer.

    The calibration code traces a few hundred points per evaluation under trial postures, where
    a numba call's overhead and the kernel's pixel interface do not fit; this is the same
    model as :func:`trace` (eqs. 6-19) written with the mirror's vectorised methods
    (:class:`~omnicam.mirror.HyperbolicMirror`, :class:`~omnicam.asphere.AsphericMirror`).

    Parameters
    ----------
    xn : (N, 2) float64 ndarray
        Undistorted normalised image coordinates ``K^-1 x`` (first two components).
    R : (3, 3) ndarray
        Mirror -> camera rotation (eq. 29).
    C : (3,) ndarray
        Camera centre in the mirror frame (eq. 17).
    mirror : HyperbolicMirror or AsphericMirror

    Returns
    -------
    origins, directions : (N, 3) float64 ndarrays
        Reflection points (eqs. 8-12) and unit reflected directions (eqs. 14-15); NaN rows
        for rays that miss the mirror inside the rim.
    """
    xn = np.asarray(xn, np.float64).reshape(-1, 2)
    V = np.column_stack([xn, np.ones(len(xn))]) @ np.asarray(R, np.float64)  # R^T x~ (eq. 16)
    V /= np.linalg.norm(V, axis=1, keepdims=True)
    C = np.asarray(C, np.float64)
    P = mirror.intersect(np.broadcast_to(C, V.shape), V)  # eqs. 8-12
    return P, mirror.reflect(V, mirror.unit_normal(P))  # eqs. 14-15


def project(
    points: FloatArray,
    at_infinity: bool,
    K: FloatArray,
    D: FloatArray | None,
    R: FloatArray,
    t: FloatArray,
    C: FloatArray,
    mirror: Mirror,
) -> FloatArray:
    """Exact non-central projection of points (or directions) to pixels, ``(N, 2)``.

    For each point the reflection point on the mirror is found by Newton's method on Fermat's
    path length (see :func:`omnicam._kernels.raytrace.reflection_point`) and imaged by the pinhole
    (eq. 6) and OpenCV's distortion. Points the rig cannot see give NaN.
    """
    out = np.empty((points.shape[0], 2))
    Kk = K if D is None else np.eye(3)
    notice_if_cold(_kernels.project_points)
    run_chunks(
        _kernels.project_points,
        len(out),
        _f64(points),
        bool(at_infinity),
        _f64(R),
        _f64(t),
        _f64(C),
        mirror.kernel_params(),
        _f64(Kk),
        out,
        min_chunk=256,
    )
    if D is not None:
        out = distort_normalized(out, K, D)
    return out
