"""An independent forward model of a catadioptric rig: a pinhole behind a mirror of revolution.

Nothing here comes from omnicam (no ray tracer, mirror, camera or board code of the library):
it is the ground truth that the chessboard calibration is tested against, so a mistake shared
by the estimator and its test data cannot hide. Only numpy.

**The mirror** is a quadric of revolution about the ``z`` axis of its own frame,

    F(X) = x^2 + y^2 + alpha z^2 + 2 beta z + gamma = 0,

of which the mirror is the *cap* facing the camera below it: one branch of ``z`` as a function
of ``rho = sqrt(x^2 + y^2)``, for ``rho <= rim_radius`` (the rim, a circle at height
``z_rim``). With ``alpha != 0`` the cap's branch is ``sheet * (alpha z + beta) >= 0``.

* hyperboloid ``(x^2 + y^2) / a^2 - z^2 / b^2 = -1``, sheet ``z > 0`` (omnicam's mirror frame,
  docs/conventions.md): ``alpha = -a^2 / b^2``, ``beta = 0``, ``gamma = a^2``; foci
  ``(0, 0, +-c)``, ``c = sqrt(a^2 + b^2)``, the camera near the lower one;
* sphere of radius ``s`` centred at ``(0, 0, z0)``, its lower cap: ``alpha = 1``,
  ``beta = -z0``, ``gamma = z0^2 - s^2``;
* paraboloid ``z = z0 + rho^2 / (2 h)``: ``alpha = 0``, ``beta = -h``, ``gamma = 2 h z0``; focus
  ``(0, 0, z0 + h / 2)``;
* ellipsoid ``rho^2 / A^2 + (z - z0)^2 / C^2 = 1``, its lower cap (prolate when ``C > A``, the
  long axis the mirror's): ``alpha = A^2 / C^2``, ``beta = -alpha z0``,
  ``gamma = alpha z0^2 - A^2``; foci ``(0, 0, z0 +- sqrt(C^2 - A^2))``.

A mirror that is no quadric (``tests/revolution_rig.py``) joins the :class:`Rig` through the
same two methods, ``intersect(O, V)`` and ``reflect(P, V)``, and ``height``, ``z_rim``,
``rim_radius``, ``name``.

``grad F = (2x, 2y, 2 (alpha z + beta))`` points down, towards the camera, on all three caps:
a ray from the camera hits the cap's outside when ``V . grad F < 0``.

**The camera**: a pinhole ``K`` with OpenCV's radial distortion ``x_d = x (1 + k1 r^2 +
k2 r^4)``; its posture is OpenCV's (``X_cam = R X_mirror + t``), the camera centre
``O = -R^T t`` in the mirror frame.

**Backward**: pixel -> undistorted ray (Newton on the radius) -> first hit on the cap inside
the rim -> reflected ray ``d - 2 (d . n) n`` -> a board's plane.
**Forward**: a scene point's pixel by Gauss-Newton on the pixel (2-D, finite differences) so
that the reflected ray through it points at the point.
"""

from __future__ import annotations

import dataclasses
import functools
import math

import numpy as np

# -- the mirror ---------------------------------------------------------------------------------


@dataclasses.dataclass(frozen=True)
class Quadric:
    """A mirror cap ``x^2 + y^2 + alpha z^2 + 2 beta z + gamma = 0`` (module docstring).

    Attributes
    ----------
    alpha, beta, gamma : float
    rim_radius : float
    sheet : float
        +1 or -1: the cap is the branch ``sheet * (alpha z + beta) >= 0`` (ignored when
        ``alpha == 0``).
    name : str
    """

    alpha: float
    beta: float
    gamma: float
    rim_radius: float
    sheet: float = 1.0
    name: str = "quadric"

    def height(self, rho):
        """``z`` of the cap at radius ``rho``."""
        rho2 = np.asarray(rho, np.float64) ** 2
        if self.alpha == 0.0:
            return -(self.gamma + rho2) / (2.0 * self.beta)
        root = np.sqrt(self.beta**2 - self.alpha * (self.gamma + rho2))
        return (-self.beta + self.sheet * root) / self.alpha

    @property
    def z_rim(self) -> float:
        return float(self.height(self.rim_radius))

    def value(self, P):
        """``F(P)`` for points ``(N, 3)``."""
        x, y, z = P[..., 0], P[..., 1], P[..., 2]
        return x * x + y * y + self.alpha * z * z + 2.0 * self.beta * z + self.gamma

    def gradient(self, P):
        """``grad F`` at ``(N, 3)`` points (towards the camera on the cap)."""
        return np.stack(
            [2.0 * P[..., 0], 2.0 * P[..., 1], 2.0 * (self.alpha * P[..., 2] + self.beta)], -1
        )

    def on_cap(self, P, tol=1e-9):
        """Whether points on the quadric lie on the cap inside the rim."""
        rho2 = P[..., 0] ** 2 + P[..., 1] ** 2
        inside = rho2 <= self.rim_radius**2 * (1.0 + tol)
        if self.alpha == 0.0:
            return inside
        return inside & (self.sheet * (self.alpha * P[..., 2] + self.beta) >= 0.0)

    def intersect(self, O, V):
        """:func:`intersect` on this cap."""
        return intersect(self, O, V)

    def reflect(self, P, V):
        """:func:`reflect` on this cap."""
        return reflect(self, P, V)


