"""Remap tables for ``cv2.remap``: panoramas and virtual perspective views (paper section 4.1).

A misaligned rig has no single viewpoint (paper section 2.2), so a panorama or a perspective
view is an approximation made from one chosen point: for ``depth=None`` the scene is at
infinity and each output pixel shows the *direction* it looks along (the viewpoint plays no
part); for a finite ``depth`` it shows the point at that Euclidean distance along its ray from
the viewpoint, by default the best-fit viewpoint of section 4.1 (least mean squared distance to
the rays of all mirror pixels, :meth:`MisalignedHyperbolicCamera.best_fit_viewpoint`).
Each table entry is the *exact* non-central projection of that direction or point
(:meth:`~omnicam.camera.MisalignedHyperbolicCamera.project_directions` /
:meth:`~omnicam.camera.MisalignedHyperbolicCamera.project`) to better than 0.01 px.

The paper's uncalibrated baseline (eqs. 2-5, Fig. 7 (a), (b)) is the same function on
``MisalignedHyperbolicCamera.aligned(mirror, f_C, x_c, y_c)``.

How a table is built (:func:`_build_table`, phase by phase in :mod:`omnicam._kernels`): the
reflection point is solved exactly (Newton on Fermat's path length, the solver of ``project``) on a
grid of nodes about ``CELL_DEGREES`` apart, on the mirror sheet extended past the rim so that it is
smooth across the edge of what the mirror sees. Each cell is interpolated by the cubic Lagrange
polynomial of its 4x4 nodes, and its error is *measured* against the exact answer at the cell centre
and the middles of its edges (where the error of that interpolant peaks); a cell whose estimate
exceeds ``TOLERANCE / 2`` is refined on a grid 2 times finer, and what still fails is solved pixel
by pixel. Visibility is decided per cell when all of it is clearly seen or clearly unseen, else per
pixel with a margin, and exactly inside the margin. ``tests/test_views.py`` compares whole tables
with the exact projection of every pixel.

The view conventions (azimuth, row order, ``R``, yaw/pitch/roll) are those of
``docs/conventions.md``, section "Views".
"""

from __future__ import annotations

import functools
import math
import numbers
import warnings
from typing import Any, NamedTuple, Protocol

import cv2
import numpy as np
import numpy.typing as npt

from . import _kernels
from ._jit import notice_if_cold, run_chunks
from ._kernels import (
    CHECK_CENTRE,
    CHECK_HORIZONTAL_EDGE,
    CHECK_VERTICAL_EDGE,
    FINE,
    NEWTON_TOL_REL,
    GridMargins,
    RigArgs,
    Solutions,
    TableGrids,
    TableOutputs,
    ViewArgs,
    ViewPoints,
    cubic_blocks,
)
from ._typing import ArrayLike, FloatArray, Maps, Size
from ._validate import finite_array, float_array, real_number, refuse_complex, validate_K
from .mirror import Mirror

__all__ = [
    "init_panorama_maps",
    "init_perspective_maps",
    "rotation_from_ypr",
    "K_from_fov",
    "visible_elevation_range",
    "default_elevation_range",
    "camera_reflection_elevation",
    "DefaultElevationRange",
    "PanoramaView",
    "PerspectiveView",
    "UNSEEN",
    "PROJECTIONS",
    "M1TYPES",
    "TOLERANCE",
]

#: Source coordinate written for output pixels whose direction the mirror does not see: well
#: outside any image (at least 2 px) and inside the range of ``CV_16SC2``.
UNSEEN = -10.0

#: Panorama row layouts: rows linear in ``tan(elevation)`` or in elevation.
PROJECTIONS = ("cylindrical", "equirectangular")

#: Accepted ``m1type`` values, as ``cv2.convertMaps`` names them.
M1TYPES = {cv2.CV_16SC2: "CV_16SC2", cv2.CV_32FC1: "CV_32FC1", cv2.CV_32FC2: "CV_32FC2"}

#: ``R = None`` of a perspective view: looking horizontally at azimuth 0, image-up along +Z.
R0 = np.array([[0.0, -1.0, 0.0], [0.0, 0.0, -1.0], [1.0, 0.0, 0.0]])

#: The default band of a panorama stops here when the camera's reflection is unknown (it leaves
#: out the camera around the nadir on the default rigs: a lens barrel of 30 mm stays below it),
#: and a cylindrical one never goes lower: its rows, linear in ``tan(elevation)``, stretch
#: without bound towards the nadir (-90 deg).
CYLINDRICAL_MIN_ELEVATION = -60.0

#: Source pixels between the outline of the camera's reflection and the default lower edge of a
#: panorama (:func:`camera_reflection_elevation`): the blur of the outline's edge and the
#: scatter of the circle fitted to it (``benchmarks/bench_real_photo.py`` prints the panorama's
#: rows between the two).
REFLECTION_MARGIN_PX = 2.0

#: Where the default lower edge of a panorama came from (:class:`DefaultElevationRange`).
LOWER_EDGE_REFLECTION = "the camera's reflection as detected"
LOWER_EDGE_FIXED = "the fixed default, no camera reflection recorded"
LOWER_EDGE_FLOOR = "a cylindrical panorama's lowest default, the camera's reflection below it"
LOWER_EDGE_ABOVE = "the fixed default, the camera's reflection reaching above the band"
LOWER_EDGE_MIRROR = "what the mirror sees"


class CameraLike(Protocol):
    """What the views read of a camera: a :class:`~omnicam.camera.MisalignedHyperbolicCamera`
    (duck-typed: the views sit below the camera class and do not import it)."""

    @property
    def mirror(self) -> Mirror: ...

    @property
    def K(self) -> FloatArray: ...

    @property
    def D(self) -> FloatArray | None: ...

    @property
    def R(self) -> FloatArray: ...

    @property
    def tvec(self) -> FloatArray: ...

    @property
    def camera_center(self) -> FloatArray: ...

    @property
    def camera_reflection(self) -> tuple[float, float] | None: ...

    def project(self, object_points: ArrayLike) -> FloatArray: ...

    def unproject(self, image_points: ArrayLike) -> tuple[FloatArray, FloatArray]: ...

    def best_fit_viewpoint(self) -> tuple[FloatArray, float]: ...


#: The four outputs of a table, as :func:`_build_table` writes them: float32 x and y maps
#: (mode 0), or CV_16SC2's int16 pairs and uint16 fractions (mode 1); the others unused (1x1).
_Outputs = tuple[
    npt.NDArray[np.float32], npt.NDArray[np.float32], npt.NDArray[np.int16], npt.NDArray[np.uint16]
]
_IntArray = npt.NDArray[np.int64]


# -- helpers for view specs ----------------------------------------------------------------------
def rotation_from_ypr(yaw: float = 0.0, pitch: float = 0.0, roll: float = 0.0) -> FloatArray:
    """``R`` of a virtual view from yaw, pitch and roll in degrees (docs/conventions.md, "Views").

    The optical axis looks at azimuth ``-yaw`` (positive yaw turns right, as a panorama does
    when its column grows) and elevation ``pitch`` (positive looks up); image-up is as close to
    the mirror axis +Z as possible (image-right is horizontal); then the virtual camera turns by
    ``roll`` about its optical axis, clockwise as seen from behind it (image-right tilts towards
    image-down), so the scene appears turned counter-clockwise in the view.
    All zero gives ``R0 = [[0, -1, 0], [0, 0, -1], [1, 0, 0]]``.

    Parameters
    ----------
    yaw, pitch, roll : float
        Degrees. ``pitch = +-90`` is allowed (looking straight up or down); image-right then
        stays the horizontal direction ``yaw`` gives.

    Returns
    -------
    R : (3, 3) float64 ndarray
        Rotation taking mirror-frame directions into the virtual camera's frame (x right,
        y down, z forward), as the ``R`` of ``cv2.initUndistortRectifyMap``.
    """
    vals = []
    for name, v in (("yaw", yaw), ("pitch", pitch), ("roll", roll)):
        refuse_complex(v, name, "a finite number of degrees")
        try:
            v = float(v)
        except (TypeError, ValueError, OverflowError):
            raise ValueError(f"{name} must be a finite number of degrees, got {v!r}") from None
        if not math.isfinite(v):
            raise ValueError(f"{name} must be a finite number of degrees, got {v!r}")
        vals.append(math.radians(v))
    y, p, r = vals
    az = -y
    forward = np.array([math.cos(p) * math.cos(az), math.cos(p) * math.sin(az), math.sin(p)])
    right = np.array([math.sin(az), -math.cos(az), 0.0])  # horizontal, forward x e_z at p = 0
    down = np.cross(forward, right)
    right_r = math.cos(r) * right + math.sin(r) * down
    down_r = -math.sin(r) * right + math.cos(r) * down
    return np.stack([right_r, down_r, forward])


