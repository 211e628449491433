"""``omnicam unwarp``: panoramas, perspective and 360 views of images, videos, cameras, streams.

Several views in one call, one decode for all: each ``--panorama``, ``--perspective`` or
``--equirect`` starts a view, and the options after it (``--elevation``, ``--projection``,
``--fov``, ``--yaw``, ``--pitch``, ``--roll``, ``--depth``, ``-o``) belong to it; options given
before the first view belong to the first. Every view has its own ``-o``: an image, a video
(``.avi``, ``.mp4``, ``.m4v``, ``.mov``, ``.mkv``, ``.webm``) or an image sequence
(``out_%04d.png``, frames numbered from 0).

Video outputs are never lost: they are written by :meth:`omnicam.stream.Unwarper.stream`
(:class:`omnicam.video.VideoOutput`), to a temporary file beside the output that must decode
every frame written before it replaces the output. On Ctrl-C the run stops after the current
frame and keeps the frames so far: in the output itself when there was none before (the message
says so), else in ``NAME.partial.EXT`` beside it, leaving the earlier complete output untouched;
exit status 130. A failed write stops with an error and leaves any earlier output intact.
``.mp4``, ``.m4v`` and ``.mov`` get H.264 where the installed OpenCV writes it, else mp4v,
which browsers do not play (one warning line says so, for all such outputs); ``.webm`` gets VP9,
else VP8. The line that names each output says its codec, and for a panorama of the default
band where its lower edge came from (the camera's reflection as the calibration recorded it,
else -60 deg).
"""

from __future__ import annotations

import argparse
import contextlib
import math
import os
import re
import signal
import sys
import threading
import time
import warnings

import cv2

from .._atomic import OutputError, write_bytes
from .._validate import file_path
from ..formats.spherical_metadata import inject_spherical_mp4, jpeg_with_photosphere_xmp
from ..spherical import equirect_view
from ..stream import Unwarper
from ..video import (
    VIDEO_CODECS,
    check_even_size,
    count_frames,
    fell_back,
    open_capture,
    web_codec,
)
from ..views import PanoramaView, PerspectiveView
from ._common import (
    EXIT_FAILURE,
    EXIT_INTERRUPTED,
    EXIT_OK,
    EXIT_USAGE,
    CliError,
    check_output,
    check_video_input,
    count_arg,
    finite_arg,
    fourcc_arg,
    is_image_input,
    load_calibration,
    one_line,
    positive_arg,
    read_image_file,
    size_arg,
    warn_user,
    write_image_file,
)

#: Containers that get the spherical video metadata of an --equirect view.
SPHERICAL_CONTAINERS = (".mp4", ".m4v", ".mov")

VIEW_KINDS = ("panorama", "perspective", "equirect")


# -- the command line: views in order -------------------------------------------------------
class _InOrder(argparse.Action):
    """Record ``(dest, value)`` in command-line order, so options can attach to their view."""

    def __call__(self, parser, namespace, values, option_string=None):
        seq = getattr(namespace, "ordered", None) or []
        seq.append((self.dest, values, option_string))
        namespace.ordered = seq


class ViewSpec:
    """One view of the command line: its kind, size, options and output."""

    def __init__(self, kind, size, flag):
        self.kind, self.size, self.flag = kind, size, flag
        self.options = {}
        self.view = None
        self.output = None
        self.edge = ""  # where a default panorama's lower edge came from (_lower_edge)

    def label(self):
        return f"--{self.kind} {self.size[0]}x{self.size[1]}"


def view_specs(args):
    """The views of the command line, in order, each with its options and output."""
    specs, before = [], []
    for dest, value, flag in getattr(args, "ordered", None) or []:
        if dest in VIEW_KINDS:
            specs.append(ViewSpec(dest, value, flag))
        elif specs:
            _attach(specs[-1], dest, value, flag)
        else:
            before.append((dest, value, flag))
    if not specs:
        raise CliError(
            "give a view: --panorama WxH, --perspective WxH --fov DEG or --equirect WxH", EXIT_USAGE
        )
    for dest, value, flag in before:
        _attach(specs[0], dest, value, flag)
    for i, spec in enumerate(specs):
        spec.output = spec.options.pop("output", None)
        if spec.output is None:
            which = f"view {i + 1} ({spec.label()})" if len(specs) > 1 else spec.label()
            raise CliError(
                f"{which} has no -o OUTPUT; each view takes its own -o after it", EXIT_USAGE
            )
        spec.view = view_from_spec(spec)
    outputs = [os.path.abspath(s.output) for s in specs]
    if len(set(outputs)) != len(outputs):
        raise CliError("two views write the same output; give each view its own -o", EXIT_USAGE)
    return specs