def hyperboloid(a, b, rim_radius):
    """``(x^2 + y^2) / a^2 - z^2 / b^2 = -1``, sheet ``z > 0`` (times ``a^2``)."""
    return Quadric(-(a * a) / (b * b), 0.0, a * a, rim_radius, -1.0, f"hyperboloid {a:g}/{b:g}")


def sphere(radius, z_centre, rim_radius):
    """The lower cap of the sphere of ``radius`` centred at ``(0, 0, z_centre)``."""
    return Quadric(
        1.0, -z_centre, z_centre**2 - radius**2, rim_radius, -1.0, f"sphere r={radius:g}"
    )


def paraboloid(h, z_vertex, rim_radius):
    """``z = z_vertex + rho^2 / (2 h)``, focus at ``z_vertex + h / 2``."""
    return Quadric(0.0, -h, 2.0 * h * z_vertex, rim_radius, 1.0, f"paraboloid h={h:g}")


def ellipsoid(A, C, z_centre, rim_radius):
    """The lower cap of ``rho^2 / A^2 + (z - z_centre)^2 / C^2 = 1`` (prolate when ``C > A``);
    its vertex at ``z_centre - C``."""
    al = A * A / (C * C)
    return Quadric(
        al, -al * z_centre, al * z_centre**2 - A * A, rim_radius, -1.0, f"ellipsoid {A:g}/{C:g}"
    )


def intersect(quadric, O, V):
    """First hit of the rays ``O + t V`` (``t > 0``) on the cap from its outside.

    Returns ``(P (N, 3), t (N,))``, NaN where the ray misses the cap (no root, hits outside the
    rim or on the other branch, or reaches the cap from behind).
    """
    O = np.broadcast_to(np.asarray(O, np.float64), np.shape(V))
    V = np.asarray(V, np.float64)
    al, be = quadric.alpha, quadric.beta
    # F(O + t V) = A t^2 + 2 B t + C
    A = V[:, 0] ** 2 + V[:, 1] ** 2 + al * V[:, 2] ** 2
    B = O[:, 0] * V[:, 0] + O[:, 1] * V[:, 1] + al * O[:, 2] * V[:, 2] + be * V[:, 2]
    C = quadric.value(O)
    with np.errstate(invalid="ignore", divide="ignore"):
        disc = B * B - A * C
        sq = np.sqrt(np.where(disc >= 0.0, disc, np.nan))
        q = -(B + np.copysign(sq, B))  # the stable pair of roots: q / A and C / q
        t1 = np.where(np.abs(A) > 1e-14 * np.abs(B), q / A, np.nan)
        t2 = C / q
    best = np.full(len(V), np.inf)
    for t in (t1, t2):
        P = O + t[:, None] * V
        ok = np.isfinite(t) & (t > 1e-9) & quadric.on_cap(P)
        best = np.where(ok & (t < best), t, best)
    best[~np.isfinite(best)] = np.nan
    P = O + best[:, None] * V
    facing = np.einsum("ij,ij->i", quadric.gradient(P), V) < 0.0
    P[~facing] = np.nan
    best[~facing] = np.nan
    return P, best


def reflect(quadric, P, V):
    """Unit reflected directions of the unit rays ``V`` at the cap points ``P``."""
    n = quadric.gradient(P)
    n = n / np.linalg.norm(n, axis=1, keepdims=True)
    d = V - 2.0 * np.einsum("ij,ij->i", V, n)[:, None] * n
    return d / np.linalg.norm(d, axis=1, keepdims=True)


# -- the camera ---------------------------------------------------------------------------------


