"""The central start: ``cv2.omnidir``'s unified model and the hyperbolic rig it approximates.

A hyperbolic mirror seen from its second focus is a central camera, and the unified (Mei)
model of ``cv2.omnidir.calibrate`` describes it exactly (Geyer and Daniilidis; Mei and Rives,
table 1): with ``d = 2c`` the distance between the foci and ``4p = 2 a^2 / b`` the latus
rectum of ``Z^2 / b^2 - (X^2 + Y^2) / a^2 = 1`` (eq. 1),

    xi = d / sqrt(d^2 + 4 p^2),    gamma = f sqrt(1 - xi^2),

``gamma`` the unified model's focal length and ``f`` the pinhole's. So a central fit of the
chessboard corners (robust, and needing no start) gives the pinhole's ``K`` and the mirror's
*shape* (``a / b``); the rim's image gives its size relative to the rim radius. What no
central fit can give is the scale: every scaled copy of the rig forms the same central image.
:func:`hyperbolic_start` takes it from ``rim_radius`` (the data sheet's, or a nominal value
whose consequences :func:`omnicam.calibrate_pattern` documents).
"""

from __future__ import annotations

import dataclasses
import math

import cv2
import numpy as np

from .._typing import FloatArray
from ..calibration.plausibility import rim_depth
from ..mirror import HyperbolicMirror

__all__ = [
    "NOMINAL_RIM_RADIUS",
    "CentralFit",
    "fit_central",
    "hyperbolic_start",
    "mirror_shape_from_xi",
    "pinhole_D_from_unified",
    "pinhole_K_from_unified",
]

#: The rim radius (mm) that fixes the scale when nothing gives it: a common small mirror's.
NOMINAL_RIM_RADIUS = 30.0
_CRITERIA = (cv2.TERM_CRITERIA_COUNT + cv2.TERM_CRITERIA_EPS, 200, 1e-8)


@dataclasses.dataclass(frozen=True)
class CentralFit:
    """``cv2.omnidir.calibrate``'s result.

    Attributes
    ----------
    K : (3, 3) ndarray
        The unified model's camera matrix (``gamma_x, s, c_x; gamma_y, c_y``).
    xi : float
    D : (4,) ndarray
        ``k1, k2, p1, p2`` of the unified model (on its normalised plane, not the pinhole's).
    rms : float
        Corner RMS, px (as OpenCV reports it).
    views : tuple of int
        The indices (into the views given) that OpenCV kept.
    """

    K: np.ndarray
    xi: float
    D: np.ndarray
    rms: float
    views: tuple


def fit_central(
    image_points, obj, image_size, distortion=False, hyperbolic=True, radial=False
) -> CentralFit:
    """``cv2.omnidir.calibrate`` of the corners (any of OpenCV's orders; no start needed).

    By default with no distortion and no skew: the unified model's ``k1`` trades with ``xi``
    on a rig that is not exactly central (on the misaligned test rig ``xi`` 1.08 with ``k1``
    free, 0.946 without, 0.966 the mirror's), and only ``xi < 1`` describes a hyperboloid.

    Parameters
    ----------
    image_points : sequence of (N, 2) array_like
        Each view's corners, px.
    obj : (N, 3) array_like
        The board's corners (``z = 0``).
    image_size : (int, int)
        ``(width, height)``.
    distortion : bool
        Also fit ``k1, k2, p1, p2`` and the skew (``cv2.omnidir``'s defaults).
    radial : bool
        Fit ``k1, k2`` only (``p1, p2`` and the skew held at 0): the radial distortion of a
        wide-angle lens, which a fit without distortion takes into ``K``'s aspect and ``xi``.
    hyperbolic : bool
        Refuse a fit whose ``xi`` no hyperbolic mirror has (``0 <= xi < 1``); False: any
        finite fit (a paraboloid gives ``xi = 1``, a sphere more).

    Returns
    -------
    CentralFit

    Raises
    ------
    ValueError
        Fewer than 3 views, or OpenCV's fit fails (the message says which).
    """
    if len(image_points) < 3:
        raise ValueError(f"the central fit needs 3 views or more, got {len(image_points)}")
    op = [np.asarray(obj, np.float64).reshape(1, -1, 3) for _ in image_points]
    ip = [np.asarray(p, np.float64).reshape(1, -1, 2) for p in image_points]
    o = cv2.omnidir
    flags = 0 if distortion else (o.CALIB_FIX_K1 | o.CALIB_FIX_K2 | o.CALIB_FIX_P1 | o.CALIB_FIX_P2)
    flags |= 0 if distortion else o.CALIB_FIX_SKEW
    if radial and not distortion:
        flags = o.CALIB_FIX_P1 | o.CALIB_FIX_P2 | o.CALIB_FIX_SKEW
    try:
        # cv2's stubs make K, xi and D arrays; None (OpenCV's noArray) lets calibrate start them
        rms, K, xi, D, _rv, _tv, idx = cv2.omnidir.calibrate(  # type: ignore[call-overload]
            op, ip, tuple(int(v) for v in image_size), None, None, None, flags, _CRITERIA
        )
    except cv2.error as e:
        msg = str(e).strip().splitlines()[-1] if str(e).strip() else "cv2.error"
        raise ValueError(f"cv2.omnidir.calibrate failed: {msg}") from None
    xi = float(np.ravel(xi)[0])
    K = np.asarray(K, np.float64)
    shape_ok = 0.0 <= xi < 1.0 if hyperbolic else math.isfinite(xi)
    if not (np.isfinite(K).all() and shape_ok and K[0, 0] > 0 and K[1, 1] > 0):
        raise ValueError(
            f"cv2.omnidir.calibrate gave no hyperbolic rig (xi = {xi:.3f}, fx = {K[0, 0]:.1f}; "
            f"a hyperbolic mirror has 0 < xi < 1)"
        )
    views = tuple(int(i) for i in np.ravel(idx)) if idx is not None else ()
    return CentralFit(K, xi, np.asarray(D, np.float64).ravel()[:4], float(rms), views)