def _attach(spec, dest, value, flag):
    if dest in spec.options:
        raise CliError(f"{flag} given twice for {spec.label()}", EXIT_USAGE)
    spec.options[dest] = value


def view_from_spec(spec):
    """The ``PanoramaView`` or ``PerspectiveView`` a :class:`ViewSpec` asks for.

    Options of another kind of view are refused rather than ignored; the view classes check
    the values (sizes, angle ranges, depth), and what they refuse is a usage error too.
    """
    o = spec.options
    allowed = {
        "panorama": ("elevation", "projection", "depth", "yaw"),
        "perspective": ("fov", "yaw", "pitch", "roll", "depth"),
        "equirect": ("depth", "yaw"),
    }[spec.kind]
    refused = [f"--{k}" for k in o if k not in allowed]
    if refused:
        kinds = {
            "elevation": "--panorama",
            "projection": "--panorama",
            "fov": "--perspective",
            "pitch": "--perspective",
            "roll": "--perspective",
        }
        owner = kinds.get(refused[0][2:], "--panorama")
        verb = "only apply" if len(refused) > 1 else "only applies"
        raise CliError(f"{', '.join(refused)} {verb} to {owner}, not to {spec.flag}", EXIT_USAGE)
    try:
        if spec.kind == "panorama":
            return PanoramaView(
                spec.size,
                elevation_range=o.get("elevation"),
                projection=o.get("projection") or "cylindrical",
                depth=o.get("depth"),
                yaw=o.get("yaw"),
            )
        if spec.kind == "equirect":
            return equirect_view(spec.size, depth=o.get("depth"), yaw=o.get("yaw"))
        if o.get("fov") is None:
            raise CliError("--perspective needs --fov DEG (horizontal field of view)", EXIT_USAGE)
        return PerspectiveView(
            spec.size,
            fov=o["fov"],
            yaw=o.get("yaw") or 0.0,
            pitch=o.get("pitch") or 0.0,
            roll=o.get("roll") or 0.0,
            depth=o.get("depth"),
        )
    except ValueError as e:
        raise CliError(f"{spec.flag}: {one_line(e)}", EXIT_USAGE) from None


def view_from_args(args):
    """The first view of the command line (kept for callers of the one-view CLI)."""
    return view_specs(args)[0].view


def _unwarper(camera, specs, frame_size):
    """An :class:`~omnicam.stream.Unwarper` of the views, its tables for frames of
    ``frame_size`` (``camera.scaled`` when the calibration was made at another resolution).
    A view mostly outside what the mirror sees gives a warning line."""
    size = camera.image_size
    if (
        size is not None
        and size != tuple(frame_size)
        and abs(frame_size[0] * size[1] - frame_size[1] * size[0]) > 0.01 * size[0] * size[1]
    ):
        warn_user(
            f"frames are {frame_size[0]}x{frame_size[1]} but the calibration is for "
            f"{size[0]}x{size[1]}, another aspect ratio: assuming the same sensor "
            f"rescaled (not a crop)"
        )
    views = {str(i): s.view for i, s in enumerate(specs)}
    try:
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always", RuntimeWarning)
            unwarper = Unwarper.from_camera(camera, views, frame_size=frame_size)
    except ValueError as e:
        raise CliError(f"cannot build the view: {one_line(e)}") from None
    for w in caught:
        if issubclass(w.category, RuntimeWarning) and "visible_elevation_range" in str(w.message):
            warn_user(str(w.message))
    if camera.image_size is not None and tuple(camera.image_size) != tuple(frame_size):
        camera = camera.scaled(frame_size)  # the camera the tables were built for
    for spec in specs:
        spec.edge = _lower_edge(camera, spec)
    return unwarper


def _lower_edge(camera, spec):
    """``"; lower edge -38.2 deg: the camera's reflection as detected"`` for a panorama whose
    band is the default (:func:`omnicam.views.default_elevation_range`), else ``""``."""
    band = spec.view.default_range(camera) if spec.kind == "panorama" else None
    return "" if band is None else f"; {band.describe()}"


def _is_device_or_url(spec):
    return spec.isdigit() or "://" in spec


