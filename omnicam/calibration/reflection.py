"""The camera's own reflection: a circle coaxial with the optical axis (model and detection).

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
(the exact outline of a circle for a camera), :func:`detect_reflection` (image ->
:class:`ReflectionFit`).
"""

from __future__ import annotations

import dataclasses
import math

import cv2
import numpy as np
from scipy.optimize import minimize_scalar

from .._typing import FloatArray
from ..images import to_gray
from ..mirror import HyperbolicMirror
from ..raytrace import distort_normalized
from .errors import EstimationError
from .rim import RimFit, fit_rim
from .robust import mad_sigma

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


# -- geometry ----------------------------------------------------------------------------------
#: :func:`fit_circle` seeks ``z`` up to this fraction of the camera's distance to the mirror
#: vertex (a lens barrel may reach far towards the mirror: the stress renders' fronts lie at
#: 5-40 mm with the vertex at 65 mm), on a grid of ``Z_GRID`` values refined by Brent.
Z_MAX_FRACTION = 0.9
Z_GRID = 25

#: A dark-to-bright rise votes for a silhouette when it exceeds this fraction of the contrast
#: between the dark centre and the mirror's scene: a fifth first; when that finds nothing, or
#: only a silhouette without a core, a tenth (kept if it finds one with a core around the
#: coreless one, else the coreless one stands): the barrel's front ring against a dark box
#: behind it rises by a fifth of the contrast or less (stress renders, seed 0, 1920x1080,
#: case 6: grey 26 to 51 against 117). A tenth at once would let the glass's inner rings vote
#: and win over a uniformly dark barrel (seed 0, case 87).
RISE_FRACTIONS = (0.2, 0.1)

#: Inlier cut (px) of the consensus on the subpixel outline points (the cut then grows with the
#: points' own scatter, :func:`.rim.fit_rim`).
SUBPIXEL_INLIER_PX = 0.75

#: Subpixel rounds along rays from the current ellipse: at least two, more while the ellipse
#: still moves (by 0.05 px or more in its centre or axes), up to this many (a vote centred a
#: third of the radius off, e.g. on a box's edges, needs a third round).
SUBPIXEL_ROUNDS = 5

#: A silhouette is dark inside when this fraction of the annulus 0.6-0.95 of its radius is
#: darker than the dark centre plus 60 % of the contrast (for the voted circle and again for
#: the refined one).
DARK_INSIDE = 0.8

#: A silhouette is round when its ellipse's axes differ by at most this ratio. The outline of
#: a coaxial circle is nearly a circle: the stress renders' barrels (tilts up to 5 deg, offsets
#: up to 5 mm, mild distortion; seeds 0-2, 199 outlines) give 1.003 (median) to 1.009 (max);
#: a pixel aspect of a few % adds as much. An ellipse through the barrel's edge on some rays
#: and the glass's on others is flatter (seed 0, case 37: 1.12). (Was 1.4.)
MAX_ASPECT = 1.1


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


# -- detection ---------------------------------------------------------------------------------
@dataclasses.dataclass(frozen=True, eq=False)
class ReflectionFit:
    """The outline of the camera's reflection found by :func:`detect_reflection`.

    Attributes
    ----------
    points : (N, 2) float64 ndarray
        Subpixel outline points (outer dark-to-bright edge, inliers of the ellipse fit), px.
    center : (2,) float64 ndarray
        Centre of the fitted ellipse, px.
    radius : float
        Mean semi-axis of the fitted ellipse, px.
    rms : float
        RMS distance of ``points`` to the ellipse, px: the measurement's own scatter (the
        outline of a coaxial circle is close to, not exactly, an ellipse).
    quality : float
        Fraction of the search rays that gave an inlier edge point, in [0, 1].
    contrast : float
        Median grey-level rise across the outline.
    core : bool
        Whether the silhouette has a darker core (the lens glass). Only
        ``detect_reflection(..., allow_coreless=True)`` returns one without: a uniformly dark
        silhouette may be a camera with dark glass or a dark floor, which the caller tells apart
        by the size of its circle.
    """

    points: np.ndarray
    center: np.ndarray
    radius: float
    rms: float
    quality: float
    contrast: float
    core: bool = True

    def __post_init__(self):
        for name in ("points", "center"):
            arr = np.array(getattr(self, name), np.float64)
            arr.flags.writeable = False
            object.__setattr__(self, name, arr)

    def __repr__(self):
        return (
            f"ReflectionFit(center=({self.center[0]:.2f}, {self.center[1]:.2f}), radius="
            f"{self.radius:.2f} px, points={len(self.points)}, rms={self.rms:.3f} px, "
            f"quality={self.quality:.2f}, contrast={self.contrast:.1f})"
        )


