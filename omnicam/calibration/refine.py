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
  infinity and would bias a refinement).

Parameters: two small rotations of the mirror axis (about two axes perpendicular to it), the
three components of the mirror origin ``tvec``, and per line a rotation of ``e`` (2) and a shift
of ``Q`` perpendicular to ``e`` (2). The rotation about the mirror axis is not observable and
stays in the gauge of conventions.md. ``scipy.optimize.least_squares`` (imported lazily;
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
"""
from __future__ import annotations

import dataclasses
import math

import cv2
import numpy as np


__all__ = ["RefineResult", "refine_posture", "posture_uncertainty", "gauge_rotation"]

_N_POSTURE = 5


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
    lens_rms : float
        RMS outline residual of the camera's reflection for the kept posture, px (NaN without
        the lens).
    rho : float
        Fitted radius of the ball that models the camera body (NaN without the lens).
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
    lens_rms: float = math.nan
    rho: float = math.nan


def gauge_rotation(axis):
    """The smallest rotation taking ``e_z`` to the unit ``axis`` (the gauge of conventions.md)."""
    a = np.asarray(axis, np.float64)
    a = a / np.linalg.norm(a)
    v = np.array([-a[1], a[0], 0.0])  # e_z x a
    s = float(np.linalg.norm(v))
    ang = math.atan2(s, a[2])
    if s < 1e-300:
        return np.eye(3) if a[2] > 0 else np.diag([1.0, -1.0, -1.0])
    return cv2.Rodrigues((v / s * ang).reshape(3, 1))[0]


def _perp_basis(v):
    v = v / np.linalg.norm(v)
    h = np.array([1.0, 0.0, 0.0]) if abs(v[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    b1 = np.cross(v, h)
    b1 /= np.linalg.norm(b1)
    return b1, np.cross(v, b1)


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
    if not (abs(e @ N) < 0.1 and 10 * rim_radius < dist < 1e6 * rim_radius
            and np.median(V @ Q) > 0):
        return None
    return Q, e


def _rotate(v, w):
    """Rotate ``v`` by the rotation vector ``w`` (Rodrigues)."""
    th = float(np.linalg.norm(w))
    if th == 0.0:
        return v.copy()
    k = w / th
    return v * math.cos(th) + np.cross(k, v) * math.sin(th) + k * (k @ v) * (1 - math.cos(th))


class _Problem:
    """Residuals of the refinement; see the module docstring."""

    def __init__(self, K, mirror, R0, t0, rim_px, lines_xn, lens_xn=None):
        self.K = K
        self.A = K[:2, :2]
        self.k = K[:2, 2]
        self.mirror = mirror
        self.a0 = R0[:, 2] / np.linalg.norm(R0[:, 2])
        self.b1, self.b2 = _perp_basis(self.a0)
        self.t0 = np.asarray(t0, np.float64)
        self.rim_px = rim_px
        self.lines_xn = lines_xn
        self.phi0 = self._foot_points(R0, t0, init=True)
        self.rim_w = np.ones(len(rim_px))  # sqrt of the robust weights of the rim rows
        self.line0 = []
        self.line_scale = []
        self._ray_cache = (None,)
        self.lens_xn = None if lens_xn is None or len(lens_xn) == 0 else lens_xn
        self.n_y = 4 * len(lines_xn)  # line parameters follow the posture; then rho
        if self.lens_xn is not None:
            from .lens import fit_rho, ray_distances
            self.Kinv2 = np.linalg.inv(K)[:2, :2]
            d, g = ray_distances(mirror, R0, t0, self.lens_xn, self.Kinv2)
            ok = np.isfinite(d) & np.isfinite(g) & (g > 0)
            # pixel scale of each outline row: 1 / |grad_u d| at the starting posture
            self.lens_scale = np.where(ok, 1.0 / np.where(ok, g, 1.0), 0.0)
            self.rho0 = fit_rho(d, g)

    # posture ----------------------------------------------------------------------------
    def posture(self, x):
        axis = _rotate(self.a0, x[0] * self.b1 + x[1] * self.b2)
        return gauge_rotation(axis), self.t0 + x[2:5]

    # rim --------------------------------------------------------------------------------
    def _curve(self, R, t, phi):
        """Rim image ``c(phi)`` and its first two derivatives, as component pairs of (N,)."""
        r, zr = self.mirror.rim_radius, self.mirror.z_rim
        cp, sp = np.cos(phi), np.sin(phi)
        X, X1, X2 = [], [], []
        for i in range(3):
            a, b = R[i, 0] * cp, R[i, 1] * sp
            X.append(r * (a + b) + (R[i, 2] * zr + t[i]))  # R rho + t
            X1.append(r * (R[i, 1] * cp - R[i, 0] * sp))   # R rho'
            X2.append(-r * (a + b))                          # R rho''
        iz = 1.0 / X[2]
        A, k = self.A, self.k
        p = [X[0] * iz, X[1] * iz]
        p1 = [(X1[0] - p[0] * X1[2]) * iz, (X1[1] - p[1] * X1[2]) * iz]
        p2 = [(X2[0] - p[0] * X2[2] - 2.0 * p1[0] * X1[2]) * iz,
              (X2[1] - p[1] * X2[2] - 2.0 * p1[1] * X1[2]) * iz]

        def img(q, off):
            return (A[0, 0] * q[0] + A[0, 1] * q[1] + off[0],
                    A[1, 0] * q[0] + A[1, 1] * q[1] + off[1])

        return img(p, k), img(p1, (0.0, 0.0)), img(p2, (0.0, 0.0))

    def _foot_points(self, R, t, init=False, phi=None, iters=3):
        ux, uy = self.rim_px[:, 0], self.rim_px[:, 1]
        if init:
            # start at the rim point on the pixel's ray (exact for exact data)
            Ki = np.linalg.inv(self.K)
            xh = np.concatenate([self.rim_px, np.ones((len(ux), 1))], axis=1) @ Ki.T
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

    def _rim_normals(self, R, t, phi):
        (cx, cy), (dx, dy), _ = self._curve(R, t, phi)
        nn = np.hypot(dx, dy)
        return cx, cy, dy / nn, -dx / nn

    def rim_residuals(self, R, t):
        phi = self._foot_points(R, t, phi=self.phi0)
        cx, cy, nx, ny = self._rim_normals(R, t, phi)
        return ((self.rim_px[:, 0] - cx) * nx + (self.rim_px[:, 1] - cy) * ny) * self.rim_w

    def set_robust_weights(self, R, t, k=2.0):
        """Huber weights of the rim rows from their residuals at ``(R, t)``, fixed thereafter
        (one reweighting step): ``w = min(1, k s / |r|)``, ``s = 1.4826 MAD``."""
        self.rim_w = np.ones(len(self.rim_px))
        r = np.abs(self.rim_residuals(R, t))
        s = 1.4826 * float(np.median(r))
        if s > 0:
            self.rim_w = np.sqrt(np.minimum(1.0, k * s / np.maximum(r, 1e-300)))

    # lines ------------------------------------------------------------------------------
    def rays(self, R, t, xn):
        """Reflected rays of normalised coordinates (eqs. 6-19), in numpy: the line sets are
        small and this runs hundreds of times (no thread start-up per call)."""
        C = -R.T @ t  # F_M (eq. 17)
        V = np.concatenate([xn, np.ones((len(xn), 1))], axis=1) @ R  # V_M = R^T V_C (eq. 16)
        V /= np.linalg.norm(V, axis=1, keepdims=True)
        P = self.mirror.intersect(C, V)  # eqs. 8-12
        return P, self.mirror.reflect(V, self.mirror.unit_normal(P))  # eqs. 14-15

    def init_lines(self, R, t, depth):
        """Initial 3-D lines from the rays of the analytic posture (eqs. 30-31)."""
        self.line0, self.line_scale = [], []
        for xn in self.lines_xn:
            P, V = self.rays(R, t, xn)
            ok = np.isfinite(V).all(axis=1)
            P, V = P[ok], V[ok]
            w, E = np.linalg.eigh(V.T @ V)
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
        zero = np.zeros(4 * len(self.lines_xn))
        base = self.line_residuals(R, t, zero, scaled=False)
        h = 1e-4
        grads = []
        for dx in ((h, 0.0), (0.0, h)):
            shifted = []
            for xn in self.lines_xn:
                Ki = np.linalg.inv(self.K)
                shifted.append(xn + np.array(dx) @ Ki[:2, :2].T)
            grads.append((self.line_residuals(R, t, zero, scaled=False, lines_xn=shifted)
                          - base) / h)
        g = np.hypot(grads[0], grads[1])
        self.line_scale = np.where(g > 0, 1.0 / np.where(g > 0, g, 1.0), 0.0)

    def line(self, i, y):
        Qa, e0, f1, f2, depth = self.line0[i]
        e = e0 + y[0] * f1 + y[1] * f2
        e /= np.linalg.norm(e)
        Q = Qa + depth * (y[2] * f1 + y[3] * f2)
        return Q, e

    def line_residuals(self, R, t, y, scaled=True, lines_xn=None):
        lines_xn = self.lines_xn if lines_xn is None else lines_xn
        if not lines_xn:
            return np.zeros(0)
        sizes = [len(xn) for xn in lines_xn]
        if lines_xn is self.lines_xn:  # the rays depend on the posture only: cache them
            key = (R.tobytes(), t.tobytes())
            if self._ray_cache[0] != key:
                P, V = self.rays(R, t, np.concatenate(lines_xn))
                self._ray_cache = (key, P, V)
            _, P, V = self._ray_cache
        else:
            P, V = self.rays(R, t, np.concatenate(lines_xn))
        idx = np.repeat(np.arange(len(sizes)), sizes)
        Q = np.empty((len(lines_xn), 3))
        E = np.empty((len(lines_xn), 3))
        for i in range(len(lines_xn)):
            Q[i], E[i] = self.line(i, y[4 * i:4 * i + 4])
        n = np.cross(Q[idx] - P, E[idx])
        n /= np.linalg.norm(n, axis=1, keepdims=True)
        r = (V * n).sum(axis=1)
        r = np.where(np.isfinite(r), r, 0.0)
        return r * self.line_scale if scaled else r

    # lens ---------------------------------------------------------------------------------
    def lens_residuals(self, R, t, rho):
        """``(d - rho) / |grad d|`` of the blob outline (px); rays that miss give 0."""
        if self.lens_xn is None:
            return np.zeros(0)
        from .lens import ray_distances
        r = (ray_distances(self.mirror, R, t, self.lens_xn) - rho) * self.lens_scale
        return np.where(np.isfinite(r), r, 0.0)

    # all --------------------------------------------------------------------------------
    def residuals(self, x):
        R, t = self.posture(x[:_N_POSTURE])
        parts = [self.rim_residuals(R, t)]
        if self.lines_xn:
            parts.append(self.line_residuals(R, t, x[_N_POSTURE:_N_POSTURE + self.n_y]))
        if self.lens_xn is not None:
            parts.append(self.lens_residuals(R, t, x[_N_POSTURE + self.n_y]))
        return parts[0] if len(parts) == 1 else np.concatenate(parts)

    def line_jacobian(self, R, t, y, steps):
        """Line rows and line columns only (the posture fixed): 4 grouped forward differences."""
        base = self.line_residuals(R, t, y)
        sizes = [len(xn) for xn in self.lines_xn]
        rows = np.repeat(np.arange(len(sizes)), sizes)
        J = np.zeros((len(base), len(y)))
        for k in range(4):
            yk = y.copy()
            yk[k::4] += steps[k]
            d = (self.line_residuals(R, t, yk) - base) / steps[k]
            J[np.arange(len(base)), 4 * rows + k] = d
        return J

    def jacobian(self, x, steps):
        """Rim rows: the envelope theorem at the foot points (``d dist / d p = -n . dc/dp``),
        with ``dc/dR`` by differences of ``R`` and ``dc/dt`` analytic. Line rows: forward
        differences, posture columns one by one, line columns in 4 groups."""
        R, t = self.posture(x[:_N_POSTURE])
        phi = self._foot_points(R, t, phi=self.phi0)
        cx, cy, nx, ny = self._rim_normals(R, t, phi)
        n_rim = len(self.rim_px)
        n_line = sum(len(xn) for xn in self.lines_xn)
        n_lens = 0 if self.lens_xn is None else len(self.lens_xn)
        J = np.zeros((n_rim + n_line + n_lens, len(x)))
        for k in range(2):
            xk = x[:_N_POSTURE].copy()
            xk[k] += steps[k]
            Rk, _ = self.posture(xk)
            (ckx, cky), _, _ = self._curve(Rk, t, phi)
            J[:n_rim, k] = -((ckx - cx) * nx + (cky - cy) * ny) / steps[k] * self.rim_w
        r, zr = self.mirror.rim_radius, self.mirror.z_rim
        rho = np.stack([r * np.cos(phi), r * np.sin(phi), np.full_like(phi, zr)], axis=1)
        X = rho @ R.T + t
        z = X[:, 2]
        # n^T A, then d pi / d t = [[1/z, 0, -x/z^2], [0, 1/z, -y/z^2]]
        m0 = nx * self.A[0, 0] + ny * self.A[1, 0]
        m1 = nx * self.A[0, 1] + ny * self.A[1, 1]
        J[:n_rim, 2] = -m0 / z * self.rim_w
        J[:n_rim, 3] = -m1 / z * self.rim_w
        J[:n_rim, 4] = (m0 * X[:, 0] + m1 * X[:, 1]) / z**2 * self.rim_w
        if n_line:
            y = x[_N_POSTURE:_N_POSTURE + self.n_y]
            base = self.line_residuals(R, t, y)
            for k in range(_N_POSTURE):
                xk = x[:_N_POSTURE].copy()
                xk[k] += steps[k]
                Rk, tk = self.posture(xk)
                J[n_rim:n_rim + n_line, k] = (self.line_residuals(Rk, tk, y) - base) / steps[k]
            J[n_rim:n_rim + n_line, _N_POSTURE:_N_POSTURE + self.n_y] = self.line_jacobian(
                R, t, y, steps[_N_POSTURE:_N_POSTURE + self.n_y])
        if n_lens:
            rho = x[_N_POSTURE + self.n_y]
            base = self.lens_residuals(R, t, rho)
            for k in range(_N_POSTURE):
                xk = x[:_N_POSTURE].copy()
                xk[k] += steps[k]
                Rk, tk = self.posture(xk)
                J[n_rim + n_line:, k] = (self.lens_residuals(Rk, tk, rho) - base) / steps[k]
            J[n_rim + n_line:, -1] = -self.lens_scale
        return J


def refine_posture(K, mirror, rvec, tvec, rim_points, far_lines_normalized=(), line_depth=None,
                   max_nfev=15, robust=True, lens_normalized=None):
    """Refine a mirror posture by non-linear least squares (rim and far lines).

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
    lens_normalized : (M, 2) ndarray, optional
        Undistorted normalised coordinates of the outline of the camera's reflection
        (:mod:`.lens`); adds the rows ``(d - rho) / |grad d|`` (px) and ``rho`` as one more
        parameter (started at its closed-form best fit, :func:`.lens.fit_rho`).
    robust : bool
        Weight the rim rows by Huber weights (``k = 2`` robust standard deviations) computed
        from the residuals of the starting posture: boundary points that the rim fit kept but
        that sit off the rim (reflections, holder edges, clipped borders) then count less.
        The costs compared to accept the result use the same weights.

    Returns
    -------
    RefineResult
    """
    from scipy.optimize import least_squares  # lazy: scipy comes with scikit-image

    K = np.asarray(K, np.float64)
    R0 = cv2.Rodrigues(np.asarray(rvec, np.float64).reshape(3, 1))[0]
    t0 = np.asarray(tvec, np.float64)
    rim_px = np.ascontiguousarray(np.asarray(rim_points, np.float64).reshape(-1, 2))
    lines_xn = [np.ascontiguousarray(np.asarray(x, np.float64)) for x in far_lines_normalized]
    depth = 1000.0 * mirror.rim_radius if line_depth is None else float(line_depth)
    # lines whose rays mostly miss the mirror under this posture are left out
    probe = _Problem(K, mirror, R0, t0, rim_px[:5], [])
    lines_xn = [x for x in lines_xn if np.isfinite(probe.rays(R0, t0, x)[1]).all(axis=1).sum() >= 3]
    lens_xn = None
    if lens_normalized is not None and len(lens_normalized):
        lens_xn = np.ascontiguousarray(np.asarray(lens_normalized, np.float64).reshape(-1, 2))
    prob = _Problem(K, mirror, R0, t0, rim_px, lines_xn, lens_xn)
    if prob.lens_xn is not None and not np.isfinite(prob.rho0):
        prob = _Problem(K, mirror, R0, t0, rim_px, lines_xn)  # the outline misses the camera
    has_lens = prob.lens_xn is not None
    if robust:
        prob.set_robust_weights(R0, t0)
    n_lines = len(lines_xn)
    if n_lines:
        prob.init_lines(R0, t0, depth)
    steps = np.array([1e-7, 1e-7, 1e-6, 1e-6, 1e-6] + [1e-7] * 4 * n_lines + [1e-6] * has_lens)
    x0 = np.zeros(_N_POSTURE + 4 * n_lines + has_lens)
    if has_lens:
        x0[-1] = prob.rho0  # closed-form best rho at the analytic posture (its fair cost)

    opts = dict(method="lm", x_scale="jac", xtol=1e-8, ftol=1e-6, gtol=1e-10)
    # stage 1: the line parameters alone at the analytic posture (its fair cost)
    nfev = 0
    if n_lines:
        sl = slice(_N_POSTURE, _N_POSTURE + 4 * n_lines)
        s1 = least_squares(lambda y: prob.line_residuals(R0, t0, y), x0[sl],
                           jac=lambda y: prob.line_jacobian(R0, t0, y, steps[sl]),
                           max_nfev=max_nfev, **opts)
        x0[sl] = s1.x
        nfev += s1.nfev
    r_init = prob.residuals(x0)
    cost_init = 0.5 * float(r_init @ r_init)

    # stage 2: posture and lines together (skipped when the start is already exact)
    x, r, cost_fin, accepted = x0, r_init, cost_init, False
    if cost_init > 1e-20 * len(r_init):
        sol = least_squares(prob.residuals, x0, jac=lambda x: prob.jacobian(x, steps),
                            max_nfev=max_nfev, **opts)
        nfev += sol.nfev
        r_fin = prob.residuals(sol.x)
        cost_fin = 0.5 * float(r_fin @ r_fin)
        # keep the refined posture only if it is better: never worse than the analytic one
        if np.isfinite(cost_fin) and cost_fin < cost_init:
            x, r, accepted = sol.x, r_fin, True
    R, t = prob.posture(x[:_N_POSTURE])
    n_rim = len(rim_px)
    rim_rms = float(np.sqrt(np.mean((r[:n_rim] / prob.rim_w) ** 2)))
    n_line = sum(len(xn) for xn in lines_xn)
    line_rms = float(np.sqrt(np.mean(r[n_rim:n_rim + n_line] ** 2))) if n_lines else math.nan
    lens_rms = float(np.sqrt(np.mean(r[n_rim + n_line:] ** 2))) if has_lens else math.nan
    rho = float(x[-1]) if has_lens else math.nan
    lines = [prob.line(i, x[_N_POSTURE + 4 * i:_N_POSTURE + 4 * i + 4]) for i in range(n_lines)]
    rvec_out = cv2.Rodrigues(R)[0].ravel()
    return RefineResult(rvec=rvec_out, tvec=np.asarray(t, np.float64), accepted=accepted,
                        cost_initial=cost_init, cost_final=cost_fin, rim_rms=rim_rms,
                        line_rms=line_rms, lines=lines, nfev=int(nfev), lens_rms=lens_rms,
                        rho=rho)


def posture_uncertainty(K, mirror, rvec, tvec, rim_points, rms, lens_normalized=None,
                        lens_rms=None):
    """First-order standard deviations of the posture from the rim (and the lens outline).

    With ``J`` the Jacobian of the rim residuals (px) with respect to the two axis angles and
    ``tvec``, the covariance is ``rms^2 (J^T J)^-1``. The rim pins the axis only weakly: a tilt
    of the mirror and a lateral shift that keep the rim ellipse almost unchanged (about 1 deg
    per px of noise on 360 points for the default rigs), which is why this is reported.

    With ``lens_normalized`` (the outline of the camera's reflection, :mod:`.lens`) and its
    RMS residual ``lens_rms`` (px), its rows join ``J`` weighted by ``1 / lens_rms`` (the rim
    rows by ``1 / rms``), with ``rho`` as one more column.

    Returns
    -------
    axis_std_deg : float
        RMS error of the axis direction (square root of the summed variances of the two
        angles), degrees.
    origin_std_mm : float
        Standard deviation of the origin (square root of the covariance's trace), length unit.
    """
    R = cv2.Rodrigues(np.asarray(rvec, np.float64).reshape(3, 1))[0]
    rim_px = np.ascontiguousarray(np.asarray(rim_points, np.float64).reshape(-1, 2))
    lens_xn = None
    if lens_normalized is not None and len(lens_normalized) and lens_rms is not None \
            and np.isfinite(lens_rms) and lens_rms > 0:
        lens_xn = np.ascontiguousarray(np.asarray(lens_normalized, np.float64).reshape(-1, 2))
    prob = _Problem(np.asarray(K, np.float64), mirror, R, np.asarray(tvec, np.float64), rim_px, [],
                    lens_xn)
    x = np.zeros(_N_POSTURE)
    if prob.lens_xn is not None and np.isfinite(prob.rho0):
        x = np.append(x, prob.rho0)
    else:
        prob.lens_xn = None
    J = prob.jacobian(x, np.array([1e-7, 1e-7, 1e-6, 1e-6, 1e-6, 1e-6])[:len(x)])
    w = np.full(len(J), 1.0 / float(rms))
    w[len(rim_px):] = 1.0 / float(lens_rms) if prob.lens_xn is not None else 1.0
    J = J * w[:, None]
    try:
        cov = np.linalg.inv(J.T @ J)
    except np.linalg.LinAlgError:
        return math.inf, math.inf
    axis_std = math.degrees(math.sqrt(max(cov[0, 0] + cov[1, 1], 0.0)))
    origin_std = math.sqrt(max(float(np.trace(cov[2:5, 2:5])), 0.0))
    return axis_std, origin_std
