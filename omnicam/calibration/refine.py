"""Non-linear refinement of the 5-DOF mirror posture (beyond the paper).

Started from the analytic posture of Chen's method (:mod:`.chen`), it minimises, in pixels,

* **rim reprojection**: for each observed boundary point ``u_j`` (undistorted pixels ``K x_n``)
  the orthogonal distance to the image of the rim circle, ``c(phi) = K pi(R rho(phi) + t)``
  with ``rho(phi) = (r cos phi, r sin phi, z_rim)``; ``phi_j`` is the foot point, found by
  Newton's method for every evaluation (variable projection), so the residual is the true
  geometric distance and is exactly zero at the true posture on exact data;
* **far lines** (optional): every far line is one 3-D line ``L = {Q + s e}`` (4 nuisance
  parameters), and every traced ray ``(P_i, V_i)`` (eqs. 6-19) of its pixels must meet it. The
  residual is the sine of the angle between ``V_i`` and the plane through ``P_i`` and ``L``,
  ``(V_i, n_i)`` with ``n_i = unit((Q - P_i) x e)``, converted to pixels by the local
  derivative of that sine with respect to the pixel. It is exactly zero when the rays meet the
  line at any distance (eq. 31's coplanarity of directions is only the limit of a line at
  infinity and would bias a refinement);
* **the camera's reflection** (optional, :mod:`.reflection`): for each outline pixel the radius
  at which its reflected ray crosses the plane ``z_c = z`` of the coaxial circle, minus ``r``,
  in pixels by the local derivative; ``r`` and ``z`` nuisance parameters unless known.

Each kind of residual is one class (:class:`RimTerm`, :class:`FarLineTerm`,
:class:`ReflectionTerm`) with ``residuals(R, t, y)`` and ``jacobian(posture, x, y, steps)``
(posture columns, own nuisance columns); ``_Problem`` stacks the terms it is given.

Parameters: two small rotations of the mirror axis (about two axes perpendicular to it), the
three components of the mirror origin ``tvec``, and per line a rotation of ``e`` (2) and a shift
of ``Q`` perpendicular to ``e`` (2). The rotation about the mirror axis is not observable and
stays in the gauge of docs/conventions.md. ``scipy.optimize.least_squares`` (imported lazily;
MINPACK's Levenberg-Marquardt) solves it. The Jacobian of the rim rows follows from the
envelope theorem at the foot points; the far-line rows use forward differences, the lines'
nuisance columns in 4 groups (they share no rows). The lines are started from the rays of the
analytic posture: their plane (eq. 31) and, linearly in Plucker coordinates, the line itself.

What it can add: the rim ellipse has 5 parameters and so has the posture, so with a geometric
ellipse fit (:func:`.rim.fit_rim`) the analytic posture is already the best the rim allows and
the rim term alone changes nothing. Far lines constrain mostly the coplanarity of their rays,
which a rim-consistent error of the axis (a tilt with a compensating shift) barely changes:
on the default rigs three far lines shrink the axis uncertainty by well under 1 %.

The result is kept only if its cost is lower than the cost of the analytic posture (with the
line parameters fitted to it), so refinement never makes an exact analytic result worse.
Whether a cue may join the rim at all is decided by :func:`.steps.refinement_step`;
:func:`posture_uncertainty` gives the first-order a posteriori covariance and its weakest
direction, :func:`profile_uncertainty` the one stated: widened to the region of the cost itself
where that reaches farther (near alignment, where the rim depends on the tilt only to second
order). Both weight each source by its observed residuals and their correlation along the
contour over every lag (:func:`correlation_factor`).
"""

from __future__ import annotations

import dataclasses
import math
import typing

import cv2
import numpy as np
from scipy.optimize import least_squares

from ..gauge import (
    gauge_rotation,  # re-exported: refine.gauge_rotation
    perpendicular_basis,
)
from ..gauge import rotate_vector as _rotate
from ..mirror import HyperbolicMirror
from .reflection import plane_radius
from .robust import mad_sigma

__all__ = [
    "posture_offsets",
    "perturbed_posture",
    "RefineResult",
    "ReflectionSpec",
    "Uncertainty",
    "RimTerm",
    "FarLineTerm",
    "ReflectionTerm",
    "refine_posture",
    "posture_uncertainty",
    "profile_uncertainty",
    "correlation_factor",
    "uncertainty_from_cov",
    "gauge_rotation",
]

_N_POSTURE = 5
_STEPS = np.array([1e-7, 1e-7, 1e-6, 1e-6, 1e-6])  # posture steps of the difference quotients


@dataclasses.dataclass(frozen=True, eq=False)
class RefineResult:
    """Outcome of :func:`refine_posture`.

    Attributes
    ----------
    rvec, tvec : (3,) float64 ndarray
        The posture kept (the refined one if ``accepted``, else the analytic one).
    accepted : bool
        Whether the refined posture had the lower cost and was kept.
    cost_initial, cost_final : float
        ``0.5 * sum(residual^2)`` (px^2) at the analytic posture (line parameters fitted) and at
        the refined one.
    rim_rms : float
        RMS orthogonal distance of the boundary points to the rim image of the kept posture, px.
    line_rms : float
        RMS far-line residual of the kept posture, px (NaN without lines).
    lines : list of ((3,) ndarray, (3,) ndarray)
        The fitted 3-D lines ``(Q, e)`` in the mirror frame.
    nfev : int
        Residual evaluations of the solver.
    reflection_rms : float
        RMS outline residual of the camera's reflection for the kept posture, px (NaN without).
    r, z : float
        The reflection's coaxial circle (NaN without).
    rim_cost : float
        ``0.5 * sum(rim residual^2)`` (robust weights) at the kept posture: against the rim-only
        fit's, how much the other terms moved the rim (the acceptance test of a cue).
    n_rim : int
        Number of rim rows.
    """

    rvec: np.ndarray
    tvec: np.ndarray
    accepted: bool
    cost_initial: float
    cost_final: float
    rim_rms: float
    line_rms: float
    lines: list
    nfev: int
    reflection_rms: float = math.nan
    r: float = math.nan
    z: float = math.nan
    rim_cost: float = math.nan
    n_rim: int = 0