def _polar(G, center, radii, angles):
    """Samples of ``G`` along rays: (n_angles, n_radii) float32 (bilinear, NaN outside)."""
    ca, sa = np.cos(angles)[:, None], np.sin(angles)[:, None]
    mx = (center[0] + ca * radii[None, :]).astype(np.float32)
    my = (center[1] + sa * radii[None, :]).astype(np.float32)
    out = cv2.remap(G, mx, my, cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT, borderValue=np.nan)
    return out


def _dark_inside(G, center, radius, angles, dark_max):
    """Whether a silhouette is dark inside: :data:`DARK_INSIDE` of the annulus 0.6-0.95 of
    ``radius`` about ``center`` (along ``angles``) is darker than ``dark_max`` (a dark scene
    line or ring is dark only along itself)."""
    band = _polar(G, center, np.linspace(0.6, 0.95, 8) * radius, angles)
    ok = np.isfinite(band)
    return bool(ok.any()) and float(np.mean(band[ok] < dark_max)) >= DARK_INSIDE


def _core_and_shell(G, center, radius, angles):
    """Median grey of a silhouette's core (within half its radius) and of its edge band
    (0.75-0.95 of it): the lens glass is darker than the ring around it."""
    core = _polar(G, center, np.linspace(0.0, 0.5, 12) * radius, angles)
    shell = _polar(G, center, np.linspace(0.75, 0.95, 8) * radius, angles)
    return _finite_median(core), _finite_median(shell)


def _finite_median(values):
    """Median of the finite values; NaN (and no numpy warning) when there are none, as for a
    silhouette that lies outside the image."""
    v = np.asarray(values, np.float64)
    v = v[np.isfinite(v)]
    return float(np.median(v)) if v.size else math.nan


def _rises(prof, dr, min_rise, dark_max, k=3):
    """Per ray, radii of strong dark-to-bright rises: local maxima of the radial derivative
    whose rise over +-k samples exceeds ``min_rise`` with the inner side below ``dark_max``.

    Returns (ray index, radius index) arrays."""
    d = np.gradient(prof, axis=1) / dr
    inner = np.full_like(prof, np.nan)
    outer = np.full_like(prof, np.nan)
    inner[:, k:] = prof[:, :-k]
    outer[:, :-k] = prof[:, k:]
    with np.errstate(invalid="ignore"):
        peak = (d > 0) & (d >= np.roll(d, 1, axis=1)) & (d > np.roll(d, -1, axis=1))
        strong = (outer - inner > min_rise) & (inner < dark_max)
    peak[:, :k] = False
    peak[:, -k:] = False
    return np.nonzero(peak & strong)


