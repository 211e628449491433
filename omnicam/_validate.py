"""Validators of the model's parameters, shared by the camera, io, views and calibration.

The lowest layer of omnicam with :mod:`omnicam.mirror` and :mod:`omnicam.gauge`: it imports
nothing from the package. Each function returns the value in its canonical form (float64 arrays,
tuples of ints) or raises ``ValueError`` naming the argument and what it must be
(``docs/conventions.md``).
"""
from __future__ import annotations

import numpy as np

__all__ = ["validate_K", "validate_D", "validate_image_size", "finite_array", "D_LENGTHS"]

D_LENGTHS = (4, 5, 8, 12, 14)  # as cv2.projectPoints takes them


def finite_array(value, name, shape, expected):
    try:
        arr = np.array(value, dtype=np.float64)
    except (TypeError, ValueError):
        raise ValueError(f"{name} must be {expected}, got {value!r}") from None
    if arr.size != int(np.prod(shape)):
        raise ValueError(f"{name} must be {expected}, got shape {arr.shape}")
    arr = arr.reshape(shape)
    if not np.isfinite(arr).all():
        raise ValueError(f"{name} must be finite, got {arr.ravel().tolist()}")
    return arr


def validate_K(K, name="K"):
    """Return ``K`` as a (3, 3) float64 array or raise ``ValueError`` naming ``name``."""
    try:
        arr = np.array(K, dtype=np.float64)
    except (TypeError, ValueError):
        raise ValueError(f"{name} must be a 3x3 camera matrix, got {K!r}") from None
    if arr.shape != (3, 3):
        raise ValueError(f"{name} must be a 3x3 camera matrix, got shape {arr.shape}")
    if not np.isfinite(arr).all():
        raise ValueError(f"{name} must be finite")
    if not np.allclose(arr[2], (0.0, 0.0, 1.0)):
        raise ValueError(f"{name} must have last row (0, 0, 1), got {arr[2].tolist()}")
    if abs(np.linalg.det(arr)) < 1e-12 or arr[0, 0] == 0 or arr[1, 1] == 0:
        raise ValueError(f"{name} must be non-singular (fx, fy non-zero)")
    return arr


def validate_D(D):
    """Return ``D`` as a flat float64 array of an OpenCV length, or ``None``."""
    if D is None:
        return None
    try:
        arr = np.array(D, dtype=np.float64).ravel()
    except (TypeError, ValueError):
        raise ValueError(f"D must be None or 4, 5, 8, 12 or 14 numbers, got {D!r}") from None
    if arr.size not in D_LENGTHS:
        raise ValueError(f"D must have 4, 5, 8, 12 or 14 coefficients (as cv2.projectPoints), "
                         f"got {arr.size}")
    if not np.isfinite(arr).all():
        raise ValueError("D must be finite")
    return arr


def validate_image_size(image_size):
    """Return ``(width, height)`` as a tuple of positive ints, or ``None``."""
    if image_size is None:
        return None
    try:
        w, h = (int(v) for v in image_size)
        exact = all(float(v) == int(v) for v in image_size)
    except (TypeError, ValueError):
        raise ValueError(f"image_size must be (width, height), got {image_size!r}") from None
    if not exact or w <= 0 or h <= 0:
        raise ValueError(f"image_size must be two positive integers (width, height), "
                         f"got {image_size!r}")
    return (w, h)
