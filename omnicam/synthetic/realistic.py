"""Renders that look like real rigs: an independent forward renderer for stress tests.

This module shares **nothing** with the estimator: it does not call :mod:`omnicam.raytrace`,
:mod:`omnicam._kernels`, the :class:`~omnicam.mirror.HyperbolicMirror` methods, the camera's
``project``/``unproject`` or any calibration code. It reads a truth
:class:`~omnicam.camera.MisalignedHyperbolicCamera` only as numbers (``K, D, R, tvec`` and the
mirror's ``a, b, rim_radius``) and traces every subpixel itself:

1. camera ray: ``V_C = K^-1 (x, y, 1)`` (eq. 6, after undoing ``D`` with
   ``cv2.undistortPointsIter`` on an identity camera, so skew counts), into the mirror frame
   ``V_M = R^T V_C`` from ``F_M = -R^T tvec`` (eqs. 16-17);
2. the first hit on the sheet ``(X^2 + Y^2)/a^2 - Z^2/b^2 = -1, Z > 0`` (eqs. 1, 8-12) inside
   the rim; before it, struts (thin rods) may occlude the mirror; a ray that misses the mirror
   may hit the holder plate in the rim plane, else it shows the background;
3. the reflection ``V_out = V - 2 N (N, V)`` with the unit normal ``N`` of eq. 14 (eq. 15);
4. the reflected ray meets, nearest first, the camera's own body (a lens barrel coaxial with
   the optical axis with a glass front disc, in front of a wider box), a strut or a chessboard
   (:class:`Chessboard`, a plane at a finite distance, for pattern calibration); otherwise it
   sees a room at infinity (:class:`RoomScene`, looked up by direction only).

Hostile elements (:data:`VARIANTS`), each switchable: the camera body, a holder ring around the
rim, struts across the mirror, a dark floor, a clipped rim, Gaussian blur, vignetting, sensor
noise, JPEG compression and mild lens distortion. The ground truth comes back with the image:
the truth camera, the coaxial circles ``(r, z)`` (camera frame, docs/conventions.md "The
camera's own reflection") whose reflections make the outermost round dark silhouette, far-line
pixels of the room's straight edges (:func:`far_line_pixels`, own bisection) and a label per pixel.

Typical use (the stress benchmark ``benchmarks/bench_stress.py``)::

    for case in stress_cases(100, seed=0):
        r = render_case(case)
        cam, report = MisalignedHyperbolicCamera.calibrate(r.camera.K, r.camera.mirror,
                                                           image=r.image, D=r.camera.D)

Supersampling: pixel ``(x, y)`` covers ``[x - 1/2, x + 1/2]^2``; its ``s x s`` samples sit at
offsets ``(k + 1/2)/s - 1/2`` and their colours are averaged (linear), so edges are area-true.
Samples are taken only near edges (where the centres of a 3x3 neighbourhood disagree);
per-pixel labels are those of the pixel centre.
"""

from __future__ import annotations

import dataclasses
import math

import cv2
import numpy as np

__all__ = [
    "LABELS",
    "VARIANTS",
    "BodyGeometry",
    "Chessboard",
    "Holder",
    "Photometric",
    "RealisticRender",
    "Rendering",
    "Rig",
    "RoomScene",
    "StressCase",
    "Strut",
    "camera_rays",
    "degrade",
    "far_line_pixels",
    "intersect_mirror",
    "mirror_normal",
    "random_body",
    "random_room",
    "random_struts",
    "reflect",
    "render_case",
    "render_rig",
    "stress_cases",
    "trace",
]

#: The switchable hostile elements of a stress case.
VARIANTS = (
    "body",
    "holder",
    "struts",
    "dark_floor",
    "clipped",
    "blur",
    "vignette",
    "noise",
    "jpeg",
    "distortion",
)

#: Per-sample / per-pixel labels: what the (reflected) ray finally meets.
LABELS = {
    "background": 0,  # primary ray misses mirror and holder
    "holder": 1,  # primary ray hits the holder plate around the rim
    "strut": 2,  # primary ray hits a strut before the mirror
    "scene": 3,  # reflected ray sees the room at infinity
    "dark_floor": 4,  # reflected ray sees the dark floor
    "glass": 5,  # reflected ray hits the barrel's front glass
    "front_ring": 6,  # ... the barrel's front ring (between glass and barrel edge)
    "barrel_side": 7,  # ... the barrel's side
    "box": 8,  # ... the camera box behind the barrel
    "strut_reflected": 9,  # ... a strut, seen in the mirror
    "board": 10,  # ... a chessboard (Rig.boards)
}
_L = LABELS
_MIRROR_LABELS = (3, 4, 5, 6, 7, 8, 9, 10)
_FRONT_LABELS = (5, 6)
_CHUNK = 1 << 18  # samples traced per chunk
_CRITERIA = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 100, 1e-14)


# -- geometry descriptions ----------------------------------------------------------------------
@dataclasses.dataclass(frozen=True)
class BodyGeometry:
    """The camera's body in the camera frame (z along the optical axis, towards the mirror).

    A lens barrel: the cylinder ``x^2 + y^2 = r_barrel^2`` from the box's front ``z = z_box`` to
    ``z_barrel``, closed by a front disc at ``z_barrel``: dark glass inside ``r_glass`` (with
    an aperture, inner rings of lens elements and specular highlights) and a dark knurled front
    ring outside it. Behind it a box (not a body of revolution): ``|x'| <= w_box``,
    ``|y'| <= h_box``, ``z_box - depth_box <= z <= z_box`` in axes turned by ``box_angle_deg``
    about the optical axis.

    Attributes
    ----------
    r_barrel, z_barrel, r_glass, r_aperture : float
    rings : tuple of float
        Radii of the inner rings (lens element edges) on the glass.
    highlights : tuple of (x, y, radius)
        Bright specular spots on the glass (camera frame, in the front plane).
    z_box, w_box, h_box, depth_box, box_angle_deg : float
    glass_color, ring_color, side_color, box_color : BGR tuples
    """

    r_barrel: float = 12.0
    z_barrel: float = 20.0
    r_glass: float = 10.0
    r_aperture: float = 2.5
    rings: tuple = (5.5, 8.0)
    highlights: tuple = ((3.0, -4.0, 0.8), (-2.0, 3.5, 0.5))
    z_box: float = -5.0
    w_box: float = 22.0
    h_box: float = 17.0
    depth_box: float = 40.0
    box_angle_deg: float = 0.0
    glass_color: tuple = (22.0, 12.0, 10.0)
    ring_color: tuple = (48.0, 46.0, 45.0)
    side_color: tuple = (105.0, 102.0, 100.0)
    box_color: tuple = (52.0, 52.0, 54.0)

    def circles(self):
        """Coaxial circles ``(r, z)`` whose reflections bound the round dark silhouette.

        The barrel's front edge ``(r_barrel, z_barrel)``; the back edge ``(r_barrel, z_box)`` joins
        (by :func:`render_rig`) only when the barrel's side is seen beside it.
        """
        return ((float(self.r_barrel), float(self.z_barrel)),)


@dataclasses.dataclass(frozen=True)
class Holder:
    """A plate in the rim plane around the rim (mirror frame), its outer edge an ellipse.

    Attributes
    ----------
    outer_axes : (float, float)
        Semi-axes of the outer edge (mirror units), each larger than the rim radius.
    angle_deg : float
        Orientation of the first semi-axis, from +X towards +Y.
    kind : {"white", "black", "metal"}
    """

    outer_axes: tuple = (36.0, 33.0)
    angle_deg: float = 0.0
    kind: str = "black"


@dataclasses.dataclass(frozen=True)
class Strut:
    """A thin rod (cylinder of ``radius``) from ``start`` to ``end``, mirror frame."""

    start: tuple
    end: tuple
    radius: float = 0.6
    color: tuple = (25.0, 25.0, 25.0)