def pinhole_K_from_unified(K_unified, xi, principal_point=None) -> FloatArray:
    """The pinhole's ``K`` behind a unified model: focal lengths and skew ``/ sqrt(1 - xi^2)``,
    the principal point unchanged or ``principal_point``.

    A start for a misaligned rig takes the focal length only: the central fit's principal
    point carries the mirror's tilt (on a misaligned rig it lies farther off than the image
    centre), which the non-central adjustment must then undo along its weakest valley.
    """
    K = np.array(K_unified, np.float64)
    s = math.sqrt(max(1.0 - float(xi) ** 2, 1e-12))
    K[0, :2] /= s
    K[1, 1] /= s
    if principal_point is not None:
        K[0, 2], K[1, 2] = (float(v) for v in principal_point)
    return K


def pinhole_D_from_unified(D_unified, xi) -> FloatArray:
    """The pinhole's radial distortion ``(k1, k2, 0, 0)`` behind a unified model's ``D``.

    The unified model distorts its normalised plane, which is the pinhole's scaled by
    ``1 / sqrt(1 - xi^2)`` (the ratio of the focal lengths, :func:`pinhole_K_from_unified`):
    with ``s^2 = 1 - xi^2``, ``r_unified = r / s``, so ``k1 = k1_unified / s^2`` and
    ``k2 = k2_unified / s^4``. The tangential terms are not carried over.
    """
    D = np.ravel(np.asarray(D_unified, np.float64))
    s2 = max(1.0 - float(xi) ** 2, 1e-12)
    return np.array([D[0] / s2, D[1] / (s2 * s2), 0.0, 0.0])


def mirror_shape_from_xi(xi) -> tuple[float, float]:
    """``(a / b, c / b)`` of the hyperboloid whose unified model has ``xi`` (0 < xi < 1).

    From ``xi = 2c / sqrt(4 c^2 + a^4 / b^2)`` with ``a^2 = c^2 - b^2``: with
    ``s = sqrt(1 - xi^2) / xi``, ``c / b = s + sqrt(s^2 + 1)``.
    """
    xi = float(xi)
    if not 0.0 < xi < 1.0:
        raise ValueError(f"xi must be in (0, 1) for a hyperbolic mirror, got {xi!r}")
    s = math.sqrt(1.0 - xi * xi) / xi
    gamma = s + math.sqrt(s * s + 1.0)
    return math.sqrt(gamma * gamma - 1.0), gamma


def hyperbolic_start(
    K_unified, xi, rim_px_radius, rim_radius=NOMINAL_RIM_RADIUS, K=None, principal_point=None
) -> tuple[FloatArray, HyperbolicMirror]:
    """The aligned hyperbolic rig a central fit describes: ``(K, HyperbolicMirror)``.

    The mirror's shape from ``xi`` (:func:`mirror_shape_from_xi`), ``K`` from the unified
    model's (:func:`pinhole_K_from_unified`; or the one given), and the size from the rim: an
    aligned rig images the rim circle (radius ``R`` at height ``z_rim``, camera at ``-c``) with
    radius ``f R / (z_rim + c)`` px, so ``sqrt(b^2 + R^2 / alpha^2) + gamma b = f R / r_px``
    with ``alpha = a / b`` and ``gamma = c / b``: a quadratic in ``b``.

    Parameters
    ----------
    K_unified : (3, 3) array_like
    xi : float
    rim_px_radius : float
        The rim's image radius (px; the geometric mean of the ellipse's semi-axes).
    rim_radius : float
        The rim's radius in mirror units: fixes the scale.
    K : (3, 3) array_like, optional
        The pinhole's camera matrix, if known.
    principal_point : (2,) array_like, optional
        The start's principal point instead of the central fit's
        (:func:`pinhole_K_from_unified`).
    """
    alpha, gamma = mirror_shape_from_xi(xi)
    if K is None:
        K = pinhole_K_from_unified(K_unified, xi, principal_point)
    K = np.asarray(K, np.float64)
    f = math.sqrt(K[0, 0] * K[1, 1])
    R = float(rim_radius)
    q = rim_depth(f, float(rim_px_radius), R)
    # (gamma^2 - 1) b^2 - 2 q gamma b + (q^2 - R^2 / alpha^2) = 0, root with q - gamma b >= 0
    A, B, C = gamma * gamma - 1.0, -2.0 * q * gamma, q * q - R * R / (alpha * alpha)
    disc = B * B - 4.0 * A * C
    if not (disc >= 0 and A > 0):
        raise ValueError(
            f"no hyperbolic mirror images its rim {rim_px_radius:.1f} px wide with xi = "
            f"{xi:.3f} and f = {f:.1f} px"
        )
    b = (-B - math.sqrt(disc)) / (2.0 * A)
    if not (b > 0 and q - gamma * b >= 0):
        raise ValueError(
            f"no hyperbolic mirror images its rim {rim_px_radius:.1f} px wide with xi = "
            f"{xi:.3f} and f = {f:.1f} px"
        )
    return K, HyperbolicMirror(alpha * b, b, R)
