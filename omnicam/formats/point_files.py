"""Pixels a user gives in files: far lines, rim boundary points, chessboard corners.

Far lines are JSON (:func:`read_far_lines`, :func:`write_far_lines`), pre-scanned as every
omnicam file is (:mod:`.filestorage`) and parsed by the standard library; rim boundary points
JSON or a ``cv2.FileStorage`` matrix (:func:`read_boundary_points`); another tool's chessboard
corners JSON or ``.npz`` (:func:`read_corners`).
"""

from __future__ import annotations

import json
import os
import re

import numpy as np

from .._atomic import write_bytes
from .._typing import FloatArray, PathLike
from .._validate import file_path, shown
from .filestorage import json_loads, prescan, reading

__all__ = [
    "BOUNDARY_FORMAT",
    "read_boundary_points",
    "read_corners",
    "read_far_lines",
    "write_far_lines",
]


def read_far_lines(path: PathLike) -> list[FloatArray]:
    """Far-line pixels from JSON: a list of lines, each a list of ``[x, y]`` pixels.

    The ``far_lines`` of section 3.2, as a user clicked them along the images of far straight
    lines. Returns a list of ``(N_i, 2)`` float64 arrays (each line at least 3 points). The file
    is pre-scanned as calibration files are (regular file, size, UTF-8, nesting) and parsed by
    the standard library.

    Raises
    ------
    FileNotFoundError
        No file at ``path``.
    ValueError
        Not JSON of that shape, non-finite coordinates, or a file refused by the pre-scan,
        naming the file (and the line).
    """
    what = "far-lines file"
    path = file_path(path, what)
    text = prescan(path, what, json_only=True)
    name = shown(path)
    data = json_loads(text, f"{what} {name}")
    try:
        return _far_lines(data, "lines")
    except ValueError as e:
        raise ValueError(f"{what} {name}: {e}") from None


def _far_lines(data, name):
    """Validate far lines (a list of lines of ``[x, y]`` pixels): a list of (N, 2) arrays."""
    expected = "a list of lines, each a list of at least 3 [x, y] pixels"
    if isinstance(data, np.ndarray) and data.ndim == 3:
        data = list(data)
    if not isinstance(data, (list, tuple)) or not data:
        raise ValueError(f"{name} must be {expected}, got {type(data).__name__}")
    lines = []
    for i, line in enumerate(data):
        try:
            arr = np.asarray(line)
        except (TypeError, ValueError, OverflowError):
            arr = None
        if arr is not None and arr.dtype.kind == "O":
            arr = None
        if arr is not None and arr.ndim == 3 and arr.shape[1:] == (1, 2):
            arr = arr.reshape(-1, 2)  # OpenCV's (N, 1, 2)
        if (
            arr is None
            or arr.dtype.kind not in "iuf"
            or arr.ndim != 2
            or arr.shape[1] != 2
            or arr.shape[0] < 3
        ):
            raise ValueError(
                f"{name}: line {i} must be a list of at least 3 [x, y] pixels ({expected})"
            )
        arr = arr.astype(np.float64)
        if not np.isfinite(arr).all():
            raise ValueError(f"{name}: line {i} has non-finite coordinates")
        lines.append(arr)
    return lines


def write_far_lines(path: PathLike, far_lines: list) -> None:
    """Write far-line pixels as JSON (what :func:`read_far_lines` reads), atomically.

    Raises
    ------
    ValueError
        ``far_lines`` is not a list of lines of at least 3 finite ``[x, y]`` pixels (naming
        it), or the file cannot be written (the old file is unchanged, naming the file).
    """
    what = "far-lines file"
    path = file_path(path, what)
    data = [line.tolist() for line in _far_lines(far_lines, "far_lines")]

    def verify(tmp):
        with open(tmp, encoding="utf-8") as f:
            return json.load(f) == data

    write_bytes(path, json.dumps(data), what=what, verify=verify)


BOUNDARY_FORMAT = (
    "JSON list of [x, y] pixels on the mirror rim (at least 6, spread along it; "
    "e.g. [[412.5, 80.0], [530.2, 101.7], ...]), or a cv2.FileStorage file "
    "(.yaml/.yml/.xml/.json) with an Nx2 matrix 'boundary_points'"
)