def _line_from_rays(P, V, N, rim_radius):
    """The 3-D line meeting every ray ``(P_i, V_i)``, linearly in Plucker coordinates.

    A line ``(e, m)`` (direction, moment ``Q x e``) meets the ray ``(V_i, P_i x V_i)`` iff
    ``(e, P_i x V_i) + (V_i, m) = 0``. Near-central rays make this nearly degenerate: the
    solution is used only if it is a plausible far line (direction in the rays' plane of normal
    ``N``, distance between 10 and 10^6 rim radii); otherwise ``None``.
    Returns ``(Q, e)`` with ``Q`` the point of the line nearest to the origin of ``P``.
    """
    scale = float(np.max(np.linalg.norm(P, axis=1))) or 1.0
    A = np.concatenate([np.cross(P / scale, V), V], axis=1)
    try:
        _, sv, Wt = np.linalg.svd(A)
    except np.linalg.LinAlgError:
        return None
    z = Wt[-1]
    e, m = z[:3], z[3:] * scale
    ne = float(np.linalg.norm(e))
    if not ne > 0:
        return None
    e, m = e / ne, m / ne
    Q = np.cross(e, m)
    dist = float(np.linalg.norm(Q))
    if not (
        abs(e @ N) < 0.1 and 10 * rim_radius < dist < 1e6 * rim_radius and np.median(V @ Q) > 0
    ):
        return None
    return Q, e


class _Posture:
    """The 5 posture parameters: two small rotations of the mirror axis about axes
    perpendicular to it, and the shift of ``tvec`` (the rotation about the axis is the gauge)."""

    def __init__(self, R0, t0):
        self.a0 = R0[:, 2] / np.linalg.norm(R0[:, 2])
        self.b1, self.b2 = perpendicular_basis(self.a0)
        self.t0 = np.asarray(t0, np.float64)

    def __call__(self, x):
        axis = _rotate(self.a0, x[0] * self.b1 + x[1] * self.b2)
        return gauge_rotation(axis), self.t0 + x[2:5]


class RimTerm:
    """Rim reprojection rows: orthogonal pixel distance of each boundary point to the image of
    the rim circle ``c(phi) = K pi(R rho(phi) + t)``, ``phi`` the foot point (Newton, variable
    projection), optionally Huber-weighted (weights fixed at the start). No nuisance parameter.
    The Jacobian follows from the envelope theorem at the foot points."""

    name = "rim"
    n_nuisance = 0

    def __init__(self, K, mirror, R0, t0, rim_px):
        self.K = K
        self.A = K[:2, :2]
        self.k = K[:2, 2]
        self.mirror = mirror
        self.px = rim_px
        self.phi0 = self._foot_points(R0, t0, init=True)
        self.w = np.ones(len(rim_px))  # sqrt of the robust weights

    def __len__(self):
        return len(self.px)

    def x0(self):
        """The term's own parameters at the start (none: the rim has no nuisance parameters)."""
        return np.zeros(0)

    def _curve(self, R, t, phi):
        """Rim image ``c(phi)`` and its first two derivatives, as component pairs of (N,)."""
        r, zr = self.mirror.rim_radius, self.mirror.z_rim
        cp, sp = np.cos(phi), np.sin(phi)
        X, X1, X2 = [], [], []
        for i in range(3):
            a, b = R[i, 0] * cp, R[i, 1] * sp
            X.append(r * (a + b) + (R[i, 2] * zr + t[i]))  # R rho + t
            X1.append(r * (R[i, 1] * cp - R[i, 0] * sp))  # R rho'
            X2.append(-r * (a + b))  # R rho''
        iz = 1.0 / X[2]
        A, k = self.A, self.k
        p = [X[0] * iz, X[1] * iz]
        p1 = [(X1[0] - p[0] * X1[2]) * iz, (X1[1] - p[1] * X1[2]) * iz]
        p2 = [
            (X2[0] - p[0] * X2[2] - 2.0 * p1[0] * X1[2]) * iz,
            (X2[1] - p[1] * X2[2] - 2.0 * p1[1] * X1[2]) * iz,
        ]

        def img(q, off):
            return (
                A[0, 0] * q[0] + A[0, 1] * q[1] + off[0],
                A[1, 0] * q[0] + A[1, 1] * q[1] + off[1],
            )

        return img(p, k), img(p1, (0.0, 0.0)), img(p2, (0.0, 0.0))

    def _foot_points(self, R, t, init=False, phi=None, iters=3):
        ux, uy = self.px[:, 0], self.px[:, 1]
        if init:
            # start at the rim point on the pixel's ray (exact for exact data)
            Ki = np.linalg.inv(self.K)
            xh = np.concatenate([self.px, np.ones((len(ux), 1))], axis=1) @ Ki.T
            a = xh @ R  # R^T x~
            b = R.T @ t
            with np.errstate(divide="ignore", invalid="ignore"):
                s = (self.mirror.z_rim + b[2]) / a[:, 2]
            phi = np.arctan2(s * a[:, 1] - b[1], s * a[:, 0] - b[0])
            phi = np.where(np.isfinite(phi), phi, 0.0)
            iters = 10
        for _ in range(iters):
            (cx, cy), (dx, dy), (ex, ey) = self._curve(R, t, phi)
            wx, wy = cx - ux, cy - uy
            g = wx * dx + wy * dy
            h1 = dx * dx + dy * dy
            h = h1 + wx * ex + wy * ey
            phi = phi - g / np.where(h > 0, h, h1)
        return phi

    def _normals(self, R, t, phi):
        (cx, cy), (dx, dy), _ = self._curve(R, t, phi)
        nn = np.hypot(dx, dy)
        return cx, cy, dy / nn, -dx / nn

    def residuals(self, R, t, y=None, weighted=True):
        """Signed distances (px) of the rim points to the rim's image under ``R, t`` (robust weights
        applied when ``weighted``)."""
        phi = self._foot_points(R, t, phi=self.phi0)
        cx, cy, nx, ny = self._normals(R, t, phi)
        r = (self.px[:, 0] - cx) * nx + (self.px[:, 1] - cy) * ny
        return r * self.w if weighted else r

    def set_robust_weights(self, R, t, k=2.0):
        """Huber weights from the residuals at ``(R, t)``, fixed thereafter (one reweighting
        step): ``w = min(1, k s / |r|)``, ``s = 1.4826 MAD``."""
        self.w = np.ones(len(self.px))
        r = np.abs(self.residuals(R, t))
        s = mad_sigma(r)
        if s > 0:
            self.w = np.sqrt(np.minimum(1.0, k * s / np.maximum(r, 1e-300)))

    def jacobian(self, posture, x, y, steps):
        """Posture columns (5): ``d dist / d p = -n . dc/dp`` at the foot points, ``dc/dR`` by
        differences of ``R`` and ``dc/dt`` analytic."""
        R, t = posture(x)
        phi = self._foot_points(R, t, phi=self.phi0)
        cx, cy, nx, ny = self._normals(R, t, phi)
        J = np.zeros((len(self.px), _N_POSTURE))
        for k in range(2):
            xk = x.copy()
            xk[k] += steps[k]
            Rk, _ = posture(xk)
            (ckx, cky), _, _ = self._curve(Rk, t, phi)
            J[:, k] = -((ckx - cx) * nx + (cky - cy) * ny) / steps[k] * self.w
        r, zr = self.mirror.rim_radius, self.mirror.z_rim
        rho = np.stack([r * np.cos(phi), r * np.sin(phi), np.full_like(phi, zr)], axis=1)
        X = rho @ R.T + t
        z = X[:, 2]
        # n^T A, then d pi / d t = [[1/z, 0, -x/z^2], [0, 1/z, -y/z^2]]
        m0 = nx * self.A[0, 0] + ny * self.A[1, 0]
        m1 = nx * self.A[0, 1] + ny * self.A[1, 1]
        J[:, 2] = -m0 / z * self.w
        J[:, 3] = -m1 / z * self.w
        J[:, 4] = (m0 * X[:, 0] + m1 * X[:, 1]) / z**2 * self.w
        return J, np.zeros((len(self.px), 0))