def detect_reflection(
    image,
    rim,
    *,
    center=None,
    center_search=0.08,
    max_radius=0.6,
    min_radius=0.03,
    rng=0,
    allow_coreless=False,
) -> ReflectionFit:
    """Find the outermost round dark silhouette around the image of the camera centre.

    1. Radial profiles from ``center`` (default the rim centre) out to ``max_radius`` times the
       rim's minor semi-axis, of the image smoothed in proportion to the rim's size.
    2. Per ray, every strong dark-to-bright rise (local maximum of the radial derivative whose
       rise exceeds a fraction of the contrast between the dark centre and the mirror's
       scene, with a dark inner side): a fifth first, a tenth when that finds nothing or only
       a silhouette without a core (:data:`RISE_FRACTIONS`; a barrel on a dark box rises
       little); highlights and inner rings of the glass give inner rises, struts and scene
       edges give rises off the common circle.
    3. A vote over circle centres near ``center`` and radii (one vote per ray and radius bin)
       finds the round silhouettes that are dark inside; the **outermost** one supported by at
       least 40 % of the rays is kept (the lens barrel or body, not the glass's inner rings;
       bins within two of a group's outermost are one circle).
    4. The rises near that circle, then a robust ellipse (RANSAC, :func:`.rim.fit_rim`)
       rejects struts and highlights (first on the rises at least ``min_radius`` from
       ``center``, then, if that declines, on those from 3 px: a small lens off ``center`` has
       its near side there); then rounds (2 to :data:`SUBPIXEL_ROUNDS`, until the ellipse
       stops moving) along rays from the ellipse's centre in a narrow window, unsmoothed but
       for 0.7 px: per ray the outermost separate rise (a narrow front ring's inner rise may
       be the steeper), at the centroid of the radial derivative within 1.5 px of its peak;
       a consensus ellipse through them (RANSAC, :data:`SUBPIXEL_INLIER_PX`) leaves out the
       rays where the edge does not contrast and an inner rise stands in.
    5. Declines (:class:`~.errors.EstimationError`) when the centre is not darker than the
       scene, no round silhouette has enough support, the refined one is not round
       (:data:`MAX_ASPECT`), ragged or not dark inside, or the silhouette has no darker core
       (the lens glass; a uniformly dark floor or clutter has none). A silhouette inside a
       declined dark one must lie within it (and, if that one is uniformly dark, be
       concentric with it: its own glass's rings).
    6. A silhouette brighter inside than near its edge (90th percentile of its inner 60 %) is
       a dark surround, e.g. a dark floor, holding the body: when no silhouette is accepted,
       steps 1-5 run once more inside it (to 85 % of its radius), with its interior's level
       as the scene's (the body's edges rise against the body, not against the mirror's
       scene).
    7. If that finds nothing and the surround is uniform, the body's edge may fall to the
       surround's level (a grey front ring on a black floor): per ray the outermost crossing
       from above to below the level halfway between the surround's and its interior's,
       then steps 4-5 on the negated image (:func:`_body_in_surround`).

    Parameters
    ----------
    image : (H, W) or (H, W, 3|4) ndarray
        Grey or BGR(A) image, uint8, uint16 or float.
    rim : RimFit
        The rim (its centre and size bound the search).
    center : (2,) array_like, optional
        Where to look (e.g. the mean of the candidates' self-reflection pixels); default the rim
        centre.
    center_search : float
        The silhouette's centre is sought within this many rim semi-axes of ``center``.
    max_radius, min_radius : float
        Search radii in units of the rim's minor semi-axis.
    rng : int or numpy.random.Generator
        Seed of the RANSAC sampling.
    allow_coreless : bool
        Instead of declining, return the first round dark silhouette that only lacked a darker
        core (``ReflectionFit.core`` False): the calibration keeps it only if its circle is
        camera-sized (:func:`omnicam.calibration.steps.reflection_step`).

    Returns
    -------
    ReflectionFit

    Raises
    ------
    EstimationError
        No camera reflection found (the message says why); the calibration then goes on
        without it.
    ValueError
        Bad arguments.
    """
    coreless, found = None, None
    for k, fraction in enumerate(RISE_FRACTIONS):
        try:
            fit = _detect(
                image, rim, center, center_search, max_radius, min_radius, rng, None, fraction
            )
        except _Coreless as err:
            coreless = coreless or err
            continue
        except EstimationError:
            if k == len(RISE_FRACTIONS) - 1 and coreless is None and found is None:
                raise
            continue
        # the weaker rises may find a silhouette with a core around the one found (or the one
        # without a core): the outermost is the body's (a knurled front ring around dark glass
        # taken for a dark surround, or around its own inner rings)
        inner = found or (coreless.fit if coreless is not None else None)
        if inner is None or (fit.radius > inner.radius + 1.0 and _inside(inner, fit, 1.0)):
            found = fit
    if found is not None:
        return found
    assert coreless is not None  # nothing found and nothing raised: a coreless one was
    if allow_coreless:
        return coreless.fit
    raise EstimationError(str(coreless)) from None


