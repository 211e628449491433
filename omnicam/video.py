"""Video files: opening a capture, choosing a codec, and writing a video safely.

Reading: :func:`open_capture` opens a ``cv2.VideoCapture`` (a file, a camera index, an image
sequence or a stream URL) or says what could not be opened; :func:`count_frames` counts the
frames that decode from a file.

Codecs: :func:`video_codec` picks the first codec of a container's list (:data:`VIDEO_CODECS`)
that writes a frame which reads back here, since a ``cv2.VideoWriter`` can open and still
write nothing.

Writing: :class:`VideoOutput` writes frames to a temporary file beside the output, watches the
free space, checks at the end that every frame decodes (a full disk makes
``cv2.VideoWriter`` drop frames silently), and only then puts the file in place, atomically
(:mod:`omnicam._atomic`). :class:`omnicam.stream.Unwarper` writes its videos through it.
"""

from __future__ import annotations

import contextlib
import math
import os
from typing import Literal, NamedTuple

import cv2
import numpy as np

from ._atomic import OutputError, publish, remove_quietly, sigint_deferred, temp_beside
from ._quiet import opencv_silenced

__all__ = [
    "FREE_SPACE_EVERY",
    "H264",
    "MIN_FREE_BYTES",
    "OTHER_CODECS",
    "VIDEO_CODECS",
    "WEB_CODECS",
    "OutputError",
    "VideoOutput",
    "WrittenVideo",
    "count_frames",
    "fell_back",
    "open_capture",
    "video_codec",
    "web_codec",
]


# -- reading --------------------------------------------------------------------------------------
def open_capture(source) -> cv2.VideoCapture:
    """A ``cv2.VideoCapture`` that is open, or ``ValueError`` naming what could not be opened.

    Parameters
    ----------
    source : int, str, os.PathLike or cv2.VideoCapture
        A camera index, a video file, an image sequence pattern (``img_%04d.png``) or a stream
        URL (``scheme://...``), or a capture that is already open (or any object with its
        ``read``, ``get`` and ``isOpened``).

    Returns
    -------
    cap : cv2.VideoCapture
        Open; the caller releases it (a capture passed in is returned as it is).
    """
    if is_capture(source):
        cap, what = source, "the capture"
    elif isinstance(source, (int, np.integer)) and not isinstance(source, bool):
        cap, what = None, f"camera {int(source)}"
        source = int(source)
    elif isinstance(source, (str, os.PathLike)):
        source = os.fspath(source)
        if "://" in source:
            what = f"stream {source}"
        elif "%" in source:
            what = f"image sequence {source}"
        elif os.path.exists(source):
            size = os.stat(source).st_size if os.path.isfile(source) else None
            what = f"{source}: not a video OpenCV can open" + (
                f" ({size} bytes)" if size is not None else ""
            )
        else:
            raise ValueError(f"source {source}: no such file")
        cap = None
    else:
        raise ValueError(
            f"source must be a camera index, a path, a URL or a cv2.VideoCapture, got {source!r}"
        )
    try:
        if cap is None:
            with opencv_silenced(ffmpeg=True):  # FFmpeg's "moov atom not found" and the like
                cap = cv2.VideoCapture(source)
        opened = cap.isOpened()
    except cv2.error:
        opened = False
    if not opened:
        raise ValueError(f"cannot open {what}")
    return cap


def is_capture(source):
    """A ``cv2.VideoCapture``, or an object that reads like one (a wrapper, say)."""
    return isinstance(source, cv2.VideoCapture) or all(
        callable(getattr(source, m, None)) for m in ("read", "get", "isOpened")
    )


def count_frames(path, limit=None) -> int:
    """Frames OpenCV decodes from the video file ``path`` (it stops counting after ``limit``).

    Returns 0 for a file OpenCV cannot open.
    """
    cap = cv2.VideoCapture(os.fspath(path))
    n = 0
    try:
        if not cap.isOpened():
            return 0
        while (limit is None or n < limit) and cap.grab():
            n += 1
    finally:
        cap.release()
    return n