def rotation(rvec):
    """Rodrigues' formula: the rotation matrix of the axis-angle vector ``rvec``."""
    r = np.asarray(rvec, np.float64)
    th = float(np.linalg.norm(r))
    if th < 1e-15:
        return np.eye(3)
    k = r / th
    Kx = np.array([[0.0, -k[2], k[1]], [k[2], 0.0, -k[0]], [-k[1], k[0], 0.0]])
    return np.eye(3) + math.sin(th) * Kx + (1.0 - math.cos(th)) * (Kx @ Kx)


def distort(xy, k1, k2):
    """OpenCV's radial distortion of normalised points ``(N, 2)``."""
    r2 = np.sum(xy * xy, axis=1, keepdims=True)
    return xy * (1.0 + k1 * r2 + k2 * r2 * r2)


def undistort(xy_d, k1, k2, iterations=60):
    """Inverse of :func:`distort` by Newton on the radius, ``r (1 + k1 r^2 + k2 r^4) = r_d``
    (radial distortion keeps the direction); NaN where it does not converge."""
    if k1 == 0.0 and k2 == 0.0:
        return np.array(xy_d, np.float64)
    rd = np.linalg.norm(xy_d, axis=1)
    r = rd.copy()
    for _ in range(iterations):
        g = r * (1.0 + k1 * r**2 + k2 * r**4) - rd
        dg = 1.0 + 3.0 * k1 * r**2 + 5.0 * k2 * r**4
        step = g / dg
        r = r - step
        if not np.any(np.abs(step) > 1e-15 * (1.0 + r)):
            break
    bad = np.abs(r * (1.0 + k1 * r**2 + k2 * r**4) - rd) > 1e-12 * np.maximum(rd, 1.0)
    bad |= (1.0 + 3.0 * k1 * r**2 + 5.0 * k2 * r**4) <= 0.0  # past the lens's fold
    with np.errstate(invalid="ignore", divide="ignore"):
        s = np.where(rd > 0, r / rd, 1.0)
    out = xy_d * s[:, None]
    out[bad] = np.nan
    return out