def read_boundary_points(path):
    """Rim pixels from ``path``: a JSON list of ``[x, y]`` or a FileStorage ``boundary_points``
    (N x 2 matrix; ``N x 1`` two-channel as ``cv2`` writes point vectors works too).

    Returns
    -------
    (N, 2) float64 ndarray

    Raises
    ------
    FileNotFoundError
        No file at ``path``.
    ValueError
        Not a file, not either layout, fewer than 6 points or non-finite ones, naming the file.
    """
    what = "boundary-points file"
    if not os.path.isfile(path):
        if not os.path.exists(path):
            raise FileNotFoundError(f"{what} {path} does not exist")
        raise ValueError(f"{what} {path} is not a file")
    data = None
    if os.path.splitext(path)[1].lower() == ".json":
        try:
            with open(path, encoding="utf-8") as f:
                data = json.load(f)
        except json.JSONDecodeError as e:
            raise ValueError(f"{what} {path}: not valid JSON ({e})") from None
        except (OSError, UnicodeDecodeError) as e:
            raise ValueError(f"{what} {path}: cannot read ({e})") from None
    if isinstance(data, list):
        ok = all(
            isinstance(p, list)
            and len(p) == 2
            and all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in p)
            for p in data
        )
        if not ok:
            raise ValueError(f"{what} {path}: expected a {BOUNDARY_FORMAT}")
        pts = np.array(data, dtype=np.float64).reshape(-1, 2)
    elif data is not None and not isinstance(data, dict):
        raise ValueError(f"{what} {path}: expected a {BOUNDARY_FORMAT}")
    else:
        pts = reading(path, what).matrix("boundary_points")
        if pts.ndim == 3 and pts.shape[1:] == (1, 2):
            pts = pts.reshape(-1, 2)
        if pts.ndim != 2 or pts.shape[1] != 2:
            raise ValueError(
                f"{what} {path}: 'boundary_points' must be an Nx2 matrix, got {pts.shape}"
            )
    if len(pts) < 6:
        raise ValueError(
            f"{what} {path}: {len(pts)} point(s); give at least 6 pixels spread along the rim"
        )
    if not np.isfinite(pts).all():
        raise ValueError(f"{what} {path}: non-finite coordinates")
    return pts


def read_corners(path, image_paths, n_corners, what="corners file"):
    """Chessboard corners per image from another tool's file, in OpenCV's order (row by row of
    the board's inner corners).

    JSON: an object ``{"image file name": [[x, y], ...] or null}`` or a list in the order of
    ``image_paths``; or ``.npz``: one ``(N, 2)`` array per image file name (or ``arr_0``,
    ``arr_1``... in the order of ``image_paths``). Images are matched by their file names.

    Parameters
    ----------
    path : str
    image_paths : sequence of str
        The images, whose base names the file's keys are.
    n_corners : int
        Corners of the board (``cols * rows``): each image's must have that many.
    what : str
        How messages name the file before its path (``omnicam calibrate`` names its option).

    Returns
    -------
    list
        One ``(n_corners, 2)`` float64 array, or None (no corners there), per image.

    Raises
    ------
    FileNotFoundError
        No file at ``path``.
    ValueError
        Unreadable, a name that is none of the images', or corners that are not ``n_corners``
        finite ``(x, y)`` pairs, naming the file.
    """
    names = [os.path.basename(p) for p in image_paths]
    try:
        if path.lower().endswith(".npz"):
            with np.load(path, allow_pickle=False) as z:
                table = {k: z[k] for k in z.files}
            if all(re.fullmatch(r"arr_\d+", k) for k in table):
                table = {names[int(k[4:])]: v for k, v in table.items() if int(k[4:]) < len(names)}
        else:
            with open(path, encoding="utf-8") as f:
                data = json.load(f)
            table = dict(zip(names, data)) if isinstance(data, list) else data
            if not isinstance(table, dict):
                raise ValueError("expected an object {image name: corners} or a list")
    except FileNotFoundError:
        raise FileNotFoundError(f"{what} {path}: no such file") from None
    except (OSError, ValueError) as e:
        raise ValueError(f"{what} {path}: cannot read it: {_one_line(e)}") from None
    unknown = sorted(set(table) - set(names))
    if unknown:
        raise ValueError(
            f"{what} {path}: {unknown[0]!r} is not one of the IMAGES' names "
            f"({', '.join(names[:3])}{', ...' if len(names) > 3 else ''})"
        )
    out = []
    for name in names:
        v = table.get(name)
        if v is None:
            out.append(None)
            continue
        try:
            arr = np.asarray(v, np.float64).reshape(-1, 2)
        except (TypeError, ValueError):
            raise ValueError(f"{what} {path}: the corners of {name} are not (x, y) pairs") from None
        if len(arr) != n_corners or not np.isfinite(arr).all():
            raise ValueError(
                f"{what} {path}: {name} has {len(arr)} corners (finite: "
                f"{int(np.isfinite(arr).all(axis=1).sum())}); the board has {n_corners}"
            )
        out.append(arr)
    return out


def _one_line(e):
    """``str(e)`` on one line (a JSON error's message, an OS error's)."""
    return " ".join(str(e).split()) or type(e).__name__
