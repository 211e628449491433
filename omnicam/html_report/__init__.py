"""A calibration report people look at: one self-contained HTML page.

The page shows what a calibration rests on and how far to trust it, drawn with cv2 and numpy
alone (no plotting library), every image embedded as a ``data:`` URI (PNG for plots, JPEG for
photographs), the style inline: one file that opens offline, with no external reference.

- :func:`pattern_report_html`: a chessboard calibration
  (:class:`~omnicam.chessboard.PatternReport`): the figures, the per-view RMS and held-out
  errors, the boards' coverage over the image and over the directions, the residual vectors,
  the rim, the viewing directions' uncertainty, a panorama with the boards, the posture.
- :func:`image_report_html`: a calibration from one image
  (:class:`~omnicam.calibration.CalibrationReport`): the rim, the four candidate postures
  side by side as panoramas with the far lines, the choice and its confidence, the posture.
- :func:`write_report`: write a page atomically (:mod:`omnicam._atomic`).
"""

from __future__ import annotations

from .._atomic import write_bytes
from .._typing import PathLike
from .image import IMAGE_SECTIONS, image_report_html
from .pattern import PATTERN_SECTIONS, pattern_report_html

__all__ = [
    "IMAGE_SECTIONS",
    "PATTERN_SECTIONS",
    "image_report_html",
    "pattern_report_html",
    "write_report",
]


def write_report(path: PathLike, page: str, overwrite: bool = True) -> None:
    """Write the HTML ``page`` to ``path`` atomically (a temporary file renamed into place).

    Raises
    ------
    OutputError
        As :func:`omnicam._atomic.atomic_output` (a missing folder, a full disk, an existing
        ``path`` with ``overwrite=False``); the previous file is unchanged.
    """
    write_bytes(path, page, what="report", overwrite=overwrite)
