"""Unwarp frame after frame: one or more views' remap tables applied with ``cv2.remap``.

The tables are built once (:mod:`omnicam.views`, paper section 4.1); each frame then costs one
``cv2.remap`` per view into a preallocated output, so the per-frame overhead over bare
``cv2.remap`` is a few dictionary look-ups. :meth:`Unwarper.stream` reads a ``cv2.VideoCapture``
source (:func:`open_capture`: a file, a camera index or a stream URL), unwarps, writes each view
and yields the frames, so callers can show progress and stop at any time.

Videos are written safely (:class:`VideoOutput`, the one video writer of omnicam, used by
``omnicam unwarp`` too): frames go to a temporary file beside the output; at the end the file is
read back and must decode every frame written (a full disk makes ``cv2.VideoWriter`` drop
frames silently), and only then replaces the output, atomically. A run that stops early (Ctrl-C,
the caller closing the stream) keeps the frames so far, in the output when there was none, else
in ``NAME.partial.EXT`` beside it; an error removes them and leaves an earlier output intact.
The codec is H.264 where the container and the installed OpenCV can write it (browsers play
it), else the container's usual one (:data:`VIDEO_CODECS`), checked by writing a frame
(:func:`video_codec`); the stream says which (``VideoStream.fourcc``).

Frame size: the tables map into a source image of one size. An Unwarper built from a camera
uses ``camera.image_size``, or, with ``frame_size=``, ``camera.scaled(frame_size)`` (the same
sensor at another resolution). A frame of any other size raises ``ValueError``: a crop or a
different camera cannot be told from a rescale, so we do not guess.
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
from ._typing import Maps, Size
from .views import PanoramaView, PerspectiveView

__all__ = [
    "MIN_FREE_BYTES",
    "VIDEO_CODECS",
    "Unwarper",
    "VideoOutput",
    "VideoStream",
    "WrittenVideo",
    "count_frames",
    "open_capture",
    "video_codec",
]

_INTERPOLATIONS = (cv2.INTER_NEAREST, cv2.INTER_LINEAR, cv2.INTER_CUBIC, cv2.INTER_LANCZOS4)
_BORDERS = (
    cv2.BORDER_CONSTANT,
    cv2.BORDER_REPLICATE,
    cv2.BORDER_REFLECT,
    cv2.BORDER_WRAP,
    cv2.BORDER_REFLECT_101,
    cv2.BORDER_TRANSPARENT,
)


def _check_maps(name, maps):
    try:
        map1, map2 = maps
    except (TypeError, ValueError):
        raise ValueError(f"view {name!r}: maps must be a pair (map1, map2)") from None
    if not isinstance(map1, np.ndarray) or map1.ndim not in (2, 3) or map1.size == 0:
        raise ValueError(f"view {name!r}: map1 must be a non-empty 2-D or (h, w, 2) array")
    h, w = map1.shape[:2]
    if map1.ndim == 3 and map1.shape[2] == 2 and map1.dtype == np.int16:
        if map2 is not None and (
            not isinstance(map2, np.ndarray) or map2.dtype != np.uint16 or map2.shape != (h, w)
        ):
            raise ValueError(
                f"view {name!r}: a CV_16SC2 map1 needs map2 uint16 of shape {(h, w)} or None"
            )
    elif map1.ndim == 3 and map1.shape[2] == 2 and map1.dtype == np.float32:
        if map2 is not None:
            raise ValueError(f"view {name!r}: a CV_32FC2 map1 takes map2=None")
    elif map1.ndim == 2 and map1.dtype == np.float32:
        if not isinstance(map2, np.ndarray) or map2.dtype != np.float32 or map2.shape != (h, w):
            raise ValueError(f"view {name!r}: a CV_32FC1 map1 needs map2 float32 of shape {(h, w)}")
    else:
        raise ValueError(
            f"view {name!r}: map1 must be CV_16SC2, CV_32FC1 or CV_32FC2 "
            f"(as cv2.convertMaps), got {map1.dtype} of shape {map1.shape}"
        )
    return map1, map2


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
    if _is_capture(source):
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


def _is_capture(source):
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


def _check_border_value(value):
    """``border_value`` as 4 floats (``cv2.remap``'s scalar), or ``ValueError`` naming it."""
    values = (value,) if np.isscalar(value) else value
    try:
        out = tuple(values)
        ok = 1 <= len(out) <= 4 and all(
            isinstance(v, (int, float, np.integer, np.floating))
            and not isinstance(v, bool)
            and math.isfinite(float(v))
            for v in out
        )
    except TypeError:
        ok = False
    if not ok:
        raise ValueError(
            f"border_value must be a finite number or 1 to 4 finite numbers (one "
            f"per channel, as cv2.remap's borderValue), got {value!r}"
        )
    out = tuple(float(v) for v in out)
    return out * 4 if len(out) == 1 else out + (0.0,) * (4 - len(out))


def _check_frame_size(frame_size):
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


#: The dtypes ``cv2.remap`` takes.
_REMAP_DTYPES = tuple(np.dtype(t) for t in (np.uint8, np.uint16, np.int16, np.float32, np.float64))


class Unwarper:
    """Named views' remap tables, applied to frames with ``cv2.remap`` into preallocated outputs.

    Parameters
    ----------
    maps : dict of str -> (map1, map2)
        Tables as :func:`omnicam.views.init_panorama_maps` returns them (any ``m1type``).
    source_size : (int, int) or None
        ``(width, height)`` of the frames the tables are for; frames of another size raise
        ``ValueError``. ``None`` accepts any frame.
    interpolation : int
        ``cv2.INTER_NEAREST``, ``INTER_LINEAR`` (default), ``INTER_CUBIC`` or ``INTER_LANCZOS4``.
    border_mode : int
        ``cv2.BORDER_*``; the default ``BORDER_CONSTANT`` paints what the mirror does not see.
    border_value : scalar or tuple
        Colour of that border.

    Notes
    -----
    :meth:`unwarp` returns the *same* output arrays every frame (they are overwritten by the
    next one); copy a view to keep it.
    """

    def __init__(
        self,
        maps,
        source_size=None,
        interpolation=cv2.INTER_LINEAR,
        border_mode=cv2.BORDER_CONSTANT,
        border_value=0,
    ):
        if not isinstance(maps, dict) or not maps:
            raise ValueError("maps must be a non-empty dict of name -> (map1, map2)")
        self._maps = {str(k): _check_maps(k, v) for k, v in maps.items()}
        if source_size is not None:
            try:
                w, h = (int(v) for v in source_size)
            except (TypeError, ValueError):
                raise ValueError(
                    f"source_size must be (width, height), got {source_size!r}"
                ) from None
            if w <= 0 or h <= 0:
                raise ValueError(f"source_size must be positive, got {source_size!r}")
            source_size = (w, h)
        self._source_size = source_size
        if interpolation not in _INTERPOLATIONS:
            raise ValueError(
                f"interpolation must be one of cv2.INTER_NEAREST, INTER_LINEAR, "
                f"INTER_CUBIC, INTER_LANCZOS4, got {interpolation!r}"
            )
        if border_mode not in _BORDERS:
            raise ValueError(f"border_mode must be a cv2.BORDER_* constant, got {border_mode!r}")
        self._interp = int(interpolation)
        self._border = int(border_mode)
        self._border_value = _check_border_value(border_value)
        self._out = {}
        self._out_key = None
        # per view: (name, map1, map2, output shape without channels) for the hot loop
        self._plan = [(n, m1, m2, m1.shape[:2]) for n, (m1, m2) in self._maps.items()]

    @classmethod
    def from_camera(cls, camera, views, frame_size=None, m1type=cv2.CV_16SC2, **kwargs) -> Unwarper:
        """Build the tables of ``views`` for ``camera``.

        Parameters
        ----------
        camera : MisalignedHyperbolicCamera
        views : dict of str -> PanoramaView or PerspectiveView
        frame_size : (int, int) or None
            Size of the frames to unwarp. ``None``: ``camera.image_size``. Another size than
            ``camera.image_size``: the tables are built for ``camera.scaled(frame_size)``. A
            camera without ``image_size`` is used as it is, for frames of ``frame_size``.
        m1type : int
            Table type (``cv2.CV_16SC2`` is the fastest to remap).
        **kwargs
            ``interpolation``, ``border_mode``, ``border_value`` of :class:`Unwarper`.
        """
        if not isinstance(views, dict) or not views:
            raise ValueError(
                "views must be a non-empty dict of name -> PanoramaView or PerspectiveView"
            )
        for name, spec in views.items():
            if not isinstance(spec, (PanoramaView, PerspectiveView)):
                raise ValueError(
                    f"view {name!r} must be a PanoramaView or PerspectiveView, "
                    f"got {type(spec).__name__}"
                )
        if frame_size is not None:
            frame_size = _check_frame_size(frame_size)
            if camera.image_size is not None and tuple(camera.image_size) != frame_size:
                camera = camera.scaled(frame_size)
        source = frame_size if frame_size is not None else camera.image_size
        maps = {name: spec.maps(camera, m1type) for name, spec in views.items()}
        return cls(maps, source_size=source, **kwargs)

    # -- properties ---------------------------------------------------------------------------
    @property
    def names(self) -> list[str]:
        """View names, in order."""
        return list(self._maps)

    @property
    def maps(self) -> dict[str, Maps]:
        """Dict of name -> (map1, map2)."""
        return dict(self._maps)

    @property
    def source_size(self) -> Size | None:
        """(width, height) of the frames the tables are for, or None."""
        return self._source_size

    def view_size(self, name) -> Size:
        """(width, height) of view ``name``."""
        h, w = self._maps[name][0].shape[:2]
        return (w, h)

    # -- per frame ----------------------------------------------------------------------------
    def _allocate(self, frame):
        key = (frame.dtype, frame.shape[2:])
        self._out = {
            n: np.empty(shape + frame.shape[2:], frame.dtype) for n, _, _, shape in self._plan
        }
        self._out_key = key

    def unwarp(self, frame: np.ndarray, copy: bool = False) -> dict:
        """All views of one frame.

        The output arrays are allocated once and **reused**: each call overwrites the arrays
        (and returns the same dict) of the previous call, so the per-frame cost is only the
        remaps. Keep a view across frames with ``copy=True`` (or ``view.copy()``).

        Parameters
        ----------
        frame : (H, W) or (H, W, C) ndarray
            A frame of ``source_size``, of a dtype ``cv2.remap`` takes (:data:`_REMAP_DTYPES`).
        copy : bool
            Return new arrays (and a new dict) that later calls do not touch.

        Returns
        -------
        views : dict of str -> ndarray
            The preallocated outputs, overwritten by the next call (unless ``copy``).
        """
        if not isinstance(frame, np.ndarray) or frame.ndim not in (2, 3) or frame.size == 0:
            raise ValueError(
                f"frame must be a non-empty (H, W) or (H, W, C) image array, "
                f"got {type(frame).__name__}"
            )
        if frame.dtype not in _REMAP_DTYPES:
            raise ValueError(
                f"frame has dtype {frame.dtype}, which cv2.remap does not take: give uint8, "
                f"uint16, int16, float32 or float64 (e.g. frame.astype(np.uint8) * 255 for a "
                f"bool mask)"
            )
        if self._source_size is not None and (
            frame.shape[1] != self._source_size[0] or frame.shape[0] != self._source_size[1]
        ):
            raise ValueError(
                f"frame is {frame.shape[1]}x{frame.shape[0]} but the tables are for "
                f"{self._source_size[0]}x{self._source_size[1]} frames; build the "
                f"Unwarper with frame_size=({frame.shape[1]}, {frame.shape[0]})"
            )
        if (
            self._out_key is None
            or self._out_key[0] != frame.dtype
            or self._out_key[1] != frame.shape[2:]
        ):
            self._allocate(frame)
        out = self._out
        interp, border, value = self._interp, self._border, self._border_value
        for name, m1, m2, _ in self._plan:
            cv2.remap(frame, m1, m2, interp, dst=out[name], borderMode=border, borderValue=value)
        if copy:
            return {name: view.copy() for name, view in out.items()}
        return out

    __call__ = unwarp

    # -- video ----------------------------------------------------------------------------------
    def stream(
        self,
        source,
        outputs=None,
        fourcc=None,
        fps=None,
        max_frames=None,
        overwrite=True,
        finalize=None,
    ) -> VideoStream:
        """Read, unwarp and write frames; an iterator of ``(index, views)``, one per frame.

        Each output is a :class:`VideoOutput`: its frames go to a temporary file beside it,
        and only a file from which every frame decodes replaces it, atomically, when the
        source ends or ``max_frames`` is reached. On an exception (a frame of another size, a
        full disk, ...) the temporary files are removed and earlier outputs are unchanged. When
        the run stops early -- ``KeyboardInterrupt`` while reading or writing, or the caller
        closes the stream (``close()``, ``with``, ``contextlib.closing``, or drops it) -- the
        frames so far are kept: in the output when there was none, else in
        ``NAME.partial.EXT`` beside the earlier one, which stays as it was.

        Parameters
        ----------
        source : int, str, os.PathLike or cv2.VideoCapture
            See :func:`open_capture`; a capture passed in is not released.
        outputs : dict of str -> path, optional
            View name -> video file (opened at the first frame; the container follows the
            extension).
        fourcc : str, sequence of str or None
            The codec, or codecs tried in order (:func:`video_codec`); None: H.264 where the
            container and this OpenCV can (``.mp4``, ``.m4v``, ``.mov``), else mp4v; MJPG for
            ``.avi`` and ``.mkv`` (:data:`VIDEO_CODECS`). The codec used is in
            ``fourcc`` of the returned stream.
        fps : float, optional
            Frame rate of the outputs; default the source's, or 30 if it has none.
        max_frames : int, optional
            Stop after this many frames (a complete run).
        overwrite : bool
            Replace existing outputs; False: an existing output is an error.
        finalize : dict of str -> callable, optional
            ``finalize[name](tmp)`` on an output's checked temporary file before it is put in
            place (e.g. to add metadata); see :meth:`VideoOutput.close`.

        Returns
        -------
        stream : VideoStream
            Yields ``(index, views)``, ``views`` as :meth:`unwarp` returns them (overwritten by
            the next frame). ``stream.fourcc`` names the codec of each output (from the first
            frame on), ``stream.written`` what was put where (once it has ended or is closed).

        Notes
        -----
        The capture, if this opened it, and the writers are released when the source ends,
        when the stream is closed, or on an exception. Frames are read when iterated: errors
        about the source or the outputs' files come with the first ``next``.
        """
        outputs, finalize = self._check_outputs(outputs, fourcc, fps, max_frames, finalize)
        record = _Record()
        frames = self._frames(record, source, outputs, fourcc, fps, max_frames, overwrite, finalize)
        return VideoStream(frames, record)

    def _check_outputs(self, outputs, fourcc, fps, max_frames, finalize):
        """``outputs`` and ``finalize`` as dicts, or ``ValueError`` naming what is wrong."""
        try:
            outputs = {} if outputs is None else {str(k): os.fspath(v) for k, v in outputs.items()}
        except (AttributeError, TypeError):
            raise ValueError(
                f"outputs must be a dict of view name -> path, got {outputs!r}"
            ) from None
        unknown = set(outputs) - set(self._maps)
        if unknown:
            raise ValueError(
                f"outputs name unknown view(s) {sorted(unknown)}; views are {self.names}"
            )
        if fourcc is not None:
            _codec_candidates("", fourcc)
        odd = {n: self.view_size(n) for n in outputs if any(v % 2 for v in self.view_size(n))}
        if odd:
            raise ValueError(
                f"video outputs need an even width and height (cv2.VideoWriter "
                f"silently drops an odd last row or column); got {odd}"
            )
        if fps is not None:
            _check_fps(fps)
        if max_frames is not None and not (
            isinstance(max_frames, (int, np.integer)) and max_frames >= 0
        ):
            raise ValueError(f"max_frames must be a non-negative integer, got {max_frames!r}")
        finalize = {} if finalize is None else dict(finalize)
        if set(finalize) - set(outputs) or not all(map(callable, finalize.values())):
            raise ValueError("finalize must map names of outputs to callables f(tmp_path)")
        return outputs, finalize

    def _frames(self, record, source, outputs, fourcc, fps, max_frames, overwrite, finalize):
        own = not _is_capture(source)
        cap = open_capture(source)
        videos, ending = {}, "failed"
        try:
            fps = _capture_fps(cap) if fps is None else fps
            index = 0
            while max_frames is None or index < max_frames:
                ok, frame = cap.read()
                if not ok or frame is None:
                    break
                views = self.unwarp(frame)
                if outputs and not videos:
                    color = frame.ndim == 3 and frame.shape[2] == 3
                    for name, path in outputs.items():  # filled in place: the finally sees them
                        videos[name] = VideoOutput(
                            path, self.view_size(name), fps, fourcc, color, overwrite
                        )
                    record.fourcc = {name: v.fourcc for name, v in videos.items()}
                for name, video in videos.items():
                    video.write(views[name])
                record.frames = index + 1
                yield index, views
                index += 1
            ending = "complete"
        except (KeyboardInterrupt, GeneratorExit):
            ending = "failed" if record.aborted else "partial"
            raise
        finally:
            if own:
                cap.release()
            record.written = _settle(videos, ending, finalize)

    def run(self, source, outputs, **kwargs) -> int:
        """Unwarp a whole source into ``outputs`` (see :meth:`stream`); returns the frame count."""
        return sum(1 for _ in self.stream(source, outputs, **kwargs))


def _check_fps(fps):
    """``fps`` as a positive finite float, or ``ValueError`` naming it."""
    if not (
        isinstance(fps, (int, float, np.integer, np.floating))
        and not isinstance(fps, bool)
        and 0 < float(fps) < math.inf
    ):
        raise ValueError(f"fps must be a positive finite number, got {fps!r}")
    return float(fps)


def _capture_fps(cap):
    """The capture's frame rate, or 30 when it has none (or an implausible one)."""
    fps = cap.get(cv2.CAP_PROP_FPS)
    return float(fps) if math.isfinite(fps) and 0 < fps < 1000 else 30.0


def _settle(videos, ending, finalize):
    """Close the outputs of a stream that ended ``"complete"``, ``"partial"`` or ``"failed"``
    and put them in place (all checked before any is); returns name -> :class:`WrittenVideo`."""
    if ending == "failed":
        for video in videos.values():
            video.discard()
        return {}
    try:
        for name, video in videos.items():
            video.close(ending == "complete", finalize.get(name))
        written = {}
        for name, video in videos.items():
            result = video.commit()
            if result is not None:
                written[name] = result
    except BaseException:
        for video in videos.values():  # those not yet in place
            video.discard()
        raise
    return written


class _Record:
    """What a stream did so far, shared by the generator and its :class:`VideoStream` (which the
    generator must not reference, so that dropping the stream closes it at once)."""

    def __init__(self):
        self.frames = 0
        self.fourcc = {}
        self.written = {}
        self.aborted = False


class VideoStream:
    """The frames of :meth:`Unwarper.stream`: an iterator of ``(index, views)``, and its outputs.

    ``close()`` (or the end of a ``with`` block) stops it and keeps the frames so far;
    ``abort()``, or an exception other than ``KeyboardInterrupt`` leaving a ``with`` block,
    stops it and removes them (earlier outputs unchanged).

    Attributes
    ----------
    frames : int
        Frames unwarped (and written) so far.
    fourcc : dict of str -> str
        The codec of each output (empty before the first frame).
    written : dict of str -> WrittenVideo
        Each output's file once the stream has ended or been closed: path, frames, codec, and
        whether the run was complete. An output of which no frame was kept is absent.
    """

    def __init__(self, frames, record):
        self._frames = frames
        self._record = record

    def __iter__(self) -> VideoStream:
        return self

    def __next__(self) -> tuple[int, dict[str, np.ndarray]]:
        return next(self._frames)

    def close(self) -> None:
        """Stop; the frames so far are kept (see :meth:`Unwarper.stream`)."""
        self._frames.close()

    def abort(self) -> None:
        """Stop; the frames so far are removed and earlier outputs stay as they were."""
        self._record.aborted = True
        self._frames.close()

    def __enter__(self) -> VideoStream:
        return self

    def __exit__(self, kind, value, traceback) -> Literal[False]:
        if kind is not None and not issubclass(kind, KeyboardInterrupt):
            self.abort()
        else:
            self.close()
        return False

    @property
    def frames(self) -> int:
        """Frames unwarped so far."""
        return self._record.frames

    @property
    def fourcc(self) -> dict[str, str]:
        """Dict of output name -> the codec it is written with."""
        return dict(self._record.fourcc)

    @property
    def written(self) -> dict[str, WrittenVideo]:
        """Dict of output name -> :class:`WrittenVideo`, once the stream has ended or closed."""
        return dict(self._record.written)


# -- video files ----------------------------------------------------------------------------------
#: Codecs tried in order, per container, when no ``fourcc`` is given: H.264 first where the
#: container takes it (browsers play it), then what every FFmpeg build of OpenCV writes (mp4v:
#: MPEG-4 Part 2, which many players and no browser play). MJPG is OpenCV's own encoder.
VIDEO_CODECS = {
    ".mp4": ("avc1", "H264", "mp4v"),
    ".m4v": ("avc1", "H264", "mp4v"),
    ".mov": ("avc1", "H264", "mp4v"),
    ".avi": ("MJPG",),
    ".mkv": ("MJPG",),
}
#: Codecs for a container :data:`VIDEO_CODECS` does not name.
OTHER_CODECS = ("avc1", "H264", "mp4v")
#: H.264's FourCCs (the codec browsers play).
H264 = ("avc1", "H264", "h264", "X264", "x264", "avc3")
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


def _codec_candidates(path, fourcc):
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
        container (H.264, then mp4v, for ``.mp4``, ``.m4v`` and ``.mov``), else
        :data:`OTHER_CODECS`.
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
    candidates = _codec_candidates(path, fourcc)
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
            self.size = _check_frame_size(size)
        except ValueError:
            raise ValueError(
                f"size must be (width, height), two positive integers, got {size!r}"
            ) from None
        if any(v % 2 for v in self.size):
            raise ValueError(
                f"video {self.path}: the frames are {self.size[0]}x{self.size[1]}; video needs "
                f"an even width and height (cv2.VideoWriter drops an odd last row or column)"
            )
        fps = _check_fps(fps)
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