def _is_sequence(spec):
    """An image sequence pattern such as ``frames/img_%04d.png`` (read by cv2.VideoCapture)."""
    return re.search(r"%0?\d*d", spec) is not None and not os.path.exists(spec)


def _output_kind(path, video_input):
    ext = os.path.splitext(path)[1].lower()
    if _is_sequence(path):
        if not cv2.haveImageWriter("x" + ext):
            raise CliError(
                f"output {path}: an image sequence needs an image extension (.png, .jpg, .tif, ...)"
            )
        return "sequence"
    if video_input:
        if ext in VIDEO_CODECS:
            return "video"
        raise CliError(
            f"output {path}: the input is a video; use a video extension "
            f"({', '.join(VIDEO_CODECS)}) or an image sequence (out_%04d.png)"
        )
    if not cv2.haveImageWriter(path):
        hint = " (the input is an image)" if ext in VIDEO_CODECS else ""
        raise CliError(f"output {path}: no image writer for extension {ext or '(none)'!r}{hint}")
    return "image"


def cmd_unwarp(args):
    """``omnicam unwarp``: the module docstring."""
    specs = view_specs(args)
    source = args.input
    live = _is_device_or_url(source) or _is_sequence(source)
    if not live:
        if not os.path.exists(source):
            raise CliError(f"input {source} does not exist")
        if not os.path.isfile(source):
            raise CliError(f"input {source} is not a file")
    video_input = live or not is_image_input(source)
    if video_input and not live:
        check_video_input(source)  # a text file or a broken video: say what it is
    for spec in specs:  # a name that is not UTF-8 crashes OpenCV's writers: refuse it first
        try:
            file_path(spec.output, "output")
        except ValueError as e:
            raise CliError(str(e)) from None
    for spec in specs:
        spec.kind_out = _output_kind(spec.output, video_input)
        if spec.kind_out == "video":  # before the tables are built, which can take seconds
            try:
                check_even_size(spec.output, spec.size)
            except ValueError as e:
                raise CliError(str(e)) from None
        if not live and os.path.exists(spec.output) and os.path.samefile(source, spec.output):
            raise CliError(f"output {spec.output} is the input")
        target = _sequence_name(spec.output, 0) if spec.kind_out == "sequence" else spec.output
        check_output(target, args.overwrite)
    camera = load_calibration(args.calibration, say_doubt=True)  # one line on a doubtful file
    if not video_input:
        return _unwarp_image(args, specs, camera)
    return _unwarp_video(args, specs, camera)


def _sequence_name(pattern, index):
    return re.sub(r"%0?\d*d", lambda m: m.group(0) % index, pattern, count=1)


def _write_equirect_jpeg(path, image, size, overwrite):
    ok, jpg = cv2.imencode(".jpg", image, [cv2.IMWRITE_JPEG_QUALITY, 95])
    if not ok:
        raise CliError(f"cannot encode {path} as JPEG")
    data = jpeg_with_photosphere_xmp(jpg.tobytes(), size)

    def verify(tmp):
        back = cv2.imread(tmp, cv2.IMREAD_UNCHANGED)
        return back is not None and back.shape[:2] == image.shape[:2]

    try:
        write_bytes(path, data, what="image", overwrite=overwrite, verify=verify)
    except OutputError as e:
        raise CliError(str(e)) from None


def _write_view_image(spec, path, image, overwrite):
    is_jpeg = os.path.splitext(path)[1].lower() in (".jpg", ".jpeg")
    if spec.kind == "equirect" and is_jpeg:
        _write_equirect_jpeg(path, image, spec.size, overwrite)
    else:
        write_image_file(path, image, overwrite)


def _unwarp_image(args, specs, camera):
    image = read_image_file(args.input)
    views = _unwarper(camera, specs, (image.shape[1], image.shape[0])).unwarp(image)
    for i, spec in enumerate(specs):
        out = views[str(i)]
        path = _sequence_name(spec.output, 0) if spec.kind_out == "sequence" else spec.output
        _write_view_image(spec, path, out, args.overwrite)
        if spec.kind == "equirect" and os.path.splitext(path)[1].lower() not in (".jpg", ".jpeg"):
            warn_user(f"{path}: Photo Sphere metadata is written into .jpg outputs only")
        if not args.quiet:
            print(f"wrote {path} ({out.shape[1]}x{out.shape[0]}{spec.edge})")
    return EXIT_OK


