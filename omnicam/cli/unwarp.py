"""``omnicam unwarp``: panoramas and perspective views of images, videos, cameras and streams."""

from __future__ import annotations

import contextlib
import math
import os
import re
import sys
import time

import cv2

from ._common import (
    EXIT_INTERRUPTED,
    EXIT_OK,
    EXIT_USAGE,
    CliError,
    _check_output,
    _count,
    _finite,
    _fourcc,
    _load_camera,
    _one_line,
    _positive,
    _publish,
    _is_image_input,
    _read_image,
    _remove_quietly,
    _size,
    _temp_beside,
    _warn,
    _write_image,
)

# Video containers we write, with the codec used unless --fourcc says otherwise. MJPG in AVI is
# written by OpenCV itself on every build; the others need the FFmpeg backend of the wheels.
VIDEO_FOURCC = {
    ".avi": "MJPG",
    ".mp4": "mp4v",
    ".m4v": "mp4v",
    ".mov": "mp4v",
    ".mkv": "MJPG",
}


def view_from_args(args):
    """The view the command line asks for: a ``PanoramaView`` or ``PerspectiveView``.

    Options of the other kind of view are refused rather than ignored; the view classes check
    the values (sizes, angle ranges, depth), and what they refuse is a usage error too.
    """
    from ..views import PanoramaView, PerspectiveView

    def refuse(given, kind):
        if given:
            verb = "only apply" if len(given) > 1 else "only applies"
            raise CliError(f"{', '.join(given)} {verb} to --{kind}", EXIT_USAGE)

    try:
        if args.panorama is not None:
            refuse(
                [
                    o
                    for o, v in (
                        ("--fov", args.fov),
                        ("--yaw", args.yaw),
                        ("--pitch", args.pitch),
                        ("--roll", args.roll),
                    )
                    if v is not None
                ],
                "perspective",
            )
            return PanoramaView(
                args.panorama,
                elevation_range=args.elevation,
                projection=args.projection or "cylindrical",
                depth=args.depth,
            )
        refuse(
            [
                o
                for o, v in (
                    ("--elevation", args.elevation),
                    ("--projection", args.projection),
                )
                if v is not None
            ],
            "panorama",
        )
        if args.fov is None:
            raise CliError(
                "--perspective needs --fov DEG (horizontal field of view)", EXIT_USAGE
            )
        return PerspectiveView(
            args.perspective,
            fov=args.fov,
            yaw=args.yaw or 0.0,
            pitch=args.pitch or 0.0,
            roll=args.roll or 0.0,
            depth=args.depth,
        )
    except ValueError as e:
        option = "--panorama" if args.panorama is not None else "--perspective"
        raise CliError(f"{option}: {_one_line(e)}", EXIT_USAGE) from None


def _unwarper(camera, view, frame_size):
    """An :class:`~omnicam.stream.Unwarper` of ``view``, its tables for frames of ``frame_size``
    (``camera.scaled`` when the calibration was made at another resolution)."""
    from ..stream import Unwarper

    size = camera.image_size
    if size is not None and size != tuple(frame_size):
        if (
            abs(frame_size[0] * size[1] - frame_size[1] * size[0])
            > 0.01 * size[0] * size[1]
        ):
            _warn(
                f"frames are {frame_size[0]}x{frame_size[1]} but the calibration is for "
                f"{size[0]}x{size[1]}, another aspect ratio: assuming the same sensor "
                f"rescaled (not a crop)"
            )
    try:
        return Unwarper.from_camera(camera, {"view": view}, frame_size=frame_size)
    except ValueError as e:
        raise CliError(f"cannot build the view: {_one_line(e)}") from None


def _is_device_or_url(spec):
    return spec.isdigit() or "://" in spec


def _is_sequence(spec):
    """An image sequence pattern such as ``frames/img_%04d.png`` (read by cv2.VideoCapture)."""
    return re.search(r"%0?\d*d", spec) is not None and not os.path.exists(spec)


def cmd_unwarp(args):
    view = view_from_args(args)
    source, output = args.input, args.output
    if not (_is_device_or_url(source) or _is_sequence(source)):
        if not os.path.exists(source):
            raise CliError(f"input {source} does not exist")
        if not os.path.isfile(source):
            raise CliError(f"input {source} is not a file")
        if os.path.exists(output) and os.path.samefile(source, output):
            raise CliError(f"output {output} is the input")
    _check_output(output, args.overwrite)
    camera = _load_camera(args.calibration)

    if not (_is_device_or_url(source) or _is_sequence(source)) and _is_image_input(source):
        return _unwarp_image(args, view, camera)
    return _unwarp_video(args, view, camera)


def _unwarp_image(args, view, camera):
    if not cv2.haveImageWriter(args.output):
        ext = os.path.splitext(args.output)[1]
        hint = " (the input is an image)" if ext.lower() in VIDEO_FOURCC else ""
        raise CliError(
            f"output {args.output}: no image writer for extension "
            f"{ext or '(none)'!r}{hint}"
        )
    image = _read_image(args.input)
    out = _unwarper(camera, view, (image.shape[1], image.shape[0])).unwarp(image)[
        "view"
    ]
    _write_image(args.output, out, args.overwrite)
    if not args.quiet:
        print(f"wrote {args.output} ({out.shape[1]}x{out.shape[0]})")
    return EXIT_OK