def _rays(mirror, R, t, xn):
    """Reflected rays of normalised coordinates (eqs. 6-19) in the mirror frame, in numpy: the
    sets are small and this runs hundreds of times (no thread start-up per call)."""
    C = -R.T @ t  # F_M (eq. 17)
    V = np.concatenate([xn, np.ones((len(xn), 1))], axis=1) @ R  # V_M = R^T V_C (eq. 16)
    V /= np.linalg.norm(V, axis=1, keepdims=True)
    P = mirror.intersect(C, V)  # eqs. 8-12
    return P, mirror.reflect(V, mirror.unit_normal(P))  # eqs. 14-15


class FarLineTerm:
    """Far-line rows: every far line is one 3-D line ``L = {Q + s e}`` (4 nuisance parameters:
    a rotation of ``e`` and a shift of ``Q``), and each traced ray ``(P_i, V_i)`` of its pixels
    must meet it; residual ``(V_i, n_i)``, ``n_i = unit((Q - P_i) x e)``, in pixels by the local
    derivative with respect to the pixel at the start (exact at any distance of the line, where
    eq. 31 is only the limit of a line at infinity)."""

    name = "far lines"

    def __init__(self, K, mirror, R0, t0, lines_xn, depth):
        self.K = K
        self.mirror = mirror
        self.lines_xn = lines_xn
        self.n_nuisance = 4 * len(lines_xn)
        self._cache = (None,)
        self._init_lines(R0, t0, depth)

    def __len__(self):
        return sum(len(x) for x in self.lines_xn)

    def x0(self):
        """The lines' nuisance parameters at the start: zero offsets from their initial 3-D
        lines (:meth:`line`)."""
        return np.zeros(self.n_nuisance)

    def _init_lines(self, R, t, depth):
        """Initial 3-D lines from the rays of the analytic posture (eqs. 30-31)."""
        self.line0 = []
        self.scale = np.ones(len(self))
        for xn in self.lines_xn:
            P, V = _rays(self.mirror, R, t, xn)
            ok = np.isfinite(V).all(axis=1)
            P, V = P[ok], V[ok]
            _, E = np.linalg.eigh(V.T @ V)
            N = E[:, 0]  # normal of the plane of the rays  (eq. 31)
            p = P.mean(axis=0)
            m = np.cross(N, V[0])
            ang = np.arctan2(V @ m, V @ V[0])
            i, j = int(np.argmin(ang)), int(np.argmax(ang))
            Qa, Qb = p + depth * V[i], p + depth * V[j]
            lin = _line_from_rays(P - p, V, N, self.mirror.rim_radius)
            if lin is not None:  # exact for exact data (the rays then meet one line)
                Qa, Qb = p + lin[0], p + lin[0] + depth * lin[1]
            e0 = (Qb - Qa) / np.linalg.norm(Qb - Qa)
            f1 = N - e0 * (N @ e0)
            f1 /= np.linalg.norm(f1)
            f2 = np.cross(e0, f1)
            self.line0.append((Qa, e0, f1, f2, depth))
        # pixel scale of each residual: 1 / |d residual / d pixel| at the analytic posture
        zero = self.x0()
        base = self._raw(R, t, zero, self.lines_xn)
        h = 1e-4
        Ki = np.linalg.inv(self.K)
        grads = []
        for dx in ((h, 0.0), (0.0, h)):
            shifted = [xn + np.array(dx) @ Ki[:2, :2].T for xn in self.lines_xn]
            grads.append((self._raw(R, t, zero, shifted) - base) / h)
        g = np.hypot(grads[0], grads[1])
        self.scale = np.where(g > 0, 1.0 / np.where(g > 0, g, 1.0), 0.0)

    def line(self, i, y):
        """Line ``i`` as ``(point, unit direction)``: its initial line turned by ``y[0:2]`` and
        moved by ``y[2:4]`` (times its depth) across itself."""
        Qa, e0, f1, f2, depth = self.line0[i]
        e = e0 + y[0] * f1 + y[1] * f2
        e /= np.linalg.norm(e)
        return Qa + depth * (y[2] * f1 + y[3] * f2), e

    def _raw(self, R, t, y, lines_xn):
        sizes = [len(xn) for xn in lines_xn]
        if lines_xn is self.lines_xn:  # the rays depend on the posture only: cache them
            key = (R.tobytes(), t.tobytes())
            if self._cache[0] != key:
                self._cache = (key, *_rays(self.mirror, R, t, np.concatenate(lines_xn)))
            _, P, V = self._cache
        else:
            P, V = _rays(self.mirror, R, t, np.concatenate(lines_xn))
        idx = np.repeat(np.arange(len(sizes)), sizes)
        Q = np.empty((len(lines_xn), 3))
        E = np.empty((len(lines_xn), 3))
        for i in range(len(lines_xn)):
            Q[i], E[i] = self.line(i, y[4 * i : 4 * i + 4])
        n = np.cross(Q[idx] - P, E[idx])
        n /= np.linalg.norm(n, axis=1, keepdims=True)
        r = (V * n).sum(axis=1)
        return np.where(np.isfinite(r), r, 0.0)

    def residuals(self, R, t, y, weighted=True):
        """Every far-line pixel's distance (px) to the image of its line under ``R, t``."""
        return self._raw(R, t, y, self.lines_xn) * self.scale

    def nuisance_jacobian(self, R, t, y, steps):
        """Line rows and line columns (the posture fixed): 4 grouped forward differences."""
        base = self.residuals(R, t, y)
        rows = np.repeat(np.arange(len(self.lines_xn)), [len(x) for x in self.lines_xn])
        J = np.zeros((len(base), len(y)))
        for k in range(4):
            yk = y.copy()
            yk[k::4] += steps[k]
            J[np.arange(len(base)), 4 * rows + k] = (self.residuals(R, t, yk) - base) / steps[k]
        return J

    def jacobian(self, posture, x, y, steps):
        """Derivatives of the residuals by the posture and by this term's parameters, at ``x`` and
        ``y``."""
        R, t = posture(x)
        return _posture_fd(self, posture, x, y, steps), self.nuisance_jacobian(
            R, t, y, np.full(len(y), 1e-7)
        )


