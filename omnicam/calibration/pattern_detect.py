"""Chessboard corners in omnidirectional images: detect in virtual perspective views, map back.

``cv2.findChessboardCorners`` fails on boards that the mirror bends strongly. Given a first
calibration (even a rough one), :func:`find_pattern` looks at the annulus through virtual
perspective views (:func:`omnicam.views.init_perspective_maps`, scene at infinity), several yaws
and pitches covering the band of elevations the mirror sees, where the board's lines are nearly
straight again. In each view it runs ``cv2.findChessboardCorners`` (fast check first) and refines
the corners with ``cv2.cornerSubPix``; a detection is accepted only if a homography fits
the view's corners to the board's grid to :data:`HOMOGRAPHY_RMS_PX` RMS with no corner
standing out (:data:`HOMOGRAPHY_MAX_PX`): a wrong or partial grid, or one corner pulled off
by cornerSubPix, does not. The view's corners are mapped back to the source image exactly
through the view's own remap table: a feature at view pixel ``u`` was sampled from source pixel
``map(u)``, bilinear in the float tables, whatever the calibration's errors (optionally they are
refined once more by ``cv2.cornerSubPix`` in the source image, ``refine_in_source``). Of several
views that see the same board the one with the board farthest from its border is kept.

Accuracy (``benchmarks/bench_pattern.py --detect``): on independent renders
(:mod:`omnicam.synthetic.realistic`'s own tracer) of 1000x1000 of random rigs tilted up to 5 deg
and offset up to 5 mm, random rooms, the camera's lens barrel, blur 0.3-1.2 px, sensor noise
1-4 grey levels, JPEG 75-95 and vignetting, a 9x6 board of 60 mm squares 0.3-1.5 m away and
wholly visible (corner spacing 6-19 px), 60 renders: found in 57 (95 %; the 3 misses are
boards 1.4-1.5 m away near the centre of the annulus, corner spacing about 6 px), corner error
RMS 0.11 px (median 0.06, 95th percentile 0.20, largest 1.1 px); boards with a corner spacing of
10 px or more: 23 of 23, RMS 0.06 px, largest 0.23 px; none of the 9 renders without a board
gave corners; 0.31 s per image.

Corner order: OpenCV's (row by row); the board's 180-degree ambiguity is resolved so that the
first row runs left to right in the view whose image-up is the mirror axis.
"""

from __future__ import annotations

import math

import cv2
import numpy as np

__all__ = ["HOMOGRAPHY_MAX_PX", "HOMOGRAPHY_RMS_PX", "detection_views", "find_pattern"]

#: Largest RMS (view px) of a view's corners about the board grid's best homography.
HOMOGRAPHY_RMS_PX = 1.5
#: A corner farther than this (view px) and than 6 times the median from that homography
#: rejects the view's detection.
HOMOGRAPHY_MAX_PX = 1.0
_FIND_FLAGS = cv2.CALIB_CB_ADAPTIVE_THRESH | cv2.CALIB_CB_NORMALIZE_IMAGE | cv2.CALIB_CB_FAST_CHECK
_CACHE = {}
_CACHE_MAX = 8
#: Passes of views: 80-degree views first; 120-degree ones for boards too large for those.
_PASSES = (
    {},
    {"fov_deg": 120.0, "yaw_step_deg": 40.0, "pitches_deg": (-15.0, -50.0), "scale": 0.5},
)


def _camera_key(camera):
    D = camera.D
    return (
        camera.K.tobytes(),
        None if D is None else D.tobytes(),
        camera.rvec.tobytes(),
        camera.tvec.tobytes(),
        repr(camera.mirror),
        camera.image_size,
    )