def _detect(image, rim, center, center_search, max_radius, min_radius, rng, scene_level, fraction):
    """:func:`detect_reflection`; ``scene_level`` (grey) replaces the mirror scene's level when
    looking inside a dark surround."""
    if not isinstance(rim, RimFit):
        raise ValueError(
            f"rim must be a RimFit (from detect_rim or fit_rim), got {type(rim).__name__}"
        )
    if not (0 < min_radius < max_radius <= 1.0) or not (0 <= center_search <= 0.5):
        raise ValueError(
            "need 0 < min_radius < max_radius <= 1 and 0 <= center_search <= 0.5 (units of "
            "the rim's semi-axis)"
        )
    gray = to_gray(image)
    r_rim = float(min(rim.axes))
    c0 = np.asarray(rim.center if center is None else center, np.float64).reshape(2)
    if not np.isfinite(c0).all():
        raise ValueError("center must be a finite pixel")
    R_max, R_min = max_radius * r_rim, max(3.0, min_radius * r_rim)
    sig = max(0.7, r_rim / 300.0)
    G = cv2.GaussianBlur(gray, (0, 0), sig)
    n_rays = int(np.clip(2 * np.pi * R_max / 6.0, 180, 720))
    ang = np.linspace(0, 2 * np.pi, n_rays, endpoint=False)
    dr = max(0.5, sig / 2)
    radii = np.arange(0.0, R_max, dr)
    prof = _polar(G, c0, radii, ang)
    # levels: the dark centre and the mirror's scene (a ring well inside the rim)
    centre = prof[:, radii < max(R_min, 0.05 * r_rim)]
    ring = _polar(G, c0, np.linspace(0.7, 0.9, 16) * r_rim, ang)
    near = np.abs(np.diff(_polar(gray, c0, radii[:40], ang), axis=1))
    if min(np.isfinite(a).sum() for a in (centre, ring, near)) < 16:
        raise EstimationError(
            f"no camera reflection found: the place to look, ({c0[0]:.0f}, {c0[1]:.0f}), is "
            f"not in the image"
        )
    dark, scene = float(np.nanmedian(centre)), float(np.nanmedian(ring))
    if scene_level is not None:  # inside a dark surround: its interior is the scene
        scene = float(scene_level)
    contrast = scene - dark
    noise = mad_sigma(near)
    if not (np.isfinite(contrast) and contrast > max(10.0, 4.0 * noise)):
        raise EstimationError(
            f"no camera reflection found: the centre (grey {dark:.0f}) is not clearly darker "
            f"than the mirror's scene (grey {scene:.0f})"
        )
    ri, rj = _rises(prof, dr, fraction * contrast, dark + 0.6 * contrast)
    # rises from 3 px of c0 on: a small lens off c0 has its near side nearer than R_min; they
    # vote, and step 4 tries the rises beyond R_min first (highlights lie near c0), then all
    keep = radii[rj] >= (3.0 if scene_level is None else R_min)  # (not inside a surround)
    ri, rj = ri[keep], rj[keep]
    if len(ri) < 0.3 * n_rays:
        raise EstimationError(
            f"no camera reflection found: too few dark-to-bright edges around ({c0[0]:.0f}, "
            f"{c0[1]:.0f})"
        )
    pts = c0 + radii[rj, None] * np.stack([np.cos(ang[ri]), np.sin(ang[ri])], axis=1)
    far_pts = pts[radii[rj] >= R_min]
    dark_max = dark + 0.6 * contrast

    def dark_inside(rho, c):
        return _dark_inside(G, c, rho, ang[::2], dark_max)

    # 3. vote over centres within center_search of c0 (steps of 1 % of the rim) and radii
    half = float(center_search) * r_rim
    offs = np.linspace(-half, half, int(np.clip(np.ceil(half / (0.01 * r_rim)) + 1, 9, 31)))
    bw = max(2.0, 0.025 * R_max)
    seeds = _vote_circles(pts, ri, c0, offs, bw, R_max, R_min, n_rays, dark_inside)
    fit, first_why, surround, coreless = _try_silhouettes(
        gray,
        G,
        seeds,
        (far_pts, pts) if len(pts) > len(far_pts) else (pts,),
        bw,
        sig,
        (contrast, dark_max),
        rng,
    )
    if fit is not None:
        return fit
    if scene_level is None and surround is not None:
        try:
            return _inside_surround(
                image,
                rim,
                c0,
                center_search,
                min_radius,
                rng,
                fraction,
                (gray, G, surround, bw, sig),
            )
        except _Coreless as err:  # a uniformly dark body in the surround, rather than it
            coreless = err
        except EstimationError:
            pass
    raise coreless or first_why