@dataclasses.dataclass(frozen=True)
class RoomScene:
    """A room-like scene at infinity: an axis-aligned box seen from the origin (directions).

    The box ``[-half_x, half_x] x [-half_y, half_y] x [-floor, ceiling]`` (metres, in the mirror
    frame turned by ``yaw_deg`` about +Z) gives every direction a wall, floor or ceiling
    colour; its edges (wall-floor lines, vertical corners) and the edges of the rectangles on
    it (doors, posters, windows, rugs) are great circles of directions: straight lines at
    infinity.

    Attributes
    ----------
    half_x, half_y, floor, ceiling, yaw_deg : float
    wall_colors : tuple of 6 BGR
        Surfaces -X, +X, -Y, +Y walls, floor, ceiling.
    rects : tuple of (surface, u0, u1, v0, v1, BGR)
        Flat rectangles on a surface, in its (u, v) coordinates: X walls (y, z), Y walls
        (x, z), floor/ceiling (x, y).
    plank : float
        Floor plank width (m); 0 for a plain floor.
    dark_floor_deg : float or None
        Every direction below this elevation is near-black (a dark floor), or None.
    """

    half_x: float = 2.5
    half_y: float = 3.0
    floor: float = 1.3
    ceiling: float = 1.4
    yaw_deg: float = 0.0
    wall_colors: tuple = (
        (170.0, 180.0, 190.0),
        (140.0, 160.0, 175.0),
        (185.0, 175.0, 160.0),
        (150.0, 170.0, 150.0),
        (70.0, 110.0, 140.0),
        (225.0, 225.0, 225.0),
    )
    rects: tuple = ()
    plank: float = 0.18
    dark_floor_deg: object = None

    def edges(self):
        """The wall-floor edges as 3-D segments ``(p1, p2)`` in the mirror frame (metres)."""
        hx, hy, fl = self.half_x, self.half_y, -self.floor
        corners = [(-hx, -hy), (hx, -hy), (hx, hy), (-hx, hy)]
        c, s = math.cos(math.radians(self.yaw_deg)), math.sin(math.radians(self.yaw_deg))
        out = []
        for i in range(4):
            (x1, y1), (x2, y2) = corners[i], corners[(i + 1) % 4]
            p1 = np.array([c * x1 - s * y1, s * x1 + c * y1, fl])
            p2 = np.array([c * x2 - s * y2, s * x2 + c * y2, fl])
            out.append((p1, p2))
        return out


@dataclasses.dataclass(frozen=True)
class Photometric:
    """Image degradations, applied in this order; 0 / None switches one off.

    Attributes
    ----------
    vignette : float
        Gain ``1 - vignette * (r / r_corner)^2`` about the image centre.
    blur_sigma : float
        Gaussian blur, px.
    noise_sigma : float
        Sensor noise: Gaussian, ``sqrt(noise_sigma^2 + 0.05 * value)`` grey levels.
    jpeg_quality : int or None
        ``cv2.imencode`` JPEG quality (70-95 in the stress cases).
    """

    vignette: float = 0.0
    blur_sigma: float = 0.0
    noise_sigma: float = 0.0
    jpeg_quality: object = None


@dataclasses.dataclass(frozen=True)
class Chessboard:
    """A flat chessboard in the scene (mirror frame), as OpenCV describes one.

    ``pattern_size = (cols, rows)`` inner corners at ``(i s, j s, 0)`` of the board frame
    (``s = square_size``, docs/conventions.md "Pattern calibration"), placed by
    ``X_mirror = R(rvec) X_board + tvec``. The squares cover ``-s <= x <= cols s``,
    ``-s <= y <= rows s`` (the square at the origin's lower left, ``floor(x/s) + floor(y/s)``
    even, is black), inside a white margin of ``margin`` squares; both faces are printed.

    Attributes
    ----------
    pattern_size : (int, int)
    square_size : float
    rvec, tvec : (3,) tuple
    margin : float
        White border around the squares, in squares.
    black, white : BGR tuples
    """

    pattern_size: tuple
    square_size: float
    rvec: tuple
    tvec: tuple
    margin: float = 1.0
    black: tuple = (28.0, 28.0, 30.0)
    white: tuple = (226.0, 230.0, 232.0)


@dataclasses.dataclass(frozen=True)
class Rig:
    """Everything a render needs besides the camera: what sits around the mirror.

    Attributes
    ----------
    body : BodyGeometry or None
    holder : Holder or None
    struts : tuple of Strut
    room : RoomScene
    background : (h, w, 3) float32 ndarray or None
        What the camera sees beside the mirror and holder (None: near-black).
    mirror_gain : float
        Reflectance of the mirror coating.
    boards : tuple of Chessboard
        Chessboards at finite distances, seen in the mirror (none in the stress cases).
    """

    body: object = None
    holder: object = None
    struts: tuple = ()
    room: RoomScene = RoomScene()
    background: object = None
    mirror_gain: float = 0.92
    boards: tuple = ()


# -- small linear algebra without BLAS (an (N, 3) @ (3, 3) product is slow under load) ---------
def _lin(v, M):
    """``v @ M.T`` for (N, k) ``v`` and (m, k) ``M``, column by column."""
    M = np.asarray(M, np.float64)
    out = v[:, :1] * M[:, 0]
    for j in range(1, M.shape[1]):
        out = out + v[:, j : j + 1] * M[:, j]
    return out


def _dot(v, n):
    """``v @ n`` for (N, 3) ``v`` and a (3,) vector ``n``."""
    return v[:, 0] * n[0] + v[:, 1] * n[1] + v[:, 2] * n[2]


# -- the camera's numbers --------------------------------------------------------------------
class _Numbers:
    """The truth camera read as numbers only (no method of it is called)."""

    def __init__(self, camera):
        for name in ("K", "R", "tvec", "mirror", "image_size"):
            if not hasattr(camera, name):
                raise ValueError(f"camera must be a MisalignedHyperbolicCamera, got {camera!r}")
        if camera.image_size is None:
            raise ValueError("camera has no image_size; construct it with image_size=(w, h)")
        self.K = np.array(camera.K, np.float64)
        self.Kinv = np.linalg.inv(self.K)
        self.D = None if camera.D is None else np.array(camera.D, np.float64).ravel()
        self.R = np.array(camera.R, np.float64)
        self.t = np.array(camera.tvec, np.float64)
        self.C = -self.R.T @ self.t  # camera centre in the mirror frame (eq. 17)
        self.a = float(camera.mirror.a)
        self.b = float(camera.mirror.b)
        self.rim = float(camera.mirror.rim_radius)
        self.z_rim = self.b * math.sqrt(1.0 + (self.rim / self.a) ** 2)
        self.size = tuple(int(v) for v in camera.image_size)


# -- the pure math: camera rays, the mirror, the reflection ------------------------------------
def camera_rays(K, D, pixels):
    """Unit camera rays ``V_C`` of pixels (camera frame), eq. 6 with OpenCV's distortion undone.

    Parameters
    ----------
    K : (3, 3) array_like
        Camera matrix (skew allowed: ``inv(K)`` is applied here).
    D : array_like or None
        OpenCV distortion coefficients, undone with ``cv2.undistortPointsIter`` on an identity
        camera with tight criteria (100 iterations, 1e-14).
    pixels : (N, 2) array_like

    Returns
    -------
    (N, 3) float64 ndarray
    """
    pix = np.asarray(pixels, np.float64).reshape(-1, 2)
    Kinv = np.linalg.inv(np.asarray(K, np.float64))
    xn = _lin(pix, Kinv[:2, :2]) + Kinv[:2, 2]
    if D is not None:
        src = np.ascontiguousarray(xn.reshape(-1, 1, 2))
        Dn = np.asarray(D, np.float64)
        if hasattr(cv2, "undistortPointsIter"):  # OpenCV 4
            und = cv2.undistortPointsIter(src, np.eye(3), Dn, None, None, _CRITERIA)
        else:  # OpenCV 5 takes the criteria in undistortPoints
            und = cv2.undistortPoints(src, np.eye(3), Dn, R=None, P=None, criteria=_CRITERIA)
        xn = und.reshape(-1, 2)
    v = np.concatenate([xn, np.ones((len(xn), 1))], axis=1)
    return v / np.linalg.norm(v, axis=1, keepdims=True)