class ReflectionTerm:
    """Rows of the camera's reflection (:mod:`.reflection`): for each outline pixel the radius
    ``rho`` at which its reflected ray crosses the plane ``z_c = z``, minus ``r``, in pixels by
    ``1 / |grad_u rho|`` at the start. Nuisance parameters ``r`` and ``z`` unless given; a free
    ``z`` is pulled weakly towards its start (one extra row, ``(z - z0) / c`` px), since for a
    nearly central rig only ``r / (2c - z)`` is determined."""

    name = "reflection"

    def __init__(self, K, mirror, R0, t0, xn, r0, z0, r_known=False, z_known=False):
        self.mirror = mirror
        self.xn = xn
        self.r0, self.z0 = float(r0), float(z0)
        self.free = [not r_known, not z_known]
        self.n_nuisance = sum(self.free)
        _, g = plane_radius(mirror, R0, t0, xn, self.z0, np.linalg.inv(K)[:2, :2])
        ok = np.isfinite(g) & (g > 0)
        self.scale = np.where(ok, 1.0 / np.where(ok, g, 1.0), 0.0)
        # a weak prior on z, relative to the mirror's size (c for a hyperboloid)
        size = mirror.c if isinstance(mirror, HyperbolicMirror) else mirror.rim_radius
        self.prior = 1e-2 / size if self.free[1] else None

    def __len__(self):
        return len(self.xn) + (self.prior is not None)

    def x0(self):
        """The circle's ``(r, z)`` at the start, those not known."""
        return np.array([v for v, f in zip((self.r0, self.z0), self.free) if f])

    def circle(self, y):
        """``(r, z)`` of the camera's circle: the known ones and those in ``y``."""
        it = iter(y)
        r = next(it) if self.free[0] else self.r0
        z = next(it) if self.free[1] else self.z0
        return float(r), float(z)

    def residuals(self, R, t, y, weighted=True, outline_only=False):
        """The outline pixels' residuals (px) under ``R, t`` and the circle in ``y``; with
        ``outline_only`` no prior term."""
        r, z = self.circle(y)
        res = (plane_radius(self.mirror, R, t, self.xn, z) - r) * self.scale
        res = np.where(np.isfinite(res), res, 0.0)
        if self.prior is None or outline_only:
            return res
        return np.append(res, (z - self.z0) * self.prior)

    def jacobian(self, posture, x, y, steps):
        """Derivatives of the residuals by the posture and by the circle's parameters."""
        R, t = posture(x)
        Jp = _posture_fd(self, posture, x, y, steps)
        base = self.residuals(R, t, y)
        Jn = np.zeros((len(base), len(y)))
        for k in range(len(y)):
            yk = y.copy()
            h = 1e-6 * max(1.0, abs(yk[k]))
            yk[k] += h
            Jn[:, k] = (self.residuals(R, t, yk) - base) / h
        return Jp, Jn


def _posture_fd(term, posture, x, y, steps):
    """Posture columns of a term by forward differences."""
    R, t = posture(x)
    base = term.residuals(R, t, y)
    J = np.zeros((len(base), _N_POSTURE))
    for k in range(_N_POSTURE):
        xk = x.copy()
        xk[k] += steps[k]
        Rk, tk = posture(xk)
        J[:, k] = (term.residuals(Rk, tk, y) - base) / steps[k]
    return J


class _Problem:
    """A sum of terms over the posture and each term's nuisance parameters."""

    def __init__(self, posture, terms):
        self.posture = posture
        self.terms = terms
        self.slices, i = [], _N_POSTURE
        for term in terms:
            self.slices.append(slice(i, i + term.n_nuisance))
            i += term.n_nuisance
        self.n = i

    def x0(self):
        return np.concatenate([np.zeros(_N_POSTURE)] + [t.x0() for t in self.terms])

    def parts(self, x):
        R, t = self.posture(x[:_N_POSTURE])
        return [term.residuals(R, t, x[s]) for term, s in zip(self.terms, self.slices)]

    def residuals(self, x):
        return np.concatenate(self.parts(x))

    def jacobian(self, x, steps=_STEPS):
        rows = []
        for term, s in zip(self.terms, self.slices):
            Jp, Jn = term.jacobian(self.posture, x[:_N_POSTURE], x[s], steps)
            block = np.zeros((len(Jp), self.n))
            block[:, :_N_POSTURE] = Jp
            block[:, s] = Jn
            rows.append(block)
        return np.concatenate(rows)