def K_from_fov(fov_deg: float, size: Size) -> FloatArray:
    """Camera matrix of a virtual perspective view with horizontal field of view ``fov_deg``.

    Square pixels, no skew, principal point at the image centre with pixel centres at integers:
    ``f = (w / 2) / tan(fov / 2)``, ``c = ((w - 1) / 2, (h - 1) / 2)``.

    Parameters
    ----------
    fov_deg : float
        Horizontal field of view across the full width, in degrees, in (0, 180).
    size : (int, int)
        ``(width, height)`` of the view.

    Returns
    -------
    K : (3, 3) float64 ndarray
    """
    w, h = _check_size(size)
    refuse_complex(fov_deg, "fov_deg", "a number of degrees in (0, 180)")
    try:
        fov = float(fov_deg)
    except (TypeError, ValueError, OverflowError):
        raise ValueError(
            f"fov_deg must be a number of degrees in (0, 180), got {fov_deg!r}"
        ) from None
    if not (0.0 < fov < 180.0):
        raise ValueError(f"fov_deg must be in (0, 180) degrees, got {fov_deg!r}")
    f = 0.5 * w / math.tan(math.radians(fov) / 2.0)
    return np.array([[f, 0.0, (w - 1) / 2.0], [0.0, f, (h - 1) / 2.0], [0.0, 0.0, 1.0]])


# -- validation ----------------------------------------------------------------------------------
def _check_size(size: Any, min_height: int = 1) -> Size:
    try:
        w, h = size
        if not all(
            isinstance(v, numbers.Real) and not isinstance(v, (bool, np.bool_)) for v in (w, h)
        ):
            raise TypeError
        exact = all(isinstance(v, numbers.Integral) or float(v) == int(v) for v in (w, h))
        w, h = int(w), int(h)
    except (TypeError, ValueError, OverflowError):
        raise ValueError(
            f"size must be (width, height), two positive integers, got {size!r}"
        ) from None
    if not exact or w < 1 or h < min_height:
        raise ValueError(
            f"size must be (width, height), two integers with width >= 1 and "
            f"height >= {min_height}, got {size!r}"
        )
    if w > 32767 or h > 32767:
        raise ValueError(f"size must be at most 32767 x 32767 (cv2.remap), got {size!r}")
    return w, h


def _check_camera(camera: object) -> object:
    """A camera (duck-typed: views sit below the camera class and do not import it)."""
    if not all(hasattr(camera, a) for a in ("mirror", "K", "R", "unproject", "rim_image_points")):
        raise ValueError(
            f"camera must be a MisalignedHyperbolicCamera, got {type(camera).__name__}"
        )
    return camera


def _check_m1type(m1type: object) -> int:
    if (
        isinstance(m1type, bool)
        or not isinstance(m1type, numbers.Integral)
        or int(m1type) not in M1TYPES
    ):
        raise ValueError(
            f"m1type must be cv2.CV_16SC2, cv2.CV_32FC1 or cv2.CV_32FC2, got {m1type!r}"
        )
    return int(m1type)


def _check_rotation(R: ArrayLike, name: str = "R") -> FloatArray:
    arr = float_array(R, name, "a 3x3 rotation matrix")
    if arr.shape != (3, 3) or not np.isfinite(arr).all():
        raise ValueError(f"{name} must be a finite 3x3 rotation matrix, got shape {arr.shape}")
    if not np.allclose(arr @ arr.T, np.eye(3), atol=1e-6) or np.linalg.det(arr) < 0:
        raise ValueError(f"{name} must be a rotation matrix (orthonormal, det +1)")
    return arr


def _check_depth(depth: float | None) -> float | None:
    if depth is None:
        return None
    return real_number(
        depth, "depth", 0.0, lo_open=True, expected="None or a positive finite distance"
    )


def _check_viewpoint(
    camera: CameraLike | None, viewpoint: ArrayLike | None, depth: float | None
) -> FloatArray | None:
    if depth is None:
        return None  # directions: the viewpoint plays no part (do not compute the best fit)
    if viewpoint is None:
        assert camera is not None, "the view specs pass a viewpoint to check, never None"
        return np.asarray(camera.best_fit_viewpoint()[0], dtype=np.float64)
    return finite_array(viewpoint, "viewpoint", (3,), "None or 3 numbers (mirror frame)")


def _check_elevation_range(
    elevation_range: tuple[float, float], projection: str
) -> tuple[float, float]:
    try:
        lo, hi = (real_number(v, "elevation_range") for v in elevation_range)
    except (TypeError, ValueError):
        raise ValueError(
            f"elevation_range must be None or (lo, hi) in degrees, got {elevation_range!r}"
        ) from None
    if not (math.isfinite(lo) and math.isfinite(hi)) or lo >= hi:
        raise ValueError(f"elevation_range must be (lo, hi) with lo < hi, got {elevation_range!r}")
    if projection == "cylindrical":
        if not (-90.0 < lo and hi < 90.0):
            raise ValueError(
                f"elevation_range must lie inside (-90, 90) degrees for a cylindrical "
                f"panorama, got {elevation_range!r}"
            )
    elif not (-90.0 <= lo and hi <= 90.0):
        raise ValueError(
            f"elevation_range must lie inside [-90, 90] degrees, got {elevation_range!r}"
        )
    return lo, hi


# -- the band a mirror sees ---------------------------------------------------------------------
@functools.lru_cache(maxsize=8)
def _rim_directions_of(mirror: Mirror, centre_bytes: bytes, n: int) -> FloatArray:
    """Reflected directions of ``n`` rim points (eqs. 14-15 at the rim), mirror frame.

    They depend on the mirror and the camera centre only; the last few rigs' are kept (every
    table needs them, and they cost about as much as a small table).
    """
    P = mirror.rim_points(n)
    V = P - np.frombuffer(centre_bytes, dtype=np.float64)
    V /= np.linalg.norm(V, axis=1, keepdims=True)
    nrm = mirror.unit_normal(P)
    out = mirror.reflect(V, nrm)
    out.flags.writeable = False
    return out


def _rim_band(camera: CameraLike) -> tuple[float, float, bool]:
    """``(lowest, highest)`` elevation of the rim's reflected directions (degrees,
    :func:`_rim_directions_of`) and whether the nadir is seen (:func:`_nadir_seen`); the last
    few rigs' are kept."""
    m = camera.mirror
    C = np.asarray(camera.camera_center, dtype=np.float64)
    return _rim_band_of(m, C.tobytes())


@functools.lru_cache(maxsize=8)
def _rim_band_of(mirror: Mirror, centre_bytes: bytes, n: int = 3600) -> tuple[float, float, bool]:
    rim_dirs = _rim_directions_of(mirror, centre_bytes, n)
    el = _elevation_deg(rim_dirs)
    centre = np.frombuffer(centre_bytes, dtype=np.float64)
    nadir = bool(_nadir_seen(mirror.vertex_z, centre, rim_dirs))
    return float(np.min(el)), float(np.max(el)), nadir


def _elevation_deg(d: FloatArray) -> FloatArray:
    return np.degrees(np.arctan2(d[..., 2], np.hypot(d[..., 0], d[..., 1])))


