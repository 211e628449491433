"""Central approximations of the exact non-central rig: the central models that fit it best.

Tools such as ``cv2.omnidir``, Kalibr, camodocal and OCamCalib only know *central* models: one
viewpoint. A misaligned rig has none (paper section 2.2), so each fit here is the central
model that best matches the exact rig in the least-squares sense over the pixels that see the
mirror (inside the rim ellipse, and inside the frame when ``image_size`` is known), and states
what it costs: the RMS and maximum distance, in pixels, between the exact pixel of each sampled
ray and the pixel the central model gives for it. An aligned rig *is* central (the unified
model with the camera at the lower focus), so its fit is exact to numerical precision.

The unified (Mei) model of ``cv2.omnidir`` (:func:`fit_omnidir`)
    ``X_omni = M (X_mirror - origin)``, ``Xs = X_omni / |X_omni|``,
    ``x = Xs_x / (Xs_z + xi)``, ``y = Xs_y / (Xs_z + xi)``, radial-tangential ``D = (k1, k2, p1,
    p2)`` on ``(x, y)``, then ``u = fx xd + s yd + cx``, ``v = fy yd + cy`` (``K`` with skew
    ``s = K[0, 1]``). This is exactly what ``cv2.omnidir.projectPoints(X_omni, 0, 0, K, xi, D)``
    computes (checked in ``tests/test_export.py``), and Kalibr's ``omni`` + ``radtan`` and
    camodocal's ``MEI`` model are the same formula without skew.

**Handedness.** ``M`` is orthogonal with ``det M = -1``: the image of a mirror is mirror-reversed.
In the aligned rig a pixel right of the centre sees a direction with ``+X`` (mirror frame) and a
pixel below it ``+Y``, while the image centre sees the nadir ``-Z``; the unified model with
positive focal lengths sends ``+x_omni`` right, ``+y_omni`` down and ``+z_omni`` to the centre,
so ``M = diag(1, 1, -1)`` for the aligned rig, a reflection. No proper rotation can do it with
positive ``fx, fy``. Use ``M`` as given (``X_omni = M (X - origin)``); if a tool insists on a
rotation, pass ``det(M) M`` and negate the point coordinates' sign convention it uses for the
camera's z axis (points become ``-X_omni``: the same direction on the unit sphere's opposite
side, which the unified model does not treat the same way, so prefer ``M``).

OCamCalib's Scaramuzza model (:func:`fit_ocamcalib`) has its own frame: x along image rows
(down), y along columns (right), z out of the image, so there too ``det M = -1`` in general
(``[[0, 1, 0], [1, 0, 0], [0, 0, 1]]`` for the aligned rig).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import cv2
import numpy as np

from .._typing import FloatArray
from .._validate import positive_number

__all__ = [
    "F_OMNI",
    "OcamFit",
    "OmnidirFit",
    "fit_ocamcalib",
    "fit_omnidir",
    "ocam_cam2world",
    "ocam_world2cam",
    "omnidir_project",
    "sample_pixels",
]

#: ``M`` of the aligned rig (see the module notes on handedness).
F_OMNI = np.diag([1.0, 1.0, -1.0])


# -- samples of the exact model -------------------------------------------------------------------
def sample_pixels(camera, max_points=20000) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Integer pixels that see the mirror (in the frame when ``image_size`` is known), evenly
    thinned to at most ``max_points``; returns ``(pixels, origins, directions)`` (mirror frame)."""
    pix = camera.mirror_pixels()
    if camera.image_size is not None:
        w, h = camera.image_size
        inside = (pix[:, 0] >= 0) & (pix[:, 0] <= w - 1) & (pix[:, 1] >= 0) & (pix[:, 1] <= h - 1)
        pix = pix[inside]
    if len(pix) < 50:
        raise ValueError(
            "camera: fewer than 50 pixels see the mirror inside the frame; nothing to fit"
        )
    if len(pix) > max_points:
        idx = np.round(np.linspace(0, len(pix) - 1, max_points)).astype(np.int64)
        pix = pix[idx]
    P, d = camera.unproject(pix)
    ok = np.isfinite(d).all(axis=1)
    return pix[ok], P[ok], d[ok]