class ReflectionSpec(typing.NamedTuple):
    """The camera's reflection as a cue of :func:`refine_posture` and
    :func:`posture_uncertainty` (the arguments of :class:`ReflectionTerm`).

    Attributes
    ----------
    xn : (M, 2) array_like
        Undistorted normalised coordinates of the outline of the camera's reflection.
    r, z : float
        The starting coaxial circle (e.g. :func:`.reflection.fit_circle`'s).
    r_known, z_known : bool
        Which of ``r``, ``z`` are known (kept fixed); the others are nuisance parameters.
    """

    xn: object
    r: float
    z: float
    r_known: bool
    z_known: bool


def _reflection_spec(reflection):
    """A checked :class:`ReflectionSpec` (any 5-sequence in its order), or None if the outline
    is empty or the circle not finite."""
    if reflection is None:
        return None
    xn, r0, z0, r_known, z_known = reflection
    xn = np.ascontiguousarray(np.asarray(xn, np.float64).reshape(-1, 2))
    if len(xn) == 0 or not (np.isfinite(r0) and np.isfinite(z0)):
        return None
    return ReflectionSpec(xn, float(r0), float(z0), bool(r_known), bool(z_known))


def refine_posture(
    K,
    mirror,
    rvec,
    tvec,
    rim_points,
    far_lines_normalized=(),
    line_depth=None,
    max_nfev=15,
    robust=True,
    reflection=None,
):
    """Refine a mirror posture by non-linear least squares (rim, far lines, reflection).

    Parameters
    ----------
    K : (3, 3) ndarray
        Camera matrix.
    mirror : HyperbolicMirror
    rvec, tvec : (3,) array_like
        Starting (analytic) posture.
    rim_points : (N, 2) ndarray
        Observed boundary points in undistorted pixels ``K x_n`` (N >= 5).
    far_lines_normalized : sequence of (N_i, 2) ndarray
        Undistorted normalised coordinates of the far-line pixels (may be empty).
    line_depth : float, optional
        Starting distance of the 3-D lines; default ``1000 * rim_radius``.
    max_nfev : int
        Cap on residual evaluations of each of the two solver stages.
    robust : bool
        Huber weights on the rim rows (``k = 2`` robust standard deviations) from the residuals
        of the starting posture; the costs compared to accept the result use the same weights.
    reflection : ReflectionSpec, optional
        The outline of the camera's reflection, the starting circle and which of its ``r``,
        ``z`` are known (a plain ``(xn, r, z, r_known, z_known)`` tuple is taken too).

    Returns
    -------
    RefineResult
    """
    K = np.asarray(K, np.float64)
    R0 = cv2.Rodrigues(np.asarray(rvec, np.float64).reshape(3, 1))[0]
    t0 = np.asarray(tvec, np.float64)
    rim_px = np.ascontiguousarray(np.asarray(rim_points, np.float64).reshape(-1, 2))
    lines_xn = [np.ascontiguousarray(np.asarray(x, np.float64)) for x in far_lines_normalized]
    depth = 1000.0 * mirror.rim_radius if line_depth is None else float(line_depth)
    # lines whose rays mostly miss the mirror under this posture are left out
    lines_xn = [
        x for x in lines_xn if np.isfinite(_rays(mirror, R0, t0, x)[1]).all(axis=1).sum() >= 3
    ]
    rim = RimTerm(K, mirror, R0, t0, rim_px)
    if robust:
        rim.set_robust_weights(R0, t0)
    terms = [rim]
    if lines_xn:
        terms.append(FarLineTerm(K, mirror, R0, t0, lines_xn, depth))
    spec = _reflection_spec(reflection)
    if spec is not None:
        terms.append(ReflectionTerm(K, mirror, R0, t0, *spec))
    prob = _Problem(_Posture(R0, t0), terms)
    x0 = prob.x0()
    opts = dict(method="lm", x_scale="jac", xtol=1e-8, ftol=1e-6, gtol=1e-10)
    nfev = 0
    # stage 1: the line parameters alone at the analytic posture (its fair cost)
    if lines_xn:
        lt, sl = terms[1], prob.slices[1]
        s1 = least_squares(
            lambda y: lt.residuals(R0, t0, y),
            x0[sl],
            jac=lambda y: lt.nuisance_jacobian(R0, t0, y, np.full(len(y), 1e-7)),
            max_nfev=max_nfev,
            **opts,
        )
        x0[sl] = s1.x
        nfev += s1.nfev
    r_init = prob.residuals(x0)
    cost_init = 0.5 * float(r_init @ r_init)
    # stage 2: posture and nuisances together (skipped when the start is already exact)
    x, cost_fin, accepted = x0, cost_init, False
    if cost_init > 1e-20 * len(r_init):
        sol = least_squares(prob.residuals, x0, jac=prob.jacobian, max_nfev=max_nfev, **opts)
        nfev += sol.nfev
        r_fin = prob.residuals(sol.x)
        cost_fin = 0.5 * float(r_fin @ r_fin)
        # keep the refined posture only if it is better: never worse than the analytic one
        if np.isfinite(cost_fin) and cost_fin < cost_init:
            x, accepted = sol.x, True
    R, t = prob.posture(x[:_N_POSTURE])
    rim_rms = float(np.sqrt(np.mean(rim.residuals(R, t, weighted=False) ** 2)))
    line_rms, lines = math.nan, []
    if lines_xn:
        lr = terms[1].residuals(R, t, x[prob.slices[1]])
        line_rms = float(np.sqrt(np.mean(lr**2)))
        y = x[prob.slices[1]]
        lines = [terms[1].line(i, y[4 * i : 4 * i + 4]) for i in range(len(lines_xn))]
    refl_rms, r_c, z_c = math.nan, math.nan, math.nan
    if spec is not None:
        term = terms[-1]
        y = x[prob.slices[-1]]
        refl_rms = float(np.sqrt(np.mean(term.residuals(R, t, y, outline_only=True) ** 2)))
        r_c, z_c = term.circle(y)
    return RefineResult(
        rvec=cv2.Rodrigues(R)[0].ravel(),
        tvec=np.asarray(t, np.float64),
        accepted=accepted,
        cost_initial=cost_init,
        cost_final=cost_fin,
        rim_rms=rim_rms,
        line_rms=line_rms,
        lines=lines,
        nfev=int(nfev),
        reflection_rms=refl_rms,
        r=r_c,
        z=z_c,
        rim_cost=0.5 * float(np.sum(rim.residuals(R, t) ** 2)),
        n_rim=len(rim_px),
    )