def intersect_mirror(a, b, rim, origins, dirs):
    """First hit of rays ``o + t v`` (t > 0) on the sheet ``Z > 0`` of eq. 1, inside the rim.

    Solves ``A t^2 + 2 B t + G = 0`` (eqs. 8-11) with
    ``A = (vx^2 + vy^2)/a^2 - vz^2/b^2``, ``B = (ox vx + oy vy)/a^2 - oz vz/b^2``,
    ``G = (ox^2 + oy^2)/a^2 - oz^2/b^2 + 1``, keeping the smallest positive root with
    ``Z > 0`` (eq. 12's choice for a ray from outside the sheet).

    Returns
    -------
    t : (N,) float64 ndarray
        NaN where the ray misses the sheet or hits it outside the rim.
    """
    o = np.asarray(origins, np.float64)
    v = np.asarray(dirs, np.float64)
    ia2, ib2 = 1.0 / (a * a), 1.0 / (b * b)
    A = (v[:, 0] ** 2 + v[:, 1] ** 2) * ia2 - v[:, 2] ** 2 * ib2
    B = (o[:, 0] * v[:, 0] + o[:, 1] * v[:, 1]) * ia2 - o[:, 2] * v[:, 2] * ib2
    G = (o[:, 0] ** 2 + o[:, 1] ** 2) * ia2 - o[:, 2] ** 2 * ib2 + 1.0
    disc = B * B - A * G
    with np.errstate(invalid="ignore", divide="ignore"):
        sq = np.sqrt(disc)
        q = -(B + np.copysign(sq, B))  # stable roots: q / A and G / q
        t1 = q / A
        t2 = G / q
    best = np.full(len(o), np.inf)
    for t in (t1, t2):
        with np.errstate(invalid="ignore"):
            z = o[:, 2] + t * v[:, 2]
            ok = np.isfinite(t) & (t > 0) & (z > 0)
        best = np.where(ok & (t < best), t, best)
    with np.errstate(invalid="ignore"):
        X = o + best[:, None] * v
        inside = (X[:, 0] ** 2 + X[:, 1] ** 2 <= rim * rim) & np.isfinite(best)
    return np.where(inside & (disc >= 0), best, np.nan)


def mirror_normal(a, b, points):
    """Unit normal of eq. 1 at ``points``: the gradient ``(X/a^2, Y/a^2, -Z/b^2)`` (eq. 14),
    normalised (docs/conventions.md erratum to eq. 15)."""
    p = np.asarray(points, np.float64)
    n = np.stack([p[:, 0] / (a * a), p[:, 1] / (a * a), -p[:, 2] / (b * b)], axis=1)
    return n / np.linalg.norm(n, axis=1, keepdims=True)


def reflect(dirs, normals):
    """Mirror reflection ``V_out = V - 2 N (N, V)`` (eq. 15, unit ``N``)."""
    v = np.asarray(dirs, np.float64)
    n = np.asarray(normals, np.float64)
    return v - 2.0 * np.einsum("ij,ij->i", n, v)[:, None] * n


# -- primitives ----------------------------------------------------------------------------------
def _keep_nearer(t_best, lab, c_out, t, label, colors):
    """Where ``t < t_best`` the hit at ``t`` wins: its label and colour are written into
    ``lab`` and ``c_out`` (in place); returns the new nearest distances."""
    nearer = t < t_best
    if not nearer.any():
        return t_best
    lab[nearer] = label
    c_out[nearer] = colors[nearer]
    return np.where(nearer, t, t_best)


def _rod_hits(o, v, strut):
    """Entry ``t`` of unit rays on a strut's cylinder (inf where missed) and ``dist / radius``.

    Exact for the cylinder's silhouette: a ray touches it where its distance to the axis line
    equals the radius; the closest point on the axis must lie on the segment.
    """
    s0 = np.asarray(strut.start, np.float64)
    u = np.asarray(strut.end, np.float64) - s0
    length = float(np.linalg.norm(u))
    e = u / length
    w = o - s0
    bb = _dot(v, e)
    d = np.einsum("ij,ij->i", v, w)
    ew = _dot(w, e)
    denom = 1.0 - bb * bb
    with np.errstate(invalid="ignore", divide="ignore"):
        t = (bb * ew - d) / denom
        s = ew + bb * t
        gap = w + t[:, None] * v - s[:, None] * e
        dist = np.linalg.norm(gap, axis=1)
        rr = strut.radius
        hit = (dist <= rr) & (s >= 0) & (s <= length) & (denom > 1e-12)
        t_in = t - np.sqrt(np.maximum(rr * rr - dist * dist, 0.0) / np.maximum(denom, 1e-300))
    ok = hit & (t_in > 1e-9)
    return np.where(ok, t_in, np.inf), dist / rr


def _near_body(o, v, body):
    """Indices of camera-frame rays that pass the body's bounding sphere (ahead of them)."""
    zlo = min(0.0, body.z_box - body.depth_box)
    zc = 0.5 * (zlo + body.z_barrel)
    half = np.array([max(body.w_box, body.r_barrel), max(body.h_box, body.r_barrel)])
    rad2 = float(half @ half) + (0.5 * (body.z_barrel - zlo)) ** 2
    wx, wy, wz = -o[:, 0], -o[:, 1], zc - o[:, 2]
    tc = wx * v[:, 0] + wy * v[:, 1] + wz * v[:, 2]
    miss2 = wx * wx + wy * wy + wz * wz - tc * tc
    return np.flatnonzero((miss2 <= rad2) & (tc > 0))


def _body_hits(o, v, body):
    """Nearest hit of camera-frame rays on the body: ``t`` (inf: none), part label, hit point."""
    n = len(o)
    t_best = np.full(n, np.inf)
    label = np.zeros(n, np.int8)
    with np.errstate(invalid="ignore", divide="ignore"):
        # front disc z = z_barrel, seen from the mirror side
        tf = (body.z_barrel - o[:, 2]) / v[:, 2]
        xf = o[:, 0] + tf * v[:, 0]
        yf = o[:, 1] + tf * v[:, 1]
        rho2 = xf * xf + yf * yf
        ok = (v[:, 2] < 0) & (tf > 0) & (rho2 <= body.r_barrel**2)
        t_best = np.where(ok, tf, t_best)
        label = np.where(ok, np.where(rho2 <= body.r_glass**2, 5, 6), label).astype(np.int8)
        # barrel side: x^2 + y^2 = r^2 from outside, z_box <= z <= z_barrel
        A = v[:, 0] ** 2 + v[:, 1] ** 2
        B = o[:, 0] * v[:, 0] + o[:, 1] * v[:, 1]
        Cc = o[:, 0] ** 2 + o[:, 1] ** 2 - body.r_barrel**2
        disc = B * B - A * Cc
        ts = (-B - np.sqrt(disc)) / A
        zs = o[:, 2] + ts * v[:, 2]
        ok = (
            (disc >= 0)
            & (Cc > 0)
            & (ts > 0)
            & (zs <= body.z_barrel)
            & (zs >= body.z_box)
            & (ts < t_best)
        )
        t_best = np.where(ok, ts, t_best)
        label = np.where(ok, 7, label).astype(np.int8)
        # box: slab test in axes turned by box_angle about z
        ca, sa = (
            math.cos(math.radians(body.box_angle_deg)),
            math.sin(math.radians(body.box_angle_deg)),
        )
        ob = np.stack([ca * o[:, 0] + sa * o[:, 1], -sa * o[:, 0] + ca * o[:, 1], o[:, 2]], axis=1)
        vb = np.stack([ca * v[:, 0] + sa * v[:, 1], -sa * v[:, 0] + ca * v[:, 1], v[:, 2]], axis=1)
        lo = np.array([-body.w_box, -body.h_box, body.z_box - body.depth_box])
        hi = np.array([body.w_box, body.h_box, body.z_box])
        t1 = (lo - ob) / vb
        t2 = (hi - ob) / vb
        tmin = np.fmin(t1, t2)
        tmax = np.fmax(t1, t2)
        par = vb == 0
        inside = (ob >= lo) & (ob <= hi)
        tmin = np.where(par, np.where(inside, -np.inf, np.inf), tmin)
        tmax = np.where(par, np.where(inside, np.inf, -np.inf), tmax)
        tn = tmin.max(axis=1)
        tx = tmax.min(axis=1)
        ok = (tn <= tx) & (tn > 0) & (tn < t_best)
        t_best = np.where(ok, tn, t_best)
        label = np.where(ok, 8, label).astype(np.int8)
        X = o + np.where(np.isfinite(t_best), t_best, 0.0)[:, None] * v
    return t_best, label, X


def _board_hits(o, v, board):
    """Hits of rays ``o + t v`` (mirror frame, t > 0) on a :class:`Chessboard`: ``t`` (inf where
    missed) and the BGR colour of the hit (black or white square, or the white margin)."""
    Rb = cv2.Rodrigues(np.asarray(board.rvec, np.float64).reshape(3, 1))[0]
    tb = np.asarray(board.tvec, np.float64)
    nrm = Rb[:, 2]
    den = _dot(v, nrm)
    with np.errstate(divide="ignore", invalid="ignore"):
        t = (float(tb @ nrm) - _dot(o, nrm)) / den
        X = o + np.where(np.isfinite(t), t, 0.0)[:, None] * v
    xb = _lin(X - tb, Rb.T)  # board frame: R^T (X - t)
    cols, rows = (int(c) for c in board.pattern_size)
    fx = xb[:, 0] / board.square_size
    fy = xb[:, 1] / board.square_size
    m = 1.0 + float(board.margin)
    with np.errstate(invalid="ignore"):
        hit = np.isfinite(t) & (t > 0)
        inside = hit & (fx >= -m) & (fx <= cols + m - 1) & (fy >= -m) & (fy <= rows + m - 1)
        squares = (fx >= -1) & (fx <= cols) & (fy >= -1) & (fy <= rows)
    parity = (np.floor(np.nan_to_num(fx)) + np.floor(np.nan_to_num(fy))) % 2 == 0
    col = np.where(
        (squares & parity)[:, None], np.asarray(board.black), np.asarray(board.white)
    ).astype(np.float64)
    return np.where(inside, t, np.inf), col


