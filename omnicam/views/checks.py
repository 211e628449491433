"""The argument checks every view function shares: each names the argument it refuses.

Also the sets a view's arguments are checked against (``PROJECTIONS``, ``M1TYPES``).
"""

from __future__ import annotations

import math
import numbers
from typing import Any

import cv2
import numpy as np

from .._typing import ArrayLike, FloatArray, Size
from .._validate import finite_array, float_array, real_number
from ..camera import MisalignedCatadioptricCamera

#: Panorama row layouts: rows linear in ``tan(elevation)`` or in elevation.
PROJECTIONS = ("cylindrical", "equirectangular")

#: Accepted ``m1type`` values, as ``cv2.convertMaps`` names them.
M1TYPES = {cv2.CV_16SC2: "CV_16SC2", cv2.CV_32FC1: "CV_32FC1", cv2.CV_32FC2: "CV_32FC2"}


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


def _check_panorama_size(size: Any) -> Size:
    """A panorama's ``(W, H)``: ``H >= 2`` and not taller than wide (its width spans 360 deg,
    so a taller one is mostly a swapped size; the message gives the size to give)."""
    w, h = _check_size(size, min_height=2)
    if h > w:
        raise ValueError(
            f"size: a panorama is (width, height) with its width spanning 360 deg, and {w}x{h} "
            f"is taller than wide; give size=({h}, {w}) (or any width >= the height)"
        )
    return w, h


def _check_yaw(yaw: object) -> float | None:
    if yaw is None:
        return None
    return real_number(yaw, "yaw", expected="None or a finite number of degrees")


def _check_camera(camera: object) -> object:
    """The camera, refused unless it has what the views use of it (duck-typed, so the error
    names the class users know rather than an isinstance failure)."""
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
    camera: MisalignedCatadioptricCamera | None, viewpoint: ArrayLike | None, depth: float | None
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