class Progress:
    r"""A one-line progress bar on stderr (``\r`` text): frames, percentage, frames per second."""

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
        """Frames per second so far."""
        elapsed = time.perf_counter() - self.start
        return self.frames / elapsed if elapsed > 0 else 0.0

    def update(self, frames, force=False):
        """Show ``frames`` done (at most a few times a second unless ``force``)."""
        self.frames = frames
        now = time.perf_counter()
        if not self.enabled or (not force and now - self.last < self.interval):
            return
        self.last = now
        if self.total:
            bar_len = 24
            done = min(frames / self.total, 1.0)
            fill = round(done * bar_len)
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
        """End the bar's line."""
        if self.enabled and self.width:  # nothing drawn (no frame): nothing to end
            self.update(self.frames, force=True)
            self.stream.write("\n")
            self.stream.flush()


def _open_capture(source):
    """:func:`omnicam.video.open_capture` of the command's INPUT (digits: a camera index)."""
    try:
        return open_capture(int(source) if source.isdigit() else source)
    except ValueError as e:
        raise CliError(one_line(e)) from None


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


@contextlib.contextmanager
def _ctrl_c_stops(flag):
    """While streaming, the first Ctrl-C asks the loop to stop after the current frame (no
    exception anywhere in OpenCV or in a rename); a second one interrupts at once."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return

    def on_sigint(signum, frame):
        if flag["stop"]:
            raise KeyboardInterrupt
        flag["stop"] = True

    previous = signal.signal(signal.SIGINT, on_sigint)
    try:
        yield
    finally:
        signal.signal(signal.SIGINT, previous)


def _unwarp_video(args, specs, camera):
    flag = {"stop": False}
    with _ctrl_c_stops(flag):
        return _unwarp_video_guarded(args, specs, camera, flag)


def _unwarp_video_guarded(args, specs, camera, flag):
    """Unwarp a video input through :meth:`omnicam.stream.Unwarper.stream`, which writes the
    video outputs safely; image sequences and previews are written here, frame by frame."""
    cap = _open_capture(args.input)
    try:
        frame_size = _frame_size(cap, args.input)
        count = cap.get(cv2.CAP_PROP_FRAME_COUNT)
        declared = int(count) if math.isfinite(count) and count > 0 else 0  # 0: unknown
        unwarper = _unwarper(camera, specs, frame_size)
        outputs = {str(i): s.output for i, s in enumerate(specs) if s.kind_out == "video"}
        finalize = {
            name: _spherical_metadata(specs[int(name)].output)
            for name in outputs
            if specs[int(name)].kind == "equirect"
        }
        try:
            stream = unwarper.stream(
                cap,
                outputs,
                fourcc=args.fourcc,
                max_frames=args.max_frames,
                overwrite=args.overwrite,
                finalize=finalize,
            )
        except ValueError as e:
            raise CliError(one_line(e)) from None
        written, how = _stream(stream, specs, declared, args, flag)
    finally:
        cap.release()
    return _finish(args, specs, stream, written, how, declared)


def _stream(stream, specs, declared, args, flag):
    """Run ``stream`` until the input ends, ``--max-frames``, Ctrl-C or a full disk, writing the
    image sequences and previews of each frame.

    Returns ``(frames, how)``, ``how`` one of ``"end"``, ``"truncated"``, ``"interrupted"``.
    """
    total = min(declared or args.max_frames or 0, args.max_frames or declared)
    progress = Progress(total, enabled=not args.quiet)
    how = "interrupted" if flag["stop"] else "end"  # a Ctrl-C while the tables were built
    try:
        with stream:  # an error in the loop removes the videos' frames; Ctrl-C keeps them
            for index, views in stream if how == "end" else ():
                _write_frame_images(specs, views, index, args)
                progress.update(index + 1)
                if flag["stop"]:
                    how = "interrupted"
                    break
    except KeyboardInterrupt:
        how = "interrupted"
    except OutputError as e:
        raise CliError(one_line(e)) from None
    except ValueError as e:  # e.g. a frame of another size than the capture announced
        raise CliError(f"cannot unwarp {args.input}: {one_line(e)}") from None
    finally:
        progress.close()
    written = stream.frames
    if written == 0 and how != "interrupted":
        raise CliError(f"cannot read a frame from {args.input}")
    if how == "end" and written < declared and not (args.max_frames and written >= args.max_frames):
        how = "truncated"
    return written, how


def _write_frame_images(specs, views, index, args):
    """The frame's image of each image-sequence view, and the previews due."""
    for i, spec in enumerate(specs):
        image = views[str(i)]
        if spec.kind_out == "sequence":
            _write_view_image(spec, _sequence_name(spec.output, index), image, args.overwrite)
        if args.preview and index % args.preview == 0:
            write_image_file(_preview_name(spec.output, index), image, True)