@dataclasses.dataclass(frozen=True)
class Uncertainty:
    """A posteriori uncertainty of the posture (:func:`posture_uncertainty`,
    :func:`profile_uncertainty`).

    Attributes
    ----------
    axis_std_deg : float
        RMS error of the mirror axis direction, degrees.
    origin_std : float
        Square root of the trace of the origin's covariance, length unit.
    weak_tilt_deg, weak_shift : float
        The least determined combination of the posture (the covariance's principal direction,
        angles scaled by the camera's distance to the mirror): one standard deviation along it
        is a tilt of ``weak_tilt_deg`` with a shift of the origin of ``weak_shift``.
    weak_share : float
        Fraction of the posture's variance along that direction.
    cov : (5, 5) ndarray or None
        The posture's covariance: two small rotations of the mirror axis (radians, about the
        axes of :func:`posture_offsets`) and the origin's shift (length unit).
    first_order_axis_std_deg : float
        ``axis_std_deg`` of the first-order covariance at the estimate (what the Jacobian
        alone says; NaN when that is all there is).
    aligned_chi2 : float
        How much the cost (in units of the observed residual variance, every parameter but
        the two axis angles fitted) rises from the estimate to the aligned posture, midway
        between it and its twin (the other physical posture of the same rim), where the rim's
        image depends on the tilt only to second order (NaN without a twin).
    aligned_px : float
        The RMS change of the rim's image between the estimate and that aligned posture, px.
    twin_deg : float
        The angle between the mirror axes of the estimate and its twin, degrees.
    widened : bool
        Whether the cost itself widened the first-order uncertainty of the axis.
    """

    axis_std_deg: float
    origin_std: float
    weak_tilt_deg: float = math.nan
    weak_shift: float = math.nan
    weak_share: float = math.nan
    cov: object = dataclasses.field(default=None, compare=False, repr=False)
    first_order_axis_std_deg: float = math.nan
    aligned_chi2: float = math.nan
    aligned_px: float = math.nan
    twin_deg: float = math.nan
    widened: bool = False

    def with_cov(self, cov, tvec):
        """The same, with the covariance ``cov`` (at the posture with ``tvec``) in place of
        this one's: the axis and origin uncertainties and the weak direction follow it."""
        new = uncertainty_from_cov(cov, tvec)
        return dataclasses.replace(
            self,
            **{k: getattr(new, k) for k in ("axis_std_deg", "origin_std", "cov")},
            **{k: getattr(new, k) for k in ("weak_tilt_deg", "weak_shift", "weak_share")},
        )

    def describe(self):
        """The weakly determined direction in words."""
        if not np.isfinite(self.weak_tilt_deg):
            return "unknown"
        return (
            f"a tilt of {self.weak_tilt_deg:.3g} deg with a compensating shift of "
            f"{self.weak_shift:.3g} (one standard deviation; {100 * self.weak_share:.0f} % "
            f"of the posture's variance)"
        )


#: Fewest independent residuals a contour is taken to be worth (:func:`correlation_factor`):
#: twice the posture's 5 parameters.
MIN_EFFECTIVE_POINTS = 10


