"""The start of any mirror's calibration: the aligned rig a central fit implies.

A central fit (Scaramuzza's Taylor model, :mod:`.taylor`, or Mei's unified model,
:mod:`.central`) gives each pixel's scene direction. Read along radii about its principal
point, averaged over azimuth, that is an elevation ``alpha(rho)``; :mod:`.profile` turns it,
for a pinhole focal length ``f`` and the rim's radius, into the meridian profile of the mirror
that an aligned camera would need to see exactly those directions, and fits an even asphere to
it. The result is the rig start ``K``, ``AsphericMirror(R, k, rim_radius, alphas, vertex_z)``,
``rvec = 0``, ``tvec``, for the non-central adjustment.

What the central fit cannot give, the start has to choose:

- the scale: the rim's radius fixes it (a data sheet's, or
  :data:`omnicam.chessboard.central.NOMINAL_RIM_RADIUS`);
- the focal length ``f``: for every ``f`` there is a mirror (eq. 5 of :mod:`.profile`) whose
  aligned rig sees the central model's directions exactly; only the rays' positions differ, and
  boards at a few mirror diameters barely tell them apart. Given ``f`` (a lens data sheet,
  :func:`omnicam.chessboard.calibrate_intrinsics`, or Mei's fit with ``xi < 1``: ``f = gamma /
  sqrt(1 - xi^2)``, :func:`omnicam.chessboard.central.pinhole_K_from_unified`, exact for a
  hyperboloid seen from its focus) is used as is; otherwise the start takes the ``f`` that
  makes the rim subtend :data:`RIM_HALF_ANGLE_DEG` from the camera, as the library's default
  HyperOmni-style rig does (30 mm rim 82 mm away). The adjustment must then free ``f``: with
  the mirror's shape free, ``f`` and the profile trade along a valley that only near boards
  and the rim's image break.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable

import numpy as np
from scipy.interpolate import CubicSpline

from .._typing import FloatArray
from .heldout import unified_predictor
from .profile import (
    AsphereFit,
    MirrorProfile,
    asphere_elevations,
    fit_convex_asphere,
    profile_from_central,
)

__all__ = [
    "RIM_HALF_ANGLE_DEG",
    "CentralStart",
    "central_start",
    "elevations_along_radii",
    "unified_directions",
]

#: The rim's half-angle from the camera (deg) that fixes ``f`` when nothing gives it: the
#: library's default rig's (``omnicam.synthetic.default_mirror`` seen from its focus: 20.0).
RIM_HALF_ANGLE_DEG = 20.0
#: Radii and azimuths at which the central model's elevations are read.
N_RADII, N_AZIMUTHS = 256, 72


@dataclasses.dataclass(frozen=True)
class CentralStart:
    """The aligned rig a central fit implies (module docstring).

    Attributes
    ----------
    K : (3, 3) ndarray
        ``[[f, 0, x_c], [0, f, y_c], [0, 0, 1]]``, the principal point the central model's.
    f : float
        The pinhole focal length, px.
    f_given : bool
        True if ``f`` was given, False if it is the :data:`RIM_HALF_ANGLE_DEG` default.
    rvec, tvec : (3,) ndarray
        The mirror's posture in the camera frame (``X_cam = R X_mirror + tvec``): ``rvec = 0``,
        ``tvec = (0, 0, vertex_distance - vertex_z)``.
    mirror : AsphereFit
        ``R, k, alphas, rim_radius, vertex_z`` of the mirror, and the fit's error.
    profile : MirrorProfile
        The exact profile (camera's centre at the origin) the asphere was fitted to.
    rho, alpha, alpha_spread : (n,) ndarray
        The radii (px) where the central model was read, its elevation there (rad, mean over
        azimuth) and the spread over azimuth (rad, standard deviation): how far the central
        model is from symmetric about its principal point.
    direction_error_deg : float
        The largest difference (deg) between the elevations the start's rig sees through the
        fitted asphere and the central model's, over the profile's camera rays
        (:func:`~omnicam.chessboard.profile.asphere_elevations`): what the asphere's fit
        error costs in directions (the profile itself is exact).
    """

    K: FloatArray
    f: float
    f_given: bool
    rvec: FloatArray
    tvec: FloatArray
    mirror: AsphereFit
    profile: MirrorProfile
    rho: FloatArray
    alpha: FloatArray
    alpha_spread: FloatArray
    direction_error_deg: float

    def mirror_kwargs(self) -> dict:
        """The arguments of :class:`omnicam.asphere.AsphericMirror` for :attr:`mirror`."""
        m = self.mirror
        return dict(R=m.R, k=m.k, rim_radius=m.rim_radius, alpha=m.alphas, vertex_z=m.vertex_z)


def elevations_along_radii(
    directions: Callable, principal_point, rho_max: float, n_rho=N_RADII, n_azimuth=N_AZIMUTHS
) -> tuple[FloatArray, FloatArray, FloatArray]:
    """A central model's scene elevation along radii about its principal point.

    The elevation is taken about the model's own axis, its camera frame's ``z`` (Mei's and
    Scaramuzza's): ``alpha = asin(-sigma d_z)`` with ``sigma`` the sign of ``d_z`` at the
    principal point, which a convex mirror sees straight back (``alpha = -pi/2``) whichever
    way the model's gauge turns ``z`` (Mei's puts it on ``+z``, OCamCalib's ``a0 < 0`` on
    ``-z``).

    Parameters
    ----------
    directions : callable
        ``directions(pixels (N, 2)) -> (N, 3)`` unit rays (NaN where the model sees nothing).
    principal_point : (2,) array_like
        The model's centre of symmetry, px.
    rho_max : float
        The largest radius, px.
    n_rho, n_azimuth : int
        Radii (uniform on ``[0, rho_max]``) and azimuths per radius.

    Returns
    -------
    rho, alpha, spread : (n_rho,) ndarray
        The radii (px), the mean elevation over azimuth (rad) and its standard deviation.

    Raises
    ------
    ValueError
        The model sees no direction at some radius, or none at the principal point.
    """
    c = np.asarray(principal_point, np.float64).reshape(2)
    d0 = np.asarray(directions(c.reshape(1, 2)), np.float64).reshape(3)
    if not (np.all(np.isfinite(d0)) and abs(d0[2]) > 0.5):
        raise ValueError(
            f"directions: the principal point {c.round(2).tolist()} must see along the model's "
            f"axis (z), got {np.round(d0, 3).tolist()}"
        )
    rho = np.linspace(0.0, float(rho_max), int(n_rho))
    az = np.linspace(0.0, 2 * np.pi, int(n_azimuth), endpoint=False)
    px = c + (rho[:, None, None] * np.stack([np.cos(az), np.sin(az)], axis=1)[None]).reshape(-1, 2)
    d = np.asarray(directions(px), np.float64).reshape(len(rho), len(az), 3)
    with np.errstate(invalid="ignore"):
        el = np.arcsin(np.clip(-np.sign(d0[2]) * d[..., 2], -1.0, 1.0))
    el[~np.all(np.isfinite(d), axis=2)] = np.nan
    seen = np.isfinite(el).any(axis=1)
    if not seen.all():
        raise ValueError(
            f"directions: the central model sees nothing at {rho[~seen][0]:.1f} px from its "
            f"principal point (within rho_max = {rho_max:.1f} px)"
        )
    alpha = np.nanmean(el, axis=1)
    alpha[0] = -0.5 * np.pi  # the principal point: straight back, by the symmetry
    return rho, alpha, np.nanstd(el, axis=1)


def central_start(
    directions: Callable,
    principal_point,
    rho_rim: float,
    rim_radius: float,
    f: float | None = None,
    max_terms: int = 6,
    vertex_z: float = 0.0,
) -> CentralStart:
    """The aligned rig, with an even-asphere mirror, whose pixels see a central model's
    directions: the start of any mirror's calibration (module docstring).

    Parameters
    ----------
    directions : callable
        ``directions(pixels (N, 2)) -> (N, 3)`` unit rays of the central model in its camera
        frame (:meth:`omnicam.chessboard.taylor.TaylorFit.directions`, or Mei's via
        :func:`unified_directions`).
    principal_point : (2,) array_like
        The central model's centre (Taylor's ``centre``, Mei's ``K[:2, 2]``), px.
    rho_rim : float
        The rim's image radius, px (e.g. the geometric mean of the rim ellipse's semi-axes).
        Beyond the boards' reach the central model is extrapolated.
    rim_radius : float
        The rim's radius, mirror units: the scale.
    f : float, optional
        The pinhole's focal length, px; by default the one that makes the rim subtend
        :data:`RIM_HALF_ANGLE_DEG` (``f = rho_rim / tan(20 deg)``).
    max_terms : int
        Most even polynomial terms of the asphere: the convex fit of least maximum error with
        0 to ``max_terms`` terms (:func:`~omnicam.chessboard.profile.fit_convex_asphere`).
    vertex_z : float
        The vertex's height in the mirror frame wanted (0: the mirror frame's origin at the
        vertex, ``tvec = (0, 0, camera-vertex distance)``).

    Returns
    -------
    CentralStart

    Raises
    ------
    ValueError
        The model sees nothing somewhere inside the rim's image, or its elevations make no
        mirror (:func:`~omnicam.chessboard.profile.profile_from_central`).
    """
    f_given = f is not None
    if f is None:
        f = float(rho_rim) / math.tan(math.radians(RIM_HALF_ANGLE_DEG))
    rho, alpha, spread = elevations_along_radii(directions, principal_point, rho_rim)
    spline = CubicSpline(rho, alpha)
    profile = profile_from_central(spline, float(f), float(rho_rim), float(rim_radius))
    mirror = fit_convex_asphere(profile.r, profile.z, rim_radius, max_terms, profile.slope)
    seen = asphere_elevations(mirror, profile.phi, np.hypot(profile.r, profile.z))
    error = float(np.degrees(np.max(np.abs(seen - spline(f * np.tan(profile.phi))))))
    shift = float(vertex_z) - mirror.vertex_z
    mirror = dataclasses.replace(mirror, vertex_z=float(vertex_z))
    c = np.asarray(principal_point, np.float64).reshape(2)
    K = np.array([[f, 0.0, c[0]], [0.0, f, c[1]], [0.0, 0.0, 1.0]])
    tvec = np.array([0.0, 0.0, -shift])
    return CentralStart(
        K, float(f), f_given, np.zeros(3), tvec, mirror, profile, rho, alpha, spread, error
    )


def unified_directions(K, xi, D=None) -> Callable:
    """``directions(pixels) -> (N, 3)`` of Mei's unified model (``cv2.omnidir``'s ``K, xi,
    D``), for :func:`central_start` (NaN past the model's horizon when ``xi > 1``)."""
    rays = unified_predictor(K, float(xi), np.zeros(4) if D is None else D)[1]
    return lambda px: rays(np.asarray(px, np.float64).reshape(-1, 2))[1]