def _preview_name(output, index):
    stem = (
        re.split(r"%0?\d*d", output, maxsplit=1)[0]
        if _is_sequence(output)
        else os.path.splitext(output)[0]
    )
    return f"{stem.rstrip('_.-') or 'view'}.preview_{index:06d}.png"


def _finish(args, specs, stream, written, how, declared):
    """Say where each output went; the exit status."""
    _say_fallback(args, specs, stream)
    for i, spec in enumerate(specs):
        if spec.kind_out == "video":
            _say_video(args, spec, stream.written.get(str(i)), how, declared)
        elif spec.kind_out == "sequence":
            if how == "interrupted":
                warn_user(f"interrupted: kept the {written} frames written so far as {spec.output}")
            elif not args.quiet:
                edge = f" ({spec.edge[2:]})" if spec.edge else ""
                print(f"wrote {written} frames as {spec.output}{edge}")
    if how == "interrupted" and not any(s.kind_out in ("video", "sequence") for s in specs):
        warn_user("interrupted")
    return EXIT_INTERRUPTED if how == "interrupted" else EXIT_OK


def _say_video(args, spec, video, how, declared):
    """One line on a video output: where its frames are, and in which codec."""
    output = spec.output
    if video is None:
        warn_user(f"interrupted before a frame of {output} was written: nothing kept")
    elif how == "interrupted" and video.path != output:
        warn_user(
            f"interrupted: kept the {video.frames} frames written so far in {video.path}; "
            f"the earlier {output} is unchanged"
        )
    elif how == "interrupted":
        warn_user(
            f"interrupted: kept the {video.frames} frames written so far in {output} "
            f"(there was no earlier output)"
        )
    elif how == "truncated":
        warn_user(
            f"input ended after {video.frames} of its {declared} frames (truncated, or a "
            f"frame it cannot decode); kept them in {output}"
        )
    elif not args.quiet:
        print(
            f"wrote {output} ({video.frames} frames, {spec.size[0]}x{spec.size[1]}, "
            f"{_codec_text(video.fourcc)}{spec.edge})"
        )


def _codec_text(fourcc):
    """``"H.264 (avc1)"`` for a codec browsers play, else ``"codec mp4v"``."""
    name = web_codec(fourcc)
    return f"{name} ({fourcc})" if name else f"codec {fourcc}"


def _say_fallback(args, specs, stream):
    """One warning line for all the video outputs written in a codec browsers do not play
    because this OpenCV has no encoder for the one they do (never for a ``--fourcc`` given)."""
    if args.fourcc is not None:
        return
    videos = [stream.written.get(str(i)) for i, s in enumerate(specs) if s.kind_out == "video"]
    fallen = [v for v in videos if v is not None and fell_back(v.path, v.fourcc)]
    if fallen:
        paths = [v.path for v in fallen]
        named = " and ".join([", ".join(paths[:-1]), paths[-1]] if len(paths) > 1 else paths)
        codecs = " and ".join(sorted({v.fourcc for v in fallen}))
        warn_user(
            f"this OpenCV has no H.264 encoder, so {named} {'is' if len(paths) == 1 else 'are'} "
            f"in {codecs}, which browsers do not play; for a video they play, write .webm (VP9)"
        )


def _spherical_metadata(output):
    """The ``finalize`` of an equirectangular video: its spherical metadata, in MP4/MOV."""

    def add(tmp):
        if os.path.splitext(output)[1].lower() not in SPHERICAL_CONTAINERS:
            warn_user(f"{output}: spherical video metadata is written into .mp4/.m4v/.mov only")
            return
        try:
            with open(tmp, "rb") as f:
                new = inject_spherical_mp4(f.read())
        except ValueError as e:
            raise CliError(f"cannot add 360 metadata to {output}: {e}") from None
        try:
            with open(tmp, "wb") as f:
                f.write(new)
                f.flush()
                os.fsync(f.fileno())
        except OSError as e:
            raise CliError(
                f"cannot write video {output}: {e.strerror or e}; the previous file is unchanged"
            ) from None

    return add