def _target_directions(P, d, origin, depth):
    """Directions from ``origin`` of the scene points the rays show: ``d`` itself at infinity,
    else the point at Euclidean distance ``depth`` from ``origin`` along each ray."""
    if depth is None:
        return d
    w = P - origin
    b = np.einsum("ij,ij->i", w, d)
    disc = b * b - (np.einsum("ij,ij->i", w, w) - depth * depth)
    t = -b + np.sqrt(np.maximum(disc, 0.0))
    return w + t[:, None] * d


def _check_depth(depth):
    if depth is None:
        return None
    return positive_number(depth, "depth", "None or a positive distance")


def _errors(pred, pix):
    """RMS and max pixel distance over the rows the model can map, and how many it cannot."""
    e = np.linalg.norm(pred - pix, axis=1)
    bad = ~np.isfinite(e)
    if bad.all():
        return math.inf, math.inf, int(bad.sum())
    good = e[~bad]
    return float(np.sqrt(np.mean(good**2))), float(good.max()), int(bad.sum())


# -- the unified (Mei) model -------------------------------------------------------------------
def omnidir_project(points, K, xi, D=None) -> FloatArray:
    """``cv2.omnidir.projectPoints(points, 0, 0, K, xi, D)`` in numpy, NaN where undefined.

    Parameters
    ----------
    points : (N, 3) array_like
        Points (or directions) in the omnidir camera frame.
    K : (3, 3) array_like
        ``[[fx, s, cx], [0, fy, cy], [0, 0, 1]]``.
    xi : float
    D : (4,) array_like or None
        ``k1, k2, p1, p2``.

    Returns
    -------
    (N, 2) float64 ndarray
        NaN for points with ``Xs_z + xi <= 0`` (behind the model's projection centre), where
        the model is not defined.
    """
    X = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    Xs = X / np.linalg.norm(X, axis=1, keepdims=True)
    z = Xs[:, 2] + xi
    z = np.where(z > 0, z, np.nan)
    x, y = Xs[:, 0] / z, Xs[:, 1] / z
    k1, k2, p1, p2 = (0.0, 0.0, 0.0, 0.0) if D is None else np.ravel(D)[:4]
    r2 = x * x + y * y
    rad = 1.0 + k1 * r2 + k2 * r2 * r2
    xd = x * rad + 2.0 * p1 * x * y + p2 * (r2 + 2.0 * x * x)
    yd = y * rad + p1 * (r2 + 2.0 * y * y) + 2.0 * p2 * x * y
    K = np.asarray(K, dtype=np.float64)
    return np.stack([K[0, 0] * xd + K[0, 1] * yd + K[0, 2], K[1, 1] * yd + K[1, 2]], axis=1)


