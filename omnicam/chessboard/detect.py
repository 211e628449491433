"""Chessboard corners in omnidirectional images: OpenCV's detectors first, then unwarped views.

:func:`detect_pattern` needs no camera to start. It tries, in order:

1. ``"raw"``: ``cv2.findChessboardCorners`` on the image as it is, refined by
   ``cv2.cornerSubPix``; then ``"raw-sb"``: ``cv2.findChessboardCornersSB`` (exhaustive,
   accurate), when the first finds no board. A board the mirror bends little is found so, as
   OpenCV finds it for ``cv2.omnidir.calibrate``. A grid is accepted only if it is consistent
   with a chessboard (:func:`check_grid`): no quadrilateral of neighbouring corners folds or
   degenerates (a wrongly linked grid does), and the cells between the corners, and those of
   the ring around them, alternate dark and light (:func:`parity_failure`;
   ``findChessboardCornersSB`` asked for fewer corners than the board has may return a grid
   that skips rows of squares). :func:`detect_grids` lists the grids rejected so. One
   reflection shows the board mirrored, so the rows OpenCV returns are put back in the
   board's order;
2. ``"views"``, given a first calibration (even a rough one): the annulus is looked at through
   virtual perspective views (:func:`omnicam.views.init_perspective_maps`, scene at
   infinity), several yaws and pitches covering the band of elevations the mirror sees, where
   the board's lines are nearly straight again. In each view ``cv2.findChessboardCorners``
   runs (fast check first) and ``cv2.cornerSubPix`` refines; a detection is accepted only if a
   homography fits the view's corners to the board's grid to :data:`HOMOGRAPHY_RMS_PX` RMS
   with no corner standing out (:data:`HOMOGRAPHY_MAX_PX`) and its cells alternate dark and
   light in the view: a wrong or partial grid, or one corner pulled off by cornerSubPix, does
   not. The view's corners are mapped back to the
   source image exactly through the view's own remap table: a feature at view pixel ``u`` was
   sampled from source pixel ``map(u)``, bilinear in the float tables, whatever the
   calibration's errors (optionally they are refined once more by ``cv2.cornerSubPix`` in the
   source image, ``refine_in_source``). Of several views that see the same board the one with
   the board farthest from its border is kept.

:func:`omnicam.calibrate_pattern` runs the raw detectors on every image, the views from its
start camera on the rest, and the views again with each better camera until no new board is
found.

Accuracy: ``benchmarks/bench_pattern.py --detect`` prints it on independent renders
(:mod:`omnicam.synthetic.realistic`'s own tracer: random rigs, rooms, lens barrel, blur, noise,
JPEG, vignetting), and ``benchmarks/bench_chessboard_real.py`` on real images beside
OCamCalib's own corners: boards with a corner spacing under about 6 px near the centre of the
annulus are the ones missed.

Corner order: OpenCV's (row by row); the board's 180-degree ambiguity is resolved so that the
first row runs left to right in the view whose image-up is the mirror axis (``"views"``) or,
in the raw image, counterclockwise about the image of the mirror axis (the camera's principal
point, or the image centre without a camera).
"""

from __future__ import annotations

import dataclasses
import math
from typing import Any

import cv2
import numpy as np
import numpy.typing as npt

from ..views import K_from_fov, rotation_from_ypr, visible_elevation_range
from .intrinsics import check_pattern_size, gray8

__all__ = [
    "HOMOGRAPHY_MAX_PX",
    "HOMOGRAPHY_RMS_PX",
    "METHODS",
    "PARITY_BORDER_MISSES",
    "PARITY_MARGIN",
    "PARITY_MIN_CONTRAST",
    "PatternDetection",
    "cell_values",
    "check_grid",
    "detect_grids",
    "detect_pattern",
    "detection_views",
    "find_pattern",
    "parity_failure",
]

