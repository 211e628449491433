"""Pixels a user gives in files: far lines, rim boundary points, chessboard corners.

Far lines are JSON (:func:`read_far_lines`, :func:`write_far_lines`), pre-scanned as every
omnicam file is (:mod:`.filestorage`) and parsed by the standard library.
"""

from __future__ import annotations

import json

import numpy as np

from .._atomic import write_bytes
from .._typing import FloatArray, PathLike
from .._validate import file_path, shown
from .filestorage import json_loads, prescan

__all__ = ["read_far_lines", "write_far_lines"]


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
