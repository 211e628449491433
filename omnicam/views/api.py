"""The public face of the views: ``init_panorama_maps``, ``init_perspective_maps``, the view
specs ``PanoramaView`` and ``PerspectiveView`` the Unwarper and the CLI hold, and the helpers
``rotation_from_ypr`` and ``K_from_fov``.

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

The view conventions (azimuth, row order, ``R``, yaw/pitch/roll) are those of
``docs/conventions.md``, section "Views".

Each function checks its arguments (:mod:`omnicam.views.checks`), takes a default band from
:mod:`omnicam.views.elevation` and builds its table with :mod:`omnicam.views.grid`.
"""

from __future__ import annotations

import math
import warnings
from typing import Any

import cv2
import numpy as np

from .._typing import ArrayLike, FloatArray, Maps, Size
from .._validate import refuse_complex, validate_K
from ..camera import MisalignedCatadioptricCamera
from .checks import (
    PROJECTIONS,
    _check_camera,
    _check_depth,
    _check_elevation_range,
    _check_m1type,
    _check_panorama_size,
    _check_rotation,
    _check_size,
    _check_viewpoint,
    _check_yaw,
)
from .elevation import (
    DefaultElevationRange,
    _default_range,
    default_elevation_range,
    visible_elevation_range,
)
from .grid import _KIND, Directions, _step_for, _table

#: ``R = None`` of a perspective view: looking horizontally at azimuth 0, image-up along +Z.
R0 = np.array([[0.0, -1.0, 0.0], [0.0, 0.0, -1.0], [1.0, 0.0, 0.0]])


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


#: Below this tilt of the camera's optical axis from the panorama's up axis, the way the axis
#: leans is no forward direction: a calibration knows the axis to about 0.1 deg (its report's
#: ``axis_std_deg``), which leaves the azimuth of a smaller lean to chance. The default centre
#: of a panorama is then azimuth 0 (the camera's x axis, image-right, by the gauge).
FORWARD_MIN_TILT_DEG = 1.0


def camera_forward_yaw(camera: MisalignedCatadioptricCamera, R: ArrayLike | None = None) -> float:
    """The yaw (degrees, as :func:`rotation_from_ypr`'s) of the camera's forward direction:
    the centre of a default panorama (docs/conventions.md, "Views").

    Forward is the azimuth of the camera's optical axis (its +z axis, ``camera.R[2]`` in the
    mirror frame) in the panorama frame (``R @`` it; ``R=None`` the mirror frame): the way the
    camera leans, seen from above. When the axis leans less than ``FORWARD_MIN_TILT_DEG`` from
    the panorama's up axis (an aligned rig, exactly along it) forward is azimuth 0: the mirror
    frame's +X, which the gauge puts along the camera's x axis (image-right). The yaw looking
    at azimuth ``phi`` is ``-phi`` (positive yaw turns right).

    Parameters
    ----------
    camera : MisalignedHyperbolicCamera
    R : (3, 3) array_like or None
        The panorama's rotation, as for :func:`init_panorama_maps`.

    Returns
    -------
    float
        Degrees in (-180, 180].
    """
    _check_camera(camera)
    Rm = np.eye(3) if R is None else _check_rotation(R)
    return _forward_yaw(camera, Rm)


def _forward_yaw(camera: MisalignedCatadioptricCamera, Rm: FloatArray) -> float:
    """:func:`camera_forward_yaw` of a checked rotation."""
    x, y, z = (float(v) for v in Rm @ np.asarray(camera.R, dtype=np.float64)[2])
    if math.degrees(math.atan2(math.hypot(x, y), z)) < FORWARD_MIN_TILT_DEG:
        return 0.0
    yaw = -math.degrees(math.atan2(y, x))
    return 180.0 if yaw == -180.0 else yaw + 0.0  # (-180, 180], no -0.0