@dataclass(frozen=True)
class OmnidirFit:
    """The unified (Mei) model closest to the exact rig, and what it costs.

    Attributes
    ----------
    K : (3, 3) ndarray
        ``[[fx, s, cx], [0, fy, cy], [0, 0, 1]]`` (``s = 0`` when fitted with ``skew=False``).
    xi : float
    D : (1, 4) ndarray
        ``k1, k2, p1, p2`` as ``cv2.omnidir`` takes them.
    M : (3, 3) ndarray
        Orthogonal, ``det M = -1`` (module notes): ``X_omni = M (X_mirror - origin)``.
    origin : (3,) ndarray
        The model's single viewpoint in the mirror frame: the best-fit viewpoint (section 4.1).
    rms_px, max_px : float
        Distance between the exact pixel and the model's pixel of each sampled ray, over every
        integer pixel that sees the mirror (in the frame), not only those fitted.
    n_points : int
        Pixels in that evaluation; ``extra["undefined_points"]`` of them (pixels whose
        direction is behind the model's projection centre) have no model pixel and are left
        out of ``rms_px`` and ``max_px`` (:meth:`summary` says so).
    depth : float or None
        The scene the fit is for: ``None`` at infinity, else the sphere of that radius about
        ``origin``.
    """

    K: np.ndarray
    xi: float
    D: np.ndarray
    M: np.ndarray
    origin: np.ndarray
    rms_px: float
    max_px: float
    n_points: int
    depth: float | None = None
    extra: dict = field(default_factory=dict, repr=False)

    def summary(self) -> str:
        """One line: the model, the scene, its errors and over how many pixels."""
        where = "at infinity" if self.depth is None else f"at {self.depth:g} from the origin"
        undefined = self.extra.get("undefined_points", 0)
        over = f"over {self.n_points - undefined} pixels"
        if undefined:
            over += (
                f" (the unified model is undefined at {undefined} more: their directions are "
                f"behind its projection centre)"
            )
        return (
            f"unified (Mei) model, scene {where}: xi = {self.xi:.6f}, RMS {self.rms_px:.3g} px, "
            f"max {self.max_px:.3g} px {over}"
        )

    def as_tuple(self) -> tuple[FloatArray, float, FloatArray, FloatArray, FloatArray, float]:
        """``(K, xi, D, M, origin, rms_px)``, what :meth:`to_omnidir` returns."""
        return self.K, self.xi, self.D, self.M, self.origin, self.rms_px

    def project(self, points_mirror) -> FloatArray:
        """Pixels of mirror-frame points (or, at infinity, directions) through the fitted model
        with ``cv2.omnidir.projectPoints``."""
        X = np.asarray(points_mirror, dtype=np.float64).reshape(-1, 3)
        if self.depth is not None:
            X = X - self.origin
        Xo = (X @ self.M.T).reshape(1, -1, 3)
        ip, _ = cv2.omnidir.projectPoints(
            Xo, np.zeros(3), np.zeros(3), self.K, float(self.xi), self.D
        )
        return np.asarray(ip, np.float64).reshape(-1, 2)


def _omni_unpack(p, skew):
    if skew:
        fx, fy, s, cx, cy = p[:5]
        rest = p[5:]
    else:
        fx, fy, cx, cy = p[:4]
        s = 0.0
        rest = p[4:]
    xi = rest[0]
    D = np.array(rest[1:5], dtype=np.float64).reshape(1, 4)
    w = np.array(rest[5:8], dtype=np.float64)
    K = np.array([[fx, s, cx], [0.0, fy, cy], [0.0, 0.0, 1.0]])
    return K, float(xi), D, w


def _omni_linear_start(Y, pix, xi):
    """K (with skew) by linear least squares for a given ``xi``, no distortion, ``M = F_OMNI``."""
    Ys = Y / np.linalg.norm(Y, axis=1, keepdims=True)
    z = Ys[:, 2] + xi
    ok = z > 1e-3
    x, y = Ys[ok, 0] / z[ok], Ys[ok, 1] / z[ok]
    one = np.ones_like(x)
    A = np.stack([x, y, one], axis=1)
    cu, *_ = np.linalg.lstsq(A, pix[ok, 0], rcond=None)
    B = np.stack([y, one], axis=1)
    cv_, *_ = np.linalg.lstsq(B, pix[ok, 1], rcond=None)
    res = np.concatenate([A @ cu - pix[ok, 0], B @ cv_ - pix[ok, 1]])
    cost = float(np.mean(res**2)) if ok.mean() > 0.99 else math.inf
    return cost, (cu[0], cv_[0], cu[1], cu[2], cv_[1])


