"""The residuals of the posture's refinement (:mod:`.refine`) and their Jacobians.

Started from the analytic posture of Chen's method (:mod:`.chen`), the refinement minimises, in
pixels,

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
(posture columns, own nuisance columns); ``Problem`` stacks the terms it is given.

Parameters: two small rotations of the mirror axis (about two axes perpendicular to it), the
three components of the mirror origin ``tvec``, and per line a rotation of ``e`` (2) and a shift
of ``Q`` perpendicular to ``e`` (2). The rotation about the mirror axis is not observable and
stays in the gauge of docs/conventions.md. The Jacobian of the rim rows follows from the
envelope theorem at the foot points; the far-line rows use forward differences, the lines'
nuisance columns in 4 groups (they share no rows). The lines are started from the rays of the
analytic posture: their plane (eq. 31) and, linearly in Plucker coordinates, the line itself.
"""

from __future__ import annotations

import typing

import numpy as np

from ..gauge import gauge_rotation, perpendicular_basis
from ..gauge import rotate_vector as _rotate
from ..mirror import HyperbolicMirror
from .reflection import plane_radius
from .robust import mad_sigma

__all__ = [
    "N_POSTURE",
    "FarLineTerm",
    "Posture",
    "Problem",
    "ReflectionSpec",
    "ReflectionTerm",
    "RimTerm",
    "reflected_rays",
    "reflection_spec",
]

N_POSTURE = 5  # two angles of the mirror axis and tvec
_STEPS = np.array([1e-7, 1e-7, 1e-6, 1e-6, 1e-6])  # posture steps of the difference quotients


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


class Posture:
    """The 5 posture parameters: two small rotations of the mirror axis about axes
    perpendicular to it, and the shift of ``tvec`` (the rotation about the axis is the gauge)."""

    def __init__(self, R0, t0):
        self.a0 = R0[:, 2] / np.linalg.norm(R0[:, 2])
        self.b1, self.b2 = perpendicular_basis(self.a0)
        self.t0 = np.asarray(t0, np.float64)

    def __call__(self, x):
        """``(R, t)`` of the parameters ``x`` (5,)."""
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
        J = np.zeros((len(self.px), N_POSTURE))
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


def reflected_rays(mirror, R, t, xn):
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
            P, V = reflected_rays(self.mirror, R, t, xn)
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
                self._cache = (key, *reflected_rays(self.mirror, R, t, np.concatenate(lines_xn)))
            _, P, V = self._cache
        else:
            P, V = reflected_rays(self.mirror, R, t, np.concatenate(lines_xn))
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
    J = np.zeros((len(base), N_POSTURE))
    for k in range(N_POSTURE):
        xk = x.copy()
        xk[k] += steps[k]
        Rk, tk = posture(xk)
        J[:, k] = (term.residuals(Rk, tk, y) - base) / steps[k]
    return J


class Problem:
    """A sum of terms over the posture and each term's nuisance parameters."""

    def __init__(self, posture, terms):
        self.posture = posture
        self.terms = terms
        self.slices, i = [], N_POSTURE
        for term in terms:
            self.slices.append(slice(i, i + term.n_nuisance))
            i += term.n_nuisance
        self.n = i

    def x0(self):
        """The start: the posture unchanged, each term's nuisances at their start."""
        return np.concatenate([np.zeros(N_POSTURE)] + [t.x0() for t in self.terms])

    def parts(self, x):
        """Each term's residuals at ``x``, a list."""
        R, t = self.posture(x[:N_POSTURE])
        return [term.residuals(R, t, x[s]) for term, s in zip(self.terms, self.slices)]

    def residuals(self, x):
        """All the residuals at ``x``, px."""
        return np.concatenate(self.parts(x))

    def jacobian(self, x, steps=_STEPS):
        """The Jacobian at ``x``: each term's posture and own nuisance columns."""
        rows = []
        for term, s in zip(self.terms, self.slices):
            Jp, Jn = term.jacobian(self.posture, x[:N_POSTURE], x[s], steps)
            block = np.zeros((len(Jp), self.n))
            block[:, :N_POSTURE] = Jp
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


def reflection_spec(reflection):
    """A checked :class:`ReflectionSpec` (any 5-sequence in its order), or None if the outline
    is empty or the circle not finite."""
    if reflection is None:
        return None
    xn, r0, z0, r_known, z_known = reflection
    xn = np.ascontiguousarray(np.asarray(xn, np.float64).reshape(-1, 2))
    if len(xn) == 0 or not (np.isfinite(r0) and np.isfinite(z0)):
        return None
    return ReflectionSpec(xn, float(r0), float(z0), bool(r_known), bool(z_known))