def detection_views(
    camera, fov_deg=80.0, yaw_step_deg=30.0, pitches_deg=None, scale=0.7, node_step=8
):
    """The virtual views of :func:`find_pattern`: ``[(yaw, pitch, size, map_x, map_y)]``.

    Views of ``fov_deg`` (horizontal and vertical), one every ``yaw_step_deg`` of yaw, at the
    pitches ``pitches_deg`` (default: three pitches spreading over the band the mirror sees,
    from its upper edge to 75 deg below the horizon), with ``scale`` times as many pixels per
    degree as the source has along the rim (the most it has anywhere).

    The tables need not be exact (a corner is mapped back through the very table that made
    the view, so their error only bends the view a little): the exact projection
    (:meth:`project_directions`, directions ``R^T K_new^-1 u`` as in
    :func:`omnicam.views.init_perspective_maps`) is computed every ``node_step`` px and the
    ``CV_32FC1`` tables are bilinear between those nodes (``cv2.resize``), which is also how
    :func:`_bilinear` maps corners back. Cached per camera.
    """
    from ..views import K_from_fov, rotation_from_ypr, visible_elevation_range

    key = (
        _camera_key(camera),
        float(fov_deg),
        float(yaw_step_deg),
        None if pitches_deg is None else tuple(pitches_deg),
        float(scale),
        int(node_step),
    )
    if key in _CACHE:
        return _CACHE[key]
    if pitches_deg is None:
        _, hi = visible_elevation_range(camera)
        top, bottom = hi - 0.3 * fov_deg, -75.0 + 0.4 * fov_deg
        pitches_deg = np.linspace(top, bottom, 3) if top > bottom else [0.5 * (top + bottom)]
    rim = camera.rim_image_points(360)
    perimeter = float(np.sum(np.linalg.norm(np.diff(np.vstack([rim, rim[:1]]), axis=0), axis=1)))
    px_per_rad = scale * perimeter / (2 * math.pi)
    n = max(8, round(2 * px_per_rad * math.tan(math.radians(fov_deg) / 2) / node_step))
    size = n * node_step + 1  # nodes at 0, step, ..., size - 1
    K_new = K_from_fov(fov_deg, (size, size))
    g = np.arange(0, size, node_step, dtype=np.float64)
    gx, gy = np.meshgrid(g, g)
    rays = np.linalg.inv(K_new) @ np.stack([gx.ravel(), gy.ravel(), np.ones(gx.size)])
    views, dirs = [], []
    specs = [(float(p), float(y)) for p in pitches_deg for y in np.arange(0.0, 360.0, yaw_step_deg)]
    for pitch, yaw in specs:
        dirs.append((rotation_from_ypr(yaw, pitch).T @ rays).T)
    px = camera.project_directions(np.concatenate(dirs)).reshape(len(specs), len(g), len(g), 2)
    # bilinear between the nodes, separably: table = A nodes A^T
    t = np.arange(size) / node_step
    k = np.minimum(np.floor(t).astype(int), len(g) - 2)
    A = np.zeros((size, len(g)))
    A[np.arange(size), k] = 1.0 - (t - k)
    A[np.arange(size), k + 1] = t - k
    for (pitch, yaw), nodes in zip(specs, px):
        bad = ~np.isfinite(nodes).all(axis=2)
        nodes = np.where(bad[..., None], -1e4, nodes)  # unseen: far outside the source
        mx = (A @ nodes[..., 0] @ A.T).astype(np.float32)
        my = (A @ nodes[..., 1] @ A.T).astype(np.float32)
        views.append((yaw, pitch, (size, size), mx, my))
    if len(_CACHE) >= _CACHE_MAX:
        _CACHE.pop(next(iter(_CACHE)))
    _CACHE[key] = views
    return views


def _bilinear(mx, my, pts):
    """Source pixels of view pixels ``pts`` (N, 2): the float tables, bilinearly."""
    h, w = mx.shape
    x, y = pts[:, 0], pts[:, 1]
    x0 = np.clip(np.floor(x).astype(int), 0, w - 2)
    y0 = np.clip(np.floor(y).astype(int), 0, h - 2)
    fx, fy = x - x0, y - y0
    out = np.empty_like(pts)
    for k, m in enumerate((mx, my)):
        m = m.astype(np.float64)
        out[:, k] = (m[y0, x0] * (1 - fx) + m[y0, x0 + 1] * fx) * (1 - fy) + (
            m[y0 + 1, x0] * (1 - fx) + m[y0 + 1, x0 + 1] * fx
        ) * fy
    return out


def _spacing(grid):
    return min(
        np.linalg.norm(np.diff(grid, axis=0), axis=2).min(),
        np.linalg.norm(np.diff(grid, axis=1), axis=2).min(),
    )


def _gray(image):
    from .intrinsics import _gray8

    return _gray8(image, 0)