def _turn(yaw: float, w: int) -> FloatArray:
    """``Rz(phi0)``, taking the panorama's kernel layout (column ``j`` at azimuth ``-360 j / W``)
    to the one of docs/conventions.md: column ``(W - 1) / 2`` at azimuth ``-yaw``."""
    phi0 = -math.radians(yaw) + math.pi * (w - 1) / w
    c, s = math.cos(phi0), math.sin(phi0)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


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
    camera: MisalignedCatadioptricCamera,
    size: Size,
    elevation_range: tuple[float, float] | None = None,
    projection: str = "cylindrical",
    R: ArrayLike | None = None,
    m1type: int = cv2.CV_16SC2,
    depth: float | None = None,
    viewpoint: ArrayLike | None = None,
    *,
    yaw: float | None = None,
) -> Maps:
    """``cv2.remap`` tables of a 360-degree panorama (paper section 4.1, Fig. 7).

    Column ``j`` looks at azimuth ``-yaw - 360 (j - (W - 1) / 2) / W`` degrees (measured in the
    panorama frame from +X towards +Y, so the panorama turns right as ``j`` grows, and its
    centre looks where a perspective view of that ``yaw`` looks); row 0 is elevation ``hi``, row
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
        ``(W, H)`` of the panorama, ``2 <= H <= W``.
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
    yaw : float or None
        Degrees: the centre column looks at azimuth ``-yaw`` (as a perspective view of that
        yaw). ``None``: the camera's forward direction (:func:`camera_forward_yaw`), so what
        is in front of the camera is not cut by the seam.

    Returns
    -------
    map1, map2 : ndarray
        As ``cv2.initUndistortRectifyMap`` returns them for ``m1type`` (``map2`` is None for
        ``CV_32FC2``). Output pixels the mirror does not see map to ``(UNSEEN, UNSEEN)``.

    Raises
    ------
    ValueError
        Naming the argument: malformed ``size`` or one taller than wide, unknown
        ``projection``, bad ``elevation_range``, ``R``, ``m1type``, ``depth``, ``viewpoint``
        or ``yaw``.

    Notes
    -----
    Float entries are within ``TOLERANCE`` (0.01 px) of the exact projection; ``CV_16SC2`` is
    that table rounded to OpenCV's 1/32 px grid exactly as ``cv2.convertMaps`` does. A pixel
    whose direction grazes the rim (its exact mirror point on the rim to ~1e-12) may be called
    seen or unseen either way. For the aligned rig the default ``hi`` is exactly the rim's
    elevation, so row 0 lies on the rim.
    """
    _check_camera(camera)
    w, h = _check_panorama_size(size)
    if projection not in PROJECTIONS:
        raise ValueError(f"projection must be one of {PROJECTIONS}, got {projection!r}")
    m1type = _check_m1type(m1type)
    Rm = np.eye(3) if R is None else _check_rotation(R)
    depth = _check_depth(depth)
    vp = _check_viewpoint(camera, viewpoint, depth)
    yaw = _check_yaw(yaw)
    if elevation_range is None:  # above the camera's own reflection, else from -60 deg
        lo, hi, _ = _default_range(camera, projection, Rm, depth, vp)
    else:
        lo, hi = _check_elevation_range(elevation_range, projection)
    p0, p1, az_step = _panorama_params((w, h), lo, hi, projection)
    st = np.zeros(9, np.int64)
    turn = _turn(_forward_yaw(camera, Rm) if yaw is None else yaw, w)
    directions = Directions(_KIND[projection], Rm.T @ turn, p0, p1, az_step)
    maps = _table(camera, directions, (w, h), depth, vp, m1type, stats=st)
    # a full-sphere panorama (a 360 video's frame) is black above the band by its format
    _warn_if_unseen(camera, st[8] / (w * h), "panorama" if hi - lo < 170.0 else "360 panorama")
    return maps


def init_perspective_maps(
    camera: MisalignedCatadioptricCamera,
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
    maps = _table(camera, Directions(0, M), (w, h), depth, vp, m1type, step=step, stats=st)
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


def _warn_if_unseen(camera: MisalignedCatadioptricCamera, frac: float, what: str) -> None:
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
        ``(W, H)``, ``2 <= H <= W``.
    elevation_range, projection, R, depth, viewpoint, yaw
        As for :func:`init_panorama_maps` (``yaw=None``: the camera's forward direction at
        the centre column, :func:`camera_forward_yaw`).
    """

    __slots__ = ("size", "elevation_range", "projection", "R", "depth", "viewpoint", "yaw")

    def __init__(
        self,
        size: Size,
        elevation_range: tuple[float, float] | None = None,
        projection: str = "cylindrical",
        R: ArrayLike | None = None,
        depth: float | None = None,
        viewpoint: ArrayLike | None = None,
        *,
        yaw: float | None = None,
    ) -> None:
        self.size = _check_panorama_size(size)
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
        self.yaw = _check_yaw(yaw)

    def default_range(self, camera: MisalignedCatadioptricCamera) -> DefaultElevationRange | None:
        """The band this view covers for ``camera`` when its ``elevation_range`` is None
        (:func:`default_elevation_range`), else None (the given range)."""
        if self.elevation_range is not None:
            return None
        return default_elevation_range(camera, self.projection, self.R, self.depth, self.viewpoint)

    def maps(self, camera: MisalignedCatadioptricCamera, m1type: int = cv2.CV_16SC2) -> Maps:
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
            yaw=self.yaw,
        )

    def __repr__(self) -> str:
        return (
            f"PanoramaView(size={self.size}, elevation_range={self.elevation_range}, "
            f"projection={self.projection!r}, depth={self.depth}, yaw={self.yaw})"
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

    def maps(self, camera: MisalignedCatadioptricCamera, m1type: int = cv2.CV_16SC2) -> Maps:
        """``(map1, map2)`` of this view for ``camera``."""
        return init_perspective_maps(
            camera, self.K_new, self.size, self.R, m1type, self.depth, self.viewpoint
        )

    def __repr__(self) -> str:
        return f"PerspectiveView(size={self.size}, K_new={self.K_new.tolist()}, depth={self.depth})"
