"""Unwarp frame after frame: one or more views' remap tables applied with ``cv2.remap``.

The tables are built once (:mod:`omnicam.views`, paper section 4.1); each frame then costs one
``cv2.remap`` per view into a preallocated output, so the per-frame overhead over bare
``cv2.remap`` is a few dictionary look-ups. :meth:`Unwarper.stream` reads a ``cv2.VideoCapture``
source (:func:`open_capture`: a file, a camera index or a stream URL), unwarps, writes each view
and yields the frames, so callers can show progress and stop at any time.

Videos are written by :class:`omnicam.video.VideoOutput` (temporary file, every frame read
back, atomic rename; see :mod:`omnicam.video`), one per output. A run that stops early (Ctrl-C,
the caller closing the stream) keeps the frames so far, in the output when there was none, else
in ``NAME.partial.EXT`` beside it; an error removes them and leaves an earlier output intact.
The stream says which codec each output got (``VideoStream.fourcc``).

Frame size: the tables map into a source image of one size. An Unwarper built from a camera
uses ``camera.image_size``, or, with ``frame_size=``, ``camera.scaled(frame_size)`` (the same
sensor at another resolution). A frame of any other size raises ``ValueError``: a crop or a
different camera cannot be told from a rescale, so we do not guess.
"""

from __future__ import annotations

import math
import os
from typing import Literal

import cv2
import numpy as np

from ._typing import Maps, Size
from .video import (
    H264,
    MIN_FREE_BYTES,
    VIDEO_CODECS,
    OutputError,
    VideoOutput,
    WrittenVideo,
    capture_fps,
    check_even_size,
    check_fps,
    check_frame_size,
    codec_candidates,
    count_frames,
    is_capture,
    open_capture,
    video_codec,
)
from .views import PanoramaView, PerspectiveView

# the video names that callers of the Unwarper use are importable from here too
__all__ = [
    "H264",
    "MIN_FREE_BYTES",
    "VIDEO_CODECS",
    "OutputError",
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
            frame_size = check_frame_size(frame_size)
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
            container and this OpenCV can (``.mp4``, ``.m4v``, ``.mov``), else mp4v; VP9, else
            VP8, for ``.webm``; MJPG for ``.avi`` and ``.mkv`` (:data:`VIDEO_CODECS`). The codec
            used is in ``fourcc`` of the returned stream (:func:`omnicam.video.fell_back`: one
            browsers do not play although the container has one they do).
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
            codec_candidates("", fourcc)
        for name, path in outputs.items():
            check_even_size(path, self.view_size(name))
        if fps is not None:
            check_fps(fps)
        if max_frames is not None and not (
            isinstance(max_frames, (int, np.integer)) and max_frames >= 0
        ):
            raise ValueError(f"max_frames must be a non-negative integer, got {max_frames!r}")
        finalize = {} if finalize is None else dict(finalize)
        if set(finalize) - set(outputs) or not all(map(callable, finalize.values())):
            raise ValueError("finalize must map names of outputs to callables f(tmp_path)")
        return outputs, finalize

    def _frames(self, record, source, outputs, fourcc, fps, max_frames, overwrite, finalize):
        own = not is_capture(source)
        cap = open_capture(source)
        videos, ending = {}, "failed"
        try:
            fps = capture_fps(cap) if fps is None else fps
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