@dataclasses.dataclass(frozen=True, eq=False)
class Rig:
    """A pinhole (``K``, radial ``k1, k2``) behind a :class:`Quadric`, posture ``(R, t)`` with
    ``X_cam = R X_mirror + t``; ``image_size = (width, height)``."""

    K: np.ndarray
    k1: float
    k2: float
    R: np.ndarray
    t: np.ndarray
    mirror: Quadric
    image_size: tuple

    @property
    def centre(self):
        """The camera centre in the mirror frame, ``-R^T t``."""
        return -self.R.T @ self.t

    @property
    def D(self):
        """OpenCV's distortion vector ``(k1, k2, 0, 0)``."""
        return np.array([self.k1, self.k2, 0.0, 0.0])

    def pixels_of_camera_points(self, X_cam):
        """Pixels of points in the camera frame (the pinhole alone, no mirror)."""
        xy = X_cam[:, :2] / X_cam[:, 2:3]
        xy = distort(xy, self.k1, self.k2)
        K = self.K
        return np.stack(
            [K[0, 0] * xy[:, 0] + K[0, 1] * xy[:, 1] + K[0, 2], K[1, 1] * xy[:, 1] + K[1, 2]], 1
        )

    def camera_rays(self, pixels):
        """Unit rays ``(N, 3)`` of pixels in the mirror frame (NaN past the lens's fold)."""
        p = np.asarray(pixels, np.float64).reshape(-1, 2)
        K = self.K
        y = (p[:, 1] - K[1, 2]) / K[1, 1]
        x = (p[:, 0] - K[0, 2] - K[0, 1] * y) / K[0, 0]
        xy = undistort(np.stack([x, y], 1), self.k1, self.k2)
        v = np.column_stack([xy, np.ones(len(xy))]) @ self.R  # R^T v, row-wise
        return v / np.linalg.norm(v, axis=1, keepdims=True)

    def trace(self, pixels):
        """``(P, d)``: the mirror point and the unit reflected direction of each pixel (mirror
        frame), NaN where the pixel does not see the cap."""
        V = self.camera_rays(pixels)
        P, _ = self.mirror.intersect(self.centre, V)
        return P, self.mirror.reflect(P, V)

    def rim_pixels(self, n=720):
        """The rim circle as the camera sees it (directly, not in the mirror)."""
        phi = 2.0 * np.pi * np.arange(n) / n
        m = self.mirror
        P = np.column_stack(
            [m.rim_radius * np.cos(phi), m.rim_radius * np.sin(phi), np.full(n, m.z_rim)]
        )
        return self.pixels_of_camera_points(P @ self.R.T + self.t)

    def rim_centre_and_radius(self):
        """The rim image's mean point and its smallest distance from it, px."""
        rim = self.rim_pixels(360)
        c = rim.mean(axis=0)
        return c, float(np.linalg.norm(rim - c, axis=1).min())

    def mirror_pixels(self, step=6.0, inner=0.0, outer=0.97):
        """A grid of pixels whose rays hit the cap, between ``inner`` and ``outer`` of the rim
        image's smallest radius from its centre."""
        c, r = self.rim_centre_and_radius()
        g = np.arange(-r, r + step, step)
        u, v = np.meshgrid(g + c[0], g + c[1])
        px = np.column_stack([u.ravel(), v.ravel()])
        rr = np.linalg.norm(px - c, axis=1)
        px = px[(rr <= outer * r) & (rr >= inner * r)]
        _, d = self.trace(px)
        return px[np.isfinite(d).all(axis=1)]

    @functools.lru_cache(maxsize=4)  # noqa: B019 (a few rigs per test module)
    def _start_grid(self, step):
        grid = self.mirror_pixels(step, 0.0, 1.0)
        return (grid, *self.trace(grid))

    def project(self, X, step=8.0, iterations=30, h=1e-4):
        """Pixels ``(N, 2)`` whose reflected rays pass through the mirror-frame points ``X``.

        Start: the pixel of a grid (``step`` px) whose ray points closest to the point; then
        Gauss-Newton on the pixel, the 3-vector ``unit(X - P) - d`` as residual and its
        Jacobian by forward differences of ``h`` px. NaN where it does not converge to
        ``1e-9`` rad.
        """
        X = np.asarray(X, np.float64).reshape(-1, 3)
        grid, Pg, dg = self._start_grid(step)
        u = np.empty((len(X), 2))
        for s in range(0, len(X), 64):  # the grid pixel whose ray points at X best
            e = X[s : s + 64, None, :] - Pg[None]
            e /= np.linalg.norm(e, axis=2, keepdims=True)
            u[s : s + 64] = grid[np.argmax(np.einsum("nmk,mk->nm", e, dg), axis=1)]

        def residual(px):
            P, d = self.trace(px)
            e = X - P
            return e / np.linalg.norm(e, axis=1, keepdims=True) - d

        for _ in range(iterations):
            r = residual(u)
            if np.all(np.linalg.norm(r, axis=1) < 1e-13):
                break
            J = np.stack(
                [(residual(u + [h, 0.0]) - r) / h, (residual(u + [0.0, h]) - r) / h], axis=2
            )
            JT = np.transpose(J, (0, 2, 1))
            step_u = np.linalg.solve(JT @ J, -(JT @ r[:, :, None]))[:, :, 0]
            # keep a step within the cap (halve it until the pixel sees the mirror)
            for _ in range(20):
                ok = np.isfinite(residual(u + step_u)).all(axis=1)
                if ok.all():
                    break
                step_u[~ok] *= 0.5
            u = u + step_u
            if not np.any(np.abs(step_u) > 1e-10):
                break
        err = np.linalg.norm(residual(u), axis=1)
        u[~(err < 1e-9)] = np.nan
        return u


def posture(tilt_deg, tilt_azimuth_deg, offset, c):
    """``(R, t)`` of the mirror tilted by ``tilt_deg`` towards ``tilt_azimuth_deg`` (about an
    axis in the camera's x-y plane: the smallest turn from the camera's +z to the mirror axis,
    omnicam's gauge) and moved by ``offset`` (camera frame) from ``(0, 0, c)``."""
    phi = math.radians(tilt_azimuth_deg)
    rvec = math.radians(tilt_deg) * np.array([-math.sin(phi), math.cos(phi), 0.0])
    return rotation(rvec), np.array([0.0, 0.0, c]) + np.asarray(offset, np.float64)