def capture_fps(cap):
    """The capture's frame rate, or 30 when it has none (or an implausible one)."""
    fps = cap.get(cv2.CAP_PROP_FPS)
    return float(fps) if math.isfinite(fps) and 0 < fps < 1000 else 30.0


# -- arguments ------------------------------------------------------------------------------------
def check_frame_size(frame_size):
    """``frame_size`` as ``(width, height)`` positive ints, or ``ValueError`` naming it."""
    try:
        w, h = frame_size
        ok = all(
            isinstance(v, (int, float, np.integer, np.floating))
            and not isinstance(v, bool)
            and math.isfinite(float(v))
            and float(v) == int(v)
            and 0 < v <= 100_000
            for v in (w, h)
        )
    except (TypeError, ValueError):
        ok = False
    if not ok:
        raise ValueError(
            f"frame_size must be (width, height), two positive integers up to "
            f"100000, got {frame_size!r}"
        )
    return int(w), int(h)


def check_even_size(path, size):
    """``ValueError`` naming the video ``path``, its frame ``size`` and an even size to give
    instead, unless ``(width, height)`` are both even (``cv2.VideoWriter`` silently drops an odd
    last row or column)."""
    w, h = size
    if w % 2 or h % 2:
        raise ValueError(
            f"cannot write video {os.fspath(path)} at {w}x{h}: a video needs an even width "
            f"and height (OpenCV drops an odd last row or column); give {w + w % 2}x{h + h % 2} "
            f"(or another even size)"
        )


def check_fps(fps):
    """``fps`` as a positive finite float, or ``ValueError`` naming it."""
    if not (
        isinstance(fps, (int, float, np.integer, np.floating))
        and not isinstance(fps, bool)
        and 0 < float(fps) < math.inf
    ):
        raise ValueError(f"fps must be a positive finite number, got {fps!r}")
    return float(fps)


# -- codecs ---------------------------------------------------------------------------------------
#: Codecs tried in order, per container, when no ``fourcc`` is given: first what browsers play
#: (H.264 in MP4 and MOV, VP9 then VP8 in WebM), where this OpenCV writes it; then, in MP4 and
#: MOV, mp4v (MPEG-4 Part 2), which every FFmpeg build of OpenCV writes and many players, but no
#: browser, play (:func:`fell_back` tells). The FFmpeg inside the opencv-python wheels has no
#: H.264 encoder; it has VP9 and VP8. VP9 encodes several times slower than VP8 (``"VP80"``).
#: MJPG is OpenCV's own encoder.
VIDEO_CODECS = {
    ".mp4": ("avc1", "H264", "X264", "mp4v"),
    ".m4v": ("avc1", "H264", "X264", "mp4v"),
    ".mov": ("avc1", "H264", "X264", "mp4v"),
    ".webm": ("VP90", "VP80"),
    ".avi": ("MJPG",),
    ".mkv": ("MJPG",),
}
#: Codecs for a container :data:`VIDEO_CODECS` does not name.
OTHER_CODECS = ("avc1", "H264", "X264", "mp4v")
#: H.264's FourCCs (the codec browsers play).
H264 = ("avc1", "H264", "h264", "X264", "x264", "avc3")
#: The codecs browsers play, by name, and their FourCCs.
WEB_CODECS = {"H.264": H264, "VP9": ("VP90", "vp09"), "VP8": ("VP80", "vp08")}


def web_codec(fourcc) -> str | None:
    """The name of the codec ``fourcc`` if browsers play it (``"H.264"``, ``"VP9"``, ``"VP8"``),
    else None."""
    return next((name for name, codes in WEB_CODECS.items() if fourcc in codes), None)


def fell_back(path, fourcc) -> bool:
    """Whether ``fourcc``, the codec :func:`video_codec` chose for ``path`` by default, is a
    fallback browsers do not play: the container's first choice is a codec they play, and this
    OpenCV wrote none of those."""
    ext = os.path.splitext(os.fspath(path))[1].lower()
    first = VIDEO_CODECS.get(ext, OTHER_CODECS)[0]
    return web_codec(first) is not None and web_codec(fourcc) is None