def _inside_surround(image, rim, c0, center_search, min_radius, rng, fraction, found):
    """Steps 6-7 of :func:`detect_reflection`: the body inside the dark surround of ``found``
    (``gray, G, surround, bw, sig`` of the search that found it), or
    :class:`~.errors.EstimationError` (a :class:`_Coreless` for a uniformly dark body)."""
    gray, G, surround, bw, sig = found
    inner = 0.85 * surround.radius / float(min(rim.axes))
    if not inner > 2.0 * min_radius:
        raise EstimationError("no camera reflection found: the dark surround is too small")
    # 6. the body's edges rise against the surround's interior, not against the mirror's
    # scene; look again inside, once per rise fraction (the body may contrast little with
    # what is around it inside the surround)
    for f in RISE_FRACTIONS[RISE_FRACTIONS.index(fraction) :]:
        try:
            return _detect(
                image, rim, c0, center_search, inner, min_radius, rng, surround.interior, f
            )
        except _Coreless:
            break
        except EstimationError:
            pass
    # 7. a body brighter than the surround at its edge (a grey front ring on a dark floor)
    return _body_in_surround(gray, G, surround, bw, sig, rng)


def _vote_circles(pts, ri, c0, offs, bw, R_max, R_min, n_rays, dark_inside):
    """Step 3 of :func:`detect_reflection`: the round dark silhouettes the rises ``pts`` (on
    rays ``ri`` of ``n_rays`` from ``c0``) support, outermost first, as up to four ``(centre,
    radius)`` seeds.

    One vote per (ray, radius bin of ``bw`` px, two bins overlapping) for each centre
    ``c0 + (ox, oy)`` (``ox``, ``oy`` in ``offs``); a radius counts where at least 40 % of
    the rays vote and ``dark_inside(radius, centre)``.
    """
    nb = int(R_max / bw) + 2
    found = {}  # radius bin -> (support, centre): the best centre for each supported radius
    for ox in offs:
        for oy in offs:
            c = c0 + (ox, oy)
            rad = np.hypot(pts[:, 0] - c[0], pts[:, 1] - c[1])
            b = np.clip((rad / bw).astype(int), 0, nb - 1)
            hist = np.zeros(nb)
            for shift in (0, 1):  # bins of 2 bw, overlapping
                key = np.unique(ri * nb + np.clip(b - shift, 0, nb - 1))
                h = np.bincount(key % nb, minlength=nb)
                hist = np.maximum(hist, np.r_[h[shift:], np.zeros(shift)] if shift else h)
            for j in np.flatnonzero((hist >= 0.4 * n_rays) & (np.arange(nb) * bw >= R_min)):
                if int(j) not in found or hist[j] > found[int(j)][0]:
                    found[int(j)] = (hist[j], c)
    # circles dark inside, outermost first; bins within 2 of a group's outermost are one circle
    # (its best centre); a chain of neighbours is not: a knurled front ring a few bins wide
    # would otherwise merge the barrel's edge with the glass's
    order = [j for j in sorted(found, reverse=True) if dark_inside((j + 1) * bw, found[j][1])]
    circles = []
    for j in order:
        if circles and circles[-1][1] - j <= 2:
            if found[j][0] > found[circles[-1][0]][0]:
                circles[-1] = (j, circles[-1][1])
            continue
        circles.append((j, j))
    if not circles:
        raise EstimationError(
            "no camera reflection found: no round dark silhouette around the image centre "
            "(edges on fewer than 40 % of the rays share a circle that is dark inside)"
        )
    return [(found[j][1], j * bw) for j, _ in circles[:4]]


