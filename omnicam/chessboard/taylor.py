"""Scaramuzza's generic central model (OCamCalib's Taylor polynomial), fitted from chessboards.

The model (Scaramuzza, Martinelli, Siegwart, "A toolbox for easily calibrating omnidirectional
cameras", IROS 2006, eqs. 1-5): the pixel ``p`` of the sensor point ``s = (u, v)`` is

    p = A s + (x_c, y_c),    A = [[c, d], [e, 1]]                              (eq. 5)

and sees the ray, in the camera frame,

    (u, v, f(rho)),   rho = |s|,   f(rho) = a0 + a2 rho^2 + ... + aN rho^N          (eq. 3)

(``a1 = 0``: the profile is smooth at the axis). It describes any central camera whose
pixels' rays are symmetric about an axis: a catadioptric rig with any mirror of revolution
seen from its single viewpoint, or approximately one that is nearly central.

The fit follows the toolbox: for a candidate centre, the two-step linear calibration (eqs.
7-14: each view's ``r1, r2`` and ``t1, t2`` from the third row of ``s x P = 0``, then the
polynomial and every ``t3`` by linear least squares); the centre is searched on a shrinking grid
(section 4.2); then centre, affine, polynomial and poses are refined jointly on the reprojection
error by Levenberg-Marquardt (Urban, Leitloff, Hinz, "Improved wide-angle, fisheye and
omnidirectional camera calibration", ISPRS J. 2015), for each degree, keeping the best.

Internally ``rho`` and ``f`` are divided by a scale ``S`` (px, half the image's shorter side) so
that the coefficients ``b_k = a_k S^(k - 1)`` are O(1). Two gauges are fixed: the sign of the
ray's z axis (free for planar boards) so that ``a0 < 0``, as OCamCalib's; and ``d = 0``, since
``A -> A Q k`` for a rotation ``Q`` about the axis and a scale ``k`` changes nothing that the
poses and ``f`` cannot absorb. With ``a0 < 0`` the principal point's ray is ``-z``: for a
catadioptric rig that is the ray seen straight back towards the camera, so the ray's elevation
``asin(z)`` is the physical one with the camera's ``+z`` towards the mirror.

This is the library port of the team's reference ``shared/tools/taylor.py`` (same method, same
numbers: ``benchmarks/check_taylor.py``).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence

import cv2
import numpy as np
from scipy.optimize import least_squares

from .._typing import FloatArray

__all__ = ["TaylorFit", "fit_taylor", "linear_init", "find_centre"]

#: Polynomial degrees tried by :func:`fit_taylor` (OCamCalib's default is 4).
DEGREES = (3, 4, 5)
#: The centre search: half-width (fraction of the image's shorter side), grid points per side,
#: levels of refinement (each shrinks the step by ``grid // 2 + 1``).
CENTRE_SPAN, CENTRE_GRID, CENTRE_LEVELS = 0.15, 7, 3
#: Residual (px) given to a corner the model cannot project (as the shared held-out test).
_UNSEEN_PX = 1e3
#: Samples of the elevation table that starts :func:`_camera_to_pixels`' Newton iterations.
_TABLE = 256


def _poly(b, q):
    """``f(q S) / S`` for the scaled coefficients ``b = [b0, b2, ..., bN]``."""
    return b[0] + sum(bk * q**k for k, bk in enumerate(b[1:], 2))


def _dpoly(b, q):
    """Derivative of :func:`_poly` in ``q``."""
    return sum(k * bk * q ** (k - 1) for k, bk in enumerate(b[1:], 2))


def _rays(th, pixels, scale) -> FloatArray:
    """Unit rays (N, 3) of ``pixels`` (N, 2); ``th = [xc, yc, c, d, e, b0, b2, ..., bN]``."""
    xc, yc, c, d, e = th[:5]
    p = np.asarray(pixels, np.float64).reshape(-1, 2) - [xc, yc]
    s = np.linalg.solve([[c, d], [e, 1.0]], p.T).T / scale  # eq. 5 inverted
    v = np.c_[s, _poly(th[5:], np.hypot(*s.T))]  # eq. 3
    return v / np.linalg.norm(v, axis=1, keepdims=True)


def _camera_to_pixels(th, X, scale, qmax) -> FloatArray:
    """Pixels (N, 2) of camera-frame points ``X`` (N, 3).

    The normalised radius ``q = rho / S`` of a point of elevation ``atan2(z, r)`` is read off a
    table of the ray elevation ``atan2(F(q), q)`` over its rising part ``[0, qmax]``, then
    polished by Newton on ``F(q) r - z q = 0`` (the toolbox takes the smallest positive root).
    A point on the axis (``r = 0``) gives NaN.
    """
    b = th[5:]
    r = np.hypot(X[:, 0], X[:, 1])
    z = X[:, 2]
    qs = np.linspace(1e-9, qmax, _TABLE)
    el = np.arctan2(_poly(b, qs), qs)
    k = np.r_[np.flatnonzero(np.diff(el) <= 0), len(qs) - 1][0]
    q = np.interp(np.arctan2(z, r), el[: k + 1], qs[: k + 1])
    for _ in range(4):
        q = q - (_poly(b, q) * r - z * q) / (_dpoly(b, q) * r - z)
    s = (q * scale / r)[:, None] * X[:, :2]
    xc, yc, c, d, e = th[:5]
    return np.c_[c * s[:, 0] + d * s[:, 1] + xc, e * s[:, 0] + s[:, 1] + yc]


# -- the linear calibration (Scaramuzza et al. 2006, section 4) -------------------------------
def _view_rows(s, obj) -> tuple[FloatArray, FloatArray]:
    """One view's ``h = (r11, r12, r21, r22, t1, t2)`` and its ``(r31, r32)`` up to a common
    sign, from the third row of ``s x P = 0``: ``u P2 - v P1 = 0`` (eq. 8).

    The scale is fixed by ``|r1| = |r2| = 1``, ``r1 . r2 = 0`` (which give ``r31^2`` as the
    positive root of a quadratic), the sign by the board lying on the side of its image points.
    """
    u, v = s.T
    X, Y = obj[:, 0], obj[:, 1]
    h = np.linalg.svd(np.c_[-v * X, -v * Y, u * X, u * Y, -v, u])[2][-1]
    r11, r12, r21, r22 = h[:4]
    C = -(r11 * r12 + r21 * r22)
    B = r12**2 + r22**2 - r11**2 - r21**2
    x = (B + np.sqrt(B * B + 4 * C * C)) / 2  # r31^2
    if x > 1e-12 * (B * B + 1):
        r3 = np.array([np.sqrt(x), C / np.sqrt(x)])
    else:
        r3 = np.array([0.0, np.sqrt(-B)])
    lam = 1 / np.sqrt(r11**2 + r21**2 + x)
    h, r3 = h * lam, r3 * lam
    if np.sum(u * (h[0] * X + h[1] * Y + h[4]) + v * (h[2] * X + h[3] * Y + h[5])) < 0:
        h = -h
    return h, r3


def _view_system(s, obj, h, r3, degree):
    """One view's rows of the second linear step (eq. 12-14): ``v (W + t3) - F P2 = 0`` and
    ``F P1 - u (W + t3) = 0`` with ``W = r31 X + r32 Y``, as ``A b + a t3 = y``; returns
    ``(A, a, y)`` and the normal-equation pieces with ``t3`` eliminated."""
    X, Y = obj[:, 0], obj[:, 1]
    P1 = h[0] * X + h[1] * Y + h[4]
    P2 = h[2] * X + h[3] * Y + h[5]
    W = r3[0] * X + r3[1] * Y
    q = np.hypot(*s.T)
    Bq = np.stack([np.ones_like(q)] + [q**k for k in range(2, degree + 1)], axis=1)
    A = np.r_[-P2[:, None] * Bq, P1[:, None] * Bq]
    a = np.r_[s[:, 1], -s[:, 0]]
    y = np.r_[-s[:, 1] * W, s[:, 0] * W]
    Ap = A - np.outer(a, a @ A) / (a @ a)
    yp = y - a * (a @ y) / (a @ a)
    return (A, a, y), Ap.T @ Ap, Ap.T @ yp


def _choose_signs(M) -> FloatArray:
    """The views' signs ``g`` (+-1) that maximise ``g' M g``: the leading eigenvector's signs,
    then single flips while they help.

    A single view cannot tell its board from the mirror image (``(r31, r32, t3, F) -> -(...)``);
    with ``t3`` eliminated the joint residual is ``c - g(s)' N^-1 g(s)``, ``g(s) = sum_j s_j
    g_j``, so the best signs maximise that quadratic form.
    """
    sg = np.sign(np.linalg.eigh(M)[1][:, -1])
    sg[sg == 0] = 1
    for _ in range(len(sg)):
        gain = -4 * sg * (M @ sg - np.diag(M) * sg)
        if gain.max() <= 1e-12 * abs(sg @ M @ sg):
            break
        sg[np.argmax(gain)] *= -1
    return sg


def _rotations(views, signs) -> FloatArray:
    """The views' rotations ``(V, 3, 3)``: ``r1, r2`` of each (:func:`_view_rows`, ``r3``
    signed by ``signs``) completed and projected onto a rotation, all at once."""
    H = np.array([h for h, _ in views])
    R3 = np.array([r3 for _, r3 in views]) * np.asarray(signs, np.float64)[:, None]
    r1 = np.stack([H[:, 0], H[:, 2], R3[:, 0]], axis=1)
    r2 = np.stack([H[:, 1], H[:, 3], R3[:, 1]], axis=1)
    U, _, Wt = np.linalg.svd(np.stack([r1, r2, np.cross(r1, r2)], axis=2))
    U[:, :, 2] *= np.linalg.det(U @ Wt)[:, None]  # U diag(1, 1, det) Wt: a rotation
    return U @ Wt


def _linear(points, obj, centre, degree, scale) -> tuple[FloatArray, FloatArray, FloatArray]:
    """:func:`linear_init` with the poses as rotations ``(V, 3, 3)`` and translations
    ``(V, 3)``: ``(th, Rs, ts)``."""
    ss = [(p - centre) / scale for p in points]
    views = [_view_rows(s, obj) for s in ss]
    N = 0.0
    G, parts = [], []
    for s, (h, r3) in zip(ss, views):
        part, Nj, gj = _view_system(s, obj, h, r3, degree)
        N = N + Nj
        G.append(gj)
        parts.append(part)
    Gm = np.array(G).T
    sg = _choose_signs(Gm.T @ np.linalg.solve(N, Gm))
    b = np.linalg.solve(N, Gm @ sg)
    t3 = np.array([a @ (g * y - A @ b) / (a @ a) for (A, a, y), g in zip(parts, sg)])
    if b[0] > 0:  # gauge: a0 < 0
        b, t3, sg = -b, -t3, -sg
    ts = np.stack([[h[4], h[5], tz] for (h, _), tz in zip(views, t3)])
    return np.r_[centre, 1.0, 0.0, 0.0, b], _rotations(views, sg), ts


def linear_init(points, obj, centre, degree, scale) -> tuple[FloatArray, list]:
    """Scaramuzza's two-step linear calibration at a given centre (affine = identity).

    Parameters
    ----------
    points : sequence of (N, 2) ndarray
        Each view's corners, px.
    obj : (N, 3) ndarray
        The board's corners (``z = 0``).
    centre : (2,) array_like
        The candidate centre ``(x_c, y_c)``, px.
    degree : int
        Degree of ``f``.
    scale : float
        ``S`` (px).

    Returns
    -------
    th : ndarray
        ``[xc, yc, c, d, e, b0, b2, ..., bN]``.
    poses : list of (rvec, tvec)
    """
    th, Rs, ts = _linear(points, obj, centre, degree, scale)
    return th, [(cv2.Rodrigues(R)[0].ravel(), t) for R, t in zip(Rs, ts)]


# -- the joint refinement (Urban et al. 2015) -------------------------------------------------
def _full(x):
    """``th`` from the refined intrinsics ``[xc, yc, c, e, b...]`` (``d = 0``, a gauge)."""
    return np.r_[x[:3], 0.0, x[3:]]


def _pack(th, poses) -> FloatArray:
    return np.r_[np.delete(th, 3), np.concatenate([np.r_[r, t] for r, t in poses])]


def _unpack_poses(x, ni, n) -> list:
    """The ``n`` views' ``(rvec, tvec)`` after the ``ni`` intrinsics of ``x``."""
    return [(x[ni + 6 * j : ni + 6 * j + 3], x[ni + 6 * j + 3 : ni + 6 * j + 6]) for j in range(n)]