def _nadir_seen(vertex_z: float, camera_center: FloatArray, rim_dirs: FloatArray) -> bool:
    """Whether the straight-down direction (0, 0, -1) is among those the mirror shows.

    The cap maps one-to-one onto the directions it shows, so these are the region bounded by
    the closed curve of rim rays that contains the ray of the apex. The nadir is in it when that
    curve winds around the mirror axis and the apex ray lies below the whole curve.
    """
    V = np.array([0.0, 0.0, vertex_z]) - camera_center
    apex_ray = np.array([V[0], V[1], -V[2]])  # reflection about the apex normal (0, 0, -1)
    az = np.arctan2(rim_dirs[:, 1], rim_dirs[:, 0])
    turns = np.diff(np.append(az, az[0]))
    turns = (turns + np.pi) % (2.0 * np.pi) - np.pi
    winding = int(round(float(turns.sum()) / (2.0 * np.pi)))
    return abs(winding) == 1 and float(_elevation_deg(apex_ray)) < float(
        np.min(_elevation_deg(rim_dirs))
    )


def visible_elevation_range(camera: CameraLike) -> tuple[float, float]:
    """The band of elevations the mirror sees, ``(lo, hi)`` in degrees, mirror frame.

    ``hi`` is the highest elevation of the rays of the rim (the reflected directions of the rim
    circle, eqs. 14-15): the map from the mirror cap to directions has no interior maximum of
    elevation, so the highest direction seen is a rim ray. ``lo`` is -90 when the nadir is
    seen (it is, for any rig with the camera below the mirror near its axis), else the lowest
    rim ray. For a misaligned rig the upper edge of what is seen varies with azimuth; the band
    is the union over azimuths, so some pixels near ``hi`` are unseen at some azimuths.
    """
    _check_camera(camera)
    lowest, hi, nadir = _rim_band(camera)
    lo = -90.0 if nadir else lowest
    return lo, hi


def camera_reflection_elevation(
    camera: CameraLike,
    R: ArrayLike | None = None,
    depth: float | None = None,
    viewpoint: ArrayLike | None = None,
    margin_px: float = REFLECTION_MARGIN_PX,
    n: int = 360,
) -> float | None:
    """The highest elevation at which the camera's own reflection shows, in degrees.

    The reflection is that of the circle ``camera.camera_reflection = (r, z)`` (radius ``r`` at
    the axial distance ``z`` in the camera frame; docs/conventions.md, "The camera's own
    reflection"). ``n`` points of it are projected exactly (:meth:`project`: the pixels of its
    outline), moved ``margin_px`` source pixels outwards (away from the outline's centre) and
    traced back (:meth:`unproject`). The elevation of each ray is taken as a panorama with the
    same ``R``, ``depth`` and ``viewpoint`` sees it (:func:`init_panorama_maps`): of its
    direction for ``depth=None``, else of the point where it meets the sphere of radius
    ``depth`` about ``viewpoint``. Below the highest of them the panorama may show the camera
    at some azimuth; above it, at none.

    Parameters
    ----------
    camera : MisalignedHyperbolicCamera
    R, depth, viewpoint
        As for :func:`init_panorama_maps` (``viewpoint=None``: the best-fit viewpoint).
    margin_px : float
        Source pixels beyond the outline (``REFLECTION_MARGIN_PX``).
    n : int
        Points along the circle.

    Returns
    -------
    float or None
        None when the camera's reflection is unknown (``camera_reflection`` None), or when
        part of its outline (with the margin) does not see the mirror or, for a finite
        ``depth``, its rays do not reach the sphere.
    """
    _check_camera(camera)
    Rm = np.eye(3) if R is None else _check_rotation(R)
    depth = _check_depth(depth)
    vp = _check_viewpoint(camera, viewpoint, depth)
    margin = real_number(margin_px, "margin_px", 0.0, expected="a number of pixels >= 0")
    if isinstance(n, bool) or not isinstance(n, numbers.Integral) or n < 8:
        raise ValueError(f"n must be an integer >= 8 (points along the circle), got {n!r}")
    return _reflection_top(camera, Rm, depth, vp, margin, int(n))


def _reflection_top(
    camera: CameraLike,
    Rm: FloatArray,
    depth: float | None,
    vp: FloatArray | None,
    margin_px: float,
    n: int = 360,
) -> float | None:
    """:func:`camera_reflection_elevation` of checked arguments."""
    body = getattr(camera, "camera_reflection", None)
    if body is None:
        return None
    r, z = (float(v) for v in body)
    t = np.linspace(0.0, 2.0 * np.pi, n, endpoint=False)
    circle = np.stack([r * np.cos(t), r * np.sin(t), np.full(n, z)], axis=1)  # camera frame
    X = (circle - np.asarray(camera.tvec)) @ np.asarray(camera.R)  # R^T (X_cam - t): mirror
    u = np.asarray(camera.project(X), dtype=np.float64)
    if not np.isfinite(u).all():
        return None
    out = u - u.mean(axis=0)
    out /= np.linalg.norm(out, axis=1, keepdims=True)
    P, V = camera.unproject(u + margin_px * out)
    if not np.isfinite(V).all():
        return None
    if depth is None:
        d = V
    else:
        assert vp is not None, "_check_viewpoint gives a viewpoint with every depth"
        w = P - vp  # |w + s V| = depth, the far root (the ray leaves from inside the sphere)
        b = np.einsum("ij,ij->i", w, V)
        disc = b * b - (np.einsum("ij,ij->i", w, w) - depth * depth)
        if np.any(disc < 0.0):
            return None
        s = -b + np.sqrt(disc)
        if np.any(s <= 0.0):
            return None
        d = w + s[:, None] * V
    return float(np.max(_elevation_deg(d @ Rm.T)))  # R d: the panorama's frame


class DefaultElevationRange(NamedTuple):
    """The default band of a panorama (:func:`default_elevation_range`): ``(lo, hi)`` in
    degrees and, in a short phrase, where ``lo`` came from (one of the ``LOWER_EDGE_*``)."""

    lo: float
    hi: float
    lower_edge: str

    def describe(self) -> str:
        """``"lower edge -38.2 deg: the camera's reflection as detected"``."""
        return f"lower edge {self.lo:.1f} deg: {self.lower_edge}"


def default_elevation_range(
    camera: CameraLike,
    projection: str = "cylindrical",
    R: ArrayLike | None = None,
    depth: float | None = None,
    viewpoint: ArrayLike | None = None,
) -> DefaultElevationRange:
    """The band a panorama covers when its ``elevation_range`` is None.

    ``hi`` is the top of what the mirror sees (:func:`visible_elevation_range`; at most 89 deg
    for ``"cylindrical"``). ``lo`` leaves out the camera's own reflection: with the camera's
    reflection known (``camera.camera_reflection``, as a calibration detected it) it is the
    highest elevation of its outline, ``REFLECTION_MARGIN_PX`` source pixels outwards, as this
    panorama sees it (:func:`camera_reflection_elevation`), for ``"cylindrical"`` at least
    ``CYLINDRICAL_MIN_ELEVATION`` (-60 deg: its rows stretch as ``tan(elevation)``); without
    it, ``CYLINDRICAL_MIN_ELEVATION``. Never below what the mirror sees.

    Parameters
    ----------
    camera : MisalignedHyperbolicCamera
    projection, R, depth, viewpoint
        As for :func:`init_panorama_maps`.

    Returns
    -------
    DefaultElevationRange
        ``(lo, hi, lower_edge)``.

    Raises
    ------
    ValueError
        Bad ``projection``, ``R``, ``depth`` or ``viewpoint``, or no usable band (``lo`` not
        below ``hi``).
    """
    _check_camera(camera)
    if projection not in PROJECTIONS:
        raise ValueError(f"projection must be one of {PROJECTIONS}, got {projection!r}")
    Rm = np.eye(3) if R is None else _check_rotation(R)
    depth = _check_depth(depth)
    return _default_range(camera, projection, Rm, depth, _check_viewpoint(camera, viewpoint, depth))


