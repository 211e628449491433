"""Intrinsics of the perspective camera alone (without the mirror), from chessboard images.

The paper assumes a calibrated camera: ``K`` (and here ``D``) enter Chen's method through
``Q_e = K^T Q_I K`` (eq. 24, after undistorting the rim points). This module is a thin, validated
wrapper of OpenCV: ``cv2.findChessboardCorners`` + ``cv2.cornerSubPix`` + ``cv2.calibrateCamera``.
"""

from __future__ import annotations

import os

import cv2
import numpy as np

from .._typing import FloatArray
from .._validate import positive_number
from ..images import check_image, read_image, to_gray

__all__ = ["calibrate_intrinsics", "check_pattern_size", "find_chessboard", "gray8"]

_FIND_FLAGS = cv2.CALIB_CB_ADAPTIVE_THRESH | cv2.CALIB_CB_NORMALIZE_IMAGE


def check_pattern_size(pattern_size) -> tuple[int, int]:
    """``(columns, rows)`` of inner corners as ``cv2.findChessboardCorners`` takes them, checked
    (two integers >= 2); ``ValueError`` names what is wrong."""
    try:
        cols, rows = (int(v) for v in pattern_size)
        exact = all(float(v) == int(v) for v in pattern_size)
    except (TypeError, ValueError):
        raise ValueError(
            f"pattern_size must be (columns, rows) of inner corners, got {pattern_size!r}"
        ) from None
    if not exact or cols < 2 or rows < 2:
        raise ValueError(
            f"pattern_size must be two integers >= 2 (inner corners per row and "
            f"per column, as cv2.findChessboardCorners), got {pattern_size!r}"
        )
    return cols, rows


def gray8(image, index) -> np.ndarray:
    """8-bit grey of an image (array or file path) for OpenCV's corner detectors.

    An 8-bit image as ``cv2.cvtColor`` gives it; one of more bits (or float) stretched from its
    minimum to its maximum (:func:`omnicam.images.to_gray`, ``"range"``), so that a 12-bit image
    in a 16-bit file is not nearly black.
    """
    name = f"images[{index}]"
    if isinstance(image, (str, os.PathLike)):
        image = read_image(image, cv2.IMREAD_UNCHANGED, name)
    elif not isinstance(image, np.ndarray):
        raise ValueError(
            f"{name} must be an image array or a file path, got {type(image).__name__}"
        )
    image = check_image(image, name)
    return to_gray(image, "levels" if image.dtype == np.uint8 else "range", np.uint8, name)


def find_chessboard(gray, pattern_size) -> np.ndarray | None:
    """Inner chessboard corners to subpixel precision, or ``None`` if the board is not found.

    Parameters
    ----------
    gray : (H, W) uint8 ndarray
    pattern_size : (int, int)
        Inner corners ``(columns, rows)``, as ``cv2.findChessboardCorners``.

    Returns
    -------
    corners : (N, 1, 2) float32 ndarray or None
        In OpenCV's order (row by row), refined by ``cv2.cornerSubPix``.
    """
    found, corners = cv2.findChessboardCorners(gray, tuple(pattern_size), flags=_FIND_FLAGS)
    if not found:
        return None
    cols, rows = pattern_size
    grid = corners.reshape(rows, cols, 2)
    # a search window of ~40 % of the smallest corner spacing, 2..11 px half-size
    spacing = min(
        np.linalg.norm(np.diff(grid, axis=0), axis=2).min(),
        np.linalg.norm(np.diff(grid, axis=1), axis=2).min(),
    )
    half = int(np.clip(0.4 * spacing, 2, 11))
    criteria = (cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_MAX_ITER, 100, 1e-4)
    return cv2.cornerSubPix(gray, corners, (half, half), (-1, -1), criteria)


def calibrate_intrinsics(
    images, pattern_size, square_size, flags=0, min_views=3
) -> tuple[float, FloatArray, FloatArray]:
    """Calibrate the perspective camera from chessboard images taken without the mirror.

    Wraps ``cv2.findChessboardCorners`` (adaptive threshold, normalised image),
    ``cv2.cornerSubPix`` and ``cv2.calibrateCamera``; images where the board is not found are
    skipped.

    Parameters
    ----------
    images : sequence of ndarray or path, or (N, H, W[, C]) ndarray
        Grey or BGR images (uint8, uint16 or float) or image files, all of the same size.
    pattern_size : (int, int)
        Inner corners ``(columns, rows)`` of the board, as ``cv2.findChessboardCorners``.
    square_size : float
        Side of a square in your length unit; it sets the unit of the board poses only.
    flags : int
        ``cv2.calibrateCamera`` flags (e.g. ``cv2.CALIB_RATIONAL_MODEL`` for 8 coefficients).
    min_views : int
        Least number of images in which the board must be found (at least 3).

    Returns
    -------
    rms : float
        RMS reprojection error of the corners, px.
    K : (3, 3) float64 ndarray
        Camera matrix.
    D : (n,) float64 ndarray
        Distortion coefficients in OpenCV's order (5 by default), as ``MisalignedHyperbolicCamera``
        takes them.

    Raises
    ------
    FileNotFoundError
        An image file that does not exist.
    ValueError
        No images, unreadable or malformed images, images of different sizes, a bad
        ``pattern_size`` or ``square_size``, or the board found in fewer than ``min_views`` images.
    """
    cols, rows = check_pattern_size(pattern_size)
    square = positive_number(square_size, "square_size")
    if int(min_views) != min_views or min_views < 3:
        raise ValueError(f"min_views must be an integer >= 3, got {min_views!r}")
    if isinstance(images, (str, os.PathLike)):
        images = [images]  # one image file given alone
    elif isinstance(images, np.ndarray) and (
        images.ndim == 2 or (images.ndim == 3 and images.shape[2] in (1, 3, 4))
    ):
        images = [images]  # one image given alone; (N, H, W) and (N, H, W, C) are stacks
    try:
        images = list(images)
    except TypeError:
        raise ValueError("images must be a sequence of images or image files") from None
    if not images:
        raise ValueError(
            "no images given: pass images of a chessboard taken by the camera without the mirror"
        )
    obj = np.zeros((rows * cols, 3), np.float32)
    obj[:, :2] = np.mgrid[0:cols, 0:rows].T.reshape(-1, 2) * square
    size = None
    object_points, image_points, missed = [], [], []
    for i, image in enumerate(images):
        gray = gray8(image, i)
        if size is None:
            size = gray.shape[::-1]
        elif gray.shape[::-1] != size:
            raise ValueError(
                f"images[{i}] is {gray.shape[1]}x{gray.shape[0]} but images[0] is "
                f"{size[0]}x{size[1]}: all images must come from the same camera mode"
            )
        corners = find_chessboard(gray, (cols, rows))
        if corners is None:
            missed.append(i)
            continue
        object_points.append(obj)
        image_points.append(corners)
    if len(image_points) < min_views:
        raise ValueError(
            f"the {cols}x{rows} chessboard was found in {len(image_points)} of "
            f"{len(images)} images, need at least {min_views}: check pattern_size "
            f"(inner corners, not squares) and take more views of the whole board"
        )
    assert size is not None  # set by the first image (images is not empty)
    rms, K, D, _, _ = cv2.calibrateCamera(
        object_points, image_points, size, None, None, flags=int(flags)
    )
    return float(rms), np.asarray(K, np.float64), np.asarray(D, np.float64).ravel()