# -- shading -------------------------------------------------------------------------------------
def _shade_room(room, d):
    """Colours (N, 3) float64 of unit directions ``d`` (mirror frame) in the room at infinity."""
    n = len(d)
    c, s = math.cos(math.radians(room.yaw_deg)), math.sin(math.radians(room.yaw_deg))
    dx = c * d[:, 0] + s * d[:, 1]  # into the room's axes (turned by -yaw)
    dy = -s * d[:, 0] + c * d[:, 1]
    dz = d[:, 2]
    dr = np.stack([dx, dy, dz], axis=1)
    lo = np.array([-room.half_x, -room.half_y, -room.floor])
    hi = np.array([room.half_x, room.half_y, room.ceiling])
    with np.errstate(divide="ignore", invalid="ignore"):
        ta = np.where(dr > 0, hi, lo) / dr
    ta[~(dr != 0)] = np.inf
    axis = np.argmin(ta, axis=1)
    rows = np.arange(n)
    t = ta[rows, axis]
    X = dr * t[:, None]
    surface = 2 * axis + (dr[rows, axis] > 0)
    u = np.where(axis == 0, X[:, 1], X[:, 0])
    v = np.where(axis == 2, X[:, 1], X[:, 2])
    table = np.asarray(room.wall_colors, np.float64)
    col = table[surface].copy()
    walls = axis < 2
    # walls: lighter towards the ceiling, a soft horizontal modulation, a dark skirting board
    hgt = (v + room.floor) / (room.floor + room.ceiling)
    shade = np.where(walls, 0.78 + 0.3 * hgt + 0.04 * np.sin(2.1 * u), 1.0)
    col *= shade[:, None]
    skirting = walls & (v < -room.floor + 0.09)
    col[skirting] = (40.0, 45.0, 55.0)
    floor = surface == 4
    if room.plank > 0:
        k = np.floor(X[floor, 0] / room.plank).astype(np.int64)
        col[floor] *= (0.85 + 0.15 * ((k * 7919) % 5) / 4.0)[:, None]
    for surf, u0, u1, v0, v1, bgr in room.rects:
        idx = np.flatnonzero(surface == surf)
        inside = (u[idx] >= u0) & (u[idx] <= u1) & (v[idx] >= v0) & (v[idx] <= v1)
        col[idx[inside]] = bgr
    label = np.full(n, 3, np.int8)
    if room.dark_floor_deg is not None:
        dark = dz < math.sin(math.radians(room.dark_floor_deg))
        col[dark] = (9.0, 10.0, 11.0) + 3.0 * np.sin(40.0 * dx[dark])[:, None]
        label[dark] = 4
    return col, label


def _shade_body(body, X, label):
    """Colours of body hits (camera frame hit points ``X``, labels 5-8)."""
    col = np.zeros((len(X), 3))
    rho = np.hypot(X[:, 0], X[:, 1])
    g = label == 5
    col[g] = body.glass_color
    if g.any():
        rg = rho[g]
        cg = col[g]
        cg[rg <= body.r_aperture] = (5.0, 4.0, 4.0)
        for i, rr in enumerate(body.rings):
            band = np.abs(rg - rr) <= 0.06 * body.r_glass
            cg[band] = (38.0 + 6 * i, 36.0 + 6 * i, 40.0 + 6 * i)
            edge = np.abs(rg - rr - 0.06 * body.r_glass) <= 0.015 * body.r_glass
            cg[edge] = (95.0, 90.0, 85.0)
        for hx, hy, hr in body.highlights:
            spot = np.hypot(X[g, 0] - hx, X[g, 1] - hy) <= hr
            cg[spot] = (245.0, 245.0, 240.0)
        col[g] = cg
    f = label == 6
    if f.any():
        ang = np.arctan2(X[f, 1], X[f, 0])
        knurl = 1.0 + 0.18 * np.sign(np.sin(90.0 * ang))
        col[f] = np.asarray(body.ring_color) * knurl[:, None]
    s = label == 7
    if s.any():
        ang = np.arctan2(X[s, 1], X[s, 0])
        col[s] = np.asarray(body.side_color) * (0.85 + 0.15 * np.cos(ang))[:, None]
    b = label == 8
    if b.any():
        col[b] = (
            np.asarray(body.box_color) * (1.0 + 0.1 * np.tanh(X[b, 2] - body.z_box + 0.5))[:, None]
        )
    return col


def _shade_holder(holder, X):
    """Colours of hits on the holder plate (mirror-frame points ``X``)."""
    if holder.kind == "white":
        base = np.array([232.0, 234.0, 236.0])
        return (
            np.broadcast_to(base, (len(X), 3))
            * (1.0 - 0.02 * np.cos(np.arctan2(X[:, 1], X[:, 0])))[:, None]
        )
    if holder.kind == "black":
        return np.broadcast_to(np.array([17.0, 17.0, 19.0]), (len(X), 3)).copy()
    ang = np.arctan2(X[:, 1], X[:, 0])  # metal: brushed, brightness varies with azimuth
    g = 125.0 + 55.0 * np.cos(2.0 * ang + 0.7) + 15.0 * np.cos(5.0 * ang)
    return np.stack([g, g, g * 1.03], axis=1)


# -- the tracer ----------------------------------------------------------------------------------
def _trace_chunk(num, rig, pixels):
    """Trace pixel samples: labels (N,), colours (N, 3), mirror points P and reflected d."""
    n = len(pixels)
    label = np.zeros(n, np.int8)
    col = np.zeros((n, 3))
    vc = camera_rays(num.K, num.D, pixels)
    V = _lin(vc, num.R.T)  # V_M = R^T V_C  (eq. 16)
    O = np.broadcast_to(num.C, V.shape)
    t_m = intersect_mirror(num.a, num.b, num.rim, O, V)
    hit = np.isfinite(t_m)
    on_mirror = hit.copy()
    t_prim = np.where(hit, t_m, np.inf)
    # holder plate in the rim plane (only where the mirror is missed)
    if rig.holder is not None:
        with np.errstate(invalid="ignore", divide="ignore"):
            th = (num.z_rim - num.C[2]) / V[:, 2]
        Xh = num.C + np.where(np.isfinite(th), th, 0.0)[:, None] * V
        ca = math.cos(math.radians(rig.holder.angle_deg))
        sa = math.sin(math.radians(rig.holder.angle_deg))
        e1 = (ca * Xh[:, 0] + sa * Xh[:, 1]) / rig.holder.outer_axes[0]
        e2 = (-sa * Xh[:, 0] + ca * Xh[:, 1]) / rig.holder.outer_axes[1]
        on = (
            ~hit
            & (th > 0)
            & (e1 * e1 + e2 * e2 <= 1.0)
            & (Xh[:, 0] ** 2 + Xh[:, 1] ** 2 >= num.rim**2)
        )
        label[on] = 1
        col[on] = _shade_holder(rig.holder, Xh[on])
        t_prim = np.where(on, th, t_prim)
    # struts seen directly, in front of the mirror or the holder
    for strut in rig.struts:
        ts, q = _rod_hits(O, V, strut)
        front = ts < t_prim
        if front.any():
            label[front] = 2
            col[front] = (
                np.asarray(strut.color)
                * (0.7 + 0.3 * np.sqrt(np.clip(1.0 - q[front] ** 2, 0.0, 1.0)))[:, None]
            )
            t_prim = np.where(front, ts, t_prim)
            hit &= ~front
    P = np.full((n, 3), np.nan)
    d = np.full((n, 3), np.nan)
    idx = np.flatnonzero(hit)
    if len(idx):
        Pm = num.C + t_m[idx, None] * V[idx]
        dm = reflect(V[idx], mirror_normal(num.a, num.b, Pm))
        dm /= np.linalg.norm(dm, axis=1, keepdims=True)
        P[idx], d[idx] = Pm, dm
        t_best = np.full(len(idx), np.inf)
        lab = np.zeros(len(idx), np.int8)
        c_out = np.zeros((len(idx), 3))
        if rig.body is not None:
            oc = _lin(Pm, num.R) + num.t  # camera frame
            vcam = _lin(dm, num.R)
            near = _near_body(oc, vcam, rig.body)
            tb, lb, Xb = _body_hits(oc[near], vcam[near], rig.body)
            got = np.isfinite(tb)
            t_best[near] = tb
            lab[near[got]] = lb[got]
            c_out[near[got]] = _shade_body(rig.body, Xb[got], lb[got])
        for strut in rig.struts:
            ts, q = _rod_hits(Pm, dm, strut)
            shade = (
                np.asarray(strut.color)
                * (0.7 + 0.3 * np.sqrt(np.clip(1.0 - q**2, 0.0, 1.0)))[:, None]
            )
            t_best = _keep_nearer(t_best, lab, c_out, ts, 9, shade)
        for board in rig.boards:
            tb, cb = _board_hits(Pm, dm, board)
            t_best = _keep_nearer(t_best, lab, c_out, tb, 10, cb)
        sky = ~np.isfinite(t_best)
        if sky.any():
            c_sky, l_sky = _shade_room(rig.room, dm[sky])
            c_out[sky] = c_sky
            lab[sky] = l_sky
        label[idx] = lab
        col[idx] = c_out * rig.mirror_gain
    return label, col, P, d, on_mirror


