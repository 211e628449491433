"""The camera's own reflection: a circle coaxial with the optical axis (the model and its fit).

The camera and its lens are bodies of revolution about the optical axis. Seen in the mirror, the
outline of their reflection is formed by one circle of the body (the front edge of the lens
barrel or of the body): radius ``r`` at the axial distance ``z`` from the camera centre along
the camera's +z axis (docs/conventions.md, "The camera's own reflection"). An outline pixel ``u``
lies on it exactly when its reflected ray ``(P(u), V(u))`` (eqs. 6-19) passes through that
circle. In the camera frame (``P_c = R P + t``, ``V_c = R V``) the ray meets the circle's plane
``z_c = z`` at ``X = P_c + s V_c``, ``s = (z - P_c,z) / V_c,z > 0``, and

    rho(u) = sqrt(X_x^2 + X_y^2),        residual(u) = (rho(u) - r) / |grad_u rho|

is the radial distance in that plane converted to pixels by the local derivative (so it is, to
first order, the pixel distance from ``u`` to the predicted outline). It is exactly zero at the
true posture on exact data. ``r`` and ``z`` are nuisance parameters; either may be known. For a
nearly central rig the reflected rays almost meet in one point (the outer focus), so only
``r / (2c - z)`` is well determined: ``z`` is then fitted with a weak pull towards its start
(the selection's best fit), which costs nothing in the posture.

The **self-reflection pixel** is where the camera sees itself: the pinhole image of the mirror
point nearest to the camera centre ``C`` (Fermat with the scene point ``X = C``). It moves by
about twice the mirror's tilt, the direction the rim ellipse pins worst.

Functions: :func:`self_reflection_point`, :func:`self_reflection_pixel`, :func:`plane_radius`,
:func:`fit_circle` (``r`` in closed form, ``z`` by a bounded 1-D search), :func:`outline_pixels`
(the exact outline of a circle for a camera). The detection in an image,
:func:`detect_reflection` (image -> :class:`ReflectionFit`), lives in :mod:`.reflection_detect`
and :mod:`.reflection_silhouette`; both names are re-exported here.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np
from scipy.optimize import minimize_scalar

from .._typing import FloatArray
from ..mirror import HyperbolicMirror
from ..raytrace import distort_normalized
from .reflection_detect import detect_reflection
from .reflection_silhouette import ReflectionFit

__all__ = [
    "ReflectionCircle",
    "ReflectionFit",
    "self_reflection_point",
    "self_reflection_pixel",
    "plane_radius",
    "fit_circle",
    "outline_pixels",
    "detect_reflection",
]


#: :func:`fit_circle` seeks ``z`` up to this fraction of the camera's distance to the mirror
#: vertex (a lens barrel may reach most of the way towards the mirror), on a grid of ``Z_GRID``
#: values refined by Brent.
Z_MAX_FRACTION = 0.9
Z_GRID = 25


@dataclasses.dataclass(frozen=True)
class ReflectionCircle:
    """A circle coaxial with the optical axis: radius ``r`` at axial distance ``z`` (camera frame,
    the mirror's length unit), and the RMS outline residual (px) of the fit that produced it."""

    r: float
    z: float
    rms: float = math.nan


def behind_depth(mirror, vertex) -> float:
    """How far behind the camera centre the reflection's circle may lie (mirror units): ``c /
    2`` for a hyperboloid; for any other mirror half the camera's distance ``vertex`` to the
    mirror's vertex (about ``c / 2`` for a hyperboloid's aligned rig too)."""
    if isinstance(mirror, HyperbolicMirror):
        return 0.5 * mirror.c
    return 0.5 * float(vertex)


def _surface(mirror):
    """``(Z(q), dZ/dq(q))`` of the mirror's surface over ``q = (X, Y)``."""
    if isinstance(mirror, HyperbolicMirror):
        a2, b2 = mirror.a**2, mirror.b**2

        def hyperboloid(q):  # Z = b sqrt(1 + (X^2 + Y^2) / a^2)  (eq. 1)
            Z = math.sqrt(b2 * (1.0 + (q @ q) / a2))
            return Z, b2 * q / (a2 * Z)

        return hyperboloid

    def asphere(q):  # Z = vertex_z + sag(rho); the normal is (dZ/dX, dZ/dY, -1)
        Z = float(mirror.surface_z(q[0], q[1]))
        return Z, mirror.normal(np.array([q[0], q[1], Z]))[:2]

    return asphere


def self_reflection_point(mirror, C, iters=20) -> FloatArray:
    """The mirror point nearest to ``C`` (mirror frame): where the camera sees itself.

    Newton's method on ``f(X, Y) = |P(X, Y) - C|^2`` with ``P = (X, Y, Z(X, Y))`` on the mirror
    (the hyperboloid's sheet ``Z = b sqrt(1 + (X^2 + Y^2) / a^2)``, eq. 1, or any mirror of
    revolution's surface), started below ``C`` on the surface.

    Returns
    -------
    (3,) float64 ndarray
    """
    surface = _surface(mirror)
    scale = mirror.a if isinstance(mirror, HyperbolicMirror) else mirror.rim_radius
    C = np.asarray(C, np.float64)
    q = C[:2].copy()

    def grad(q):
        Z, Zq = surface(q)  # Z and dZ/d(X, Y)
        return (q - C[:2]) + (Z - C[2]) * Zq

    for _ in range(iters):
        g = grad(q)
        h = 1e-6 * max(1.0, float(np.abs(q).max()))
        H = np.stack([(grad(q + h * e) - g) / h for e in np.eye(2)], axis=1)
        step = np.linalg.solve(H, g)
        q = q - step
        if float(np.abs(step).max()) < 1e-13 * max(1.0, scale):
            break
    return np.array([q[0], q[1], surface(q)[0]])


def self_reflection_pixel(mirror, R, t, K, D=None) -> FloatArray:
    """The pixel where the camera sees itself under the posture ``(R, t)`` (distorted with ``D``).

    Returns
    -------
    (2,) float64 ndarray
    """
    C = -R.T @ t  # F_M (eq. 17)
    P = self_reflection_point(mirror, C)
    Xc = R @ P + t
    xn = Xc[:2] / Xc[2]
    if D is not None:
        return distort_normalized(xn[None], K, D)[0]  # distorted, then K
    return K[:2, :2] @ xn + K[:2, 2]


def _rays_camera(mirror, R, t, xn) -> tuple[FloatArray, FloatArray]:
    """Reflected rays ``(P_c, V_c)`` in the camera frame of normalised coordinates (eqs. 6-19)."""
    C = -R.T @ t  # F_M (eq. 17)
    V = np.concatenate([xn, np.ones((len(xn), 1))], axis=1) @ R  # V_M = R^T V_C (eq. 16)
    V /= np.linalg.norm(V, axis=1, keepdims=True)
    P = mirror.intersect(C, V)  # eqs. 8-12
    W = mirror.reflect(V, mirror.unit_normal(P))  # eqs. 14-15
    return P @ R.T + t, W @ R.T


def _radius_in_plane(Pc, Vc, z):
    """``rho`` where each ray crosses ``z_c = z`` (NaN if it does not, going forward)."""
    with np.errstate(divide="ignore", invalid="ignore"):
        s = (z - Pc[:, 2]) / Vc[:, 2]
        X = Pc[:, :2] + s[:, None] * Vc[:, :2]
        rho = np.hypot(X[:, 0], X[:, 1])
    return np.where(s > 0, rho, np.nan)


def plane_radius(
    mirror, R, t, xn, z, Kinv2=None, h=1e-2
) -> FloatArray | tuple[FloatArray, FloatArray]:
    """``rho(u)`` of each pixel's reflected ray in the plane ``z_c = z``, and ``|grad_u rho|``.

    Parameters
    ----------
    mirror : HyperbolicMirror
    R, t : (3, 3), (3,) ndarray
        Mirror posture (``X_cam = R X_mirror + t``).
    xn : (N, 2) ndarray
        Undistorted normalised coordinates of the outline pixels.
    z : float
        Axial distance of the circle's plane from the camera centre.
    Kinv2 : (2, 2) ndarray, optional
        ``inv(K)[:2, :2]``; with it the pixel gradient is also returned (central differences
        of ``h`` px).

    Returns
    -------
    rho : (N,) ndarray
        NaN where the ray misses the mirror or does not reach the plane.
    g : (N,) ndarray
        ``|grad_u rho|`` (only with ``Kinv2``).
    """
    Pc, Vc = _rays_camera(mirror, R, t, xn)
    rho = _radius_in_plane(Pc, Vc, z)
    if Kinv2 is None:
        return rho
    grads = []
    for k in range(2):
        d = h * Kinv2[:, k]
        hi = _radius_in_plane(*_rays_camera(mirror, R, t, xn + d), z)
        lo = _radius_in_plane(*_rays_camera(mirror, R, t, xn - d), z)
        grads.append((hi - lo) / (2 * h))
    return rho, np.hypot(grads[0], grads[1])


def _closed_form_r(rho, g):
    ok = np.isfinite(rho) & np.isfinite(g) & (g > 0)
    if ok.sum() < 3:
        return math.nan, math.inf
    w = 1.0 / g[ok] ** 2
    r = float((w * rho[ok]).sum() / w.sum())
    res = (rho[ok] - r) / g[ok]
    return r, float(np.sqrt(np.mean(res * res)))


def fit_circle(
    mirror, R, t, xn, Kinv2, r=None, z=None, min_fraction=0.8, h=1e-2
) -> ReflectionCircle:
    """The coaxial circle that best explains an outline under one posture.

    ``r`` minimises ``sum(((rho - r) / g)^2)`` in closed form (``g = |grad_u rho|``, central
    differences of ``h`` px, at each ``z``); ``z`` (unless given) is found on a grid of
    ``Z_GRID`` values between ``-c / 2`` and ``Z_MAX_FRACTION`` of the camera's distance to the
    mirror vertex (the circle is part of the camera, below the mirror), refined by a bounded
    1-D search (Brent) in the best grid cell.

    Returns
    -------
    ReflectionCircle
        ``rms`` is the RMS pixel residual; ``inf`` when fewer than ``min_fraction`` of the
        outline's rays reach the plane (the outline cannot be the camera's under this posture).
    """
    n = len(xn)
    rays = [_rays_camera(mirror, R, t, xn)]
    for k in range(2):
        d = h * Kinv2[:, k]
        rays += [_rays_camera(mirror, R, t, xn + d), _rays_camera(mirror, R, t, xn - d)]
    vertex = float(np.linalg.norm(R @ np.array([0.0, 0.0, mirror.vertex_z]) + t))
    z_lo, z_hi = -behind_depth(mirror, vertex), Z_MAX_FRACTION * vertex

    def rms_at(zz):
        rho, xp, xm, yp, ym = (_radius_in_plane(P, V, zz) for P, V in rays)
        g = np.hypot((xp - xm) / (2 * h), (yp - ym) / (2 * h))
        ok = np.isfinite(rho) & np.isfinite(g) & (g > 0)
        if ok.sum() < max(3, min_fraction * n):
            return math.nan, math.inf
        if r is None:
            return _closed_form_r(rho, g)
        return float(r), float(np.sqrt(np.mean(((rho[ok] - r) / g[ok]) ** 2)))

    z0 = 0.0 if z is None else float(z)
    if z is None:
        # the RMS over z has local minima (an outline of a few px fits several circles to a
        # px): a grid first, then Brent in the best grid cell
        grid = np.linspace(z_lo, z_hi, Z_GRID)
        k = int(np.argmin([min(rms_at(zz)[1], 1e30) for zz in grid]))
        best = minimize_scalar(
            lambda zz: min(rms_at(zz)[1], 1e30),
            bounds=(grid[max(k - 1, 0)], grid[min(k + 1, Z_GRID - 1)]),
            method="bounded",
            options={"xatol": 1e-3 * mirror.rim_radius},
        )
        z0 = float(best.x) if rms_at(best.x)[1] <= rms_at(grid[k])[1] else float(grid[k])
    rr, e = rms_at(z0)
    return ReflectionCircle(r=float(rr), z=z0, rms=float(e))


def outline_pixels(camera, r, z, n=90, tol=1e-10) -> tuple[FloatArray, FloatArray]:
    """Exact outline of the circle ``(r, z)`` as the camera sees it in the mirror.

    Along ``n`` rays (evenly spaced angles) from the self-reflection pixel, the pixel whose
    reflected ray crosses the plane ``z_c = z`` at the radius ``r``, by bisection (``rho`` grows
    along each ray from its value at the self-reflection pixel).

    Returns
    -------
    outline : (n, 2) float64 ndarray
        Pixels (distorted, as seen); NaN where the outline leaves the mirror.
    centre : (2,) float64 ndarray
        The self-reflection pixel.
    """
    R, t = camera.R, camera.tvec
    u0 = self_reflection_pixel(camera.mirror, R, t, camera.K, camera.D)

    def rho(u):
        P, V = camera.unproject(u)
        return _radius_in_plane(P @ R.T + t, V @ R.T, z)

    ang = np.linspace(0.0, 2.0 * np.pi, int(n), endpoint=False)
    e = np.stack([np.cos(ang), np.sin(ang)], axis=1)
    lo = np.zeros(len(e))
    hi = np.ones(len(e))
    for _ in range(60):  # grow until beyond the outline
        d = rho(u0 + hi[:, None] * e)
        grow = np.isfinite(d) & (d < r)
        if not grow.any():
            break
        hi = np.where(grow, 2.0 * hi, hi)
    while (hi - lo).max() > tol:
        mid = 0.5 * (lo + hi)
        inside = rho(u0 + mid[:, None] * e) < r
        lo = np.where(inside, mid, lo)
        hi = np.where(inside, hi, mid)
    out = u0 + (0.5 * (lo + hi))[:, None] * e
    out[~np.isfinite(rho(out))] = np.nan
    return out, u0