def _default_range(
    camera: CameraLike,
    projection: str,
    Rm: FloatArray,
    depth: float | None,
    vp: FloatArray | None,
) -> DefaultElevationRange:
    """:func:`default_elevation_range` of checked arguments."""
    lo, hi = visible_elevation_range(camera)
    if projection == "cylindrical":
        hi = min(hi, 89.0)
    top = _reflection_top(camera, Rm, depth, vp, REFLECTION_MARGIN_PX)
    if top is None:  # unknown: -60 deg, as before the camera's reflection was recorded
        top, why = CYLINDRICAL_MIN_ELEVATION, LOWER_EDGE_FIXED
    elif top >= hi:
        top, why = CYLINDRICAL_MIN_ELEVATION, LOWER_EDGE_ABOVE
    elif projection == "cylindrical" and top < CYLINDRICAL_MIN_ELEVATION:
        top, why = CYLINDRICAL_MIN_ELEVATION, LOWER_EDGE_FLOOR
    else:
        why = LOWER_EDGE_REFLECTION
    lo, why = (top, why) if top > lo else (lo, LOWER_EDGE_MIRROR)
    if not (math.isfinite(lo) and math.isfinite(hi) and lo < hi):
        raise ValueError(
            f"elevation_range: the band this camera sees, ({lo}, {hi}) deg, "
            f"is not a usable default for a {projection} panorama; give one"
        )
    return DefaultElevationRange(lo, hi, why)


# -- the fast path: the phases of omnicam._kernels -----------------------------------------------
#: Angular size of a coarse cell, degrees: the node spacing is the multiple of 4 output pixels
#: (between 8 and 64) closest to it. Cells whose measured interpolation error exceeds
#: TOLERANCE / 2 are refined on a grid 2 times finer, and sub-cells that still fail are computed
#: exactly pixel by pixel, so this only trades speed, never accuracy.
CELL_DEGREES = 5.0


def _step_for(deg_per_px: float) -> int:
    """Node spacing (pixels, a multiple of 4 in [8, 64]) of cells about CELL_DEGREES wide."""
    n = CELL_DEGREES / max(float(deg_per_px), 1e-9)
    return int(min(64, max(8, 4 * round(n / 4))))


#: Every float table entry is within this many pixels of the exact non-central projection.
TOLERANCE = 0.01

_KIND = {"perspective": 0, "cylindrical": 1, "equirectangular": 2}


def _tilt_matrix(tau_x: float, tau_y: float) -> FloatArray:
    """OpenCV's ``computeTiltProjectionMatrix`` (the tau_x, tau_y of a 14-value ``D``)."""
    cx, sx, cy, sy = math.cos(tau_x), math.sin(tau_x), math.cos(tau_y), math.sin(tau_y)
    rot_x = np.array([[1.0, 0.0, 0.0], [0.0, cx, sx], [0.0, -sx, cx]])
    rot_y = np.array([[cy, 0.0, -sy], [0.0, 1.0, 0.0], [sy, 0.0, cy]])
    rot_xy: FloatArray = rot_y @ rot_x
    proj_z = np.array(
        [[rot_xy[2, 2], 0.0, -rot_xy[0, 2]], [0.0, rot_xy[2, 2], -rot_xy[1, 2]], [0.0, 0.0, 1.0]]
    )
    return proj_z @ rot_xy


def _cap_radius(camera: CameraLike, viewpoint: FloatArray) -> float:
    """An upper bound of the distance from ``viewpoint`` to any point of the mirror cap."""
    m = camera.mirror
    r = np.linspace(0.0, m.rim_radius, 33)[:, None]
    t = np.linspace(0.0, 2.0 * np.pi, 96, endpoint=False)[None, :]
    X, Y = r * np.cos(t), r * np.sin(t)
    P = np.stack([X, Y, m.surface_z(X, Y)], axis=-1).reshape(-1, 3)
    # grid spacing <= rim_radius * 2 pi / 96 along the rim: add it as slack
    return float(np.linalg.norm(P - viewpoint, axis=1).max()) + m.rim_radius * 0.07


def _reject_sines(
    camera: CameraLike, depth: float | None, viewpoint: FloatArray | None
) -> tuple[float, float]:
    """Sines of the elevation above which nothing is seen, and above which nodes are not solved.

    At infinity nothing above the highest rim ray is seen (:func:`visible_elevation_range`).
    A point at distance ``depth > rho`` from the viewpoint, ``rho`` bounding the distance to any
    mirror point, is seen along a ray within ``asin(rho / depth)`` of its direction from the
    viewpoint, so its elevation from there is at most ``hi + asin(rho / depth)``.
    """
    hi = _rim_band(camera)[1]
    limit = hi + 0.5  # slack for the rim sampling
    if depth is not None:
        assert viewpoint is not None, "_check_viewpoint gives a viewpoint with every depth"
        rho = _cap_radius(camera, viewpoint)
        if depth <= rho * 1.001:
            return 2.0, 2.0
        limit += math.degrees(math.asin(rho / depth))
    if limit >= 90.0:
        return 2.0, 2.0
    return math.sin(math.radians(limit)), math.sin(math.radians(min(limit + 30.0, 89.5)))


def _rig_args(camera: CameraLike) -> RigArgs:
    """:class:`omnicam._kernels.RigArgs` of a camera: float64 C-contiguous writable copies (the
    kernels' one signature; numba types read-only arrays apart)."""
    D = camera.D
    dist = np.zeros(14)
    tilt = np.eye(3)
    if D is not None:
        dist[: D.size] = D
        if D.size == 14:
            tilt = _tilt_matrix(D[12], D[13])
    m = camera.mirror
    return RigArgs(
        _arg(camera.camera_center),
        _arg(camera.R),
        _arg(camera.tvec),
        m.kernel_params(),
        _arg(camera.K),
        dist,
        tilt,
        D is not None,
    )


def _view_args(
    camera: CameraLike,
    kind: int,
    A: FloatArray,
    p0: float,
    p1: float,
    az_step: float,
    depth: float | None,
    viewpoint: FloatArray | None,
) -> ViewArgs:
    """:class:`omnicam._kernels.ViewArgs` of a view (see :func:`_table`)."""
    sin_reject, sin_try = _reject_sines(camera, depth, viewpoint)
    m = camera.mirror
    return ViewArgs(
        int(kind),
        _arg(A),
        float(p0),
        float(p1),
        float(az_step),
        depth is None,
        0.0 if depth is None else float(depth),
        np.zeros(3) if viewpoint is None else _arg(viewpoint),
        float(sin_reject),
        float(sin_try),
        NEWTON_TOL_REL * float(m.length_scale),
    )


def _table(
    camera: CameraLike,
    kind: int,
    A: FloatArray,
    p0: float,
    p1: float,
    az_step: float,
    size: Size,
    depth: float | None,
    viewpoint: FloatArray | None,
    m1type: int,
    step: int | None = None,
    stats: _IntArray | None = None,
) -> Maps:
    """Build the table of a view (:func:`_build_table`) and return the maps for ``m1type``.

    ``kind, A, p0, p1, az_step`` define the output directions
    (:func:`omnicam._kernels._view_direction`), ``step`` the node spacing (a multiple of 4;
    by default from ``CELL_DEGREES``), ``stats`` (9,) int64 receives the counts of
    :func:`_build_table`.
    """
    w, h = size
    if step is None:
        if kind == 0:
            deg = CELL_DEGREES / 32.0  # callers pass the step of a perspective view
        else:  # p1: tan(elevation) or elevation per row, the largest angle per row either way
            deg = max(360.0 / w, math.degrees(abs(p1)))
        step = _step_for(deg)
    step = int(step)
    if step < 4 or step % 4:
        raise ValueError(f"step must be a multiple of 4, got {step}")
    view = _view_args(camera, kind, A, p0, p1, az_step, depth, viewpoint)
    rig = _rig_args(camera)
    # both maps are views of one buffer: numpy asks the kernel for transparent huge pages from
    # 4 MiB on, which spares the page faults of first writing a fresh table (~2 ms of a 1024x768
    # one otherwise)
    if m1type == cv2.CV_16SC2:
        mode = 1
        outx = outy = np.empty((1, 1), np.float32)
        buf = np.empty(h * w * 6, np.uint8)
        out16 = buf[: h * w * 4].view(np.int16).reshape(h, w, 2)
        outf16 = buf[h * w * 4 :].view(np.uint16).reshape(h, w)
    else:
        mode = 0
        outx, outy = np.empty((2, h, w), np.float32)
        out16 = np.empty((1, 1, 2), np.int16)
        outf16 = np.empty((1, 1), np.uint16)
    st = np.zeros(9, np.int64) if stats is None else stats
    _build_table(view, rig, (w, h), step, mode, (outx, outy, out16, outf16), st)
    if mode == 1:
        return out16, outf16
    if m1type == cv2.CV_32FC2:
        return cv2.merge([outx, outy]), None
    return outx, outy