def _trace_many(num, rig, pixels):
    """:func:`_trace_chunk` over chunks: labels, colours and the on-mirror flags."""
    out = [_trace_chunk(num, rig, pixels[i : i + _CHUNK]) for i in range(0, len(pixels), _CHUNK)]
    return tuple(np.concatenate([o[j] for o in out]) for j in (0, 1, 4))


def trace(camera, pixels, rig=None):
    """Trace pixels through the rig with this module's own tracer.

    Parameters
    ----------
    camera : MisalignedHyperbolicCamera
        The truth camera, read as numbers only.
    pixels : (N, 2) array_like
    rig : Rig or None
        ``None``: a bare mirror in the default room.

    Returns
    -------
    labels : (N,) int8 ndarray
        :data:`LABELS` of what each ray finally meets.
    colors : (N, 3) float64 ndarray
        BGR before the background is added (background samples are 0).
    origins, directions : (N, 3) float64 ndarrays
        Mirror points and unit reflected directions (mirror frame); NaN where the primary ray
        does not reach the mirror (missed, or occluded by a strut).
    """
    num = _Numbers(camera)
    rig = Rig() if rig is None else rig
    pix = np.asarray(pixels, np.float64).reshape(-1, 2)
    out = [_trace_chunk(num, rig, pix[i : i + _CHUNK])[:4] for i in range(0, len(pix), _CHUNK)]
    if not out:
        return np.zeros(0, np.int8), np.zeros((0, 3)), np.zeros((0, 3)), np.zeros((0, 3))
    return tuple(np.concatenate(parts) for parts in zip(*out))


@dataclasses.dataclass(frozen=True)
class Rendering:
    """A clean render (before :func:`degrade`).

    Attributes
    ----------
    image : (h, w, 3) float32 ndarray
        Linear BGR, 0..255.
    labels : (h, w) int8 ndarray
        :data:`LABELS` of each pixel centre.
    coverage : (h, w) float32 ndarray
        Fraction of each pixel's samples whose primary ray meets the mirror inside the rim
        (struts in front of it not counted).
    side_seen : bool
        Whether any sample hit the barrel's side (then its back edge joins the circles).
    """

    image: np.ndarray
    labels: np.ndarray
    coverage: np.ndarray
    side_seen: bool


def _rim_box(num):
    """Integer pixel bounds that can see the mirror (rim circle projected, plus margin)."""
    phi = np.linspace(0.0, 2.0 * np.pi, 721)
    rim = np.stack(
        [num.rim * np.cos(phi), num.rim * np.sin(phi), np.full_like(phi, num.z_rim)], axis=1
    )
    xc = rim @ num.R.T + num.t
    xn = xc[:, :2] / xc[:, 2:3]
    if num.D is None:
        px = xn @ num.K[:2, :2].T + num.K[:2, 2]
    else:
        obj = np.concatenate([xn, np.ones((len(xn), 1))], axis=1)
        p, _ = cv2.projectPoints(obj, np.zeros(3), np.zeros(3), np.eye(3), num.D)
        px = p.reshape(-1, 2) @ num.K[:2, :2].T + num.K[:2, 2]
    lo = np.floor(px.min(axis=0)) - 3
    hi = np.ceil(px.max(axis=0)) + 3
    return lo, hi


def render_rig(camera, rig=None, supersample=3):
    """Render what the truth camera sees of the rig (no photometric degradation).

    Parameters
    ----------
    camera : MisalignedHyperbolicCamera
        With ``image_size``.
    rig : Rig or None
    supersample : int
        ``s``: ``s x s`` samples per pixel (1..8), taken where the pixel centres of a 3x3
        neighbourhood differ in label or by more than 4 grey levels (every edge); elsewhere the
        pixel centre alone (the image is smooth there).

    Returns
    -------
    Rendering
    """
    num = _Numbers(camera)
    rig = Rig() if rig is None else rig
    if isinstance(supersample, bool) or not isinstance(supersample, (int, np.integer)):
        raise ValueError(f"supersample must be an integer from 1 to 8, got {supersample!r}")
    s = int(supersample)
    if not 1 <= s <= 8:
        raise ValueError(f"supersample must be an integer from 1 to 8, got {supersample!r}")
    w, h = num.size
    if rig.background is None:
        bg = np.full((h, w, 3), 14.0, np.float32)
    else:
        bg = np.asarray(rig.background, np.float32)
        if bg.shape != (h, w, 3):
            raise ValueError(f"rig.background must be ({h}, {w}, 3), got {bg.shape}")
    img = bg.copy()
    labels = np.zeros((h, w), np.int8)
    coverage = np.zeros((h, w), np.float32)
    lo, hi = _rim_box(num)
    if rig.holder is not None:  # the holder's outer edge reaches farther
        scale = max(rig.holder.outer_axes) / num.rim
        mid = 0.5 * (lo + hi)
        lo, hi = mid - (mid - lo) * scale * 1.05, mid + (hi - mid) * scale * 1.05
    x0, y0 = max(0, int(lo[0])), max(0, int(lo[1]))
    x1, y1 = min(w - 1, int(hi[0])), min(h - 1, int(hi[1]))
    side_seen = False
    if x0 <= x1 and y0 <= y1:
        nx, ny = x1 - x0 + 1, y1 - y0 + 1
        gx, gy = np.meshgrid(np.arange(x0, x1 + 1), np.arange(y0, y1 + 1))
        centres = np.stack([gx.ravel(), gy.ravel()], axis=1).astype(np.float64)
        block_bg = bg[y0 : y1 + 1, x0 : x1 + 1].reshape(-1, 3)
        # pass 1: pixel centres
        lab, col, on = _trace_many(num, rig, centres)
        side_seen |= bool((lab == 7).any())
        col = np.where((lab == 0)[:, None], block_bg, col).astype(np.float32)
        cov = on.astype(np.float32)
        if s > 1:
            # pass 2: s x s samples where the centres of a 3x3 neighbourhood disagree (an
            # edge of any kind: rim, body, struts, scene), so every edge is area-true
            k = np.ones((3, 3), np.uint8)
            lab2 = lab.reshape(ny, nx).astype(np.uint8)
            need = cv2.dilate(lab2, k) != cv2.erode(lab2, k)
            col2 = col.reshape(ny, nx, 3)
            spread = (cv2.dilate(col2, k) - cv2.erode(col2, k)).max(axis=2)
            need |= spread > 4.0
            idx = np.flatnonzero(need.ravel())
            if len(idx):
                off = (np.arange(s) + 0.5) / s - 0.5
                ox, oy = np.meshgrid(off, off)
                offs = np.stack([ox.ravel(), oy.ravel()], axis=1)
                sub = (centres[idx][:, None, :] + offs[None, :, :]).reshape(-1, 2)
                lab_s, col_s, on_s = _trace_many(num, rig, sub)
                side_seen |= bool((lab_s == 7).any())
                bg_s = np.repeat(block_bg[idx], s * s, axis=0)
                col_s = np.where((lab_s == 0)[:, None], bg_s, col_s)
                col[idx] = col_s.reshape(len(idx), s * s, 3).mean(axis=1)
                cov[idx] = on_s.reshape(len(idx), s * s).mean(axis=1)
        img[y0 : y1 + 1, x0 : x1 + 1] = col.reshape(ny, nx, 3)
        labels[y0 : y1 + 1, x0 : x1 + 1] = lab.reshape(ny, nx)
        coverage[y0 : y1 + 1, x0 : x1 + 1] = cov.reshape(ny, nx)
    return Rendering(image=img, labels=labels, coverage=coverage, side_seen=side_seen)