def find_pattern(image, pattern_size, camera, refine_in_source=False):
    """Inner chessboard corners in an image of the rig, or ``None`` if no whole board is found.

    Parameters
    ----------
    image : ndarray
        Grey or BGR image of the rig (uint8, uint16 or float).
    pattern_size : (int, int)
        Inner corners ``(columns, rows)``, as ``cv2.findChessboardCorners``.
    camera : MisalignedHyperbolicCamera
        A first calibration of the rig (a rough one is enough: it only aims the views; the
        corners are mapped back through the views' own tables).
    refine_in_source : bool
        Refine the mapped-back corners once more by ``cv2.cornerSubPix`` in the source image.
        Off by default: on the independent renders of the benchmark (blur 0.3-1.2 px, noise,
        JPEG) it made the corners worse on 29 of 37 boards (RMS 0.17 against 0.14 px over the
        same 37 detections; 0.81 against 0.36 px worst corner on one board), the source window
        being a few pixels where the view's is wider.

    Returns
    -------
    corners : (N, 1, 2) float32 ndarray or None
        In OpenCV's order (row by row), source pixels.
    """
    from .intrinsics import _pattern

    cols, rows = _pattern(pattern_size)
    gray = _gray(image)
    if camera.image_size is not None and camera.image_size != (gray.shape[1], gray.shape[0]):
        raise ValueError(
            f"image is {gray.shape[1]}x{gray.shape[0]} but camera.image_size is "
            f"{camera.image_size}: use camera.scaled(image_size)"
        )
    best = None
    for spec in _PASSES:
        best = _detect(gray, cols, rows, detection_views(camera, **spec))
        if best is not None:
            break
    if best is None:
        return None
    if refine_in_source:
        grid = best.reshape(rows, cols, 2)
        half = int(np.clip(_spacing(grid) / 3.0, 2, 5))
        crit = (cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_MAX_ITER, 100, 1e-4)
        refined = (
            cv2.cornerSubPix(
                gray, best.reshape(-1, 1, 2).astype(np.float32), (half, half), (-1, -1), crit
            )
            .reshape(-1, 2)
            .astype(np.float64)
        )
        # keep the refinement only where it stays within a pixel of the mapped-back corner
        ok = np.linalg.norm(refined - best, axis=1) < 1.0
        best = np.where(ok[:, None], refined, best)
    return best.reshape(-1, 1, 2).astype(np.float32)


def _detect(gray, cols, rows, views):
    """The mapped-back corners of the best detection in ``views`` (N, 2), or None."""
    best, best_margin = None, -np.inf
    for _yaw, _pitch, (w, h), mx, my in views:
        view = cv2.remap(
            gray, mx, my, cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT, borderValue=0
        )
        # OpenCV's own quick test (what CALIB_CB_FAST_CHECK runs) first: 8 ms per view
        if not cv2.checkChessboard(view, (cols, rows)):
            continue
        found, corners = cv2.findChessboardCorners(view, (cols, rows), flags=_FIND_FLAGS)
        if not found:
            continue
        grid = corners.reshape(rows, cols, 2)
        half = int(np.clip(0.4 * _spacing(grid), 2, 11))
        crit = (cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_MAX_ITER, 100, 1e-4)
        corners = cv2.cornerSubPix(view, corners, (half, half), (-1, -1), crit)
        c = corners.reshape(-1, 2).astype(np.float64)
        obj = np.mgrid[0:cols, 0:rows].T.reshape(-1, 2).astype(np.float64)
        H, _ = cv2.findHomography(obj, c, 0)
        if H is None:
            continue
        pr = cv2.perspectiveTransform(obj.reshape(-1, 1, 2), H).reshape(-1, 2)
        # every corner on the grid: a view is perspective up to the rig's non-centrality (a
        # smooth deviation, spread over the board, for near boards), so a corner far off the
        # board's homography, compared with the others, is a wrong corner
        res = np.linalg.norm(pr - c, axis=1)
        if not (
            np.sqrt(np.mean(res**2)) < HOMOGRAPHY_RMS_PX
            and res.max() < max(HOMOGRAPHY_MAX_PX, 6.0 * np.median(res))
        ):
            continue
        margin = float(
            min(c[:, 0].min(), c[:, 1].min(), w - 1 - c[:, 0].max(), h - 1 - c[:, 1].max())
        )
        if margin < half + 1:
            continue
        # OpenCV's 180-degree ambiguity: the first row runs left to right in the view
        if c[cols - 1, 0] - c[0, 0] < 0:
            c = c[::-1].copy()
        src = _bilinear(mx, my, c)
        if (
            not np.isfinite(src).all()
            or (src < 0).any()
            or (src[:, 0] > gray.shape[1] - 1).any()
            or (src[:, 1] > gray.shape[0] - 1).any()
        ):
            continue
        if margin > best_margin:
            best, best_margin = src, margin
        if best_margin > 0.15 * min(w, h):  # well inside this view: no better one to find
            break
    return best
