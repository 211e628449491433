"""The size of the board in an image, and the size to give when the one given is wrong.

A pattern size smaller than the board is the easiest mistake to make (a 7x11 board given as
7x6) and the hardest to see: OpenCV's detectors may find a sub-board of it, or
``findChessboardCornersSB`` a grid that skips rows of squares (:func:`.detect.check_grid`
rejects those). Counting squares instead of inner corners (8x12 for a 7x11 board) finds
nothing at all. :func:`board_size_in` asks ``cv2.findChessboardCornersSBWithMeta`` with
``cv2.CALIB_CB_LARGER`` for the whole board around a grid of the size given (or of one less
each way, the squares counted), and :func:`raw_boards`, the raw step of
:func:`omnicam.calibrate_pattern`, refuses a size that most images contradict, naming the size
to give.
"""

from __future__ import annotations

import warnings
from collections import Counter

import cv2
import numpy as np

from .detect import _SB_FLAGS, check_grid, detect_grids
from .intrinsics import check_pattern_size, gray8

__all__ = ["SIZE_CHECKS_AGREE", "board_size_in", "raw_boards", "wrong_size_message"]

#: :func:`raw_boards` stops asking for the whole board once this many images agree on it.
SIZE_CHECKS_AGREE = 3
#: Without any grid on the raw images, the whole board is looked for in this many images at
#: most (each costs one or two exhaustive searches).
_SIZE_CHECKS_MAX = 5


def board_size_in(image, pattern_size) -> tuple[int, int] | None:
    """Inner corners ``(columns, rows)`` of the whole board in the image, or ``None``.

    ``cv2.findChessboardCornersSBWithMeta`` with ``cv2.CALIB_CB_LARGER`` grows a grid of
    ``pattern_size`` (or, when there is none, of one corner less each way: the squares were
    counted) to the whole board; the board's grid must be a chessboard's
    (:func:`.detect.check_grid`).

    Parameters
    ----------
    image : ndarray
        Grey or BGR image (uint8, uint16 or float).
    pattern_size : (int, int)
        Inner corners ``(columns, rows)`` given for the board.

    Returns
    -------
    (int, int) or None
        The whole board's inner corners, in the order of ``pattern_size`` where the two can be
        matched (:func:`_oriented`): ``(7, 11)`` for a 7x11 board given as ``(7, 6)``, and for
        one given as ``(8, 12)`` (its squares). ``None`` if no board of at least one of those
        sizes is found.
    """
    cols, rows = check_pattern_size(pattern_size)
    gray = gray8(image, 0)
    for seed in ((cols, rows), (cols - 1, rows - 1)):
        if min(seed) < 2:
            continue
        found, corners, meta = cv2.findChessboardCornersSBWithMeta(
            gray, seed, _SB_FLAGS | cv2.CALIB_CB_LARGER
        )
        if not found or meta is None:
            continue
        r, c = meta.shape[:2]  # meta is (rows, columns) of the whole board
        if corners is None or corners.size != 2 * r * c:
            continue
        if check_grid(gray, corners.reshape(r, c, 2).astype(np.float64)):
            continue  # a grid that is no chessboard's says nothing of the board's size
        return _oriented((c, r), (cols, rows))
    return None


def _oriented(size, given):
    """``size`` or its transpose, whichever matches ``given`` (columns, rows): the squares of
    it counted, one side kept in place, containing it, or of the same aspect, in that order."""
    a, b = size
    if a == b:
        return (a, b)
    tests = (
        lambda s: (s[0] + 1, s[1] + 1) == tuple(given),
        lambda s: s[0] == given[0] or s[1] == given[1],
        lambda s: s[0] >= given[0] and s[1] >= given[1],
        lambda s: (s[0] >= s[1]) == (given[0] >= given[1]),
    )
    for test in tests:
        ok = [s for s in ((a, b), (b, a)) if test(s)]
        if len(ok) == 1:
            return ok[0]
    return (a, b)


def wrong_size_message(size, pattern_size, images, grids_found=True) -> str:
    """The refusal of ``pattern_size`` when the board in ``images`` (indices) has ``size``."""
    c, r = size
    cols, rows = pattern_size
    where = f"images[{images[0]}]" + (
        f" (and {len(images) - 1} more image{'s' if len(images) > 2 else ''})"
        if len(images) > 1
        else ""
    )
    if (c + 1, r + 1) == (cols, rows):
        return (
            f"no board of {cols}x{rows} inner corners is found, but the board in {where} has "
            f"{c}x{r}: give the inner corners, pattern_size=({c}, {r}), not the {cols}x{rows} "
            f"squares"
        )
    if grids_found:
        return (
            f"the board in {where} has {c}x{r} inner corners, not {cols}x{rows}: give "
            f"pattern_size=({c}, {r})"
        )
    return (
        f"no board of {cols}x{rows} inner corners is found, but the board in {where} has "
        f"{c}x{r} inner corners: give pattern_size=({c}, {r})"
    )