class Progress:
    """A one-line progress bar on stderr (``\\r`` text): frames, percentage, frames per second."""

    def __init__(self, total=None, stream=None, enabled=True, interval=0.25):
        self.total = total if total and total > 0 else None
        self.stream = stream or sys.stderr
        self.enabled = enabled
        self.interval = interval
        self.start = time.perf_counter()
        self.last = -math.inf
        self.frames = 0
        self.width = 0

    def fps(self):
        elapsed = time.perf_counter() - self.start
        return self.frames / elapsed if elapsed > 0 else 0.0

    def update(self, frames, force=False):
        self.frames = frames
        now = time.perf_counter()
        if not self.enabled or (not force and now - self.last < self.interval):
            return
        self.last = now
        if self.total:
            bar_len = 24
            done = min(frames / self.total, 1.0)
            fill = int(round(done * bar_len))
            text = (
                f"[{'#' * fill}{'.' * (bar_len - fill)}] {frames}/{self.total} frames "
                f"{100 * done:3.0f}%  {self.fps():6.1f} fps"
            )
        else:
            text = f"{frames} frames  {self.fps():6.1f} fps"
        self.stream.write("\r" + text.ljust(self.width))
        self.width = len(text)
        self.stream.flush()

    def close(self):
        if self.enabled:
            self.update(self.frames, force=True)
            self.stream.write("\n")
            self.stream.flush()


def _open_capture(source):
    target = int(source) if source.isdigit() else source
    try:
        cap = cv2.VideoCapture(target)
        opened = cap.isOpened()
    except cv2.error:
        opened = False
    if not opened:
        if source.isdigit():
            raise CliError(f"cannot open camera {source}")
        if "://" in source:
            raise CliError(f"cannot open stream {source}")
        raise CliError(
            f"cannot open input {source}: not an image or video OpenCV can read"
        )
    return cap


def _unwarp_video(args, view, camera):
    output = args.output
    ext = os.path.splitext(output)[1].lower()
    fourcc = args.fourcc or VIDEO_FOURCC.get(ext)
    if fourcc is None:
        raise CliError(
            f"output {output}: the input is a video; use a video extension "
            f"({', '.join(VIDEO_FOURCC)})"
        )
    cap = _open_capture(args.input)
    try:
        frame_size = _frame_size(cap, args.input)
        count = cap.get(cv2.CAP_PROP_FRAME_COUNT)
        declared = int(count) if math.isfinite(count) and count > 0 else 0  # 0: unknown
        fps = cap.get(cv2.CAP_PROP_FPS)
        if not (math.isfinite(fps) and 0 < fps < 1000):
            fps = 30.0
        unwarper = _unwarper(camera, view, frame_size)
        tmp = _temp_beside(output)
        try:
            _check_writer(tmp, fourcc, fps, unwarper.view_size("view"), output)
            written, stop = _stream(unwarper, cap, tmp, fourcc, fps, declared, args)
        except BaseException:
            _remove_quietly(tmp)
            raise
    finally:
        cap.release()
    if (
        stop == "interrupted"
    ):  # Ctrl-C may have come between a frame's write and its count
        written = max(written, _frame_count(tmp))
    _publish(tmp, output, args.overwrite)
    if stop == "interrupted":
        _warn(f"interrupted: kept the {written} frames written so far in {output}")
        return EXIT_INTERRUPTED
    if stop == "truncated":
        _warn(
            f"input ended after {written} of its {declared} frames (truncated, or a "
            f"frame it cannot decode); kept them in {output}"
        )
    elif not args.quiet:
        w, h = unwarper.view_size("view")
        print(f"wrote {output} ({written} frames, {w}x{h})")
    return EXIT_OK


def _frame_size(cap, source):
    """``(width, height)`` of the frames, from the capture's properties or, if it has none, from
    one frame read (a live source drops it; a file is reopened to start again)."""
    w, h = cap.get(cv2.CAP_PROP_FRAME_WIDTH), cap.get(cv2.CAP_PROP_FRAME_HEIGHT)
    if math.isfinite(w) and math.isfinite(h) and w >= 1 and h >= 1:
        return int(w), int(h)
    ok, frame = cap.read()
    if not ok or frame is None:
        raise CliError(f"cannot read a frame from {source}")
    if not _is_device_or_url(source):
        cap.open(source)
    return frame.shape[1], frame.shape[0]


def _frame_count(path):
    """Frames a finished video file declares (0 if it cannot say)."""
    cap = cv2.VideoCapture(path)
    try:
        n = cap.get(cv2.CAP_PROP_FRAME_COUNT) if cap.isOpened() else 0
    finally:
        cap.release()
    return int(n) if math.isfinite(n) and n > 0 else 0