def _body_in_surround(gray, G, surround, bw, sig, rng):
    """Step 7 of :func:`detect_reflection`: the body inside the dark surround ``surround`` (a
    :class:`_BrightInside`) where its edge falls to the surround's level.

    Only in a uniform surround (the 10-90 % spread of its grey at 0.85-0.93 of its radius
    within half the contrast). Per ray from the surround's centre (within 90 % of its
    radius) the outermost crossing, going out, from above to below the level halfway between
    the surround's and its interior's; a robust ellipse through them; then steps 4-5 on the
    negated image (the fall is a rise there), the core tested on the image itself.
    """
    c, floor, interior = surround.fit.center, surround.shell, surround.interior
    contrast = interior - floor
    if not (contrast > 10.0 and surround.spread < 0.5 * contrast):
        # a textured band is no dark floor or holder (the checkered ground of
        # synthetic.render_environment: spread 1.2 times the contrast; dark floors of the
        # realistic renders with planks, noise and blur: 0.2-0.3)
        raise EstimationError(
            "no camera reflection found: no uniformly dark surround with something brighter inside"
        )
    r_max = 0.9 * surround.radius
    n_rays = int(np.clip(2 * np.pi * r_max / 3.0, 90, 720))
    ang = np.linspace(0, 2 * np.pi, n_rays, endpoint=False)
    dr = max(0.5, sig / 2)
    radii = np.arange(2 * dr, r_max, dr)
    prof = _polar(G, c, radii, ang)
    above = np.nan_to_num(prof, nan=-np.inf) > floor + 0.5 * contrast
    seen = above.any(axis=1)
    last = len(radii) - 1 - np.argmax(above[:, ::-1], axis=1)
    ok = seen & (last < len(radii) - 1)
    if ok.sum() < 0.4 * n_rays:
        raise EstimationError("no camera reflection found: no body's edge inside the surround")
    e = np.stack([np.cos(ang[ok]), np.sin(ang[ok])], axis=1)
    pts = c + radii[last[ok], None] * e
    try:
        fit0 = fit_rim(pts, threshold=max(1.0, 2 * sig), rng=rng)
    except ValueError as err:
        raise EstimationError(f"no camera reflection found: {err}") from None
    r0 = float(np.mean(fit0.axes))
    neg = 255.0 - gray
    try:  # on the negated image the surround is bright and nothing needs to be dark inside
        fit = _refine_silhouette(
            neg, 255.0 - G, pts, fit0.center, r0 - bw, bw, sig, (contrast, np.inf), rng
        )
    except _Coreless as err:
        fit = err.fit
    if not fit.radius < r_max:
        raise EstimationError("no camera reflection found: the body fills the surround")
    core_level, shell_level = _core_and_shell(G, fit.center, fit.radius, ang[::4])
    margin = max(3.0, 0.05 * contrast)
    if core_level < shell_level - margin:
        return dataclasses.replace(fit, core=True)
    if core_level > shell_level + margin:  # a highlight on dark glass: the surround stands
        raise EstimationError(
            f"no camera reflection found: the spot inside the dark surround is brighter inside "
            f"(grey {core_level:.0f}) than near its edge ({shell_level:.0f}): a highlight"
        )
    raise _Coreless(  # a uniformly dark body: the caller decides, as for any such silhouette
        f"no camera reflection found: the body inside the dark surround has no darker core "
        f"(grey {core_level:.0f} inside, {shell_level:.0f} near its edge)",
        dataclasses.replace(fit, core=False),
    )


def _try_silhouettes(gray, G, seeds, point_sets, bw, sig, levels, rng):
    """Steps 4-5 on the voted circles ``seeds`` (centre, radius), outermost first.

    Returns ``(fit, first_why, surround, coreless)``: the first silhouette accepted (else
    None), the first reason one was declined, the first dark surround holding something
    brighter (:class:`_BrightInside`) and the first silhouette without a darker core
    (:class:`_Coreless`).
    """
    first_why, surround, coreless = None, None, None
    for c_est, r_est in seeds:
        for p in point_sets:
            try:
                fit = _refine_silhouette(gray, G, p, c_est, r_est, bw, sig, levels, rng)
                if coreless is None or _within(fit, coreless, max(1.0, 2.0 * sig)):
                    return fit, first_why, surround, coreless
                # not a body inside the dark silhouette but an ellipse that wandered off an
                # inner ring (struts, highlights)
                break
            except _BrightInside as err:  # a dark surround (e.g. a dark floor) holding the body
                first_why, surround = first_why or err, surround or err
                coreless = coreless or err
                break
            except _Coreless as err:  # dark glass or a dark floor: the caller decides
                first_why, coreless = first_why or err, coreless or err
                break
            except EstimationError as err:  # e.g. a square box behind the barrel: try inside it
                first_why = first_why or err
    return None, first_why, surround, coreless


def _within(fit, outer, tol):
    """Whether ``fit`` may be what the declined dark silhouette ``outer`` (a :class:`_Coreless`)
    holds: inside it (:func:`_inside`) and, unless ``outer`` is brighter inside (a dark
    surround holding a body, :class:`_BrightInside`), concentric with it to a tenth of its
    radius: a uniformly dark silhouette holds only its own glass's rings."""
    if not isinstance(outer, _BrightInside):
        off = float(np.linalg.norm(fit.center - outer.fit.center))
        if off > max(tol, 0.1 * outer.fit.radius):
            return False
    return _inside(fit, outer.fit, tol)