def raw_boards(images, pattern_size, progress=None):
    """Every image's board by OpenCV's detectors on the raw image, and the size's check.

    Each image's grids come from :func:`.detect.detect_grids` (``"raw"``, then ``"raw-sb"``);
    a grid that is no chessboard's is dropped, with a ``RuntimeWarning`` naming the image and
    why. Then the board's size is checked (:func:`board_size_in`) in the images with a grid,
    until :data:`SIZE_CHECKS_AGREE` agree and none disagrees; without any grid, in up to five
    images. When more than half of the images checked show a whole board of another size
    (the most common one), ``ValueError`` names it: ``pattern_size`` is a sub-board of it, or
    its squares, or no board of it is there.

    Parameters
    ----------
    images : sequence of ndarray
        The images of the rig.
    pattern_size : (int, int)
        Inner corners ``(columns, rows)``.
    progress : callable, optional
        ``progress(index, text)`` hears of each image.

    Returns
    -------
    points : list of (N, 1, 2) float32 ndarray or None
        Each image's corners (:func:`.detect.detect_pattern`'s order), or ``None``.
    found_by : list of str or None
        The method that found each (``"raw"`` or ``"raw-sb"``), or ``None``.
    """
    cols, rows = check_pattern_size(pattern_size)
    points, found_by, dropped = [], [], {}
    for k, im in enumerate(images):
        grids = detect_grids(im, (cols, rows), None, methods=("raw", "raw-sb"))
        board = grids[-1] if grids and not grids[-1].rejected else None
        points.append(None if board is None else board.corners)
        found_by.append(None if board is None else board.method)
        if board is None and grids:
            dropped[k] = grids
        if progress is not None:
            if board is not None:
                text = f"board ({board.method})"
            elif grids:
                text = f"no board on the raw image ({_rejections(grids)})"
            else:
                text = "no board on the raw image"
            progress(k, text)
    with_grid = [k for k, p in enumerate(points) if p is not None or k in dropped]
    if with_grid:
        size, agree = _whole_board(images, (cols, rows), with_grid)
    else:
        size, agree = _whole_board(images, (cols, rows), range(len(images)), _SIZE_CHECKS_MAX)
    if size is not None:
        raise ValueError(wrong_size_message(size, (cols, rows), agree, bool(with_grid)))
    for k, grids in dropped.items():
        warnings.warn(
            f"images[{k}]: no board on the raw image ({_rejections(grids)}); the views may find it",
            RuntimeWarning,
            stacklevel=3,
        )
    return points, found_by


#: The OpenCV detector behind each raw method, as messages name it.
_DETECTORS = {"raw": "findChessboardCorners", "raw-sb": "findChessboardCornersSB"}


def _rejections(grids):
    return "; ".join(
        f"the grid of {_DETECTORS.get(g.method, g.method)} is dropped: {g.rejected}" for g in grids
    )


def _whole_board(images, pattern_size, order, most=None):
    """``(size, images)``: the size of the whole board in most of the images ``order`` (the
    first ``most`` of them at most) when it is not ``pattern_size``, with the images that show
    it; else ``(None, [])``. Stops once :data:`SIZE_CHECKS_AGREE` images agree and none
    disagrees, or show nothing while none shows a board."""
    same, other, blank = 0, {}, 0
    for k in list(order)[:most]:
        size = board_size_in(images[k], pattern_size)
        if size is None:
            blank += 1
        elif size == tuple(pattern_size):
            same += 1
        else:
            other[k] = size
        sizes = set(other.values()) | ({tuple(pattern_size)} if same else set())
        agreed = len(sizes) == 1 and same + len(other) >= SIZE_CHECKS_AGREE
        if agreed or (blank >= SIZE_CHECKS_AGREE and not sizes):
            break
    if not other:
        return None, []
    size, count = Counter(other.values()).most_common(1)[0]
    if count <= (same + len(other)) / 2:
        return None, []
    return size, [k for k, s in other.items() if s == size]