def degrade(image, photometric, seed=0):
    """Vignetting, blur, sensor noise, rounding to uint8 and JPEG, as :class:`Photometric` says.

    Returns
    -------
    (h, w, 3) uint8 ndarray
    """
    img = np.array(image, np.float32)
    h, w = img.shape[:2]
    p = photometric or Photometric()
    if p.vignette > 0:
        yy, xx = np.mgrid[0:h, 0:w].astype(np.float32)
        r2 = ((xx - (w - 1) / 2) ** 2 + (yy - (h - 1) / 2) ** 2) / (
            ((w - 1) / 2) ** 2 + ((h - 1) / 2) ** 2
        )
        img *= (1.0 - p.vignette * r2)[..., None]
    if p.blur_sigma > 0:
        img = cv2.GaussianBlur(img, (0, 0), p.blur_sigma)
    if p.noise_sigma > 0:
        rng = np.random.default_rng(seed)
        sd = np.sqrt(p.noise_sigma**2 + 0.05 * np.clip(img, 0, None))
        img = img + rng.standard_normal(img.shape, dtype=np.float32) * sd
    out = np.clip(np.round(img), 0, 255).astype(np.uint8)
    if p.jpeg_quality is not None:
        ok, buf = cv2.imencode(".jpg", out, [cv2.IMWRITE_JPEG_QUALITY, int(p.jpeg_quality)])
        if not ok:
            raise ValueError("JPEG encoding failed")
        out = cv2.imdecode(buf, cv2.IMREAD_COLOR)
    return out


# -- far lines -----------------------------------------------------------------------------------
def _directions(num, pixels):
    """Unit reflected directions of pixels (mirror frame, NaN off the mirror): eqs. 6-15 only."""
    v = _lin(camera_rays(num.K, num.D, pixels), num.R.T)
    t = intersect_mirror(num.a, num.b, num.rim, np.broadcast_to(num.C, v.shape), v)
    P = num.C + t[:, None] * v
    with np.errstate(invalid="ignore"):
        d = reflect(v, mirror_normal(num.a, num.b, P))
        return d / np.linalg.norm(d, axis=1, keepdims=True)


def _mirror_grid(camera):
    """Integer pixels of the rim's bounding box and their reflected directions (h, w, 3)."""
    num = _Numbers(camera)
    lo, hi = _rim_box(num)
    xs = np.arange(lo[0], hi[0] + 1)
    ys = np.arange(lo[1], hi[1] + 1)
    gx, gy = np.meshgrid(xs, ys)
    d = _directions(num, np.stack([gx.ravel(), gy.ravel()], axis=1))
    return xs, ys, d.reshape(len(ys), len(xs), 3)


def far_line_pixels(camera, p1, p2, n_points=40, valid=None, margin=2, _grid=None):
    """Pixels on the image of the straight line at infinity through ``p1, p2`` (own tracer).

    The line's directions form the great-circle arc ``alpha p1 + beta p2`` (alpha, beta >= 0)
    of the plane with normal ``n = p1 x p2``. Every integer pixel of the mirror is traced;
    where ``n . d`` changes sign between horizontal or vertical neighbours, the crossing is
    found by bisection on that segment (to 1e-9 px, 30 halvings) and kept if its direction
    lies on the arc.

    Parameters
    ----------
    camera : MisalignedHyperbolicCamera
    p1, p2 : (3,) array_like
        Two points of the line, mirror frame (any unit: only directions count).
    n_points : int
        Points returned, evenly spread along the arc that is seen.
    valid : (h, w) bool ndarray or None
        Pixels where a point may be taken (e.g. the scene is seen around it); points whose
        nearest pixel is not valid, or that lie within ``margin`` px of the frame edge, are
        dropped.

    Returns
    -------
    (M, 2) float64 ndarray
        ``M <= n_points`` pixels, ordered along the line (empty when the line is not seen).
    """
    num = _Numbers(camera)
    p1 = np.asarray(p1, np.float64)
    p2 = np.asarray(p2, np.float64)
    nrm = np.cross(p1, p2)
    nrm /= np.linalg.norm(nrm)
    xs, ys, dgrid = _grid if _grid is not None else _mirror_grid(camera)

    def side(px):
        return _dot(_directions(num, px), nrm)

    f = _dot(dgrid.reshape(-1, 3), nrm).reshape(dgrid.shape[:2])
    found = []
    for axis in (0, 1):
        fa = f[:, :-1] if axis == 0 else f[:-1, :]
        fb = f[:, 1:] if axis == 0 else f[1:, :]
        cross = np.isfinite(fa) & np.isfinite(fb) & (np.sign(fa) != np.sign(fb))
        iy, ix = np.nonzero(cross)
        if not len(iy):
            continue
        a = np.stack([xs[ix], ys[iy]], axis=1).astype(np.float64)
        step = np.array([1.0, 0.0]) if axis == 0 else np.array([0.0, 1.0])
        fa0 = fa[iy, ix]
        lo_t = np.zeros(len(a))
        hi_t = np.ones(len(a))
        for _ in range(30):
            mid = 0.5 * (lo_t + hi_t)
            fm = side(a + mid[:, None] * step)
            same = np.sign(fm) == np.sign(fa0)
            lo_t = np.where(same, mid, lo_t)
            hi_t = np.where(same, hi_t, mid)
        found.append(a + (0.5 * (lo_t + hi_t))[:, None] * step)
    if not found:
        return np.zeros((0, 2))
    pts = np.concatenate(found)
    d = _directions(num, pts)
    good = np.isfinite(d[:, 0])
    on_arc = (_dot(np.cross(p1, d), nrm) >= 0) & (_dot(np.cross(d, p2), nrm) >= 0)
    w, h = num.size
    inside = (
        (pts[:, 0] >= margin)
        & (pts[:, 0] <= w - 1 - margin)
        & (pts[:, 1] >= margin)
        & (pts[:, 1] <= h - 1 - margin)
    )
    keep = good & on_arc & inside
    if valid is not None:
        ri = np.clip(np.round(pts[:, 1]).astype(int), 0, h - 1)
        ci = np.clip(np.round(pts[:, 0]).astype(int), 0, w - 1)
        keep &= np.asarray(valid, bool)[ri, ci]
    pts, d = pts[keep], d[keep]
    if not len(pts):
        return np.zeros((0, 2))
    u1 = p1 / np.linalg.norm(p1)
    ang = np.arctan2(_dot(np.cross(u1, d), nrm), _dot(d, u1))
    order = np.argsort(ang)
    pts, ang = pts[order], ang[order]
    if len(pts) > n_points:
        pick = np.searchsorted(ang, np.linspace(ang[0], ang[-1], n_points))
        pts = pts[np.unique(np.clip(pick, 0, len(pts) - 1))]
    return pts


# -- random rigs and scenes ----------------------------------------------------------------------
def random_room(rng, dark_floor=False):
    """A random :class:`RoomScene`: walls 1.5-4 m away, doors, posters, windows, a rug."""
    hx, hy = rng.uniform(1.5, 4.0, 2)
    floor, ceiling = rng.uniform(1.0, 1.8), rng.uniform(1.0, 2.2)
    walls = [tuple(rng.uniform(110, 215, 3)) for _ in range(4)]
    floor_col = tuple(rng.uniform(50, 150, 3))
    rects = []
    for surf in range(4):
        half = hy if surf < 2 else hx
        for _ in range(int(rng.integers(2, 6))):
            wdt = rng.uniform(0.3, 1.2)
            u0 = rng.uniform(-half, half - wdt)
            v0 = rng.uniform(-floor, ceiling - 0.3)
            hgt = rng.uniform(0.3, min(2.0, ceiling - v0))
            if rng.uniform() < 0.3:  # a door or a shelf down to the floor
                v0 = -floor + 0.0
            tone = rng.choice([rng.uniform(10, 60), rng.uniform(200, 250), rng.uniform(60, 200)])
            colour = tuple(np.clip(tone + rng.normal(0, 25, 3), 0, 255))
            rects.append((surf, u0, u0 + wdt, v0, v0 + hgt, colour))
    for _ in range(int(rng.integers(0, 3))):  # rugs
        cx, cy = rng.uniform(-0.6, 0.6, 2) * (hx, hy)
        rw, rh = rng.uniform(0.4, 1.4, 2)
        rects.append((4, cx - rw, cx + rw, cy - rh, cy + rh, tuple(rng.uniform(30, 220, 3))))
    return RoomScene(
        half_x=float(hx),
        half_y=float(hy),
        floor=float(floor),
        ceiling=float(ceiling),
        yaw_deg=float(rng.uniform(0, 360)),
        wall_colors=(*walls, floor_col, (230.0, 230.0, 228.0)),
        rects=tuple(rects),
        plank=float(rng.choice([0.0, 0.12, 0.2])),
        dark_floor_deg=float(rng.uniform(-72.0, -50.0)) if dark_floor else None,
    )