def add_parser(sub):
    """Register the ``unwarp`` subcommand on ``sub`` (argparse sub-parsers)."""
    p = sub.add_parser(
        "unwarp",
        help="panorama, perspective or 360 views of an image, a video, a camera or a stream",
        description="Unwarp an image, a video file, an image sequence, a camera index or a "
        "stream URL into one or more views, decoding each frame once. Each --panorama, "
        "--perspective or --equirect starts a view; the options after it, up to the next "
        "view, belong to it, and each view takes its own -o.",
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
    add_view_arguments(p)
    p.add_argument("--overwrite", action="store_true", help="replace outputs that exist")
    p.add_argument(
        "--max-frames",
        type=count_arg,
        metavar="N",
        help="video: stop after N frames (useful with a camera)",
    )
    p.add_argument(
        "--fourcc",
        type=fourcc_arg,
        metavar="CODE",
        help="video codec FourCC (default MJPG for .avi/.mkv; for .mp4/.m4v/.mov H.264 "
        "where this OpenCV writes it, else mp4v; for .webm VP9, else VP8)",
    )
    p.add_argument(
        "--preview",
        type=count_arg,
        metavar="N",
        help="video: also write every N-th frame of each view as OUTPUT.preview_FRAME.png",
    )
    p.add_argument("-q", "--quiet", action="store_true", help="no progress bar")
    p.set_defaults(func=cmd_unwarp, ordered=None)
    return p


def add_view_arguments(p, output_help=None):
    """The view options (``--panorama``, ``--perspective``, ``--equirect`` and those that
    belong to a view, ``-o`` included), recorded in order (:func:`view_specs`)."""
    p.add_argument(
        "--panorama",
        type=size_arg,
        metavar="WxH",
        action=_InOrder,
        help="a panorama of this size (starts a view)",
    )
    p.add_argument(
        "--perspective",
        type=size_arg,
        metavar="WxH",
        action=_InOrder,
        help="a virtual perspective view of this size, needs --fov (starts a view)",
    )
    p.add_argument(
        "--equirect",
        type=size_arg,
        metavar="WxH",
        action=_InOrder,
        help="a 2:1 equirectangular 360 image of the full sphere, forward at the "
        "centre; .jpg outputs get Photo Sphere XMP, .mp4/.mov the spherical video "
        "metadata (starts a view)",
    )
    p.add_argument(
        "--elevation",
        nargs=2,
        type=finite_arg,
        metavar=("LO", "HI"),
        action=_InOrder,
        help="panorama elevation range in degrees (default: what the mirror sees, above the "
        "camera's own reflection as the calibration recorded it, else from -60 deg)",
    )
    p.add_argument(
        "--projection",
        choices=("cylindrical", "equirectangular"),
        action=_InOrder,
        help="panorama rows linear in tan(elevation) or in elevation (default cylindrical)",
    )
    p.add_argument(
        "--fov",
        type=finite_arg,
        metavar="DEG",
        action=_InOrder,
        help="horizontal field of view of the perspective view, degrees",
    )
    p.add_argument(
        "--yaw",
        type=finite_arg,
        metavar="Y",
        action=_InOrder,
        help="turn right by Y degrees: a perspective view looks at azimuth -Y (default 0), a "
        "panorama or --equirect has it at its centre (default: the camera's forward direction)",
    )
    p.add_argument(
        "--pitch",
        type=finite_arg,
        metavar="P",
        action=_InOrder,
        help="perspective view: look up by P degrees (default 0)",
    )
    p.add_argument(
        "--roll",
        type=finite_arg,
        metavar="R",
        action=_InOrder,
        help="perspective view: turn the image clockwise by R degrees (default 0)",
    )
    p.add_argument(
        "--depth",
        type=positive_arg,
        metavar="MM",
        action=_InOrder,
        help="map the scene at this distance from the best-fit viewpoint (default: at infinity)",
    )
    p.add_argument(
        "-o",
        "--output",
        metavar="OUTPUT",
        action=_InOrder,
        help=output_help
        or "the view's output: an image, a video (.avi, .mp4, "
        ".m4v, .mov, .mkv, .webm) for a video input, or an image sequence (out_%%04d.png)",
    )


# re-exported for callers of the earlier one-view module
__all__ = [
    "EXIT_FAILURE",
    "VIDEO_CODECS",
    "Progress",
    "add_parser",
    "add_view_arguments",
    "cmd_unwarp",
    "count_frames",
    "view_from_args",
    "view_specs",
]
