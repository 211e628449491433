"""Chessboards seen through the mirror: poses, exact corners and ground-truth renders.

For :func:`omnicam.calibrate_pattern` and :func:`omnicam.find_pattern` (``docs/conventions.md``,
"Pattern calibration"): a board has OpenCV's object points (inner corners on its ``z = 0`` plane,
row by row, ``(i * s, j * s, 0)`` for column ``i`` and row ``j``) and a pose
``X_mirror = R(rvec_b) X_board + tvec_b`` in the mirror frame.

* :func:`board_object_points`: the object points of a ``(cols, rows)`` board;
* :func:`random_board_poses`: boards at random azimuths, elevations (inside the band the mirror
  sees) and distances, roughly facing the rig, each checked to be wholly visible;
* :func:`board_corners`: the ground-truth image points, the exact non-central projection
  (:meth:`~omnicam.camera.MisalignedHyperbolicCamera.project`) of the inner corners;
* :func:`render_board`: the image, by tracing every subpixel
  (:meth:`~omnicam.camera.MisalignedHyperbolicCamera.unproject`), intersecting the board plane
  and taking the checker colour there (a white margin of one square around the squares), the
  procedural environment elsewhere, the housing outside the rim and the camera's reflection.

The renderer shares nothing with the estimator but ``unproject``; the ground truth shares nothing
with the renderer but ``project`` (their agreement is tested in ``tests/test_camera.py``).
"""

from __future__ import annotations

import math

import cv2
import numpy as np

from . import HOUSING_COLOR, _check_camera, _render, _sample_equirect, make_environment

__all__ = [
    "board_corners",
    "board_object_points",
    "board_outline",
    "random_board_poses",
    "render_board",
]

_BLACK, _WHITE = 25.0, 230.0


def _pattern(pattern_size):
    try:
        cols, rows = (int(v) for v in pattern_size)
    except (TypeError, ValueError):
        raise ValueError(f"pattern_size must be (columns, rows), got {pattern_size!r}") from None
    if cols < 2 or rows < 2:
        raise ValueError(f"pattern_size must be two integers >= 2, got {pattern_size!r}")
    return cols, rows


def board_object_points(pattern_size, square_size):
    """OpenCV's object points: ``(cols * rows, 3)`` float64, ``(i s, j s, 0)`` row by row."""
    cols, rows = _pattern(pattern_size)
    obj = np.zeros((rows * cols, 3))
    obj[:, :2] = np.mgrid[0:cols, 0:rows].T.reshape(-1, 2) * float(square_size)
    return obj


def board_outline(pattern_size, square_size, n=8):
    """Points on the outer edge of the board with its white margin (board frame), ``(4n, 3)``."""
    cols, rows = _pattern(pattern_size)
    s = float(square_size)
    x0, x1, y0, y1 = -2 * s, (cols + 1) * s, -2 * s, (rows + 1) * s
    t = np.linspace(0.0, 1.0, n, endpoint=False)
    xs = np.concatenate([x0 + (x1 - x0) * t, np.full(n, x1), x1 - (x1 - x0) * t, np.full(n, x0)])
    ys = np.concatenate([np.full(n, y0), y0 + (y1 - y0) * t, np.full(n, y1), y1 - (y1 - y0) * t])
    return np.stack([xs, ys, np.zeros_like(xs)], axis=1)


def _to_mirror(points, rvec, tvec):
    R = cv2.Rodrigues(np.asarray(rvec, np.float64).reshape(3, 1))[0]
    return points @ R.T + np.asarray(tvec, np.float64)


def board_corners(camera, pattern_size, square_size, rvec, tvec):
    """Ground-truth image points of the inner corners, ``(N, 1, 2)`` float64 (NaN if unseen)."""
    obj = board_object_points(pattern_size, square_size)
    return camera.project(_to_mirror(obj, rvec, tvec)).reshape(-1, 1, 2)


def _visible(camera, pattern_size, square_size, rvec, tvec, margin, min_spacing, body_radius):
    w, h = camera.image_size
    corners = board_corners(camera, pattern_size, square_size, rvec, tvec).reshape(-1, 2)
    edge = camera.project(_to_mirror(board_outline(pattern_size, square_size), rvec, tvec))
    pts = np.concatenate([corners, edge])
    if not np.isfinite(pts).all():
        return False
    if (
        (pts < margin).any()
        or (pts[:, 0] > w - 1 - margin).any()
        or (pts[:, 1] > h - 1 - margin).any()
    ):
        return False
    # the board must stay clear of the camera's own reflection (the ball of render_board):
    # no ray of a corner or of the board's edge may hit it
    P, d = camera.unproject(pts)
    if not np.isfinite(d).all():
        return False
    if body_radius is not None:
        w_ = P - camera.camera_center
        b = np.einsum("ij,ij->i", w_, d)
        disc = b * b - (np.einsum("ij,ij->i", w_, w_) - (1.2 * body_radius) ** 2)
        if ((disc >= 0) & (-b + np.sqrt(np.maximum(disc, 0)) > 0)).any():
            return False
    cols, rows = _pattern(pattern_size)
    g = corners.reshape(rows, cols, 2)
    spacing = min(
        np.linalg.norm(np.diff(g, axis=0), axis=2).min(),
        np.linalg.norm(np.diff(g, axis=1), axis=2).min(),
    )
    return spacing >= min_spacing