def random_body(rng, r_range=(5.0, 25.0), z_range=(5.0, 40.0)):
    """A random :class:`BodyGeometry`: barrel radius and length from the ranges, a wider box."""
    r = float(rng.uniform(*r_range))
    z = float(rng.uniform(*z_range))
    rg = r * rng.uniform(0.7, 0.9)
    n_rings = int(rng.integers(1, 3))
    rings = tuple(sorted(rg * rng.uniform(0.4, 0.85, n_rings)))
    highlights = []
    for _ in range(int(rng.integers(1, 4))):
        rr, aa = rg * rng.uniform(0.1, 0.75), rng.uniform(0, 2 * np.pi)
        highlights.append((rr * math.cos(aa), rr * math.sin(aa), rg * rng.uniform(0.04, 0.12)))
    wb = r * rng.uniform(1.0, 2.2)
    glass = rng.uniform(8, 28)
    tone = rng.uniform()
    if tone < 0.5:  # black or dark grey body
        box = np.full(3, rng.uniform(30, 75)) + rng.uniform(-4, 4, 3)
    elif tone < 0.85:  # silver
        box = np.full(3, rng.uniform(130, 200)) + rng.uniform(-6, 6, 3)
    else:  # a bare board camera: green printed circuit board
        box = np.array([40.0, 110.0, 50.0]) + rng.uniform(-15, 15, 3)
    return BodyGeometry(
        r_barrel=r,
        z_barrel=z,
        r_glass=float(rg),
        r_aperture=float(rg * rng.uniform(0.15, 0.3)),
        rings=rings,
        highlights=tuple(highlights),
        z_box=float(rng.uniform(-10.0, 0.4 * z)),
        w_box=float(wb),
        h_box=float(wb * rng.uniform(0.6, 1.0)),
        depth_box=float(rng.uniform(20, 50)),
        box_angle_deg=float(rng.uniform(-3, 3)),
        glass_color=(glass, glass * 0.6, glass * 0.5),
        ring_color=tuple(float(x) for x in np.full(3, rng.uniform(20, 60))),
        side_color=tuple(float(x) for x in np.full(3, rng.uniform(80, 130))),
        box_color=tuple(float(x) for x in box),
    )


def random_struts(rng, camera, count=None):
    """2-4 thin rods from the holder (just outside the rim) down towards the camera.

    Each runs from a point at 1.05-1.15 rim radii just below the rim plane to a point on the
    line of sight from the camera centre to a mirror point at 25-60 % of the rim radius, 55-80 %
    of the way to the mirror: in the image a radial stripe from the rim inwards.
    """
    num = _Numbers(camera)
    count = int(rng.integers(2, 5)) if count is None else int(count)
    colour = (24.0, 24.0, 26.0) if rng.uniform() < 0.5 else (228.0, 228.0, 225.0)
    phi0 = rng.uniform(0, 2 * np.pi)
    out = []
    for k in range(count):
        phi = phi0 + 2 * np.pi * k / count + rng.uniform(-0.2, 0.2)
        rh = num.rim * rng.uniform(1.05, 1.15)
        top = np.array([rh * math.cos(phi), rh * math.sin(phi), num.z_rim - 0.5])
        rho = num.rim * rng.uniform(0.25, 0.6)
        psi = phi + rng.uniform(-0.15, 0.15)
        m = np.array(
            [rho * math.cos(psi), rho * math.sin(psi), num.b * math.sqrt(1 + (rho / num.a) ** 2)]
        )
        frac = rng.uniform(0.55, 0.8)
        for _ in range(10):  # keep the rod below the mirror surface all along
            low = num.C + frac * (m - num.C)
            s = np.linspace(0, 1, 64)[:, None]
            pts = top + s * (low - top)
            rr = np.hypot(pts[:, 0], pts[:, 1])
            zm = num.b * np.sqrt(1 + (rr / num.a) ** 2)
            if np.all((pts[:, 2] < zm - 1.0) | (rr > num.rim + 0.5)):
                break
            frac *= 0.9
        out.append(Strut(tuple(top), tuple(low), float(rng.uniform(0.35, 0.9)), colour))
    return tuple(out)