#: How a board's corners can be found, in the order :func:`detect_pattern` tries them.
METHODS = ("raw", "raw-sb", "views")

#: Largest RMS (view px) of a view's corners about the board grid's best homography.
HOMOGRAPHY_RMS_PX = 1.5
#: A corner farther than this (view px) and than 6 times the median from that homography
#: rejects the view's detection.
HOMOGRAPHY_MAX_PX = 1.0
#: Where a cell is sampled, in its own bilinear coordinates: a 3x3 patch about its centre,
#: away from its edges (a grid off by half a cell samples across an edge).
_CELL_UV = np.array([0.3, 0.5, 0.7])
#: Each pair of neighbouring cells must differ the checker's way by at least this fraction of
#: the grid's median difference (inner cells: all of them; cells of the border ring: all but
#: :data:`PARITY_BORDER_MISSES` of them).
PARITY_MARGIN = 0.25
#: The least median difference between neighbouring cells, grey levels (of 255).
PARITY_MIN_CONTRAST = 8.0
#: The fraction of border-ring pairs allowed to miss (the rim, the board's edge or a shadow
#: may cut the border squares).
PARITY_BORDER_MISSES = 0.25
_FIND_FLAGS = cv2.CALIB_CB_ADAPTIVE_THRESH | cv2.CALIB_CB_NORMALIZE_IMAGE | cv2.CALIB_CB_FAST_CHECK
_RAW_HALF_WINDOW = 5  # cornerSubPix's half window in the raw image, px
_SB_FLAGS = cv2.CALIB_CB_EXHAUSTIVE | cv2.CALIB_CB_ACCURACY | cv2.CALIB_CB_NORMALIZE_IMAGE
#: A virtual view of :func:`detection_views`: ``(yaw, pitch, size, map_x, map_y)``.
_View = tuple[float, float, tuple[int, int], npt.NDArray[np.float32], npt.NDArray[np.float32]]
_CACHE: dict[tuple[Any, ...], list[_View]] = {}
_CACHE_MAX = 8
#: Passes of views: 80-degree views first; 120-degree ones for boards too large for those.
_PASSES: tuple[dict[str, Any], ...] = (
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
) -> list[_View]:
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
    return gray8(image, 0)


@dataclasses.dataclass(frozen=True)
class PatternDetection:
    """A board found by :func:`detect_pattern`.

    Attributes
    ----------
    corners : (N, 1, 2) float32 ndarray
        Source pixels, row by row; for the raw methods with OpenCV's rows reversed (the module
        docstring's corner order).
    method : str
        How they were found: one of :data:`METHODS`.
    rejected : str
        Empty for a board; for a grid a detector returned that is no chessboard's (of
        :func:`detect_grids` only), why: it folds (:func:`_grid_is_regular`) or its cells do
        not alternate dark and light (:func:`parity_failure`).
    """

    corners: np.ndarray
    method: str
    rejected: str = ""


def find_pattern(image, pattern_size, camera=None, refine_in_source=False) -> np.ndarray | None:
    """Inner chessboard corners in an image of the rig, or ``None`` if no whole board is found.

    The corners of :func:`detect_pattern` (which also says how they were found).

    Parameters
    ----------
    image : ndarray
        Grey or BGR image of the rig (uint8, uint16 or float).
    pattern_size : (int, int)
        Inner corners ``(columns, rows)``, as ``cv2.findChessboardCorners``.
    camera : MisalignedHyperbolicCamera, optional
        A first calibration of the rig (a rough one is enough: it only aims the views; the
        corners are mapped back through the views' own tables). Without it only OpenCV's
        detectors on the raw image are tried.
    refine_in_source : bool
        Refine corners found in the views once more by ``cv2.cornerSubPix`` in the source
        image. Off by default: on the independent renders of ``benchmarks/bench_pattern.py``
        it made the corners worse (the source window is a few pixels where the view's is
        wider).

    Returns
    -------
    corners : (N, 1, 2) float32 ndarray or None
        In OpenCV's order (row by row), source pixels.
    """
    found = detect_pattern(image, pattern_size, camera, refine_in_source=refine_in_source)
    return None if found is None else found.corners