def codec_candidates(path, fourcc):
    """The codecs to try for ``path``: ``fourcc`` as a tuple, or, for None, the container's
    (:data:`VIDEO_CODECS`); ``ValueError`` for a malformed ``fourcc``."""
    if fourcc is None:
        return VIDEO_CODECS.get(os.path.splitext(path)[1].lower(), OTHER_CODECS)
    codes = (fourcc,) if isinstance(fourcc, str) else tuple(fourcc)
    if not codes or not all(isinstance(c, str) and len(c) == 4 for c in codes):
        raise ValueError(
            f"fourcc must be a 4-character code, a sequence of them or None, got {fourcc!r}"
        )
    return codes


def _new_writer(path, fourcc, fps, size, color):
    """A ``cv2.VideoWriter`` on ``path`` that is open, or None (OpenCV's own lines silenced)."""
    with opencv_silenced():
        try:
            writer = cv2.VideoWriter(path, cv2.VideoWriter_fourcc(*fourcc), fps, size, color)
            if writer.isOpened():
                return writer
            writer.release()
        except cv2.error:
            pass
    return None


def _writes_a_frame(path, fourcc, fps, size, color):
    """Whether OpenCV writes one frame of ``size`` with ``fourcc`` into ``path``'s container
    that reads back (a writer can open and still write nothing); tried on a temporary file."""
    with sigint_deferred():
        probe = temp_beside(path)
    try:
        writer = _new_writer(probe, fourcc, fps, size, color)
        if writer is None:
            return False
        frame = np.zeros((size[1], size[0], 3) if color else (size[1], size[0]), np.uint8)
        with opencv_silenced():
            writer.write(frame)
            writer.release()
            return count_frames(probe, 2) == 1
    finally:
        remove_quietly(probe)


def video_codec(path, size, fps=30.0, fourcc=None, color=True) -> str:
    """The codec a video written to ``path`` gets: the first of ``fourcc`` that works here.

    Each candidate is checked by writing one frame of ``size`` into a temporary file of the
    same container beside ``path`` and reading it back, since a ``cv2.VideoWriter`` can open
    and still write nothing (H.264, for one, needs an encoder that not every OpenCV build has).

    Parameters
    ----------
    path : str or os.PathLike
        The video to write; its extension picks the container.
    size : (int, int)
        ``(width, height)`` of the frames.
    fps : float
        Frame rate.
    fourcc : str, sequence of str or None
        A codec (``"mp4v"``) or codecs tried in order; None: :data:`VIDEO_CODECS` for the
        container (H.264, then mp4v, for ``.mp4``, ``.m4v`` and ``.mov``; VP9, then VP8, for
        ``.webm``), else :data:`OTHER_CODECS`.
    color : bool
        Three-channel (BGR) frames, else single-channel.

    Returns
    -------
    fourcc : str
        The first candidate that writes a frame that reads back.

    Raises
    ------
    ValueError
        ``fourcc`` is malformed, or none of the candidates works (:class:`OutputError` naming
        them), or the folder of ``path`` does not exist.
    """
    path = os.fspath(path)
    candidates = codec_candidates(path, fourcc)
    for code in candidates:
        if _writes_a_frame(path, code, float(fps), tuple(size), color):
            return code
    ext = os.path.splitext(path)[1] or "(no extension)"
    which = (
        f"codec {candidates[0]}"
        if len(candidates) == 1
        else f"any of the codecs {', '.join(candidates)}"
    )
    raise OutputError(
        f"cannot write video {path}: this OpenCV cannot write {which} into {ext} files "
        f"(tried by writing a frame); try another codec (fourcc) or container"
    )


# -- writing --------------------------------------------------------------------------------------
#: A video write stops before the disk is completely full (bytes free on its file system).
MIN_FREE_BYTES = 256 * 1024
#: How often (in frames) a video write looks at the free space.
FREE_SPACE_EVERY = 16