def _inside(fit, outer, tol):
    """Whether the whole ellipse through ``fit``'s outline points lies within ``tol`` px outside
    ``outer``'s outline (radii about ``outer``'s centre, interpolated over the angle)."""
    try:
        ell = fit_rim(fit.points, robust=False)
    except ValueError:
        return False
    ang = np.linspace(0.0, 2.0 * np.pi, 72, endpoint=False)
    e = np.stack([np.cos(ang), np.sin(ang)], axis=1)
    r_ray = 1.0 / np.linalg.norm(e @ np.linalg.inv(ell.shape_matrix).T, axis=1)
    curve = np.asarray(ell.center) + r_ray[:, None] * e

    def polar(p):
        d = np.asarray(p) - outer.center
        return np.arctan2(d[:, 1], d[:, 0]), np.hypot(d[:, 0], d[:, 1])

    ta, ra = polar(outer.points)
    order = np.argsort(ta)
    tb, rb = polar(curve)
    limit = np.interp(tb, ta[order], ra[order], period=2.0 * np.pi)
    return bool(np.all(rb <= limit + tol))


def _outermost_peak(d, strength=0.3, valley=0.5):
    """Per row of the radial derivative ``d`` (inside to outside), the index of the outermost
    rise: the steepest sample, or a local maximum outside it of at least ``strength`` times its
    height that is a separate edge (between the two, ``d`` falls below ``valley`` times the
    outer peak's height).

    The steepest sample alone is not the silhouette's edge on a knurled front ring: where a
    bright tooth meets dark glass the inner rise (the glass's edge) can be the steeper one.
    A shoulder of one blurred edge has no valley and does not count.
    """
    n = d.shape[1]
    d = np.where(np.isfinite(d), d, -np.inf)
    m = np.clip(np.argmax(d, axis=1), 1, n - 2)
    idx = np.arange(n)[None, :]
    peak = np.zeros(d.shape, bool)
    peak[:, 1:-1] = (d[:, 1:-1] > 0) & (d[:, 1:-1] >= d[:, :-2]) & (d[:, 1:-1] > d[:, 2:])
    low = np.minimum.accumulate(np.where(idx >= m[:, None], d, np.inf), axis=1)
    outer = (
        peak
        & (idx > m[:, None])
        & (d >= strength * d.max(axis=1, keepdims=True))
        & (low < valley * d)
    )
    last = n - 1 - np.argmax(outer[:, ::-1], axis=1)
    return np.where(outer.any(axis=1), last, m)


class _Coreless(EstimationError):
    """A round dark silhouette without a darker core; ``fit`` is its :class:`ReflectionFit`."""

    def __init__(self, message, fit):
        super().__init__(message)
        self.fit = fit


class _BrightInside(_Coreless):
    """A round dark silhouette whose interior is brighter than its edge band: a dark surround
    (a dark floor, a dark holder) with something brighter, the camera's body, inside; or dark
    glass with bright highlights (``fit``, when nothing is found inside)."""

    def __init__(self, message, fit, interior, shell, spread):
        super().__init__(message, fit)
        self.radius, self.interior = float(fit.radius), float(interior)
        # the level of its edge band (0.75-0.95 of its radius), the 10-90 % spread of 0.85-0.93
        self.shell, self.spread = float(shell), float(spread)