def detect_pattern(
    image, pattern_size, camera=None, refine_in_source=False, methods=METHODS
) -> PatternDetection | None:
    """The board's corners and how they were found, or ``None``; see the module docstring.

    Parameters
    ----------
    image, pattern_size, camera, refine_in_source
        As for :func:`find_pattern`.
    methods : sequence of str
        Which of :data:`METHODS` to try, in that order (``"views"`` needs ``camera``).

    Returns
    -------
    PatternDetection or None
    """
    for det in detect_grids(image, pattern_size, camera, refine_in_source, methods):
        if not det.rejected:
            return det
    return None


def detect_grids(
    image, pattern_size, camera=None, refine_in_source=False, methods=METHODS
) -> list[PatternDetection]:
    """The grids the detectors returned, in the order tried, up to the first board accepted.

    :func:`detect_pattern` with the grids it rejected before (or instead of) the board: those
    OpenCV's detectors returned on the raw image that fold or whose cells do not alternate dark
    and light, each with ``rejected`` saying why (the last item is the board, if one is found).
    A view's detection that fails the checks is not listed (each image has many views).

    Parameters
    ----------
    image, pattern_size, camera, refine_in_source, methods
        As for :func:`detect_pattern`.

    Returns
    -------
    list of PatternDetection
    """
    cols, rows = check_pattern_size(pattern_size)
    unknown = [m for m in methods if m not in METHODS]
    if unknown:
        raise ValueError(f"methods must be among {METHODS}, got {unknown}")
    gray = _gray(image)
    if (
        camera is not None
        and camera.image_size is not None
        and camera.image_size != (gray.shape[1], gray.shape[0])
    ):
        raise ValueError(
            f"image is {gray.shape[1]}x{gray.shape[0]} but camera.image_size is "
            f"{camera.image_size}: use camera.scaled(image_size)"
        )
    found = []
    for method in methods:
        why = ""
        if method == "views":
            if camera is None:
                continue
            corners = _detect_in_views(gray, cols, rows, camera, refine_in_source)
        else:
            corners, why = _detect_raw(gray, cols, rows, sb=method == "raw-sb")
            if corners is not None:
                corners = _counterclockwise(corners, cols, _axis_pixel(gray, camera))
        if corners is not None:
            found.append(
                PatternDetection(corners.reshape(-1, 1, 2).astype(np.float32), method, why)
            )
            if not why:
                break
    return found


def _axis_pixel(gray, camera):
    """Where the mirror axis is seen, near enough to order a board: the principal point."""
    if camera is not None:
        return np.array([camera.K[0, 2], camera.K[1, 2]])
    return np.array([(gray.shape[1] - 1) / 2.0, (gray.shape[0] - 1) / 2.0])


def _counterclockwise(c, cols, centre):
    """The corners ``c`` (N, 2) in the order whose first row runs counterclockwise (as seen
    in the image, y down) about ``centre``; OpenCV's 180-degree ambiguity resolved so."""
    a, b = c[0] - centre, c[cols - 1] - centre
    # image y points down: counterclockwise on screen is a negative cross product
    return c[::-1].copy() if a[0] * b[1] - a[1] * b[0] > 0 else c