class WrittenVideo(NamedTuple):
    """A video file a :class:`VideoOutput` put in place."""

    path: str
    """Where the frames are: the output, or ``NAME.partial.EXT`` beside an earlier output."""
    frames: int
    """Frames that decode from it."""
    fourcc: str
    """The codec it was written with."""
    complete: bool
    """False for the frames so far of a run that stopped early (Ctrl-C, the stream closed)."""


def _free_bytes(path):
    try:
        st = os.statvfs(os.path.dirname(os.path.abspath(path)))
    except (OSError, AttributeError):
        return math.inf
    return st.f_bavail * st.f_frsize


def _partial_name(path):
    """``NAME.partial.EXT`` beside ``path`` (``NAME.partial-1.EXT``, ... if it exists)."""
    stem, ext = os.path.splitext(path)
    name = f"{stem}.partial{ext}"
    k = 1
    while os.path.lexists(name):
        name = f"{stem}.partial-{k}{ext}"
        k += 1
    return name


class VideoOutput:
    """One video file, written safely: a ``cv2.VideoWriter`` on a temporary file beside it.

    Frames go to a new temporary file beside ``path`` (same extension, so the same container).
    :meth:`close` then checks the file -- every frame written must decode from it, since a full
    disk makes ``cv2.VideoWriter`` drop frames silently -- and :meth:`commit` puts it in place
    atomically (:func:`omnicam._atomic.publish`). A run that stopped early (``close(complete=
    False)``, on Ctrl-C) keeps the frames so far: in ``path`` when there was no file there,
    else in ``NAME.partial.EXT`` beside it, never over an earlier file. :meth:`discard` (or any
    failure) removes the temporary file and leaves an earlier ``path`` untouched.

    As a context manager: a normal exit closes and commits, ``KeyboardInterrupt`` keeps the
    frames so far, any other exception discards them.

    Parameters
    ----------
    path : str or os.PathLike
        The video to write.
    size : (int, int)
        ``(width, height)`` of the frames; even (``cv2.VideoWriter`` silently drops an odd
        last row or column).
    fps : float
        Frame rate.
    fourcc : str, sequence of str or None
        The codec, or codecs tried in order (:func:`video_codec`); None: H.264 where the
        container and this OpenCV can, else the container's usual codec.
    color : bool
        Three-channel (BGR) frames, else single-channel.
    overwrite : bool
        Replace an existing ``path`` at :meth:`commit`; False: an existing ``path`` is an
        error, now and (atomically) at :meth:`commit`.

    Attributes
    ----------
    path : str
    size : (int, int)
    fourcc : str
        The codec used (:func:`video_codec`).
    frames : int
        Frames written so far.
    result : WrittenVideo or None
        What :meth:`commit` put in place (None before, or when nothing was kept).

    Raises
    ------
    ValueError
        A bad size or frame rate; :class:`OutputError` when the file cannot be written (the
        folder is missing, no codec works, ``path`` exists and ``overwrite`` is False).
    """

    def __init__(self, path, size, fps, fourcc=None, color=True, overwrite=True):
        self.path = os.fspath(path)
        try:
            self.size = check_frame_size(size)
        except ValueError:
            raise ValueError(
                f"size must be (width, height), two positive integers, got {size!r}"
            ) from None
        check_even_size(self.path, self.size)
        fps = check_fps(fps)
        if os.path.isdir(self.path):
            raise OutputError(f"cannot write video {self.path}: it is a folder")
        if not overwrite and os.path.lexists(self.path):
            raise OutputError(f"cannot write video {self.path}: it exists")
        self.overwrite = bool(overwrite)
        self.fps = float(fps)
        self.fourcc = video_codec(self.path, self.size, self.fps, fourcc, color)
        self.frames = 0
        self.result = None
        self._complete = None  # set by close()
        with sigint_deferred():  # no Ctrl-C between creating the file and owning it
            self.tmp = temp_beside(self.path)
        self._writer = _new_writer(self.tmp, self.fourcc, self.fps, self.size, color)
        if self._writer is None:
            remove_quietly(self.tmp)
            raise OutputError(f"cannot write video {self.path} with codec {self.fourcc}")

    def write(self, frame) -> None:
        """Append one frame (``size``, BGR or grey as ``color``).

        Raises
        ------
        OutputError
            Less than :data:`MIN_FREE_BYTES` are left on the disk (looked at every
            :data:`FREE_SPACE_EVERY` frames); the frames so far stay in the temporary file
            until :meth:`close` or :meth:`discard`.
        """
        self._writer.write(frame)
        self.frames += 1
        if self.frames % FREE_SPACE_EVERY == 0 and _free_bytes(self.tmp) < MIN_FREE_BYTES:
            raise OutputError(
                f"cannot write video {self.path}: no space left on the device after "
                f"{self.frames} frames; the previous file is unchanged"
            )

    def close(self, complete=True, finalize=None) -> int:
        """Finish the file and check it; returns the frames that decode from it.

        Parameters
        ----------
        complete : bool
            The run ended as meant: every frame written must read back, and :meth:`commit`
            replaces ``path``. False: the frames that read back are kept (:meth:`commit`).
        finalize : callable, optional
            ``finalize(tmp)`` on the checked temporary file before it is put in place (to add
            metadata, say); the file must decode as many frames afterwards.

        Raises
        ------
        OutputError
            Frames are missing or the finalized file does not read back; the temporary file
            is removed and an earlier ``path`` is unchanged. An exception of ``finalize`` also
            removes it, and propagates.
        """
        try:
            self._writer.release()
            got = count_frames(self.tmp, self.frames + 1)
            if complete and got != self.frames:
                raise OutputError(
                    f"cannot write video {self.path}: only {got} of {self.frames} frames can be "
                    f"read back (is the disk full?); the previous file is unchanged"
                )
            if got and finalize is not None:
                finalize(self.tmp)
                if count_frames(self.tmp, got + 1) != got:
                    raise OutputError(
                        f"cannot write video {self.path}: the finished file does not read "
                        f"back; the previous file is unchanged"
                    )
        except BaseException:
            self.discard()
            raise
        self.frames, self._complete = got, bool(complete)
        return got

    def commit(self) -> WrittenVideo | None:
        """Put the closed file in place; returns the :class:`WrittenVideo`, or None.

        A complete file replaces ``path`` (if ``overwrite``). The frames of an incomplete run
        go to ``path`` when there is no file there, else to ``NAME.partial.EXT``; no frame at
        all: nothing is kept (None).

        Raises
        ------
        OutputError
            The rename failed, or the target appeared meanwhile where it may not be replaced;
            the temporary file is removed.
        """
        if self._complete is None:
            raise ValueError(f"video {self.path}: close() it before commit()")
        if not self._complete and self.frames == 0:
            self.discard()
            return None
        target, replace = self.path, self.overwrite
        if not self._complete:
            replace = False
            if os.path.lexists(target):
                target = _partial_name(self.path)
        try:
            with sigint_deferred():
                publish(self.tmp, target, replace)
        except OSError as e:
            raise OutputError(f"cannot write video {target}: {e.strerror or e}") from None
        finally:
            remove_quietly(self.tmp)
        self.result = WrittenVideo(target, self.frames, self.fourcc, self._complete)
        return self.result

    def discard(self) -> None:
        """Stop and remove the temporary file; an earlier ``path`` is unchanged."""
        with contextlib.suppress(cv2.error):
            self._writer.release()
        remove_quietly(self.tmp)

    def __enter__(self) -> VideoOutput:
        return self

    def __exit__(self, kind, value, traceback) -> Literal[False]:
        if kind is not None and not issubclass(kind, KeyboardInterrupt):
            self.discard()
            return False
        self.close(complete=kind is None)
        self.commit()
        return False
