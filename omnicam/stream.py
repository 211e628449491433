"""Unwarp frame after frame: one or more views' remap tables applied with ``cv2.remap``.

The tables are built once (:mod:`omnicam.views`, paper section 4.1); each frame then costs one
``cv2.remap`` per view into a preallocated output, so the per-frame overhead over bare
``cv2.remap`` is a few dictionary look-ups. :meth:`Unwarper.stream` reads a ``cv2.VideoCapture``
source (a file, a camera index or a stream URL), unwarps, writes each view with
``cv2.VideoWriter`` and yields the frames, so callers can show progress and stop at any time.

Frame size: the tables map into a source image of one size. An Unwarper built from a camera
uses ``camera.image_size``, or, with ``frame_size=``, ``camera.scaled(frame_size)`` (the same
sensor at another resolution). A frame of any other size raises ``ValueError``: a crop or a
different camera cannot be told from a rescale, so we do not guess.
"""

from __future__ import annotations

import math
import os

import cv2
import numpy as np

from .views import PanoramaView, PerspectiveView

__all__ = ["Unwarper", "open_capture"]

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


def open_capture(source):
    """A ``cv2.VideoCapture`` that is open, or ``ValueError``.

    Parameters
    ----------
    source : int, str, os.PathLike or cv2.VideoCapture
        A camera index, a video file, an image sequence pattern or a stream URL, or a
        capture that is already open.
    """
    if isinstance(source, cv2.VideoCapture):
        cap = source
    elif isinstance(source, (int, np.integer)) and not isinstance(source, bool):
        cap = cv2.VideoCapture(int(source))
    elif isinstance(source, (str, os.PathLike)):
        src = os.fspath(source)
        if "://" not in src and "%" not in src and not os.path.exists(src):
            raise ValueError(f"source {src}: no such file")
        cap = cv2.VideoCapture(src)
    else:
        raise ValueError(
            f"source must be a camera index, a path, a URL or a cv2.VideoCapture, got {source!r}"
        )
    if not cap.isOpened():
        raise ValueError(f"source {source!r}: cannot be opened by cv2.VideoCapture")
    return cap


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
    def from_camera(cls, camera, views, frame_size=None, m1type=cv2.CV_16SC2, **kwargs):
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
    def names(self):
        """View names, in order."""
        return list(self._maps)

    @property
    def maps(self):
        """dict of name -> (map1, map2)."""
        return dict(self._maps)

    @property
    def source_size(self):
        """(width, height) of the frames the tables are for, or None."""
        return self._source_size

    def view_size(self, name):
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
            A frame of ``source_size`` (any dtype ``cv2.remap`` takes).
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
    def stream(self, source, outputs=None, fourcc="mp4v", fps=None, max_frames=None):
        """Read, unwarp and write frames; a generator yielding ``(index, views)`` per frame.

        Parameters
        ----------
        source : int, str, os.PathLike or cv2.VideoCapture
            See :func:`open_capture`.
        outputs : dict of str -> path, optional
            View name -> video file written with ``cv2.VideoWriter`` (opened at the first
            frame; the container follows the extension).
        fourcc : str
            Four-character codec code for the writers.
        fps : float, optional
            Frame rate of the outputs; default the source's, or 30 if it has none.
        max_frames : int, optional
            Stop after this many frames.

        Yields
        ------
        index : int
        views : dict of str -> ndarray
            As :meth:`unwarp` (overwritten by the next frame).

        Notes
        -----
        The writers, and the capture if this opened it, are released when the source ends,
        when the caller stops iterating and closes the generator (``gen.close()``, or
        ``contextlib.closing``), or on an exception, so the frames written so far stay a valid
        file. Writing to temporary files and renaming them is the caller's business.
        """
        outputs = {} if outputs is None else dict(outputs)
        unknown = set(outputs) - set(self._maps)
        if unknown:
            raise ValueError(
                f"outputs name unknown view(s) {sorted(unknown)}; views are {self.names}"
            )
        if not (isinstance(fourcc, str) and len(fourcc) == 4):
            raise ValueError(f"fourcc must be a 4-character code, got {fourcc!r}")
        odd = {n: self.view_size(n) for n in outputs if any(v % 2 for v in self.view_size(n))}
        if odd:
            raise ValueError(
                f"video outputs need an even width and height (cv2.VideoWriter "
                f"silently drops an odd last row or column); got {odd}"
            )
        own = not isinstance(source, cv2.VideoCapture)
        cap = open_capture(source)
        writers = {}
        try:
            if fps is None:
                fps = cap.get(cv2.CAP_PROP_FPS)
                if not (fps and np.isfinite(fps) and fps > 0):
                    fps = 30.0
            i = 0
            while max_frames is None or i < max_frames:
                ok, frame = cap.read()
                if not ok or frame is None:
                    break
                views = self.unwarp(frame)
                if outputs and not writers:
                    color = frame.ndim == 3 and frame.shape[2] == 3
                    for name, path in outputs.items():
                        w = cv2.VideoWriter(
                            os.fspath(path),
                            cv2.VideoWriter_fourcc(*fourcc),
                            float(fps),
                            self.view_size(name),
                            color,
                        )
                        writers[name] = w
                        if not w.isOpened():
                            raise ValueError(
                                f"output {os.fspath(path)}: cv2.VideoWriter cannot "
                                f"write it (fourcc {fourcc!r})"
                            )
                for name, w in writers.items():
                    w.write(views[name])
                yield i, views
                i += 1
        finally:
            if own:
                cap.release()
            for w in writers.values():
                w.release()

    def run(self, source, outputs, **kwargs) -> int:
        """Unwarp a whole source into ``outputs`` (see :meth:`stream`); returns the frame count."""
        return sum(1 for _ in self.stream(source, outputs, **kwargs))