def fit_omnidir(camera, depth=None, skew=True, distortion=True, max_points=20000) -> OmnidirFit:
    """The unified (Mei) model of ``cv2.omnidir`` closest to the exact rig.

    Least squares over a grid of pixels (:func:`sample_pixels`): each pixel's exact ray
    (eqs. 6-19) gives the direction it sees -- or, with ``depth``, the point at that distance
    from the best-fit viewpoint along the ray -- and the model's parameters ``fx, fy, s, cx, cy,
    xi, k1, k2, p1, p2`` and the orientation ``M`` are chosen so that projecting that direction
    lands on the pixel. Started from a linear fit of ``K`` over a scan of ``xi``, refined with
    ``scipy.optimize.least_squares`` using the analytic Jacobian ``cv2.omnidir.projectPoints``
    returns.

    Parameters
    ----------
    camera : MisalignedHyperbolicCamera
    depth : float or None
        ``None``: scene at infinity (directions). A positive number: the scene on the sphere of
        that radius about the best-fit viewpoint.
    skew : bool
        Fit the skew ``K[0, 1]`` (``cv2.omnidir`` has it; Kalibr and camodocal do not).
    distortion : bool
        Fit ``D``; else ``D = 0``.
    max_points : int
        Pixels used for the fit; the reported errors use every pixel that sees the mirror.

    Returns
    -------
    OmnidirFit
    """
    from scipy.optimize import least_squares  # lazy: scipy comes with scikit-image

    depth = _check_depth(depth)
    pix, P, d = sample_pixels(camera, max_points)
    origin = np.array(camera.best_fit_viewpoint()[0], dtype=np.float64)
    Y0 = _target_directions(P, d, origin, depth)
    Y0 = Y0 / np.linalg.norm(Y0, axis=1, keepdims=True)
    Yf = Y0 @ F_OMNI.T
    # xi scan with a linear K, then the full nonlinear fit
    best = min(
        (_omni_linear_start(Yf, pix, xi) + (xi,) for xi in np.linspace(0.3, 1.5, 49)),
        key=lambda t: t[0],
    )
    fx, fy, s, cx, cy = best[1]
    xi0 = best[2]
    head = [fx, fy, s, cx, cy] if skew else [fx, fy, cx, cy]
    p0 = np.array(head + [xi0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0])
    n_k = 5 if skew else 4
    free = np.ones(p0.size, bool)
    if not distortion:
        free[n_k + 1 : n_k + 5] = False
    # Jacobian columns of cv2.omnidir.projectPoints: om(3), T(3), fx, fy, s, cx, cy, xi, D(4)
    jcols_all = ([6, 7, 8, 9, 10] if skew else [6, 7, 9, 10]) + [11, 12, 13, 14, 15, 0, 1, 2]
    jcols = np.array(jcols_all)[free]
    Yo = Yf.reshape(1, -1, 3)
    target = pix.reshape(-1)

    def full(q):
        p = p0.copy()
        p[free] = q
        return p

    def model(q):
        K, xi, D, w = _omni_unpack(full(q), skew)
        ip, J = cv2.omnidir.projectPoints(Yo, w, np.zeros(3), K, xi, D)
        return ip.reshape(-1), J

    def resid(q):
        r = model(q)[0] - target
        return np.where(np.isfinite(r), r, 1e3)

    def jac(q):
        return model(q)[1][:, jcols]

    q0 = p0[free]
    sol = least_squares(
        resid,
        q0,
        jac=jac,
        method="lm",
        xtol=1e-15,
        ftol=1e-15,
        gtol=1e-15,
        max_nfev=400,
        x_scale="jac",
    )
    K, xi, D, w = _omni_unpack(full(sol.x), skew)
    M = cv2.Rodrigues(w)[0] @ F_OMNI
    # errors over every pixel that sees the mirror
    epix, eP, ed = sample_pixels(camera, max_points=400000)
    eY = _target_directions(eP, ed, origin, depth)
    pred = omnidir_project(eY @ M.T, K, xi, D)
    rms, mx, n_bad = _errors(pred, epix)
    return OmnidirFit(
        K=K,
        xi=xi,
        D=D,
        M=M,
        origin=origin,
        rms_px=rms,
        max_px=mx,
        n_points=len(epix),
        depth=depth,
        extra={"undefined_points": n_bad, "fit_rms_px": float(np.sqrt(np.mean(sol.fun**2)))},
    )


