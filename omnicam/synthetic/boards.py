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
* :func:`render_board`: the image, by the independent tracer of
  :mod:`omnicam.synthetic.realistic` (its own camera rays, mirror intersection and reflection;
  nothing of the estimator): the board (:class:`~.realistic.Chessboard`, a white margin of one
  square around the squares), a room at infinity elsewhere, the dark housing outside the rim
  and the camera's own body (:data:`BOARD_BODY`, a lens barrel coaxial with the optical axis,
  whose reflection is the round dark silhouette :func:`omnicam.calibration.reflection.
  detect_reflection` finds), then blur, sensor noise and JPEG (:func:`~.realistic.degrade`).

The ground truth (:func:`board_corners`) is ``camera.project``, the estimator's projection; the
renderer shares nothing with it, and ``tests/test_boards.py`` checks that the independent
tracer's rays of the truth pixels pass through the corners.
"""

from __future__ import annotations

import dataclasses
import math

import cv2
import numpy as np

from . import check_camera
from . import realistic as _rl

__all__ = [
    "BOARD_BODY",
    "BOARD_PHOTOMETRIC",
    "board_corners",
    "board_object_points",
    "board_outline",
    "random_board_poses",
    "render_board",
]

#: The camera's body in the board renders: a lens barrel of radius 15 mm whose front edge is
#: 25 mm ahead of the camera centre, on a small box hidden behind it, so that the outline of
#: its reflection is the barrel's front circle ``(r, z) = (15, 25)``
#: (docs/conventions.md, "The camera's own reflection").
BOARD_BODY = _rl.BodyGeometry(
    r_barrel=15.0,
    z_barrel=25.0,
    r_glass=12.0,
    r_aperture=3.0,
    rings=(6.0, 9.5),
    highlights=((4.0, -5.0, 0.9), (-2.5, 4.0, 0.6)),
    z_box=-8.0,
    w_box=16.0,
    h_box=13.0,
    depth_box=30.0,
)
#: Photographic degradations of the board renders: slight blur, sensor noise, JPEG 92.
BOARD_PHOTOMETRIC = _rl.Photometric(blur_sigma=0.6, noise_sigma=1.5, jpeg_quality=92)


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


def _visible(camera, pattern_size, square_size, rvec, tvec, margin, min_spacing, body):
    w, h = camera.image_size
    corners = board_corners(camera, pattern_size, square_size, rvec, tvec).reshape(-1, 2)
    edge = camera.project(_to_mirror(board_outline(pattern_size, square_size, 16), rvec, tvec))
    pts = np.concatenate([corners, edge])
    if not np.isfinite(pts).all():
        return False
    if (
        (pts < margin).any()
        or (pts[:, 0] > w - 1 - margin).any()
        or (pts[:, 1] > h - 1 - margin).any()
    ):
        return False
    # no corner and no point of the board's edge hidden by the camera's own body (or off the
    # mirror), by the independent tracer
    if body is not None:
        labels, *_ = _rl.trace(camera, pts, _rl.Rig(body=body))
        if (labels != _rl.LABELS["scene"]).any():
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
    *,
    distance=(300.0, 1500.0),
    elevation=(-65.0, 5.0),
    max_tilt_deg=40.0,
    min_spacing=6.0,
    margin=3.0,
    rng=0,
    max_tries=20000,
    body=BOARD_BODY,
    azimuth=(0.0, 360.0),
):
    """``n`` board poses ``(rvec_b, tvec_b)`` (mirror frame), each wholly visible in ``camera``.

    Each board's centre is at a distance in ``distance`` (mm) from the mirror origin, at an
    azimuth in ``azimuth`` and an elevation in ``elevation`` (degrees); the board faces the
    origin, tilted by up to ``max_tilt_deg`` and turned by a random angle in its plane. A pose is
    kept when every inner corner and the board's outer edge (white margin included) project
    inside the image with ``margin`` px to spare and the smallest corner spacing is at least
    ``min_spacing`` px, and none of their reflected rays meets the camera's ``body`` (a
    :class:`~.realistic.BodyGeometry`, traced by :func:`~.realistic.trace`; None: not checked).

    Returns
    -------
    list of ((3,) ndarray, (3,) ndarray)
    """
    cols, rows = _pattern(pattern_size)
    check_camera(camera)
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
        if _visible(camera, (cols, rows), s, rvec, tvec, margin, min_spacing, body):
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
    *,
    supersample=4,
    noise=None,
    seed=0,
    body=BOARD_BODY,
    room=None,
    photometric=BOARD_PHOTOMETRIC,
):
    """What the rig sees of a chessboard (or of the scene alone, ``rvec=tvec=None``).

    Rendered by :func:`omnicam.synthetic.realistic.render_rig` (its own tracer, nothing of the
    estimator) with the board as a :class:`~.realistic.Chessboard`, the camera's ``body``, the
    ``room`` at infinity (default :class:`~.realistic.RoomScene`) and a near-black housing
    around the mirror; then :func:`~.realistic.degrade` with ``photometric``.

    Parameters
    ----------
    camera : MisalignedHyperbolicCamera
        The truth (read as numbers by the renderer).
    pattern_size, square_size, rvec, tvec
        The board (:func:`board_object_points`, ``X_mirror = R(rvec) X_board + tvec``).
    supersample : int
        Samples per pixel side near edges (1..8).
    noise : float or None
        Sensor noise in grey levels, replacing ``photometric``'s (None keeps it).
    seed : int
        Seed of the sensor noise.
    body : BodyGeometry or None
        The camera's body (default :data:`BOARD_BODY`).
    room : RoomScene or None
    photometric : Photometric or None
        Degradations (default :data:`BOARD_PHOTOMETRIC`); None: only rounding to uint8.

    Returns
    -------
    image : (h, w, 3) uint8 ndarray, BGR
    """
    check_camera(camera)
    cols, rows = _pattern(pattern_size)
    s = float(square_size)
    board = ()
    if rvec is not None:
        board = (
            _rl.Chessboard(
                (cols, rows),
                s,
                tuple(float(v) for v in np.ravel(rvec)),
                tuple(float(v) for v in np.ravel(tvec)),
            ),
        )
    rig = _rl.Rig(body=body, room=_rl.RoomScene() if room is None else room, boards=board)
    rendering = _rl.render_rig(camera, rig, supersample)
    photo = _rl.Photometric() if photometric is None else photometric
    if noise is not None:
        photo = dataclasses.replace(photo, noise_sigma=float(noise))
    return _rl.degrade(rendering.image, photo, seed=seed)