def _refine_silhouette(gray, G, pts, c_est, r_est, bw, sig, levels, rng):
    """Steps 4-5 of :func:`detect_reflection` for one voted circle; ``levels`` is the contrast
    (scene minus dark centre) and the grey below which a pixel is dark."""
    contrast, dark_max = levels

    rad = np.hypot(pts[:, 0] - c_est[0], pts[:, 1] - c_est[1])
    near = np.abs(rad - (r_est + bw)) <= 2.5 * bw
    if near.sum() < 12:
        raise EstimationError("no camera reflection found: too few edge points on the circle")
    try:
        fit = fit_rim(pts[near], threshold=max(1.0, 2 * sig), rng=rng)
    except ValueError as err:
        raise EstimationError(f"no camera reflection found: {err}") from None
    # 4. subpixel rounds along rays from the ellipse's centre, narrow window
    G1 = cv2.GaussianBlur(gray, (0, 0), 0.7)
    n_rays = int(np.clip(2 * np.pi * float(fit.axes.mean()) / 2.0, 90, 1440))
    ang = np.linspace(0, 2 * np.pi, n_rays, endpoint=False)
    for k in range(SUBPIXEL_ROUNDS):
        c, axes = np.asarray(fit.center), np.asarray(fit.axes)
        e = np.stack([np.cos(ang), np.sin(ang)], axis=1)
        # radius of the ellipse along each ray: |S^-1 e| = 1 / r
        r_ray = 1.0 / np.linalg.norm(e @ np.linalg.inv(fit.shape_matrix).T, axis=1)
        w = max(3.0, 3.0 * fit.rms + 2.0 * sig)
        tau = np.arange(-w, w + 1e-9, 0.25)
        mx = (c[0] + e[:, :1] * (r_ray[:, None] + tau)).astype(np.float32)
        my = (c[1] + e[:, 1:] * (r_ray[:, None] + tau)).astype(np.float32)
        f = cv2.remap(
            G1, mx, my, cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT, borderValue=np.nan
        )
        d = np.gradient(f, axis=1)
        rise = f[:, -1] - f[:, 0]
        dd = np.where(np.isfinite(d), d, -np.inf)
        j = _outermost_peak(dd)
        good = np.isfinite(rise) & (rise > 0.15 * contrast) & np.isfinite(dd.max(axis=1))
        # the centroid of the rise within 1.5 px of its steepest sample: the parabola through
        # the peak scatters by 0.15 px on an exact anti-aliased disk, the centroid by 0.01 px
        dn = np.nan_to_num(d, nan=0.0)
        win = (np.abs(tau[None, :] - tau[j][:, None]) <= 1.5) & (dn > 0)
        wsum = (dn * win).sum(axis=1)
        loc = (dn * win * tau[None, :]).sum(axis=1) / np.where(wsum > 0, wsum, 1.0)
        p = c + (r_ray + loc)[:, None] * e
        p, rise_k = p[good], rise[good]
        if len(p) < 12:
            raise EstimationError("no camera reflection found: its outline faded on refinement")
        try:
            # a consensus of its own: where the barrel's edge does not contrast with what is
            # behind it (a strut, a patch of the scene as dark as the ring), the ray's only
            # rise is an inner one (the glass's edge) a few px inside, which a least-squares
            # ellipse would follow
            fit = fit_rim(p, threshold=SUBPIXEL_INLIER_PX, rng=rng)
        except ValueError as err:
            raise EstimationError(f"no camera reflection found: {err}") from None
        moved = float(np.abs(np.r_[fit.center - c, fit.axes - axes]).max())
        if k >= 1 and moved < 0.05:
            break
    quality = len(fit.points) / n_rays
    radius = float(np.mean(fit.axes))
    core_level, shell_level = _core_and_shell(G, fit.center, radius, ang[::4])
    edge_rise = float(np.median(rise_k))
    why = None
    if quality < 0.4:
        why = f"its outline is found on only {100 * quality:.0f} % of the rays (need 40 %)"
    elif fit.axes[0] > MAX_ASPECT * fit.axes[1]:
        why = f"the silhouette is not round (axes {fit.axes[0]:.1f} and {fit.axes[1]:.1f} px)"
    elif fit.rms > max(0.75, 0.02 * radius):
        why = f"the silhouette's edge is ragged (RMS {fit.rms:.2f} px to an ellipse)"
    elif not _dark_inside(G, fit.center, radius, ang[::2], dark_max):
        # the vote tested its own circle; the refined one may have moved to a dark scene line
        # around the camera (a thin ring is dark only along itself)
        why = "the refined silhouette is not dark inside (a dark line, not a body)"
    if why is not None:
        raise EstimationError(f"no camera reflection found: {why}")
    if not core_level < shell_level - max(3.0, 0.05 * contrast):
        why = (
            f"the silhouette has no darker core (grey {core_level:.0f} inside, "
            f"{shell_level:.0f} near its edge): no lens glass, e.g. a dark floor"
        )
    out = ReflectionFit(
        points=fit.points,
        center=fit.center,
        radius=radius,
        rms=float(fit.rms),
        quality=float(quality),
        contrast=edge_rise,
        core=why is None,
    )
    if why is not None:
        inside = _polar(G, fit.center, np.linspace(0.0, 0.6, 16) * radius, ang[::2])
        interior = float(np.nanpercentile(inside, 90))
        if interior > shell_level + max(3.0, 0.05 * contrast):  # brighter things inside
            band = _polar(G, fit.center, np.linspace(0.85, 0.93, 4) * radius, ang)
            spread = float(np.subtract(*np.nanpercentile(band, [90, 10])))
            raise _BrightInside(
                f"no camera reflection found: {why}", out, interior, shell_level, spread
            )
        raise _Coreless(f"no camera reflection found: {why}", out)
    return out