# -- OCamCalib's Scaramuzza model --------------------------------------------------------------
def ocam_world2cam(points, invpol, xc, yc, c, d, e) -> FloatArray:
    """OCamCalib's ``world2cam``: ocam-frame points -> pixels ``(x=column, y=row)``.

    ``theta = atan(Z / sqrt(X^2 + Y^2))``, ``rho = sum invpol[i] theta^i``,
    ``row = c x + d y + xc``, ``col = e x + y + yc`` with ``(x, y) = rho (X, Y) / |(X, Y)|``.
    Returned as OpenCV ``(column, row)`` pairs.
    """
    X = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    norm = np.hypot(X[:, 0], X[:, 1])
    theta = np.arctan2(X[:, 2], norm)
    rho = np.polynomial.polynomial.polyval(theta, invpol)
    with np.errstate(invalid="ignore", divide="ignore"):
        x = np.where(norm > 0, X[:, 0] / norm * rho, 0.0)
        y = np.where(norm > 0, X[:, 1] / norm * rho, 0.0)
    row = x * c + y * d + xc
    col = x * e + y + yc
    return np.stack([col, row], axis=1)


def ocam_cam2world(pixels, pol, xc, yc, c, d, e) -> FloatArray:
    """OCamCalib's ``cam2world``: pixels ``(column, row)`` -> unit ocam-frame directions."""
    px = np.asarray(pixels, dtype=np.float64).reshape(-1, 2)
    invdet = 1.0 / (c - d * e)
    xp = invdet * ((px[:, 1] - xc) - d * (px[:, 0] - yc))
    yp = invdet * (-e * (px[:, 1] - xc) + c * (px[:, 0] - yc))
    r = np.hypot(xp, yp)
    zp = np.polynomial.polynomial.polyval(r, pol)
    v = np.stack([xp, yp, zp], axis=1)
    return v / np.linalg.norm(v, axis=1, keepdims=True)


def _shift_poly(coef, shift):
    """Coefficients in powers of ``x`` of ``sum coef[k] (x + shift)^k`` (increasing powers)."""
    out = np.zeros(len(coef))
    for k, a in enumerate(coef):
        for j in range(k + 1):
            out[j] += a * math.comb(k, j) * shift ** (k - j)
    return out


@dataclass(frozen=True)
class OcamFit:
    """OCamCalib's model closest to the exact rig (scene at infinity), and what it costs.

    ``pol`` (cam2world, ``a1 = 0`` as OCamCalib fits it) and ``invpol`` (world2cam), increasing
    powers; ``xc, yc`` the centre as row and column; ``c, d, e`` the affine parameters;
    ``M`` with ``X_ocam = M X_mirror`` (directions). ``world2cam_*`` are pixel errors of
    world2cam on the exact directions, over the ``n_points`` pixels that see the mirror;
    ``cam2world_*`` are the pixel errors of the exact model projecting the directions cam2world
    returns, over all but ``cam2world_unseen`` of them: pixels next to the rim to which
    cam2world gives a direction above the mirror's rim (its horizon), which this rig does not
    see, so no exact pixel compares.
    """

    pol: np.ndarray
    invpol: np.ndarray
    xc: float
    yc: float
    c: float
    d: float
    e: float
    M: np.ndarray
    world2cam_rms_px: float
    world2cam_max_px: float
    cam2world_rms_px: float
    cam2world_max_px: float
    n_points: int
    cam2world_unseen: int = 0

    def summary(self) -> str:
        """One line: both mappings' errors, and over how many pixels each."""
        line = (
            f"world2cam RMS {self.world2cam_rms_px:.3g} px, max {self.world2cam_max_px:.3g} px "
            f"over {self.n_points} pixels; cam2world RMS {self.cam2world_rms_px:.3g} px, max "
            f"{self.cam2world_max_px:.3g} px over {self.n_points - self.cam2world_unseen} pixels"
        )
        if self.cam2world_unseen:
            line += (
                f" (at {self.cam2world_unseen} more, next to the rim, cam2world gives a "
                f"direction above the mirror's rim, which this rig does not see)"
            )
        return line