def _arg(x: ArrayLike) -> FloatArray:
    """A writable C-contiguous float64 copy (the kernels' one signature)."""
    return np.array(x, dtype=np.float64, order="C", copy=True)


class _GridStack:
    """G node grids of one shape and spacing with their check points, solved and classified.

    The coarse grid of a table (G = 1) or the refined grids of its failing cells; see the
    section comment of :mod:`omnicam._kernels`. ``S``, ``P``, ``node_margins``: (G, NY, NX, 2)
    mirror points, pixels and margins of the nodes; ``cls`` (G, ny, nx) the cells' classes.
    """

    def __init__(
        self,
        view: ViewArgs,
        rig: RigArgs,
        origins: FloatArray,
        spacing: float,
        shape: tuple[int, int],
        coarse: _GridStack | None = None,
        cells: _IntArray | None = None,
    ) -> None:
        ny, nx = shape
        self.origins, self.spacing = origins, spacing
        refined = cells is not None
        positions, starts = _grid_nodes(origins, spacing, shape, coarse, cells)
        self.S, self.P, self.node_margins, _ok, _e = _solve(view, rig, positions, starts)
        positions, starts, interpolated = _grid_checks(origins, spacing, self.S, self.P)
        # the pixels of the interpolated mirror points only where EDGE cells can be (refined
        # grids, classify's allow_edge); the coarse grid's mirror errors stay inf, unused
        _S, _P, self.check_margins, _ok, errors = _solve(
            view, rig, positions, starts, estimates=interpolated, with_mirror_error=refined
        )
        assert errors is not None, "_solve gives the errors of estimates"
        self.pixel_error = errors[..., 0]
        self.mirror_error = errors[..., 1]

    def classify(self, view: ViewArgs, size: Size, half_tol: float, allow_edge: bool) -> _IntArray:

        G, _w, ny1, nx1 = self.pixel_error.shape
        self.cls = np.empty((G, ny1 - 1, nx1 - 1), np.int64)
        grid = GridMargins(
            self.origins,
            self.spacing,
            self.node_margins,
            self.check_margins,
            np.ascontiguousarray(self.pixel_error),
            np.ascontiguousarray(self.mirror_error),
        )
        _kernels.classify_cells(view, grid, size[0], size[1], half_tol, allow_edge, self.cls)
        return self.cls

    def n_solved(self) -> tuple[int, int]:
        """Nodes and check points with a solution."""
        return (
            int(np.count_nonzero(self.node_margins[..., 0] > -np.inf)),
            int(np.count_nonzero(self.check_margins[..., 0] > -np.inf)),
        )


def _lagrange4(t: Any) -> tuple[Any, Any, Any, Any]:
    """Cubic Lagrange weights of nodes at -1, 0, 1, 2: the operations of
    :func:`omnicam._kernels._lagrange4` in the same order, so the same bits."""
    return (
        -t * (t - 1.0) * (t - 2.0) / 6.0,
        (t + 1.0) * (t - 1.0) * (t - 2.0) / 2.0,
        -(t + 1.0) * t * (t - 2.0) / 2.0,
        (t + 1.0) * t * (t - 1.0) / 6.0,
    )


def _cubic_weights(tv: float, tu: float) -> list[np.float64]:
    """Row and column weights of the cell coordinates (tv, tu), a row of ``cubic_blocks``'
    ``weights``."""
    return [*_lagrange4(np.float64(tv)), *_lagrange4(np.float64(tu))]


@functools.lru_cache(maxsize=16)
def _node_blocks(NY: int, NX: int) -> tuple[_IntArray, FloatArray]:
    """``cubic_blocks``' blocks and weights of the Newton starts of a refined grid's nodes:
    node (p, q) is the cubic of the refined coarse cell at ((p - 1) / FINE, (q - 1) / FINE)."""
    blocks = [(p, p + 1, q, q + 1, -p, -q) for p in range(NY) for q in range(NX)]
    weights = [
        _cubic_weights((p - 1.0) / FINE, (q - 1.0) / FINE) for p in range(NY) for q in range(NX)
    ]
    return np.array(blocks, np.int64), np.array(weights)


def _grid_nodes(
    origins: FloatArray,
    spacing: float,
    shape: tuple[int, int],
    coarse: _GridStack | None,
    cells: _IntArray | None,
) -> tuple[FloatArray, FloatArray]:
    """Output positions and Newton starts of the nodes of a grid stack, (G, NY, NX, 2) each.

    Grid ``c`` has node (p, q) at output pixel ``origins[c] + ((q - 1) spacing,
    (p - 1) spacing)``. A refined grid (``cells`` (G, 2): the coarse cell (row, column) it
    refines, FINE times finer) starts Newton from the ``coarse`` grid's cubic; the coarse grid
    (``cells`` None) has no start (NaN).
    """
    G = origins.shape[0]
    NY, NX = shape[0] + 3, shape[1] + 3
    positions = np.empty((G, NY, NX, 2))
    positions[..., 0] = origins[:, 0, None, None] + ((np.arange(NX) - 1.0) * spacing)[None, None]
    positions[..., 1] = origins[:, 1, None, None] + ((np.arange(NY) - 1.0) * spacing)[None, :, None]
    starts = np.full((G, NY, NX, 2), np.nan)
    if cells is not None and G:
        assert coarse is not None, "refined grids start from the coarse one"
        blocks, weights = _node_blocks(NY, NX)
        cubic_blocks(cells, blocks, weights, coarse.S, starts)
    return positions, starts


@functools.lru_cache(maxsize=16)
def _check_layout(ny: int, nx: int) -> tuple[_IntArray, FloatArray, FloatArray, FloatArray]:
    """Where the check points of a grid of ny x nx cells lie, in ``cubic_blocks``' terms.

    Check point (which, r, k), rows ``which (ny + 1) + r`` of a (3 (ny + 1), nx + 1) layout:
    ``which`` CHECK_CENTRE: centre of cell (r, k); CHECK_HORIZONTAL_EDGE: middle of the
    horizontal edge above cell (r, k) (r = ny: below the last row); CHECK_VERTICAL_EDGE:
    middle of the vertical edge left of it (k = nx: right of the last column). Returns
    ``blocks, weights`` and the output offsets ``(x, y)`` (3, ny + 1, nx + 1) of each check
    point in cells (``(cell column + tu, cell row + tv)``; NaN for the combinations that name
    no edge, never solved).
    """
    x = np.full((3, ny + 1, nx + 1), np.nan)
    y = np.full((3, ny + 1, nx + 1), np.nan)
    blocks, weights = [], []
    # (which, rows r0:r1 and columns k0:k1, the cell's offset from (r, k) (the last edge lies
    # in the last cell), the cell coordinates (tv, tu))
    for which, r0, r1, k0, k1, dr, dk, tv, tu in (
        (CHECK_CENTRE, 0, ny, 0, nx, 0, 0, 0.5, 0.5),
        (CHECK_HORIZONTAL_EDGE, 0, ny, 0, nx, 0, 0, 0.0, 0.5),
        (CHECK_HORIZONTAL_EDGE, ny, ny + 1, 0, nx, -1, 0, 1.0, 0.5),
        (CHECK_VERTICAL_EDGE, 0, ny, 0, nx, 0, 0, 0.5, 0.0),
        (CHECK_VERTICAL_EDGE, 0, ny, nx, nx + 1, 0, -1, 0.5, 1.0),
    ):
        row0 = which * (ny + 1)
        blocks.append((row0 + r0, row0 + r1, k0, k1, dr - row0, dk))
        weights.append(_cubic_weights(tv, tu))
        x[which, r0:r1, k0:k1] = (np.arange(k0, k1) + dk + tu)[None, :]
        y[which, r0:r1, k0:k1] = (np.arange(r0, r1) + dr + tv)[:, None]
    return np.array(blocks, np.int64), np.array(weights), x, y