def _check_writer(tmp, fourcc, fps, size, output):
    """Fail early, with a clear message, if ``cv2.VideoWriter`` cannot write this output."""
    if size[0] % 2 or size[1] % 2:
        raise CliError(
            f"video {output}: the view is {size[0]}x{size[1]}; video needs an even "
            f"width and height (cv2.VideoWriter drops an odd last row or column)"
        )
    try:
        writer = cv2.VideoWriter(tmp, cv2.VideoWriter_fourcc(*fourcc), fps, size)
        ok = writer.isOpened()
        writer.release()
    except cv2.error:
        ok = False
    if not ok:
        raise CliError(
            f"cannot write video {output} with codec {fourcc}; try --fourcc or "
            f"another extension"
        )


def _stream(unwarper, cap, tmp, fourcc, fps, declared, args):
    """Unwarp frames into ``tmp`` until the input ends, ``--max-frames`` or Ctrl-C.

    ``declared`` is the input's frame count (0 if unknown): ending before it is a truncation.
    Returns ``(frames_written, how)`` with ``how`` one of ``"end"``, ``"truncated"``,
    ``"interrupted"``; the writer is released (the file finalised) in every case, by
    :meth:`Unwarper.stream` when its generator ends or is closed.
    """
    total = min(declared or args.max_frames or 0, args.max_frames or declared)
    progress = Progress(total, enabled=not args.quiet)
    frames = unwarper.stream(
        cap, outputs={"view": tmp}, fourcc=fourcc, fps=fps, max_frames=args.max_frames
    )
    written, how = 0, "end"
    try:
        with contextlib.closing(frames):
            for index, _ in frames:
                written = index + 1
                progress.update(written)
    except KeyboardInterrupt:
        how = "interrupted"
    except ValueError as e:  # e.g. a frame of another size than the capture announced
        raise CliError(f"cannot unwarp {args.input}: {_one_line(e)}") from None
    finally:
        progress.close()
    if written == 0:
        raise CliError(f"cannot read a frame from {args.input}")
    if (
        how == "end"
        and written < declared
        and not (args.max_frames and written >= args.max_frames)
    ):
        how = "truncated"
    return written, how


def add_parser(sub):
    """Register the ``unwarp`` subcommand on ``sub`` (argparse sub-parsers)."""
    p = sub.add_parser(
        "unwarp",
        help="panorama or perspective view of an image or a video",
        description="Unwarp an image, a video file, a camera index or a stream "
        "URL into a panorama or a virtual perspective view.",
    )
    p.add_argument(
        "input",
        metavar="INPUT",
        help="image or video file, image sequence (img_%%04d.png), camera index "
        "(0, 1, ...) or stream URL",
    )
    p.add_argument(
        "-c",
        "--calibration",
        required=True,
        metavar="CALIB",
        help="calibration file written by 'omnicam calibrate'",
    )
    view = p.add_mutually_exclusive_group(required=True)
    view.add_argument(
        "--panorama", type=_size, metavar="WxH", help="panorama of this size"
    )
    view.add_argument(
        "--perspective",
        type=_size,
        metavar="WxH",
        help="virtual perspective view of this size (needs --fov)",
    )
    p.add_argument(
        "--elevation",
        nargs=2,
        type=_finite,
        metavar=("LO", "HI"),
        help="panorama elevation range in degrees (default: what the mirror sees)",
    )
    p.add_argument(
        "--projection",
        choices=("cylindrical", "equirectangular"),
        help="panorama rows linear in tan(elevation) or in elevation "
        "(default cylindrical)",
    )
    p.add_argument(
        "--fov",
        type=_finite,
        metavar="DEG",
        help="horizontal field of view of the perspective view, degrees",
    )
    p.add_argument(
        "--yaw",
        type=_finite,
        metavar="Y",
        help="perspective view: turn right by Y degrees (default 0)",
    )
    p.add_argument(
        "--pitch",
        type=_finite,
        metavar="P",
        help="perspective view: look up by P degrees (default 0)",
    )
    p.add_argument(
        "--roll",
        type=_finite,
        metavar="R",
        help="perspective view: turn the image clockwise by R degrees (default 0)",
    )
    p.add_argument(
        "--depth",
        type=_positive,
        metavar="MM",
        help="map the scene at this distance from the best-fit viewpoint "
        "(default: at infinity)",
    )
    p.add_argument(
        "-o",
        "--output",
        required=True,
        metavar="OUTPUT",
        help="output image, or video (.avi, .mp4, .m4v, .mov, .mkv) for a video input",
    )
    p.add_argument(
        "--overwrite", action="store_true", help="replace OUTPUT if it exists"
    )
    p.add_argument(
        "--max-frames",
        type=_count,
        metavar="N",
        help="video: stop after N frames (useful with a camera)",
    )
    p.add_argument(
        "--fourcc",
        type=_fourcc,
        metavar="CODE",
        help="video codec FourCC (default MJPG for .avi/.mkv, mp4v for .mp4/.mov)",
    )
    p.add_argument("-q", "--quiet", action="store_true", help="no progress bar")
    p.set_defaults(func=cmd_unwarp)
    return p