def fit_ocamcalib(camera, n_invpol=12, n_pol=5, max_points=5000, omnidir=None) -> OcamFit:
    """OCamCalib's Scaramuzza model closest to the exact rig, at infinity.

    The world2cam side (centre, affine ``c, d, e``, orientation ``M`` and ``invpol``) is fitted
    by nonlinear least squares in pixels, started from the unified fit (:func:`fit_omnidir`,
    passed as ``omnidir`` or computed); ``pol`` is then the least-squares polynomial
    ``z(rho) = rho tan(theta)`` of the fitted world2cam with ``a1 = 0``, as OCamCalib has it.
    """
    from scipy.optimize import least_squares

    om = omnidir if omnidir is not None else fit_omnidir(camera, skew=False)
    pix, _, dirs = sample_pixels(camera, max_points)
    # the ocam frame from the omnidir one: x_ocam = y_omni, y_ocam = x_omni, z_ocam = -z_omni
    swap = np.array([[0.0, 1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, -1.0]])
    M0 = swap @ om.M
    xc0, yc0 = om.K[1, 2], om.K[0, 2]
    O0 = dirs @ M0.T
    theta0 = np.arctan2(O0[:, 2], np.hypot(O0[:, 0], O0[:, 1]))
    rho0 = np.hypot(pix[:, 0] - yc0, pix[:, 1] - xc0)
    # rho as a polynomial of s = theta + pi/2 without a constant term, so that the nadir maps
    # to the centre (rho = 0) and the fit is well conditioned; converted to powers of theta
    # for the file at the end
    V = np.vander(theta0 + math.pi / 2, n_invpol, increasing=True)[:, 1:]
    inv0, *_ = np.linalg.lstsq(V, rho0, rcond=None)
    p0 = np.concatenate([[xc0, yc0, 1.0, 0.0, 0.0, 0.0, 0.0], inv0])

    def unpack(p):
        # no turn about the ocam z axis: the affine c, d, e already turns the image
        xc, yc, c, d, e = p[:5]
        M = cv2.Rodrigues(np.array([p[5], p[6], 0.0]))[0] @ M0
        shifted = np.concatenate([[0.0], p[7:]])
        inv = _shift_poly(shifted, math.pi / 2)
        return xc, yc, c, d, e, M, inv

    def resid(p):
        xc, yc, c, d, e, M, inv = unpack(p)
        r = (ocam_world2cam(dirs @ M.T, inv, xc, yc, c, d, e) - pix).reshape(-1)
        return np.where(np.isfinite(r), r, 1e3)

    sol = least_squares(
        resid, p0, method="lm", xtol=1e-14, ftol=1e-14, max_nfev=2000, x_scale="jac"
    )
    xc, yc, c, d, e, M, invpol = unpack(sol.x)
    # pol: cam2world along the fitted world2cam, z = rho tan(theta), a1 = 0
    th = np.linspace(-math.pi / 2 + 1e-3, float(theta0.max()) + 0.02, 400)
    rho = np.polynomial.polynomial.polyval(th, invpol)
    z = rho * np.tan(th)
    powers = [0] + list(range(2, n_pol))
    A = np.stack([rho**k for k in powers], axis=1)
    coef, *_ = np.linalg.lstsq(A, z, rcond=None)
    pol = np.zeros(n_pol)
    pol[powers] = coef
    # errors over every pixel that sees the mirror
    epix, _, ed = sample_pixels(camera, max_points=400000)
    w_rms, w_max, _ = _errors(ocam_world2cam(ed @ M.T, invpol, xc, yc, c, d, e), epix)
    back = ocam_cam2world(epix, pol, xc, yc, c, d, e) @ M  # M orthogonal: M^T x as rows
    c_rms, c_max, c_unseen = _errors(camera.project_directions(back), epix)
    return OcamFit(
        pol=pol,
        invpol=invpol,
        xc=float(xc),
        yc=float(yc),
        c=float(c),
        d=float(d),
        e=float(e),
        M=M,
        world2cam_rms_px=w_rms,
        world2cam_max_px=w_max,
        cam2world_rms_px=c_rms,
        cam2world_max_px=c_max,
        n_points=len(epix),
        cam2world_unseen=c_unseen,
    )
