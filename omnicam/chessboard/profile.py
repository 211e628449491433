"""The mirror profile a central model implies for an aligned rig: the start for any mirror.

Geometry. The camera's centre is the origin, on the mirror's axis, looking along ``+z`` at
the mirror above it; everything happens in a meridian half-plane ``(r, z)``, ``r >= 0``. A
pixel at radius ``rho`` (px, from the principal point) sees along the camera ray at angle
``phi`` from the axis,

    tan(phi) = rho / f,          d_in = u(phi) = (sin phi, cos phi),                    (1)

and a central model (Mei's, Scaramuzza's, any) gives the scene direction of that pixel: its
elevation ``alpha(rho)`` (positive up, towards the mirror) in the same meridian plane,

    d_out = (cos alpha, sin alpha),                                                        (2)

the ray leaving the mirror outwards (``cos alpha >= 0``; the pixel at the centre sees
straight back, ``alpha(0) = -pi/2``). The reflection law ``d_out = d_in - 2 (d_in . n) n``
fixes the surface normal at the hit point,

    n ∝ d_out - d_in,                                                                      (3)

(for a convex mirror above the camera, ``d_in . n < 0`` with ``n`` the outer normal, so
``d_out - d_in`` points along ``n``: down and outwards). The hit point ``P(phi) = s(phi) u``
lies on the camera ray; its tangent ``dP/dphi = s' u + s u_perp`` (``u_perp = du/dphi =
(cos phi, -sin phi)``) is normal to ``n``, so

    d ln s / d phi = -(u_perp . n) / (u . n).                                              (4)

With ``beta = phi + alpha``: ``u . d_out = sin beta``, ``u_perp . d_out = cos beta``,
``u . d_in = 1``, ``u_perp . d_in = 0``, and (4) is the quadrature

    d ln s / d phi = cos(beta) / (1 - sin beta) = tan(pi/4 + (phi + alpha) / 2),           (5)

(the angle between the camera ray and the normal is half the angle of reflection). For an
equiangular mirror, ``alpha = g phi - pi/2``, (5) integrates to Chahl and Srinivasan's
``s = r0 cos((1 + g) phi / 2)^(-2 / (1 + g))``. The scale is the one thing no central
model gives (every scaled copy of the rig forms the same image): the rim fixes it,
``s(phi_rim) sin(phi_rim) = rim_radius`` with ``tan(phi_rim) = rho_rim / f``.

So for any ``f`` the profile reproduces the central model's *directions* exactly; the
*positions* of the rays are then the non-central rig's, not the central model's single
viewpoint. ``f`` itself is not determined by a central model (a different ``f`` gives a
different mirror with the same directions); :func:`omnicam.chessboard.central_start.central_start`
documents the choice.

Frames. :func:`profile_from_central` returns ``(r, z)`` with the camera's centre at the
origin; the vertex is at ``z = s(0)``, the camera's distance to the mirror. An
:class:`~omnicam.asphere.AsphericMirror` surface ``Z = vertex_z + sag(r)`` fitted to it by
:func:`fit_even_asphere` has ``vertex_z = s(0)`` in this frame (camera at the mirror frame's
origin); in a mirror frame with the vertex at ``vertex_z'`` instead, the aligned camera sits at
``(0, 0, vertex_z' - s(0))``, i.e. ``rvec = 0``, ``tvec = (0, 0, s(0) - vertex_z')``.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable

import numpy as np
from scipy.integrate import solve_ivp
from scipy.optimize import least_squares

from .._typing import FloatArray
from ..asphere import AsphericMirror

__all__ = [
    "AsphereFit",
    "MirrorProfile",
    "asphere_elevations",
    "even_asphere_sag",
    "even_asphere_slope",
    "fit_convex_asphere",
    "fit_even_asphere",
    "profile_from_central",
]

#: Samples of the profile, uniform in ``phi`` from the axis to the rim.
PROFILE_SAMPLES = 2001
#: Relative tolerance of the quadrature of eq. 5 (``solve_ivp``'s DOP853).
_RTOL = 1e-12
#: Fraction of the rim radius within which the vertex's osculating curvature is fitted.
_OSCULATING_FRACTION = 0.2


@dataclasses.dataclass(frozen=True)
class MirrorProfile:
    """A meridian profile of a mirror of revolution, camera's centre at the origin.

    Attributes
    ----------
    r, z : (n,) ndarray
        The profile's points (mirror units), from the vertex ``(0, vertex_distance)`` to the
        rim ``(rim_radius, z_rim)``.
    phi : (n,) ndarray
        The camera ray's angle from the axis of each point, rad.
    slope : (n,) ndarray
        ``dz/dr`` at each point, exact from eq. 3: the tangent is normal to ``d_out - d_in``,
        ``dz/dr = (cos alpha - sin phi) / (cos phi - sin alpha)``.
    f : float
        The pinhole focal length (px) the profile was built for.
    """

    r: FloatArray
    z: FloatArray
    phi: FloatArray
    slope: FloatArray
    f: float

    @property
    def vertex_distance(self) -> float:
        """``s(0)``: the distance from the camera's centre to the mirror's vertex."""
        return float(self.z[0])

    @property
    def slope_angles(self) -> FloatArray:
        """The profile's tangent angle ``atan(dz/dr)`` at each point, rad; increasing
        outwards on a convex mirror."""
        return np.arctan(self.slope)


def _log_distance_rate(phi, alpha) -> FloatArray:
    """``d ln s / d phi = tan(pi/4 + (phi + alpha) / 2)`` (eq. 5)."""
    return np.tan(0.25 * np.pi + 0.5 * (phi + alpha))


def profile_from_central(
    alpha_of_rho: Callable,
    f: float,
    rho_rim: float,
    rim_radius: float,
    samples: int = PROFILE_SAMPLES,
) -> MirrorProfile:
    """The aligned rig's mirror profile whose pixels see the central model's elevations.

    Integrates eq. 5 of the module docstring, ``ln s(phi) = int_0^phi tan(pi/4 + (t +
    alpha(f tan t)) / 2) dt``, with scipy's ``solve_ivp`` (DOP853, relative tolerance
    1e-12), then scales ``s`` so that the rim's point is at ``r = rim_radius``.

    Parameters
    ----------
    alpha_of_rho : callable
        ``alpha_of_rho(rho) -> elevation`` (rad, positive towards the mirror, ``-pi/2`` at
        ``rho = 0``) of the pixels at radius ``rho`` (px, an ndarray) from the principal point;
        smooth (the integrator samples it anywhere in ``[0, rho_rim]``).
    f : float
        The pinhole's focal length, px.
    rho_rim : float
        The rim's image radius, px.
    rim_radius : float
        The rim's radius, mirror units: fixes the scale.
    samples : int
        Points of the profile, uniform in ``phi``.

    Returns
    -------
    MirrorProfile

    Raises
    ------
    ValueError
        A non-positive ``f``, ``rho_rim`` or ``rim_radius``; elevations that are not finite, or
        that no mirror in front of the camera reflects (``phi + alpha`` outside
        ``[-pi/2, pi/2)``: the ray would not leave outwards, or would graze the surface).
    """
    for name, v in (("f", f), ("rho_rim", rho_rim), ("rim_radius", rim_radius)):
        if not (isinstance(v, (int, float, np.floating)) and math.isfinite(v) and v > 0):
            raise ValueError(f"{name} must be a positive finite number, got {v!r}")
    phi_rim = math.atan(rho_rim / f)
    phi = np.linspace(0.0, phi_rim, int(samples))
    alpha = np.asarray(alpha_of_rho(f * np.tan(phi)), np.float64)
    beta = phi + alpha
    # beta = -pi/2 at the vertex (the ray seen straight back), < pi/2 short of grazing
    if not (
        np.all(np.isfinite(alpha)) and np.all((beta >= -0.5 * np.pi - 1e-9) & (beta < 0.5 * np.pi))
    ):
        raise ValueError(
            "alpha_of_rho: no mirror in front of the camera reflects these elevations (phi + "
            "alpha must stay in [-90, 90) deg up to the rim)"
        )

    def rate(t, _y):
        a = np.asarray(alpha_of_rho(np.atleast_1d(f * math.tan(t))), np.float64)
        return _log_distance_rate(t, a)

    sol = solve_ivp(
        rate, (0.0, phi_rim), [0.0], method="DOP853", t_eval=phi, rtol=_RTOL, atol=1e-14
    )
    if not sol.success:
        raise ValueError(f"alpha_of_rho: the profile's integration failed ({sol.message})")
    s = np.exp(sol.y[0])
    s *= rim_radius / (s[-1] * math.sin(phi_rim))  # the rim fixes the scale
    r, z = s * np.sin(phi), s * np.cos(phi)
    r[-1] = rim_radius
    slope = (np.cos(alpha) - np.sin(phi)) / (np.cos(phi) - np.sin(alpha))  # eq. 3
    return MirrorProfile(r, z, phi, slope, float(f))


# -- the even asphere through a profile -------------------------------------------------------
@dataclasses.dataclass(frozen=True)
class AsphereFit:
    """An even asphere ``z = vertex_z + sag(r)`` fitted to a profile.

        sag(r) = r^2 / (R (1 + sqrt(1 - (1 + k) r^2 / R^2)))
                 + sum_j alphas[j] (r / rim_radius)^(2 j + 4),

    the arguments of :class:`omnicam.asphere.AsphericMirror` ``(R, k, rim_radius, alphas,
    vertex_z=vertex_z)``.

    Attributes
    ----------
    R : float
        Vertex radius of curvature (mirror units).
    k : float
        Conic constant (0 sphere, -1 paraboloid, < -1 hyperboloid).
    alphas : tuple of float
        Coefficients of ``(r / rim_radius)^4, ^6, ...`` (mirror units).
    rim_radius : float
    vertex_z : float
        The vertex's height in the profile's frame.
    max_error : float
        ``max |z_fit - z|`` over the profile's samples (mirror units).
    conic_error : float
        The same for the conic alone (before the polynomial terms).
    slope_error : float
        ``max |atan(sag') - atan(z')|`` over the samples (rad): twice that bounds what the fit
        turns the reflected rays by.
    convex : bool
        Whether the fitted surface is convex inside the rim (``f' > 0``, ``f'' > 0``), as
        :class:`~omnicam.asphere.AsphericMirror` requires: a profile far from a conic may
        need terms that break it (then fewer terms, or the profile itself).
    """

    R: float
    k: float
    alphas: tuple
    rim_radius: float
    vertex_z: float
    max_error: float
    conic_error: float
    convex: bool
    slope_error: float


def even_asphere_sag(r, R, k, alphas=(), rho_n=1.0) -> FloatArray:
    """The even asphere's sag at radii ``r``; NaN where the conic is not defined."""
    r = np.asarray(r, np.float64)
    u = r * r
    with np.errstate(invalid="ignore"):
        sag = u / (R * (1.0 + np.sqrt(1.0 - (1.0 + k) * u / (R * R))))
    t = u / (rho_n * rho_n)
    for j, a in enumerate(alphas):
        sag = sag + a * t ** (j + 2)
    return sag


def even_asphere_slope(r, R, k, alphas=(), rho_n=1.0) -> FloatArray:
    """``d sag / dr`` of :func:`even_asphere_sag`: ``r / (R sqrt(1 - (1 + k) r^2 / R^2)) +
    sum_j alphas[j] (2 j + 4) r^(2 j + 3) / rho_n^(2 j + 4)``."""
    r = np.asarray(r, np.float64)
    with np.errstate(invalid="ignore", divide="ignore"):
        slope = r / (R * np.sqrt(1.0 - (1.0 + k) * r * r / (R * R)))
    for j, a in enumerate(alphas):
        slope = slope + a * (2 * j + 4) * r ** (2 * j + 3) / rho_n ** (2 * j + 4)
    return slope


def asphere_elevations(fit: AsphereFit, phi, s_start) -> FloatArray:
    """The elevations (rad) the aligned camera sees through the fitted asphere along camera
    rays at ``phi`` (rad from the axis): the hit ``s u(phi)`` by Newton on ``s cos(phi) =
    vertex_z + sag(s sin(phi))`` from ``s_start`` (e.g. the profile's own ``s``), then the
    reflection law with the normal ``(sag'(r), -1)``. NaN where Newton does not converge.

    Compared with the elevations the profile was built from, this is the fit's error in the
    directions, which is what the start gets wrong (the profile itself is exact).
    """
    phi = np.asarray(phi, np.float64)
    sn, cs = np.sin(phi), np.cos(phi)
    s = np.asarray(s_start, np.float64).copy()
    args = (fit.R, fit.k, fit.alphas, fit.rim_radius)
    for _ in range(30):
        g = s * cs - fit.vertex_z - even_asphere_sag(s * sn, *args)
        s = s - g / (cs - even_asphere_slope(s * sn, *args) * sn)
    g = s * cs - fit.vertex_z - even_asphere_sag(s * sn, *args)
    n = np.stack([even_asphere_slope(s * sn, *args), -np.ones_like(s)], axis=-1)
    n /= np.linalg.norm(n, axis=-1, keepdims=True)
    u = np.stack([sn, cs], axis=-1)
    d = u - 2.0 * np.sum(u * n, axis=-1, keepdims=True) * n  # eq. 3's reflection law
    el = np.arctan2(d[..., 1], d[..., 0])
    return np.where(np.abs(g) < 1e-9 * fit.rim_radius, el, np.nan)


def _conic_from(x, rim_radius) -> tuple[float, float]:
    """``(R, k)`` of the conic parameters ``x = (ln c, v)``: curvature ``c = 1 / R`` and
    ``(1 + k) c^2 rim^2 = 1 - exp(v)``, so the conic always reaches the rim."""
    c = math.exp(x[0])
    w = 1.0 - math.exp(x[1])
    return 1.0 / c, w / (c * c * rim_radius * rim_radius) - 1.0


def _conic_to(R, k, rim_radius) -> FloatArray:
    """``(ln c, v)`` of ``(R, k)`` (:func:`_conic_from`'s inverse)."""
    w = (1.0 + k) * (rim_radius / R) ** 2
    return np.array([-math.log(R), math.log(max(1.0 - w, 1e-300))])


def _osculating_start(r, z, rim_radius) -> FloatArray:
    """``(ln c, v)`` of the osculating sphere at the vertex (``z ~ z0 + c r^2 / 2`` fitted
    within :data:`_OSCULATING_FRACTION` of the rim), or the osculating paraboloid when that
    sphere does not reach the rim."""
    inner = np.flatnonzero(r <= _OSCULATING_FRACTION * rim_radius)
    if len(inner) < 3:
        inner = np.argsort(r)[:3]
    A = np.stack([np.ones(len(inner)), r[inner] ** 2 / 2], axis=1)
    c = float(np.linalg.lstsq(A, z[inner], rcond=None)[0][1])
    if not c > 0:
        raise ValueError("z: the profile is not convex at the vertex (no positive curvature)")
    w = (c * rim_radius) ** 2  # sphere: (1 + 0) c^2 rim^2
    k_start = 0.0 if w < 0.99 else -1.0
    return np.array([math.log(c), math.log(1.0 - (1.0 + k_start) * w)])


def _is_convex(R, k, alphas, rim_radius) -> bool:
    """Whether the asphere is one :class:`~omnicam.asphere.AsphericMirror` takes: convex inside
    the rim (``f' > 0``, ``f'' > 0``), the conic defined up to it. The mirror's own check, so
    that a fit called convex here is one the camera can hold."""
    try:
        AsphericMirror(float(R), float(k), float(rim_radius), alpha=tuple(float(a) for a in alphas))
    except ValueError:
        return False
    return True


def _design(r, rim_radius, n_terms) -> tuple[FloatArray, FloatArray]:
    """The polynomial terms ``(r / rim)^(2 j + 4)`` and their ``d/dr``, ``(n, n_terms)`` each."""
    q = r / rim_radius
    powers = np.arange(n_terms)[None, :] * 2 + 4
    return q[:, None] ** powers, powers * q[:, None] ** (powers - 1) / rim_radius


def _linear_part(profile, conic, design, rim_radius) -> tuple[FloatArray, FloatArray]:
    """The vertex height and the terms by linear least squares given the conic ``(R, k)``:
    ``(coefficients, residuals)``, the residuals the heights' over ``rim_radius`` then the
    slope angles' (rad, ``(sag' - z') / (1 + z'^2)``, first order)."""
    r, z, slope = profile
    Bh, Bs = design
    w = 1.0 / (1.0 + slope * slope)
    A = np.block([[np.ones((len(r), 1)), Bh], [np.zeros((len(r), 1)), Bs * w[:, None]]])
    A[: len(r)] /= rim_radius
    y = np.r_[
        (z - even_asphere_sag(r, *conic)) / rim_radius, (slope - even_asphere_slope(r, *conic)) * w
    ]
    coef = np.linalg.lstsq(A, y, rcond=None)[0]
    return coef, A @ coef - y


def _check_profile(r, z, slope, n_terms) -> tuple[FloatArray, FloatArray, FloatArray]:
    r = np.asarray(r, np.float64).ravel()
    z = np.asarray(z, np.float64).ravel()
    if r.shape != z.shape or len(r) < 5 + n_terms:
        raise ValueError(f"r and z must be matching profiles of {5 + n_terms} points or more")
    if slope is None:
        slope = np.gradient(z, r, edge_order=2)
    slope = np.asarray(slope, np.float64).ravel()
    if slope.shape != r.shape:
        raise ValueError(f"slope must have the {len(r)} samples of r, got {slope.shape}")
    return r, z, slope


def fit_even_asphere(
    r, z, rim_radius: float, n_terms: int = 4, start=None, slope=None
) -> AsphereFit:
    """The even asphere through a profile: the conic by nonlinear least squares, then the even
    polynomial terms linear given the conic.

    The fit matches both the heights (divided by the rim radius) and the slope angles (rad):
    the slopes are what the directions depend on (a reflected ray turns by twice the normal's
    error), and a fit on heights alone leaves its largest slope errors at the rim, where the
    heights end (OCamCalib's VMR sample, 6 terms: 0.36 deg in the directions on heights
    alone, 0.064 deg with the slopes; Kaidan 0.55 and 0.29 deg).

    The conic ``(R, k)`` and the vertex height first: variable projection (the height is
    linear given the conic) on ``(ln 1/R, v)`` with ``(1 + k) rim^2 / R^2 = 1 - exp(v)`` (the
    conic reaches the rim for every value), started from the osculating sphere at the vertex
    (or the paraboloid when that sphere is too small for the rim), scipy's trf; its height
    error is :attr:`AsphereFit.conic_error`. Then the ``n_terms`` coefficients of ``(r /
    rim_radius)^4, ^6, ...`` with the height are linear given the conic, and the conic is
    refined with them (variable projection again, started from the conic alone, from the
    osculating conic and from ``start``, the least squares kept): the terms' ``(r / r_n)^4``
    trades with ``k`` (both are 4th order at the vertex), so the joint fit reaches a far
    smaller error than terms fitted to the best conic's residual (an equiangular profile of
    gain 5, 5 terms: 5e-9 against 2e-4 of the rim radius).

    Parameters
    ----------
    r, z : (n,) array_like
        The profile (mirror units), ``r`` from 0 to the rim.
    rim_radius : float
    n_terms : int
        Polynomial terms (0: the conic alone).
    start : (float, float), optional
        ``(R, k)`` of a further start of the joint fit (e.g. the fit with fewer terms:
        :func:`fit_convex_asphere`).
    slope : (n,) array_like, optional
        ``dz/dr`` at the samples (:attr:`MirrorProfile.slope`, exact); by default finite
        differences of ``z``.

    Returns
    -------
    AsphereFit

    Raises
    ------
    ValueError
        Mismatched or too few samples, or a profile not convex at the vertex.
    """
    profile = _check_profile(r, z, slope, n_terms)
    r, z, slope = profile
    design = _design(r, rim_radius, n_terms)
    no_terms = _design(r, rim_radius, 0)

    def residuals(x, design):
        return _linear_part(profile, _conic_from(x, rim_radius), design, rim_radius)[1]

    # (ln c, v) within c rim in [1e-6, 1e6] and (1 + k) c^2 rim^2 in [1 - e^10, 1 - e^-40]
    lc = math.log(1.0 / rim_radius)
    bounds = ([lc - 14.0, -40.0], [lc + 14.0, 10.0])
    opts = dict(method="trf", x_scale="jac", xtol=1e-15, ftol=1e-15, gtol=1e-15, bounds=bounds)
    x0 = np.clip(_osculating_start(r, z, rim_radius), *bounds)
    conic = least_squares(residuals, x0, args=(no_terms,), **opts)
    conic_error = float(np.max(np.abs(conic.fun[: len(r)]))) * rim_radius
    x = conic.x
    if n_terms:  # from the conic alone, the osculating conic, ``start``: the valley has minima
        starts = [x, x0]
        if start is not None:
            starts.append(np.clip(_conic_to(float(start[0]), float(start[1]), rim_radius), *bounds))
        fits = [least_squares(residuals, x1, args=(design,), **opts) for x1 in starts]
        x = min(fits, key=lambda sol: float(sol.cost)).x
    R, k = _conic_from(x, rim_radius)
    coef, _ = _linear_part(profile, (R, k), design, rim_radius)
    alphas = coef[1:]
    height = float(coef[0]) + even_asphere_sag(r, R, k, alphas, rim_radius) - z
    angle = np.arctan(even_asphere_slope(r, R, k, alphas, rim_radius)) - np.arctan(slope)
    return AsphereFit(
        R=float(R),
        k=float(k),
        alphas=tuple(float(a) for a in alphas),
        rim_radius=float(rim_radius),
        vertex_z=float(coef[0]),
        max_error=float(np.max(np.abs(height))),
        conic_error=conic_error,
        convex=_is_convex(R, k, alphas, rim_radius),
        slope_error=float(np.max(np.abs(angle))),
    )


def fit_convex_asphere(r, z, rim_radius: float, max_terms: int = 6, slope=None) -> AsphereFit:
    """The convex even asphere of least slope error with at most ``max_terms`` terms.

    Fits 0, 1, ..., ``max_terms`` terms (:func:`fit_even_asphere`, each also started from the
    fit with one term fewer) and keeps, among the convex fits (:attr:`AsphereFit.convex`), the
    one of least :attr:`AsphereFit.slope_error` (what the directions depend on); the conic
    alone is always convex. A profile far
    from a conic (OCamCalib's Kaidan sample) can make the fit with more terms neither convex
    nor better.
    """
    fits: list[AsphereFit] = []
    for n in range(int(max_terms) + 1):
        prev = (fits[-1].R, fits[-1].k) if fits else None
        fits.append(fit_even_asphere(r, z, rim_radius, n, start=prev, slope=slope))
    convex = [f for f in fits if f.convex] or fits[:1]
    return min(convex, key=lambda f: f.slope_error)
