"""Which elevations a panorama covers: what the mirror sees, and the default band.

Where the default panorama's lower edge is chosen: :func:`default_elevation_range` (above
the camera's own reflection when it is known, :func:`camera_reflection_elevation`, else from
``CYLINDRICAL_MIN_ELEVATION``; the ``LOWER_EDGE_*`` phrases say which). The band the mirror
sees at all is :func:`visible_elevation_range`, from the reflected rays of the rim
(``_rim_band``, which the table builder also uses to skip what is above it).
"""

from __future__ import annotations

import functools
import math
import numbers
from typing import NamedTuple

import numpy as np

from .._typing import ArrayLike, FloatArray
from .._validate import real_number
from ..camera import MisalignedCatadioptricCamera
from ..mirror import Mirror
from .checks import PROJECTIONS, _check_camera, _check_depth, _check_rotation, _check_viewpoint

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


def _rim_band(camera: MisalignedCatadioptricCamera) -> tuple[float, float, bool]:
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


def visible_elevation_range(camera: MisalignedCatadioptricCamera) -> tuple[float, float]:
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
    camera: MisalignedCatadioptricCamera,
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
    camera: MisalignedCatadioptricCamera,
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
    camera: MisalignedCatadioptricCamera,
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
    camera: MisalignedCatadioptricCamera,
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
    if top is None:  # unknown: the fixed edge, below the lens barrels of the default rigs
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