def _background(rng, size):
    """What the camera sees beside the mirror: a dark, blotchy housing with a few shapes."""
    w, h = size
    base = rng.uniform(12, 55)
    small = (base + rng.normal(0, 18, (6, 8, 3))).astype(np.float32)
    bg = cv2.resize(small, (w, h), interpolation=cv2.INTER_CUBIC)
    for _ in range(int(rng.integers(2, 6))):
        x0, y0 = int(rng.integers(0, w)), int(rng.integers(0, h))
        x1, y1 = x0 + int(rng.integers(20, w // 3)), y0 + int(rng.integers(20, h // 3))
        bg[y0:y1, x0:x1] = rng.uniform(10, 120)
    return np.clip(bg, 0, 255)


# -- stress cases --------------------------------------------------------------------------------
@dataclasses.dataclass(frozen=True)
class StressCase:
    """One reproducible stress render: a truth rig, the variants on, and the seed of the rest.

    Attributes
    ----------
    index, seed : int
        Case ``index`` of :func:`stress_cases` with ``seed``; every random choice of
        :func:`render_case` is drawn from ``numpy.random.default_rng([seed, index, 1])``.
    flags : frozenset of str
        The :data:`VARIANTS` switched on.
    image_size : (int, int)
    K : (3, 3) tuple
    D : tuple or None
    tilt_deg, tilt_azimuth_deg : float
    offset_mm : (3,) tuple
        Mirror origin minus ``(0, 0, c)``, camera frame.
    body : BodyGeometry or None
    photometric : Photometric
    supersample : int
    """

    index: int
    seed: int
    flags: frozenset
    image_size: tuple
    K: tuple
    D: object
    tilt_deg: float
    tilt_azimuth_deg: float
    offset_mm: tuple
    body: object
    photometric: Photometric
    supersample: int = 3

    def camera(self):
        """The truth :class:`~omnicam.camera.MisalignedHyperbolicCamera`."""
        from ..hyperbolic_camera import MisalignedHyperbolicCamera
        from . import default_mirror

        mirror = default_mirror()
        phi = math.radians(self.tilt_azimuth_deg)
        rvec = math.radians(self.tilt_deg) * np.array([-math.sin(phi), math.cos(phi), 0.0])
        tvec = np.array([0.0, 0.0, mirror.c]) + np.asarray(self.offset_mm)
        return MisalignedHyperbolicCamera(
            np.array(self.K), mirror, rvec, tvec, D=self.D, image_size=self.image_size
        )


@dataclasses.dataclass(frozen=True)
class RealisticRender:
    """A rendered stress case and its ground truth.

    Attributes
    ----------
    image : (h, w, 3) uint8 ndarray, BGR
    camera : MisalignedHyperbolicCamera
        The truth.
    body_circles : tuple of (r, z)
        Coaxial circles (camera frame) whose reflections make the outermost round dark
        silhouette; empty without a body.
    flags : frozenset of str
    far_lines : tuple of (N, 2) float64 ndarrays
        Pixels of the room's wall-floor edges that are seen (not occluded, in the frame),
        longest first: the ``far_lines`` argument of ``calibrate``.
    far_line_normals : tuple of (3,) ndarrays
        Unit normals (mirror frame) of their great circles.
    reflection_visible : bool
        The body's silhouette is in the frame and contrasts (>= 20 grey levels) with what is
        around it over >= 70 % of its outline.
    labels : (h, w) int8 ndarray
    case : StressCase
    """

    image: np.ndarray
    camera: object
    body_circles: tuple
    flags: frozenset
    far_lines: tuple
    far_line_normals: tuple
    reflection_visible: bool
    labels: np.ndarray
    case: StressCase


_SIZES = ((640, 480), (800, 600), (640, 640), (1000, 1000))
_SIZE_P = (0.4, 0.3, 0.2, 0.1)
_CLIPPED_SIZES = ((960, 540), (854, 480), (1000, 562))


def _flags_for(i, rng):
    kind = i % 4
    v = VARIANTS[(i // 4) % len(VARIANTS)]
    if kind == 0:  # one variant alone
        return frozenset({v})
    if kind == 1:  # one variant with the camera body
        return frozenset({"body", v})
    if kind == 2:  # any combination
        return frozenset(x for x in VARIANTS if rng.uniform() < 0.5)
    # a real rig: body and photographic degradations, the rest at random
    extra = [
        x
        for x in ("holder", "struts", "dark_floor", "clipped", "distortion")
        if rng.uniform() < 0.5
    ]
    return frozenset({"body", "blur", "noise", "jpeg", "vignette", *extra})


def stress_cases(n=100, seed=0, image_size=None):
    """Reproducible stress cases over the variants, seeds, postures and body sizes.

    Case ``i`` draws from ``numpy.random.default_rng([seed, i])``: ``i % 4 == 0`` one variant
    alone, ``1`` one variant with the camera body, ``2`` any combination, ``3`` a real rig (body,
    blur, noise, JPEG, vignetting and the rest at random); the variant cycles with ``i // 4``.
    Tilt up to 5 deg, offset up to 5 mm (uniform in a ball), barrel radius 5-25 mm at 5-40 mm,
    images 640x480 to 1000x1000 (clipped: 16:9 frames whose height is 1.08-1.3x smaller than
    the rim's diameter).

    Parameters
    ----------
    n : int
    seed : int
    image_size : (int, int) or None
        Force one image size (e.g. small ones for tests); clipped cases then get a 16:9 frame
        of the same width.

    Yields
    ------
    StressCase
    """
    from . import default_mirror

    mirror = default_mirror()
    depth = mirror.z_rim + mirror.c  # aligned rim depth
    for i in range(int(n)):
        rng = np.random.default_rng([seed, i])
        flags = _flags_for(i, rng)
        clipped = "clipped" in flags
        if image_size is not None:
            size = tuple(int(v) for v in image_size)
            if clipped:  # a 16:9 frame of the same width
                size = (size[0], round(size[0] * 9 / 16))
        elif clipped:
            size = _CLIPPED_SIZES[int(rng.integers(len(_CLIPPED_SIZES)))]
        else:
            size = _SIZES[int(rng.choice(len(_SIZES), p=_SIZE_P))]
        w, h = size
        if clipped:
            diameter = h * rng.uniform(1.08, 1.3)
            diameter = min(diameter, 0.92 * w)
        else:
            diameter = min(w, h) * rng.uniform(0.72, 0.88)
        f = 0.5 * diameter * depth / mirror.rim_radius
        cx = (w - 1) / 2 + rng.uniform(-0.02, 0.02) * w
        cy = (h - 1) / 2 + rng.uniform(-0.02, 0.02) * h
        K = ((f, 0.0, cx), (0.0, f, cy), (0.0, 0.0, 1.0))
        D = None
        if "distortion" in flags:
            D = (
                float(rng.uniform(-0.12, 0.08)),
                float(rng.uniform(-0.03, 0.03)),
                float(rng.uniform(-1e-3, 1e-3)),
                float(rng.uniform(-1e-3, 1e-3)),
                0.0,
            )
        u = rng.normal(size=3)
        offset = u / np.linalg.norm(u) * 5.0 * rng.uniform() ** (1 / 3)
        body = random_body(rng) if "body" in flags else None
        photo = Photometric(
            vignette=float(rng.uniform(0.2, 0.5)) if "vignette" in flags else 0.0,
            blur_sigma=float(rng.uniform(0.5, 1.5)) if "blur" in flags else 0.0,
            noise_sigma=float(rng.uniform(1.5, 5.0)) if "noise" in flags else 0.0,
            jpeg_quality=int(rng.integers(70, 96)) if "jpeg" in flags else None,
        )
        yield StressCase(
            index=i,
            seed=int(seed),
            flags=flags,
            image_size=size,
            K=K,
            D=D,
            tilt_deg=float(rng.uniform(0, 5)),
            tilt_azimuth_deg=float(rng.uniform(0, 360)),
            offset_mm=tuple(float(x) for x in offset),
            body=body,
            photometric=photo,
        )


def _reflection_visible(rendering, size, n_sectors=36):
    """Whether the barrel front's silhouette is in the frame and contrasts with its surround."""
    front = np.isin(rendering.labels, _FRONT_LABELS).astype(np.uint8)
    if front.sum() < 20:
        return False
    w, h = size
    ys, xs = np.nonzero(front)
    if xs.min() < 3 or ys.min() < 3 or xs.max() > w - 4 or ys.max() > h - 4:
        return False
    k = np.ones((3, 3), np.uint8)
    inner = cv2.erode(front, k, iterations=1).astype(bool) & ~cv2.erode(
        front, k, iterations=3
    ).astype(bool)
    outer = cv2.dilate(front, k, iterations=3).astype(bool) & ~cv2.dilate(
        front, k, iterations=1
    ).astype(bool)
    img = rendering.image
    grey = 0.114 * img[..., 0] + 0.587 * img[..., 1] + 0.299 * img[..., 2]
    cx, cy = xs.mean(), ys.mean()

    def sectors(band):
        yb, xb = np.nonzero(band)
        sec = np.floor((np.arctan2(yb - cy, xb - cx) + np.pi) / (2 * np.pi) * n_sectors)
        return grey[yb, xb], np.minimum(sec.astype(int), n_sectors - 1)

    gi, si = sectors(inner)
    go, so = sectors(outer)
    ok = 0
    for k_ in range(n_sectors):
        a, b = gi[si == k_], go[so == k_]
        if len(a) and len(b) and abs(np.median(a) - np.median(b)) >= 20.0:
            ok += 1
    return ok >= 0.7 * n_sectors


def render_case(case):
    """Render a :class:`StressCase` with its hostile elements and ground truth.

    Returns
    -------
    RealisticRender
    """
    if not isinstance(case, StressCase):
        raise ValueError(f"case must be a StressCase, got {type(case).__name__}")
    camera = case.camera()
    num = _Numbers(camera)
    rng = np.random.default_rng([case.seed, case.index, 1])
    flags = case.flags
    room = random_room(rng, dark_floor="dark_floor" in flags)
    holder = None
    if "holder" in flags:
        holder = Holder(
            outer_axes=tuple(float(x) for x in num.rim * rng.uniform(1.1, 1.3, 2)),
            angle_deg=float(rng.uniform(0, 180)),
            kind=str(rng.choice(["white", "black", "metal"])),
        )
    struts = random_struts(rng, camera) if "struts" in flags else ()
    rig = Rig(
        body=case.body if "body" in flags else None,
        holder=holder,
        struts=struts,
        room=room,
        background=_background(rng, case.image_size),
        mirror_gain=float(rng.uniform(0.85, 0.95)),
    )
    rendering = render_rig(camera, rig, case.supersample)
    image = degrade(rendering.image, case.photometric, seed=[case.seed, case.index, 2])
    circles = ()
    visible = False
    if rig.body is not None:
        circles = rig.body.circles()
        if rendering.side_seen:
            circles = circles + ((float(rig.body.r_barrel), float(rig.body.z_box)),)
        visible = _reflection_visible(rendering, case.image_size)
    # far lines: the wall-floor edges, where the scene is seen all around the pixel
    scene = np.isin(rendering.labels, (3,)).astype(np.uint8)
    valid = cv2.erode(scene, np.ones((7, 7), np.uint8)).astype(bool)
    lines = []
    grid = _mirror_grid(camera)
    for p1, p2 in room.edges():
        px = far_line_pixels(camera, p1, p2, n_points=40, valid=valid, _grid=grid)
        if len(px) >= 8:
            span = float(np.linalg.norm(px[-1] - px[0]))
            nrm = np.cross(p1, p2)
            lines.append((span, px, nrm / np.linalg.norm(nrm)))
    lines.sort(key=lambda x: -x[0])
    return RealisticRender(
        image=image,
        camera=camera,
        body_circles=tuple(circles),
        flags=flags,
        far_lines=tuple(x[1] for x in lines),
        far_line_normals=tuple(x[2] for x in lines),
        reflection_visible=bool(visible),
        labels=rendering.labels,
        case=case,
    )