def _detect_raw(gray, cols, rows, sb):
    """OpenCV's detector on the raw image (``sb``: ``findChessboardCornersSB``): ``(corners
    (N, 2), "")``, or ``(corners, why)`` for a grid that folds or whose cells do not alternate
    (:func:`check_grid`), or ``(None, "")`` when it finds nothing."""
    if sb:
        found, corners = cv2.findChessboardCornersSB(gray, (cols, rows), flags=_SB_FLAGS)
        if not found:
            return None, ""
    else:
        found, corners = cv2.findChessboardCorners(gray, (cols, rows), flags=_FIND_FLAGS)
        if not found:
            return None, ""
        # a window of 11 px (5 px in the bent raw image, smaller only for boards whose corners
        # are closer than 8 px): the most accurate on renders of known corners
        # (benchmarks/bench_pattern.py) and OCamCalib's own on its real samples
        half = int(np.clip(0.6 * _spacing(corners.reshape(rows, cols, 2)), 2, _RAW_HALF_WINDOW))
        crit = (cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_MAX_ITER, 100, 1e-4)
        corners = cv2.cornerSubPix(gray, corners, (half, half), (-1, -1), crit)
    grid = corners.reshape(rows, cols, 2).astype(np.float64)
    why = check_grid(gray, grid)
    # the mirror shows the board mirrored: OpenCV's rows of the image are the board's rows in
    # reverse, so the order that a rigid pose of the board explains has them turned back
    return grid[::-1].reshape(-1, 2).copy(), why


def check_grid(gray, grid) -> str:
    """Why the grid of corners ``(rows, cols, 2)`` in the grey image is no chessboard's, or
    ``""`` when it is consistent with one: no quadrilateral of neighbouring corners folds or
    degenerates (:func:`_grid_is_regular`), and the cells between them alternate dark and light
    (:func:`parity_failure`)."""
    if not _grid_is_regular(grid):
        return "it folds (a quadrilateral of neighbouring corners is not convex or degenerates)"
    return parity_failure(gray, grid)


def _grid_is_regular(grid):
    """Every quadrilateral of neighbouring corners convex, turning the same way as the others
    and of an area within 1/16 of the median's: a grid that folds or skips is a wrong grid."""
    p00, p01, p10, p11 = grid[:-1, :-1], grid[:-1, 1:], grid[1:, :-1], grid[1:, 1:]
    quad = np.stack([p00, p01, p11, p10], axis=2)  # (rows-1, cols-1, 4, 2), around the cell
    e = np.roll(quad, -1, axis=2) - quad
    turn = e[..., 0] * np.roll(e, -1, axis=2)[..., 1] - e[..., 1] * np.roll(e, -1, axis=2)[..., 0]
    sign = np.sign(np.median(turn))
    if sign == 0 or not (np.sign(turn) == sign).all():
        return False
    area = np.abs(turn.sum(axis=2)) / 4.0  # the mean turn: a measure of the cell's size
    med = float(np.median(area))
    return bool(med > 0 and area.min() > med / 16.0 and area.max() < 16.0 * med)


def _extend(grid):
    """The grid ``(rows, cols, 2)`` with one more row and column of corners on every side,
    extrapolated along the rows and the columns (quadratically when there are three or more,
    as the mirror bends the board's lines)."""

    def ext(g):  # along axis 0
        if len(g) >= 3:
            first, last = 3 * g[0] - 3 * g[1] + g[2], 3 * g[-1] - 3 * g[-2] + g[-3]
        else:
            first, last = 2 * g[0] - g[1], 2 * g[-1] - g[-2]
        return np.concatenate([first[None], g, last[None]])

    return ext(ext(grid).transpose(1, 0, 2)).transpose(1, 0, 2)