def correlation_factor(res, floor=0.0):
    """``sqrt(tau)``: how much the correlation of residuals along a contour (in the order
    given) inflates a standard deviation computed as if they were independent, with
    ``tau = N / N_eff = 1 + 2 sum_k rho_k`` the integrated autocorrelation time over every lag.

    Edge points share blur and interpolation, and a misfit of the model or of the edge detector
    leaves a smooth residual field whose correlation lasts for a hundred points and more (the
    rims of real photographs stay correlated over tens of lags), which lag 1 alone does not
    see. The sum is Geyer's initial monotone sequence estimator (the sums
    ``rho_2j + rho_2j+1`` of neighbouring lags, taken while positive and made non-increasing;
    ``(1 + rho) / (1 - rho)`` for an AR(1) sequence), and ``N_eff`` is at least
    ``MIN_EFFECTIVE_POINTS``.

    The noise is taken as the residuals observed plus an independent part of standard
    deviation ``floor`` px (the edge-location limit), so every ``rho_k`` is the residuals' own
    times ``m / (m + floor^2)``, ``m`` their mean square. Residuals far below the floor
    (round-off on exact data) then count as independent, whatever order their round-off
    happens to fall in (which differs between BLAS kernels); residuals far above it keep their
    own correlation.
    """
    r = np.asarray(res, np.float64)
    r = r[np.isfinite(r)] - np.mean(r[np.isfinite(r)]) if np.isfinite(r).sum() > 8 else None
    if r is None or not np.any(r):
        return 1.0
    n = len(r)
    ss = float(r @ r)
    m = ss / n
    f = np.fft.rfft(r, 2 * n)  # zero-padded: the sequence is not circular
    rho = np.fft.irfft(f * np.conj(f), 2 * n)[:n] / ss
    rho[1:] *= m / (m + float(floor) ** 2)
    rho[0] = 1.0
    pairs = rho[: 2 * (n // 2)].reshape(-1, 2).sum(axis=1)
    stop = int(np.argmax(pairs <= 0.0)) if np.any(pairs <= 0.0) else len(pairs)
    tau = -1.0 + 2.0 * float(np.sum(np.minimum.accumulate(pairs[:stop])))
    return math.sqrt(min(max(tau, 1.0), max(n / MIN_EFFECTIVE_POINTS, 1.0)))


def _weighted_problem(K, mirror, R, t, rim_px, rim_sigma, reflection, reflection_sigma, floor):
    """The rim's (and the reflection's) problem at ``(R, t)`` and each row's weight
    ``1 / (sigma f)``: ``sigma`` the source's observed RMS residual (at least ``floor``), ``f``
    its :func:`correlation_factor`; the free ``z``'s weak pull carries (almost) no weight."""
    terms = [RimTerm(K, mirror, R, t, rim_px)]
    sig = [max(float(rim_sigma), floor)]
    spec = _reflection_spec(reflection)
    if spec is not None and reflection_sigma is not None and np.isfinite(reflection_sigma):
        terms.append(ReflectionTerm(K, mirror, R, t, *spec))
        sig.append(max(float(reflection_sigma), floor))
    prob = _Problem(_Posture(R, t), terms)
    w = []
    for term, s in zip(terms, sig):
        res = term.residuals(R, t, term.x0())
        n_out = len(res) - (getattr(term, "prior", None) is not None)
        w.append(np.full(len(res), 1.0 / (s * correlation_factor(res[:n_out], floor))))
    w = np.concatenate(w)
    if len(terms) > 1 and terms[-1].prior is not None:
        w[-1] = 1e-3  # the weak pull on z is not a measurement: (almost) no information
    return prob, w


def _covariance_at(
    K, mirror, rvec, tvec, rim_points, rim_sigma, reflection, reflection_sigma, floor
):
    """At the posture ``(rvec, tvec)``: the weighted refinement problem, its row weights ``w``,
    its Jacobian ``J``, ``tvec`` as an array and the inverse of the information
    ``(J^T W J)^-1`` (None when singular)."""
    K = np.asarray(K, np.float64)
    R = cv2.Rodrigues(np.asarray(rvec, np.float64).reshape(3, 1))[0]
    t = np.asarray(tvec, np.float64)
    rim_px = np.ascontiguousarray(np.asarray(rim_points, np.float64).reshape(-1, 2))
    prob, w = _weighted_problem(
        K, mirror, R, t, rim_px, rim_sigma, reflection, reflection_sigma, floor
    )
    J = prob.jacobian(prob.x0()) * w[:, None]
    try:
        return prob, w, J, t, np.linalg.inv(J.T @ J)
    except np.linalg.LinAlgError:
        return prob, w, J, t, None


def posture_uncertainty(
    K, mirror, rvec, tvec, rim_points, rim_sigma, reflection=None, reflection_sigma=None, floor=0.02
):
    """First-order a posteriori covariance of the posture from the rim (and the reflection).

    With ``J`` the Jacobian of the residuals (px) with respect to the posture (two axis angles,
    ``tvec``) and the nuisance parameters, each source's rows weighted by ``1 / sigma`` with
    ``sigma`` its observed RMS residual (at least ``floor`` px) times the inflation that the
    correlation of the residuals along the contour implies (:func:`correlation_factor`; edge
    points share blur and interpolation), the covariance is ``(J^T J)^-1``; the posture block is
    reported. The rim pins the axis only weakly (a tilt of the mirror and a lateral shift keep
    the ellipse almost unchanged), which the weak direction names. Near alignment the rim's
    image depends on that tilt only to second order and this is too small:
    :func:`profile_uncertainty` states it from the cost itself.

    Parameters
    ----------
    rim_sigma : float
        Observed RMS of the rim residuals, px.
    reflection : ReflectionSpec, optional
        As for :func:`refine_posture`; joins with ``reflection_sigma`` (its observed RMS, px).

    Returns
    -------
    Uncertainty
    """
    *_, t, full = _covariance_at(
        K, mirror, rvec, tvec, rim_points, rim_sigma, reflection, reflection_sigma, floor
    )
    if full is None:
        return Uncertainty(math.inf, math.inf)
    return uncertainty_from_cov(full[:_N_POSTURE, :_N_POSTURE], t)


#: The stated region of the axis (:func:`profile_uncertainty`): where the profile cost rises
#: by at most the 95 % point of chi-square with 2 degrees of freedom (the two axis angles).
PROFILE_CHI2 = -2.0 * math.log(0.05)
#: The first-order covariance is kept when the profile cost at the edge of its region, along
#: the twin's direction and across it, is at least this share of ``PROFILE_CHI2`` (the region
#: reaches at most 1 / sqrt(0.8) = 1.12 times as far).
LINEAR_SHARE = 0.8
#: Directions searched for the region's reach, and the farthest tilt searched (radians).
PROFILE_DIRECTIONS = 12
MAX_REACH = math.radians(20.0)


class _TiltProfile:
    """The weighted cost (``sum (w r)^2``) with the axis turned by ``a`` (two angles, radians)
    from the estimate and every other parameter fitted, less the estimate's: Gauss-Newton
    from the first-order compensation, with the Jacobian of the estimate."""

    def __init__(self, prob, w, J):
        self.prob, self.w, self.x0 = prob, w, prob.x0()
        self.Jt = J[:, :2]
        self.pinv = np.linalg.pinv(J[:, 2:])
        self.c0, self.x = 0.0, self.x0
        self.c0 = self(np.zeros(2))

    def __call__(self, a, iters=6):
        a = np.asarray(a, np.float64)
        y = -self.pinv @ (self.Jt @ a)
        best, best_x = math.inf, None
        for _ in range(iters):
            x = self.x0.copy()
            x[:2] = a
            x[2:] += y
            r = self.w * self.prob.residuals(x)
            c = float(r @ r) if np.isfinite(r).all() else math.inf
            if not c < best - 1e-4:
                break
            best, best_x = c, x
            y = y - self.pinv @ r
        self.x = best_x if best_x is not None else self.x0
        return best - self.c0

    def rim_ms(self):
        """Mean square of the rim residuals at the last posture evaluated, px^2."""
        return float(np.mean(self.prob.parts(self.x)[0] ** 2))


def _reach(profile, d, start, cap, q):
    """How far from the estimate along ``d`` the profile cost stays within ``q`` (doubling
    from ``start``, then bisecting; the region is taken to be star-shaped about the estimate),
    at most ``cap``."""
    lo, s = 0.0, min(start, cap)
    while True:
        if not profile(s * d) <= q:
            hi = s
            break
        lo = s
        if s >= cap:
            return cap
        s = min(2.0 * s, cap)
    for _ in range(5):
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if profile(mid * d) <= q else (lo, mid)
    return 0.5 * (lo + hi)


def profile_uncertainty(
    K,
    mirror,
    rvec,
    tvec,
    rim_points,
    rim_sigma,
    reflection=None,
    reflection_sigma=None,
    floor=0.02,
    twin=None,
):
    """The posture's uncertainty with the axis's stated from the cost itself.

    :func:`posture_uncertainty` is first order: near alignment (the camera close to the
    mirror's axis) the rim's image depends on the tilt, with its compensating shift, only to
    second order (the two physical postures of a rim merge there), so the noise pushes the
    estimated tilt away from the aligned posture, where the Jacobian is larger than at the
    truth, and the first-order uncertainty is too small (``benchmarks/bench_calibrate.py`` and
    ``bench_stress.py`` print stated against found). Here the region of the two
    axis angles where the profile cost (every other parameter fitted; rows weighted as for
    :func:`posture_uncertainty`, by the residuals observed) rises by at most ``PROFILE_CHI2``
    is found, on this posture's side of its ``twin`` (the bisector between them: beyond it
    lies the other posture, a matter of the choice). Where that region reaches farther from
    the estimate than the first-order ellipse of the same level, ``D`` against ``D_1``, the
    covariance's axis block is widened by ``(D / D_1)^2``, with the origin's shift that
    compensates the tilt; else the first-order covariance stands (exact in the linear limit).

    Parameters
    ----------
    twin : (rvec, tvec), optional
        The other physical posture of the same rim (Chen's); without it the region is not
        bounded by the choice and ``aligned_chi2`` is NaN.

    Other parameters are those of :func:`posture_uncertainty`.

    Returns
    -------
    Uncertainty
        With ``first_order_axis_std_deg`` and, with a twin, ``aligned_chi2``, ``aligned_px``
        and ``twin_deg``.
    """
    prob, w, J, t, full = _covariance_at(
        K, mirror, rvec, tvec, rim_points, rim_sigma, reflection, reflection_sigma, floor
    )
    if full is None:
        return Uncertainty(math.inf, math.inf)
    cov = full[:_N_POSTURE, :_N_POSTURE]
    first = uncertainty_from_cov(cov, t)
    C = cov[:2, :2]
    lam, E = np.linalg.eigh(C)
    if not (np.isfinite(cov).all() and lam[0] > 0):
        return first
    profile = _TiltProfile(prob, w, J)
    q = PROFILE_CHI2
    Ci = np.linalg.inv(C)
    extra = {"first_order_axis_std_deg": first.axis_std_deg}
    half, u = math.inf, E[:, -1]
    if twin is not None:
        off = posture_offsets(np.asarray(rvec, np.float64), t, *twin)[:2]
        sep = float(np.linalg.norm(off))
        if sep > 0:
            u, half = off / sep, 0.5 * sep
            profile(np.zeros(2))
            ms0 = profile.rim_ms()
            chi2 = profile(0.5 * off)
            extra.update(
                aligned_chi2=max(chi2, 0.0),
                aligned_px=math.sqrt(max(profile.rim_ms() - ms0, 0.0)),
                twin_deg=math.degrees(sep),
            )
    v = np.array([-u[1], u[0]])

    def cap(d):  # this posture's side of the bisector with its twin, and MAX_REACH
        along = float(d @ u)
        return min(MAX_REACH, half / along) if along > 1e-12 else MAX_REACH

    def first_order_reach(d):
        return math.sqrt(q / float(d @ Ci @ d))

    probes = [u, -u, v, -v]
    linear = all(profile(min(first_order_reach(d), cap(d)) * d) >= LINEAR_SHARE * q for d in probes)
    if linear:
        return dataclasses.replace(first, **extra)
    angles = np.arange(PROFILE_DIRECTIONS) * (2.0 * math.pi / PROFILE_DIRECTIONS)
    reach = max(
        _reach(profile, d, first_order_reach(d), cap(d), q)
        for d in (math.cos(a) * u + math.sin(a) * v for a in angles)
    )
    scale = reach**2 / (q * lam[-1])  # (D / D_1)^2
    if not scale > 1.0:
        return dataclasses.replace(first, **extra)
    wide = cov + (scale - 1.0) * cov[:, :2] @ Ci @ cov[:2, :]
    return dataclasses.replace(uncertainty_from_cov(wide, t), widened=True, **extra)


def uncertainty_from_cov(cov, tvec):
    """The :class:`Uncertainty` of a (5, 5) posture covariance at the posture with ``tvec``."""
    cov = np.asarray(cov, np.float64)
    t = np.asarray(tvec, np.float64)
    axis_std = math.degrees(math.sqrt(max(cov[0, 0] + cov[1, 1], 0.0)))
    origin_std = math.sqrt(max(float(np.trace(cov[2:5, 2:5])), 0.0))
    L = float(np.linalg.norm(t))  # angles -> lengths at the camera's distance
    S = np.diag([L, L, 1.0, 1.0, 1.0])
    lam, E = np.linalg.eigh(S @ cov @ S)
    v = E[:, -1] * math.sqrt(max(lam[-1], 0.0))
    share = float(lam[-1] / max(lam.sum(), 1e-300))
    return Uncertainty(
        axis_std,
        origin_std,
        math.degrees(float(np.hypot(v[0], v[1])) / L),
        float(np.linalg.norm(v[2:5])),
        share,
        cov,
    )


def perturbed_posture(R0, t0, x):
    """The posture ``x`` away from ``(R0, t0)`` in the 5 parameters of :class:`Uncertainty`:
    ``(R, t)``, the mirror axis turned by ``x[:2]`` (radians) and the origin moved by ``x[2:]``."""
    return _Posture(np.asarray(R0, np.float64), t0)(np.asarray(x, np.float64))


def posture_offsets(rvec0, tvec0, rvec1, tvec1):
    """The second posture in the 5 parameters of the first's covariance (:class:`Uncertainty`).

    Returns
    -------
    (5,) ndarray
        The rotation taking the first mirror axis to the second, on the two axes perpendicular
        to the first (radians), and ``tvec1 - tvec0``.
    """
    R0 = cv2.Rodrigues(np.asarray(rvec0, np.float64).reshape(3, 1))[0]
    R1 = cv2.Rodrigues(np.asarray(rvec1, np.float64).reshape(3, 1))[0]
    a0, a1 = R0[:, 2], R1[:, 2]
    w = np.cross(a0, a1)
    s = float(np.linalg.norm(w))
    w = w * (math.atan2(s, float(a0 @ a1)) / s) if s > 0 else w
    b1, b2 = perpendicular_basis(a0)
    return np.concatenate([[w @ b1, w @ b2], np.asarray(tvec1, np.float64) - tvec0])