def rig_filling(mirror, image_size, camera_z, fill=0.85, k1=0.0, k2=0.0, R=None, t=None, f=None):
    """A rig whose aligned rim image spans ``fill`` of the shorter image side (or focal length
    ``f``), principal point at the image centre, camera at ``camera_z`` on the axis unless
    ``R, t``."""
    w, h = image_size
    if f is None:
        # the aligned rim: radius rim_radius at depth z_rim - camera_z, then distorted
        x = mirror.rim_radius / (mirror.z_rim - camera_z)
        xd = x * (1.0 + k1 * x * x + k2 * x**4)
        f = 0.5 * fill * min(w, h) / xd
    K = np.array([[f, 0.0, (w - 1) / 2.0], [0.0, f, (h - 1) / 2.0], [0.0, 0.0, 1.0]])
    if R is None:
        R, t = np.eye(3), np.array([0.0, 0.0, -camera_z])
    return Rig(K, float(k1), float(k2), R, np.asarray(t, np.float64), mirror, tuple(image_size))


def far_line_pixels(rig, azimuths=(0.0, 2.0, 4.0), depth=3000.0, height=-600.0, n=40):
    """Pixels of horizontal scene lines, one an azimuth (rad), ``depth`` from the mirror's axis
    at ``height`` and 3 m long, as ``rig`` sees them (``n`` points each, unseen ones dropped)."""
    out = []
    for az in azimuths:
        d = np.array([math.cos(az), math.sin(az), 0.0])
        e = np.array([-d[1], d[0], 0.0])
        X = d * depth + np.outer(np.linspace(-1500.0, 1500.0, n), e) + [0.0, 0.0, height]
        px = rig.project(X)
        out.append(px[np.isfinite(px).all(axis=1)])
    return out


# -- boards ------------------------------------------------------------------------------------


def board_object_points(pattern_size, square):
    """OpenCV's object points: inner corners row by row, ``x`` along the columns, ``z = 0``."""
    cols, rows = pattern_size
    j, i = np.mgrid[0:rows, 0:cols]
    return np.column_stack([i.ravel() * square, j.ravel() * square, np.zeros(cols * rows)])


def look_at(normal_towards, tilt_deg, rng):
    """A board rotation whose ``-z`` (the side the camera sees) faces along ``normal_towards``
    turned by ``tilt_deg`` about a random axis, its in-plane turn random."""
    n = -np.asarray(normal_towards, np.float64)
    n /= np.linalg.norm(n)
    axis = np.cross(n, rng.normal(size=3))
    axis /= np.linalg.norm(axis)
    n = rotation(math.radians(tilt_deg) * axis) @ n
    x = np.cross(rng.normal(size=3), n)
    x /= np.linalg.norm(x)
    return np.column_stack([x, np.cross(n, x), n])


def place_boards(
    rig,
    n_views,
    pattern_size,
    square,
    distance,
    rng,
    max_tilt_deg=40.0,
    radius=(0.35, 0.9),
    margin_px=4.0,
):
    """Boards spread around the mirror: view ``k`` centred on the ray of a pixel at azimuth
    ``360 k / n`` (jittered) and a random fraction ``radius`` of the rim image, at a distance
    drawn log-uniformly from ``distance``, tilted up to ``max_tilt_deg``; kept when every corner
    is seen at least ``margin_px`` inside the rim image and the frame. Returns
    ``[(R_b, t_b, corners (N, 2))]`` with ``X_mirror = R_b X_board + t_b``."""
    obj = board_object_points(pattern_size, square)
    obj_c = obj - obj.mean(axis=0)
    c, r_rim = rig.rim_centre_and_radius()
    w, h = rig.image_size
    views = []
    for k in range(n_views):
        for _attempt in range(200):
            az = 2.0 * np.pi * (k + rng.uniform(-0.3, 0.3)) / n_views
            px = c + rng.uniform(*radius) * r_rim * np.array([math.cos(az), math.sin(az)])
            P, d = rig.trace(px[None])
            if not np.isfinite(d).all():
                continue
            dist = math.exp(rng.uniform(math.log(distance[0]), math.log(distance[1])))
            Rb = look_at(d[0], rng.uniform(0.0, max_tilt_deg), rng)
            tb = P[0] + dist * d[0] - Rb @ obj.mean(axis=0)
            X = obj_c @ Rb.T + P[0] + dist * d[0]
            q = rig.project(X)
            if not np.isfinite(q).all():
                continue
            inside = np.linalg.norm(q - c, axis=1) < r_rim - margin_px
            in_frame = (q >= margin_px).all(axis=1) & (q[:, 0] <= w - 1 - margin_px)
            in_frame &= q[:, 1] <= h - 1 - margin_px
            if inside.all() and in_frame.all():
                views.append((Rb, tb, q))
                break
        else:
            raise RuntimeError(f"no board placement found for view {k}")
    return views