def random_board_poses(
    camera,
    n,
    pattern_size,
    square_size,
    distance=(300.0, 1500.0),
    elevation=(-65.0, 5.0),
    max_tilt_deg=40.0,
    min_spacing=6.0,
    margin=3.0,
    rng=0,
    max_tries=20000,
    body_radius=10.0,
    azimuth=(0.0, 360.0),
):
    """``n`` board poses ``(rvec_b, tvec_b)`` (mirror frame), each wholly visible in ``camera``.

    Each board's centre is at a distance in ``distance`` (mm) from the mirror origin, at an
    azimuth in ``azimuth`` and an elevation in ``elevation`` (degrees); the board faces the
    origin, tilted by up to ``max_tilt_deg`` and turned by a random angle in its plane. A pose is
    kept when every inner corner and the board's outer edge (white margin included) project
    inside the image with ``margin`` px to spare and the smallest corner spacing is at least
    ``min_spacing`` px, and none of their rays meets the camera's reflection (a ball of
    ``1.2 * body_radius`` about the camera centre; ``render_board``'s ``body_radius``).

    Returns
    -------
    list of ((3,) ndarray, (3,) ndarray)
    """
    cols, rows = _pattern(pattern_size)
    _check_camera(camera)
    rng = np.random.default_rng(rng)
    s = float(square_size)
    centre = np.array([(cols - 1) * s / 2.0, (rows - 1) * s / 2.0, 0.0])
    poses = []
    for _ in range(int(max_tries)):
        if len(poses) == n:
            break
        dist = rng.uniform(*distance)
        az = math.radians(rng.uniform(*azimuth))
        el = math.radians(rng.uniform(*elevation))
        u = np.array([math.cos(el) * math.cos(az), math.cos(el) * math.sin(az), math.sin(el)])
        # board frame: z along the line of sight (away from the rig), x roughly horizontal
        z = u
        x = np.cross(np.array([0.0, 0.0, 1.0]), z)
        x /= np.linalg.norm(x)
        y = np.cross(z, x)
        Rb = np.stack([x, y, z], axis=1)
        spin = cv2.Rodrigues(np.array([0.0, 0.0, rng.uniform(-math.pi, math.pi)]))[0]
        t_axis = rng.normal(size=2)
        t_axis = np.array([*t_axis / np.linalg.norm(t_axis), 0.0])
        tilt = cv2.Rodrigues(t_axis * math.radians(rng.uniform(0.0, max_tilt_deg)))[0]
        Rb = Rb @ tilt @ spin
        rvec = cv2.Rodrigues(Rb)[0].ravel()
        tvec = dist * u - Rb @ centre
        if _visible(camera, (cols, rows), s, rvec, tvec, margin, min_spacing, body_radius):
            poses.append((rvec, tvec))
    if len(poses) < n:
        raise ValueError(
            f"only {len(poses)} of {n} visible board poses found: widen distance or "
            f"elevation, or use a smaller board"
        )
    return poses


def render_board(
    camera,
    pattern_size,
    square_size,
    rvec,
    tvec,
    supersample=4,
    noise=0.0,
    seed=None,
    environment=None,
    body_radius=10.0,
    housing_color=HOUSING_COLOR,
):
    """What the rig sees of a chessboard (or of the scene alone, ``rvec=tvec=None``).

    Every subpixel's reflected ray ``P + t d`` (:meth:`unproject`) is intersected with the
    board plane; inside the board (squares of side ``square_size`` around the inner corners and
    a white margin of one square) it takes the checker colour, elsewhere the environment's
    colour in its direction (:func:`omnicam.synthetic.make_environment`). Supersampled, so an
    edge's pixel value is its area coverage.

    Returns
    -------
    image : (h, w, 3) uint8 ndarray, BGR
    """
    _check_camera(camera)
    cols, rows = _pattern(pattern_size)
    s = float(square_size)
    env = np.ascontiguousarray(
        make_environment() if environment is None else environment, dtype=np.float32
    )
    if rvec is None:

        def shade(P, d):
            return _sample_equirect(env, d)

        return _render(camera, shade, supersample, noise, seed, housing_color, body_radius, None)
    Rb = cv2.Rodrigues(np.asarray(rvec, np.float64).reshape(3, 1))[0]
    tb = np.asarray(tvec, np.float64)
    n = Rb[:, 2]

    def shade(P, d):
        col = _sample_equirect(env, d)
        den = d @ n
        with np.errstate(divide="ignore", invalid="ignore"):
            t = ((tb - P) @ n) / den
        hit = np.isfinite(t) & (t > 0)
        X = P[hit] + t[hit, None] * d[hit]
        xb = (X - tb) @ Rb  # board frame: R^T (X - t)
        fx, fy = xb[:, 0] / s, xb[:, 1] / s
        inside = (fx >= -2) & (fx <= cols + 1) & (fy >= -2) & (fy <= rows + 1)
        squares = (fx >= -1) & (fx <= cols) & (fy >= -1) & (fy <= rows)
        black = squares & ((np.floor(fx).astype(np.int64) + np.floor(fy).astype(np.int64)) % 2 == 0)
        val = np.where(black, _BLACK, _WHITE).astype(np.float32)
        idx = np.flatnonzero(hit)[inside]
        col[idx] = val[inside, None]
        return col

    return _render(camera, shade, supersample, noise, seed, housing_color, body_radius, None)
