"""The one stderr silencer: what OpenCV and the libraries under it print is not for the user.

omnicam reports every failure once, in its own words naming the file; OpenCV's
``[ERROR:0@...]`` lines, FFmpeg's, libpng's and libjpeg's warnings would only repeat it in
noise. Some of those lines bypass OpenCV's log level (plain ``fprintf(stderr)``), so file
descriptor 2 goes to ``/dev/null`` meanwhile. fd 2 is process-wide: output of other threads
during the block is dropped too.
"""

from __future__ import annotations

import contextlib
import os
import sys

import cv2

__all__ = ["opencv_silenced"]


@contextlib.contextmanager
def opencv_silenced(keep_messages=False, ffmpeg=False):
    """Silence OpenCV's own log and anything printed on fd 2 for the block.

    Parameters
    ----------
    keep_messages : bool
        Keep ``sys.stderr`` (omnicam's messages, warnings and tracebacks) writing to the real
        stderr through a duplicate of it: for a whole command.
    ffmpeg : bool
        Also quieten FFmpeg, which takes its level from ``OPENCV_FFMPEG_LOGLEVEL`` when a
        capture opens (a value the user set is kept).
    """
    if ffmpeg:
        os.environ.setdefault("OPENCV_FFMPEG_LOGLEVEL", "-8")  # AV_LOG_QUIET
    logging = getattr(getattr(cv2, "utils", None), "logging", None)
    previous = None
    if logging is not None:
        with contextlib.suppress(Exception):
            previous = logging.getLogLevel()
            logging.setLogLevel(logging.LOG_LEVEL_SILENT)
    swapped = saved = None
    try:
        fd = sys.stderr.fileno()
    except (AttributeError, OSError, ValueError):  # captured (pytest capsys, io.StringIO)
        fd = None
    with contextlib.suppress(Exception):
        sys.stderr.flush()
    with contextlib.suppress(OSError, ValueError):
        saved = os.dup(2)
        devnull = os.open(os.devnull, os.O_WRONLY)
        try:
            if keep_messages and fd == 2:  # our own messages keep the real stderr
                swapped = sys.stderr
                sys.stderr = open(
                    os.dup(saved),
                    "w",
                    buffering=1,
                    encoding=swapped.encoding,
                    errors="backslashreplace",
                )
            os.dup2(devnull, 2)
        finally:
            os.close(devnull)
    try:
        yield
    finally:
        if swapped is not None:
            with contextlib.suppress(Exception):
                sys.stderr.close()
            sys.stderr = swapped
        if saved is not None:
            with contextlib.suppress(OSError):
                os.dup2(saved, 2)
            os.close(saved)
        if previous is not None:
            with contextlib.suppress(Exception):
                logging.setLogLevel(previous)