def cell_values(gray, grid):
    """The brightness of every cell of the grid and of its border ring: ``(rows + 1, cols + 1)``.

    A cell's value is the median of the image (bilinear) at 3x3 points of its central part
    (:data:`_CELL_UV` in the cell's bilinear coordinates); NaN where one of them is outside the
    image. Row 0, column 0 and the last ones are the border ring, extrapolated (:func:`_extend`).
    """
    g = _extend(np.asarray(grid, np.float64))
    p00, p01, p10, p11 = g[:-1, :-1], g[:-1, 1:], g[1:, :-1], g[1:, 1:]
    u = _CELL_UV[None, None, :, None, None]  # along the row (columns)
    v = _CELL_UV[None, None, None, :, None]  # across (rows)
    pts = (
        (1 - u) * (1 - v) * p00[:, :, None, None]
        + u * (1 - v) * p01[:, :, None, None]
        + (1 - u) * v * p10[:, :, None, None]
        + u * v * p11[:, :, None, None]
    )  # (rows + 1, cols + 1, 3, 3, 2)
    h, w = gray.shape[:2]
    flat = pts.reshape(-1, 2).astype(np.float32)
    samples = cv2.remap(
        gray.astype(np.float32),
        flat[:, 0].reshape(-1, 1),
        flat[:, 1].reshape(-1, 1),
        cv2.INTER_LINEAR,
        borderMode=cv2.BORDER_CONSTANT,
        borderValue=np.nan,
    ).reshape(pts.shape[:4])
    inside = (
        (pts[..., 0] >= 0) & (pts[..., 0] <= w - 1) & (pts[..., 1] >= 0) & (pts[..., 1] <= h - 1)
    ).all(axis=(2, 3))
    values = np.median(samples.reshape(*pts.shape[:2], -1), axis=2)
    return np.where(inside, values, np.nan)


def parity_failure(gray, grid) -> str:
    """Why the cells of the grid ``(rows, cols, 2)`` are no chessboard's, or ``""``.

    The cells between neighbouring corners, and those of the ring around them that are inside
    the image, must alternate dark and light (:func:`cell_values`): every pair of neighbouring
    cells, its difference signed by the checker's parity, must lie on the side of the grid's
    median difference and exceed :data:`PARITY_MARGIN` of it, which itself must reach
    :data:`PARITY_MIN_CONTRAST`. A grid that skips a row of squares or lies over something
    that is no chessboard does not.
    """
    vals = cell_values(gray, grid)
    n_r, n_c = vals.shape
    parity = np.where((np.add.outer(np.arange(n_r), np.arange(n_c)) % 2) == 0, 1.0, -1.0)
    border = np.ones(vals.shape, bool)
    border[1:-1, 1:-1] = False
    # the difference of every pair of neighbours, signed by the first cell's parity
    d = np.concatenate(
        [
            ((vals[:, :-1] - vals[:, 1:]) * parity[:, :-1]).ravel(),
            ((vals[:-1] - vals[1:]) * parity[:-1]).ravel(),
        ]
    )
    on_border = np.concatenate(
        [(border[:, :-1] | border[:, 1:]).ravel(), (border[:-1] | border[1:]).ravel()]
    )
    inner = d[~on_border]
    if inner.size == 0:
        return ""
    contrast = float(np.median(inner))
    if abs(contrast) < PARITY_MIN_CONTRAST:
        return (
            f"its cells do not alternate dark and light (median contrast {abs(contrast):.1f} "
            f"grey levels, less than {PARITY_MIN_CONTRAST:g})"
        )
    ok = d * np.sign(contrast) > PARITY_MARGIN * abs(contrast)
    bad_inner = int(np.sum(~ok[~on_border]))
    if bad_inner:
        return (
            f"its cells do not alternate dark and light ({bad_inner} of {inner.size} pairs of "
            f"neighbouring cells do not)"
        )
    seen = on_border & np.isfinite(d)
    bad_border = int(np.sum(~ok[seen]))
    if bad_border > PARITY_BORDER_MISSES * max(int(seen.sum()), 1):
        return (
            f"the squares around its corners do not alternate dark and light ({bad_border} of "
            f"{int(seen.sum())} pairs of border cells do not)"
        )
    return ""


def _detect_in_views(gray, cols, rows, camera, refine_in_source):
    """The corners found through the views of ``camera`` (N, 2), or None."""
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
    return best


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
        if parity_failure(view, c.reshape(rows, cols, 2)):  # a grid over no chessboard
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