def _grid_checks(
    origins: FloatArray, spacing: float, S: FloatArray, P: FloatArray
) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Check points of a grid stack (:func:`_check_layout`): output positions, Newton starts
    (the cubic of the nodes' mirror points ``S``) and estimates (the cubic of their pixels
    ``P``), (G, 3, ny + 1, nx + 1, 2) each, NaN where no check point is."""
    G, NY, NX, _two = S.shape
    ny, nx = NY - 3, NX - 3
    blocks, weights, x, y = _check_layout(ny, nx)
    shape = (G, 3, ny + 1, nx + 1, 2)
    positions = np.empty(shape)
    positions[..., 0] = origins[:, 0, None, None, None] + x * spacing
    positions[..., 1] = origins[:, 1, None, None, None] + y * spacing
    starts = np.full(shape, np.nan)
    estimates = np.full(shape, np.nan)
    if G:
        layout = (G, 3 * (ny + 1), nx + 1, 2)
        offsets = np.zeros((G, 2), np.int64)
        cubic_blocks(offsets, blocks, weights, S, starts.reshape(layout))
        cubic_blocks(offsets, blocks, weights, P, estimates.reshape(layout))
    return positions, starts, estimates


def _solve(
    view: ViewArgs,
    rig: RigArgs,
    positions: FloatArray,
    starts: FloatArray,
    pixels_only: bool = False,
    estimates: FloatArray | None = None,
    with_mirror_error: bool = False,
) -> tuple[FloatArray, FloatArray, FloatArray, npt.NDArray[np.bool_], FloatArray | None]:
    """:func:`omnicam._kernels.solve_view_points` over arrays of positions (..., 2): the mirror
    points, pixels, margins and ok of each, and the errors (..., 2) of check points'
    ``estimates`` (pixel error, mirror error) (None without estimates)."""
    shape = positions.shape[:-1]
    n = int(np.prod(shape))
    ok = np.zeros(shape, np.bool_)
    S = np.empty(shape + (2,))
    P = np.empty(shape + (2,))
    margins = np.empty(shape + (3,))
    checks = estimates is not None
    if estimates is None:
        estimates = errors = np.empty((0, 2))
    else:
        errors = np.empty(shape + (2,))
    points = ViewPoints(
        positions.reshape(-1, 2),
        starts.reshape(-1, 2),
        estimates.reshape(-1, 2),
        pixels_only,
        with_mirror_error,
    )
    out = Solutions(
        ok.reshape(-1),
        S.reshape(-1, 2),
        P.reshape(-1, 2),
        margins.reshape(-1, 3),
        errors.reshape(-1, 2),
    )
    run_chunks(_kernels.solve_view_points, n, view, rig, points, out, min_chunk=32)
    return S, P, margins, ok, errors if checks else None


def _build_table(
    view: ViewArgs,
    rig: RigArgs,
    size: Size,
    step: int,
    mode: int,
    outputs: _Outputs,
    stats: _IntArray,
) -> None:
    """The phases of a table (section comment of :mod:`omnicam._kernels`), writing ``outputs``.

    ``stats`` (9,) int64 receives: nodes and check points solved, coarse cells seen / unseen /
    edge / refined, refined sub-cells left to exact pixels, pixels solved exactly, entries
    written unseen.
    """
    notice_if_cold(_kernels.solve_view_points, _kernels.fill_rows)
    w, h = size
    ny, nx = (h + step - 1) // step, (w + step - 1) // step
    half_tol = 0.5 * TOLERANCE
    coarse = _GridStack(view, rig, np.zeros((1, 2)), float(step), (ny, nx))
    cls = coarse.classify(view, size, half_tol, False)[0]
    # refine the failing cells on grids FINE times finer (own nodes, checks and classes)
    # C order as every other array the kernels take (np.argwhere's is F: a second signature
    # of each grid kernel, compiled cold and loaded warm)
    cells = np.ascontiguousarray(np.argwhere(cls == _kernels.CELL_BAD), dtype=np.int64)
    refined_index = np.full((ny, nx), -1, np.int64)
    refined_index[cells[:, 0], cells[:, 1]] = np.arange(len(cells))
    fine = _GridStack(
        view,
        rig,
        np.ascontiguousarray(cells[:, ::-1] * step, dtype=np.float64),
        float(step // _kernels.FINE),
        (_kernels.FINE, _kernels.FINE),
        coarse,
        cells,
    )
    fine_cls = fine.classify(view, size, half_tol, True)
    # the pixels: interpolated, unseen, decided at the edge, or pending an exact solution
    # the cubic weights of the node columns per column offset in a cell and in a refined
    # sub-cell, and the panoramas' per-column cos / sin of the azimuth (as _view_direction)
    weights = np.array(_lagrange4(np.arange(step) / step))
    fine_weights = np.array(_lagrange4(np.arange(step // _kernels.FINE) / (step // _kernels.FINE)))
    azimuth = view.az_step * np.arange(w)
    column_cos, column_sin = np.cos(azimuth), np.sin(azimuth)
    pending = np.zeros((h, w), np.bool_)  # bool: numpy's nonzero is ten times faster than on uint8
    row_counts = np.empty((h, 2), np.int64)  # pending and unseen entries per row
    outx, outy, out16, outf16 = outputs
    grids = TableGrids(
        cls,
        refined_index,
        coarse.P[0],
        fine.S,
        fine.P,
        fine_cls,
        column_cos,
        column_sin,
        weights,
        fine_weights,
    )
    out = TableOutputs(mode, outx, outy, out16, outf16, pending, row_counts)
    run_chunks(_kernels.fill_rows, h, view, rig, grids, out, min_chunk=16)
    rows = np.flatnonzero(row_counts[:, 0])
    q = np.flatnonzero(pending[rows])
    index = rows[q // w] * w + q % w
    positions = np.stack([index % w, index // w], axis=1).astype(np.float64)
    n_unseen = int(row_counts[:, 1].sum())
    if len(index):
        # no start of the pixels' own (NaN): Newton from the aligned start
        P = _solve(view, rig, positions, np.full_like(positions, np.nan), pixels_only=True)[1]
        n_unseen += _store_entries(index, P, mode, outputs)
    n_nodes, n_checks = coarse.n_solved()
    f_nodes, f_checks = fine.n_solved()
    stats[0] = n_nodes + f_nodes
    stats[1] = n_checks + f_checks
    stats[2:6] = [
        np.count_nonzero(cls == c)
        for c in (_kernels.CELL_SEEN, _kernels.CELL_UNSEEN, _kernels.CELL_EDGE, _kernels.CELL_BAD)
    ]
    stats[6] = np.count_nonzero(fine_cls == _kernels.CELL_BAD)
    stats[7] = len(index)
    stats[8] = n_unseen


def _store_entries(index: _IntArray, P: FloatArray, mode: int, outputs: _Outputs) -> int:
    """Write the solved entries ``P`` (n, 2) of the pixels ``index`` (flat) into ``outputs``
    as fill_rows' ``_row_store`` does: NaN as ``UNSEEN``, float32 maps (mode 0) or
    ``cv2.convertMaps``' CV_16SC2 fixed point of them (mode 1; fill_rows' in-loop
    ``_row_fixed`` gives the same bits). Returns how many were unseen."""
    outx, outy, out16, outf16 = outputs
    unseen = np.isnan(P).any(axis=1)
    fx = np.where(unseen, UNSEEN, P[:, 0]).astype(np.float32)
    fy = np.where(unseen, UNSEEN, P[:, 1]).astype(np.float32)
    if mode == 0:
        outx.reshape(-1)[index] = fx
        outy.reshape(-1)[index] = fy
        return int(np.count_nonzero(unseen))
    fixed, fraction = cv2.convertMaps(fx[None], fy[None], cv2.CV_16SC2)
    out16.reshape(-1, 2)[index] = fixed[0]
    outf16.reshape(-1)[index] = fraction[0]
    return int(np.count_nonzero(unseen))


def _panorama_params(
    size: Size, lo: float, hi: float, projection: str
) -> tuple[float, float, float]:
    w, h = size
    if projection == "cylindrical":
        p0 = math.tan(math.radians(hi))
        p1 = (math.tan(math.radians(lo)) - p0) / (h - 1)
    else:
        p0 = math.radians(hi)
        p1 = (math.radians(lo) - p0) / (h - 1)
    return p0, p1, -2.0 * math.pi / w


# -- public API ---------------------------------------------------------------------------------
def init_panorama_maps(
    camera: CameraLike,
    size: Size,
    elevation_range: tuple[float, float] | None = None,
    projection: str = "cylindrical",
    R: ArrayLike | None = None,
    m1type: int = cv2.CV_16SC2,
    depth: float | None = None,
    viewpoint: ArrayLike | None = None,
) -> Maps:
    """``cv2.remap`` tables of a 360-degree panorama (paper section 4.1, Fig. 7).

    Column ``j`` looks at azimuth ``-360 j / W`` degrees (measured in the panorama frame from +X
    towards +Y, so the panorama turns right as ``j`` grows); row 0 is elevation ``hi``, row
    ``H - 1`` is ``lo``; rows are linear in ``tan(elevation)`` (``"cylindrical"``) or in
    elevation (``"equirectangular"``). A panorama direction ``d`` is ``R^T d`` in the mirror
    frame. Each entry is the exact non-central projection (to 0.01 px) of that direction
    (``depth=None``) or of the point at distance ``depth`` from ``viewpoint`` along it.

    Parameters
    ----------
    camera : MisalignedHyperbolicCamera
        The calibrated rig, or ``MisalignedHyperbolicCamera.aligned(...)`` for the paper's
        uncalibrated baseline (eqs. 2-5).
    size : (int, int)
        ``(W, H)`` of the panorama, ``H >= 2``.
    elevation_range : (float, float) or None
        ``(lo, hi)`` in degrees, ``lo < hi``, inside (-90, 90) for ``"cylindrical"`` and
        [-90, 90] for ``"equirectangular"``. ``None``: the band the mirror sees
        (:func:`visible_elevation_range`) above the camera's own reflection
        (:func:`default_elevation_range`): above its outline as this panorama sees it when
        ``camera.camera_reflection`` is known (a calibration that detected it records it),
        else from ``CYLINDRICAL_MIN_ELEVATION`` (-60 deg). A given range always wins.
    projection : {"cylindrical", "equirectangular"}
    R : (3, 3) array_like or None
        Rotation of the panorama frame (as for perspective views); ``None`` is the identity,
        which puts the panorama's up axis on the mirror axis.
    m1type : int
        ``cv2.CV_16SC2`` (default), ``cv2.CV_32FC1`` or ``cv2.CV_32FC2``.
    depth : float or None
        ``None``: scene at infinity. A positive number: the sphere of that radius about
        ``viewpoint`` (same length unit as the mirror).
    viewpoint : (3,) array_like or None
        Mirror frame; ``None`` is the best-fit viewpoint (section 4.1). Unused when
        ``depth`` is None.

    Returns
    -------
    map1, map2 : ndarray
        As ``cv2.initUndistortRectifyMap`` returns them for ``m1type`` (``map2`` is None for
        ``CV_32FC2``). Output pixels the mirror does not see map to ``(UNSEEN, UNSEEN)``.

    Raises
    ------
    ValueError
        Naming the argument: malformed ``size``, unknown ``projection``, bad
        ``elevation_range``, ``R``, ``m1type``, ``depth`` or ``viewpoint``.

    Notes
    -----
    Float entries are within ``TOLERANCE`` (0.01 px) of the exact projection; ``CV_16SC2`` is
    that table rounded to OpenCV's 1/32 px grid exactly as ``cv2.convertMaps`` does. A pixel
    whose direction grazes the rim (its exact mirror point on the rim to ~1e-12) may be called
    seen or unseen either way. For the aligned rig the default ``hi`` is exactly the rim's
    elevation, so row 0 lies on the rim.
    """
    _check_camera(camera)
    w, h = _check_size(size, min_height=2)
    if projection not in PROJECTIONS:
        raise ValueError(f"projection must be one of {PROJECTIONS}, got {projection!r}")
    m1type = _check_m1type(m1type)
    Rm = np.eye(3) if R is None else _check_rotation(R)
    depth = _check_depth(depth)
    vp = _check_viewpoint(camera, viewpoint, depth)
    if elevation_range is None:  # above the camera's own reflection, else from -60 deg
        lo, hi, _ = _default_range(camera, projection, Rm, depth, vp)
    else:
        lo, hi = _check_elevation_range(elevation_range, projection)
    p0, p1, az_step = _panorama_params((w, h), lo, hi, projection)
    st = np.zeros(9, np.int64)
    maps = _table(
        camera, _KIND[projection], Rm.T, p0, p1, az_step, (w, h), depth, vp, m1type, stats=st
    )
    # a full-sphere panorama (a 360 video's frame) is black above the band by its format
    _warn_if_unseen(camera, st[8] / (w * h), "panorama" if hi - lo < 170.0 else "360 panorama")
    return maps


def init_perspective_maps(
    camera: CameraLike,
    K_new: ArrayLike,
    size: Size,
    R: ArrayLike | None = None,
    m1type: int = cv2.CV_16SC2,
    depth: float | None = None,
    viewpoint: ArrayLike | None = None,
) -> Maps:
    """``cv2.remap`` tables of a virtual perspective view (paper section 4.1, Fig. 8).

    Output pixel ``u`` looks along ``d = R^T K_new^-1 (u, v, 1)`` in the mirror frame; each
    entry is the exact non-central projection (to 0.01 px) of that direction (``depth=None``)
    or of the point at distance ``depth`` from ``viewpoint`` along it.

    Parameters
    ----------
    camera : MisalignedHyperbolicCamera
        The calibrated rig, or ``MisalignedHyperbolicCamera.aligned(...)`` for the paper's
        uncalibrated baseline (eqs. 2-5).
    K_new : (3, 3) array_like
        Camera matrix of the view (see :func:`K_from_fov`); skew allowed.
    size : (int, int)
        ``(width, height)`` of the view.
    R : (3, 3) array_like or None
        Rotation from the mirror frame into the view's camera frame, as the ``R`` of
        ``cv2.initUndistortRectifyMap`` (see :func:`rotation_from_ypr`); ``None`` is ``R0``,
        looking horizontally at azimuth 0 with image-up along +Z.
    m1type, depth, viewpoint
        As for :func:`init_panorama_maps`.

    Returns
    -------
    map1, map2 : ndarray
        As for :func:`init_panorama_maps`.

    Raises
    ------
    ValueError
        Naming the argument: malformed or singular ``K_new``, bad ``size``, ``R``,
        ``m1type``, ``depth`` or ``viewpoint``.

    Notes
    -----
    Accuracy and ``CV_16SC2`` as for :func:`init_panorama_maps`.
    """
    _refuse_swapped(K_new, size, "init_perspective_maps(camera, K_new, size, R=None, ...)")
    K_new = validate_K(K_new, "K_new")
    _check_camera(camera)
    w, h = _check_size(size)
    m1type = _check_m1type(m1type)
    Rm = R0 if R is None else _check_rotation(R)
    depth = _check_depth(depth)
    vp = _check_viewpoint(camera, viewpoint, depth)
    M = Rm.T @ np.linalg.inv(K_new)
    # a pixel at the principal point spans 1 / f radians (the most of any pixel of the view)
    step = _step_for(math.degrees(1.0 / min(abs(K_new[0, 0]), abs(K_new[1, 1]))))
    st = np.zeros(9, np.int64)
    maps = _table(camera, 0, M, 0.0, 0.0, 0.0, (w, h), depth, vp, m1type, step=step, stats=st)
    _warn_if_unseen(camera, st[8] / (w * h), "perspective view")
    return maps


def _is_matrix3(value: ArrayLike) -> bool:
    try:
        return np.shape(value) == (3, 3)
    except ValueError:  # ragged nesting
        return False


def _refuse_swapped(matrix_arg: Any, size_arg: Any, signature: str) -> None:
    """A clear ValueError when a camera matrix stands where the size goes (or vice versa)."""
    try:
        np.ndim(size_arg), np.ndim(matrix_arg)
    except ValueError:  # ragged nesting: the validators name the argument
        return
    if np.ndim(size_arg) == 2 and np.shape(size_arg) == (3, 3):
        raise ValueError(
            f"size: got a 3x3 matrix where (width, height) goes; the order is {signature}"
        )
    if np.ndim(matrix_arg) == 1 and np.shape(matrix_arg) == (2,) and np.ndim(size_arg) == 0:
        raise ValueError(f"got (width, height) first; the order is {signature}")


#: A view with more than this fraction of its pixels unseen gives a RuntimeWarning: half of a
#: perspective view or of a full-sphere panorama, a third of a panorama of a band.
UNSEEN_WARN_FRACTION = {"perspective view": 0.5, "panorama": 1.0 / 3.0, "360 panorama": 0.5}


def _warn_if_unseen(camera: CameraLike, frac: float, what: str) -> None:
    """RuntimeWarning when much of a view (the fraction ``frac`` of its entries unseen) lies
    outside the band the mirror sees, with the way back into it."""
    frac = float(frac)
    if frac > UNSEEN_WARN_FRACTION[what]:
        lo, hi = visible_elevation_range(camera)
        advice = (
            "narrow its elevation range to that band"
            if what.endswith("panorama")
            else "pitch it into that band, or narrow its field of view"
        )
        warnings.warn(
            f"{what}: {frac:.0%} of its pixels are outside what the mirror sees "
            f"(visible_elevation_range: {lo:.1f} to {hi:.1f} deg elevation); {advice}",
            RuntimeWarning,
            stacklevel=3,
        )


# -- view specs (what the Unwarper and the CLI hold) ----------------------------------------------
class PanoramaView:
    """A panorama spec, validated once: the arguments of :func:`init_panorama_maps`.

    Parameters
    ----------
    size : (int, int)
        ``(W, H)``, ``H >= 2``.
    elevation_range, projection, R, depth, viewpoint
        As for :func:`init_panorama_maps`.
    """

    __slots__ = ("size", "elevation_range", "projection", "R", "depth", "viewpoint")

    def __init__(
        self,
        size: Size,
        elevation_range: tuple[float, float] | None = None,
        projection: str = "cylindrical",
        R: ArrayLike | None = None,
        depth: float | None = None,
        viewpoint: ArrayLike | None = None,
    ) -> None:
        self.size = _check_size(size, min_height=2)
        if projection not in PROJECTIONS:
            raise ValueError(f"projection must be one of {PROJECTIONS}, got {projection!r}")
        self.projection = projection
        self.elevation_range = (
            None if elevation_range is None else _check_elevation_range(elevation_range, projection)
        )
        self.R = None if R is None else _check_rotation(R)
        self.depth = _check_depth(depth)
        self.viewpoint = (
            None
            if viewpoint is None
            else _check_viewpoint(None, viewpoint, 1.0 if depth is None else depth)
        )

    def default_range(self, camera: CameraLike) -> DefaultElevationRange | None:
        """The band this view covers for ``camera`` when its ``elevation_range`` is None
        (:func:`default_elevation_range`), else None (the given range)."""
        if self.elevation_range is not None:
            return None
        return default_elevation_range(camera, self.projection, self.R, self.depth, self.viewpoint)

    def maps(self, camera: CameraLike, m1type: int = cv2.CV_16SC2) -> Maps:
        """``(map1, map2)`` of this view for ``camera``."""
        return init_panorama_maps(
            camera,
            self.size,
            self.elevation_range,
            self.projection,
            self.R,
            m1type,
            self.depth,
            self.viewpoint,
        )

    def __repr__(self) -> str:
        return (
            f"PanoramaView(size={self.size}, elevation_range={self.elevation_range}, "
            f"projection={self.projection!r}, depth={self.depth})"
        )


class PerspectiveView:
    """A virtual perspective view spec, validated once (see :func:`init_perspective_maps`).

    Two forms: ``PerspectiveView(K_new, size, R=None, depth=None, viewpoint=None)``, the
    arguments in the order of :func:`init_perspective_maps` (a camera matrix first), or
    ``PerspectiveView(size, fov=90.0, yaw=0.0, pitch=0.0, roll=0.0, ...)`` for a view given by
    its field of view and direction.

    Parameters
    ----------
    size : (int, int)
        ``(width, height)`` (the second argument in the first form).
    fov : float
        Horizontal field of view in degrees (:func:`K_from_fov`); ignored if ``K_new`` is given.
    yaw, pitch, roll : float
        Degrees (:func:`rotation_from_ypr`); ignored if ``R`` is given.
    K_new, R : (3, 3) array_like, optional
        Explicit camera matrix and rotation instead.
    depth, viewpoint
        As for :func:`init_perspective_maps`.
    """

    __slots__ = ("size", "K_new", "R", "depth", "viewpoint")

    def __init__(
        self,
        size: Any,
        fov: Any = 90.0,
        yaw: Any = 0.0,
        pitch: float = 0.0,
        roll: float = 0.0,
        K_new: ArrayLike | None = None,
        R: ArrayLike | None = None,
        depth: float | None = None,
        viewpoint: ArrayLike | None = None,
    ) -> None:
        if _is_matrix3(size):  # PerspectiveView(K_new, size, R, ...): init_perspective_maps' order
            if K_new is not None:
                raise ValueError("K_new given twice: as the first argument and as K_new=")
            if R is None and _is_matrix3(yaw):
                R, yaw = yaw, 0.0
            K_new, size, fov = size, fov, 90.0
        _refuse_swapped(
            fov,
            size,
            "PerspectiveView(size, fov=90.0, ..., K_new=None, R=None, "
            "...); pass a camera matrix as K_new=",
        )
        if np.shape(fov) == (3, 3):
            raise ValueError(
                "fov: got a 3x3 matrix; pass a camera matrix as K_new= (the order "
                "is PerspectiveView(size, fov=90.0, ..., K_new=None, R=None, ...))"
            )
        self.size = _check_size(size)
        self.K_new = K_from_fov(fov, self.size) if K_new is None else validate_K(K_new, "K_new")
        self.R = rotation_from_ypr(yaw, pitch, roll) if R is None else _check_rotation(R)
        self.depth = _check_depth(depth)
        self.viewpoint = (
            None
            if viewpoint is None
            else _check_viewpoint(None, viewpoint, 1.0 if depth is None else depth)
        )

    def maps(self, camera: CameraLike, m1type: int = cv2.CV_16SC2) -> Maps:
        """``(map1, map2)`` of this view for ``camera``."""
        return init_perspective_maps(
            camera, self.K_new, self.size, self.R, m1type, self.depth, self.viewpoint
        )

    def __repr__(self) -> str:
        return f"PerspectiveView(size={self.size}, K_new={self.K_new.tolist()}, depth={self.depth})"