def _residuals(x, ni, points, obj, scale, qmax) -> FloatArray:
    """Reprojection residuals of ``x = [xc, yc, c, e, b..., (rvec, tvec) per view]``; ``ni``
    the number of intrinsics; a corner the model cannot project counts ``_UNSEEN_PX``."""
    X = np.vstack([obj @ cv2.Rodrigues(r)[0].T + t for r, t in _unpack_poses(x, ni, len(points))])
    with np.errstate(all="ignore"):
        r = (_camera_to_pixels(_full(x[:ni]), X, scale, qmax) - np.vstack(points)).ravel()
    return np.where(np.isfinite(r), r, _UNSEEN_PX)


def _jacobian(x, ni, points, obj, scale, qmax) -> FloatArray:
    """Forward differences; a view's residuals see only its own pose, so each of the 6 pose
    coordinates is stepped in all views at once."""
    args = (ni, points, obj, scale, qmax)
    f0 = _residuals(x, *args)
    J = np.zeros((f0.size, x.size))
    step = 1e-7 * (1 + np.abs(x))
    for k in range(ni):
        y = x.copy()
        y[k] += step[k]
        J[:, k] = (_residuals(y, *args) - f0) / step[k]
    rows = np.arange(f0.size)
    col = ni + 6 * (rows // (2 * len(obj)))
    for k in range(6):
        y = x.copy()
        y[ni + k :: 6] += step[ni + k :: 6]
        J[rows, col + k] = (_residuals(y, *args) - f0) / step[col + k]
    return J


def refine(th, poses, points, obj, scale, qmax, loss="linear") -> tuple[FloatArray, list]:
    """Joint refinement of centre, affine, polynomial and all poses on the reprojection error:
    Levenberg-Marquardt, or scipy's trf with a robust ``loss`` (``f_scale`` 1 px)."""
    ni = len(th) - 1
    args = (ni, points, obj, scale, qmax)
    method = dict(method="lm") if loss == "linear" else dict(method="trf", loss=loss, f_scale=1.0)
    x0 = _pack(th, poses)
    sol = least_squares(
        _residuals, x0, jac=_jacobian, args=args, x_scale="jac", max_nfev=500, **method
    )
    return _full(sol.x[:ni]), _unpack_poses(sol.x, ni, len(points))


def _rms_of_rotations(th, Rs, ts, points, obj, scale, qmax) -> float:
    """:func:`_rms` of the poses as rotations ``Rs`` (V, 3, 3) and translations ``ts`` (V, 3)."""
    X = (np.einsum("vij,nj->vni", Rs, obj) + ts[:, None, :]).reshape(-1, 3)
    with np.errstate(all="ignore"):
        r = _camera_to_pixels(th, X, scale, qmax) - np.vstack(points)
    r = np.where(np.isfinite(r), r, _UNSEEN_PX)
    return float(np.sqrt(np.mean(np.sum(r**2, 1))))


def _rms(th, poses, points, obj, scale, qmax) -> float:
    r = _residuals(_pack(th, poses), len(th) - 1, points, obj, scale, qmax).reshape(-1, 2)
    return float(np.sqrt(np.mean(np.sum(r**2, 1))))


def find_centre(points, obj, image_size, degree, scale, qmax) -> FloatArray:
    """The toolbox's centre search (Scaramuzza et al. 2006, section 4.2): the linear
    calibration at each centre of a grid (:data:`CENTRE_GRID` points a side, half-width
    :data:`CENTRE_SPAN` of the shorter side, about the image centre), keep the one of least
    reprojection error, shrink the grid around it (:data:`CENTRE_LEVELS` times); each
    candidate's poses stay rotation matrices, all views at once (150 candidates of
    KaidanOmni's 16 views cost 0.6 s instead of 2)."""
    half = CENTRE_GRID // 2
    data = (points, obj, scale, qmax)
    best = np.array(image_size, np.float64) / 2
    step = CENTRE_SPAN * min(image_size) / half
    for _ in range(CENTRE_LEVELS):
        offsets = range(-half, half + 1)
        cands = [best + step * np.r_[i, j] for i in offsets for j in offsets]
        errs = [_rms_of_rotations(*_linear(points, obj, c, degree, scale), *data) for c in cands]
        best = cands[int(np.argmin(errs))]
        step /= half + 1
    return best


# -- the result ---------------------------------------------------------------------------
@dataclasses.dataclass(frozen=True)
class TaylorFit:
    """A fitted Scaramuzza (OCamCalib) model (module docstring for the equations).

    Attributes
    ----------
    centre : (2,) ndarray
        ``(x_c, y_c)``, px.
    affine : (3,) ndarray
        ``(c, d, e)`` of ``A = [[c, d], [e, 1]]`` (``d = 0`` in this fit's gauge).
    coefficients : (degree + 1,) ndarray
        OCamCalib's ``a0, a1 = 0, a2, ..., aN`` of ``f(rho)``, ``rho`` in px (``a0 < 0``).
    scale : float
        ``S`` (px): the internal normalisation of ``rho``.
    qmax : float
        The largest ``rho / S`` the projection searches (the image's half diagonal over ``S``).
    poses : tuple of (rvec, tvec)
        Each view's board pose in the model's camera frame.
    rms : float
        Training corner RMS, px.
    """

    centre: FloatArray
    affine: FloatArray
    coefficients: FloatArray
    scale: float
    qmax: float
    poses: tuple
    rms: float

    @property
    def degree(self) -> int:
        """Degree of ``f``."""
        return len(self.coefficients) - 1

    @property
    def theta(self) -> FloatArray:
        """The internal parameters ``[xc, yc, c, d, e, b0, b2, ..., bN]``, ``b_k = a_k S^(k-1)``."""
        a = self.coefficients
        b = [a[0] / self.scale] + [a[k] * self.scale ** (k - 1) for k in range(2, len(a))]
        return np.r_[self.centre, self.affine, b]

    def directions(self, pixels) -> FloatArray:
        """Unit rays (N, 3), camera frame, of ``pixels`` (N, 2) (eqs. 3, 5)."""
        return _rays(self.theta, pixels, self.scale)

    def project(self, points) -> FloatArray:
        """Pixels (N, 2) of camera-frame points (N, 3); NaN on the axis (``x = y = 0``)."""
        X = np.asarray(points, np.float64).reshape(-1, 3)
        with np.errstate(all="ignore"):
            return _camera_to_pixels(self.theta, X, self.scale, self.qmax)

    def project_board(self, obj, rvec, tvec) -> FloatArray:
        """Pixels (N, 2) of board points ``obj`` (N, 3) at the pose ``(rvec, tvec)``."""
        R = cv2.Rodrigues(np.asarray(rvec, np.float64).reshape(3, 1))[0]
        return self.project(np.asarray(obj, np.float64).reshape(-1, 3) @ R.T + np.ravel(tvec))


def _model(th, scale, qmax, poses, rms) -> TaylorFit:
    a = np.r_[th[5] * scale, 0.0, [bk * scale ** (1 - k) for k, bk in enumerate(th[6:], 2)]]
    poses = tuple((np.asarray(r, np.float64), np.asarray(t, np.float64)) for r, t in poses)
    return TaylorFit(np.array(th[:2]), np.array(th[2:5]), a, float(scale), float(qmax), poses, rms)


def _fit_degree(points, obj, centre, degree, settings, lower) -> TaylorFit:
    """One degree's fit: the refinement of the linear start at ``centre`` and, when a lower
    degree was fitted, of that fit with the new coefficients 0; the one of least RMS.

    The second start is this library's addition to the toolbox's method: on a render of Mei's
    model (xi = 1.4) the linear start of degree 5 can fall into a valley (RMS 96 px) that the
    degree-4 fit extended avoids, and it keeps the training RMS from rising with the degree.
    """
    scale, qmax, loss = settings
    starts = [linear_init(points, obj, centre, degree, scale)]
    below = [f for f in lower if f.degree < degree]
    if below:
        prev = max(below, key=lambda f: f.degree)
        th = np.r_[prev.theta, np.zeros(degree - prev.degree)]
        starts.append((th, list(prev.poses)))
    best = None
    for th, poses in starts:
        th, poses = refine(th, poses, points, obj, scale, qmax, loss)
        fit = _model(th, scale, qmax, poses, _rms(th, poses, points, obj, scale, qmax))
        if best is None or fit.rms < best.rms:
            best = fit
    assert best is not None
    return best


def fit_taylor(
    image_points: Sequence, obj, image_size, degrees=DEGREES, loss="linear", pick="rms"
) -> TaylorFit:
    """Scaramuzza's model from chessboard corners: the centre search with the linear method at
    degree 4, then for each degree the joint refinement from the linear start at that centre
    and from the lower degree's fit (:func:`_fit_degree`), the better kept.

    Parameters
    ----------
    image_points : sequence of (N, 2) array_like
        Each view's corners, px (3 views or more).
    obj : (N, 3) array_like
        The board's corners (``z = 0``), as :func:`omnicam.chessboard.board_pose.object_points`.
    image_size : (int, int)
        ``(width, height)``.
    degrees : sequence of int
        Degrees of ``f`` tried.
    loss : str
        ``"linear"`` (Levenberg-Marquardt) or a scipy robust loss (``"soft_l1"``, ...).
    pick : {"rms", "parsimony"}
        Keep the degree of least training RMS, or the lowest degree within 5% of it.

    Returns
    -------
    TaylorFit

    Raises
    ------
    ValueError
        Fewer than 3 views, or corners that are not ``(N, 2)`` matching ``obj``.
    """
    pts = [np.asarray(p, np.float64).reshape(-1, 2) for p in image_points]
    obj = np.asarray(obj, np.float64).reshape(-1, 3)
    if len(pts) < 3:
        raise ValueError(f"image_points: the Taylor fit needs 3 views or more, got {len(pts)}")
    if any(len(p) != len(obj) for p in pts):
        raise ValueError(f"image_points: every view must have the {len(obj)} corners of obj")
    if pick not in ("rms", "parsimony"):
        raise ValueError(f"pick must be 'rms' or 'parsimony', got {pick!r}")
    scale = min(image_size) / 2.0
    qmax = float(np.hypot(*image_size)) / scale
    centre = find_centre(pts, obj, image_size, 4, scale, qmax)
    fits: list[TaylorFit] = []
    for degree in degrees:
        fits.append(_fit_degree(pts, obj, centre, degree, (scale, qmax, loss), fits))
    best = min(f.rms for f in fits)
    if pick == "parsimony":
        return next(f for f in fits if f.rms <= 1.05 * best)
    return min(fits, key=lambda f: f.rms)
