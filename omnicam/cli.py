"""The ``omnicam`` console script: ``calibrate``, ``unwarp``, ``info`` and ``demo``.

::

    omnicam calibrate IMAGE --mirror A B RIM --intrinsics K.yaml [--far-lines LINES.json]
                      -o CALIB [--no-refine] [--overlay PATH] [--overwrite]
    omnicam unwarp INPUT -c CALIB (--panorama WxH [--elevation LO HI] [--projection P]
                   | --perspective WxH --fov DEG [--yaw Y] [--pitch P] [--roll R])
                   [--depth MM] -o OUTPUT [--overwrite] [--max-frames N] [--fourcc CODE] [--quiet]
    omnicam info CALIB
    omnicam demo [-o OUTDIR]

Contract (py360convert style): :func:`main` takes ``argv`` and returns the exit status, so tests
call ``main([...])`` directly. Every failure the user can cause is one line on stderr,
``omnicam: error: ...``, with exit status 2 for a malformed command line and 1 for the rest
(130 after Ctrl-C). Nothing existing is overwritten unless ``--overwrite`` says so, and outputs
are written to a temporary file in the destination folder (same extension, so the same format)
that is renamed into place, so a good file is never replaced by a half-written one. A video
output is also renamed into place when the input ends early (a truncated file) or on Ctrl-C: the
frames written so far are kept in a valid, finalised file. Set ``OMNICAM_DEBUG=1`` to get the
traceback of an unexpected error instead of its one-line summary.
"""
from __future__ import annotations

import argparse
import contextlib
import math
import os
import re
import sys
import tempfile
import time

import cv2
import numpy as np

__all__ = ["main"]

PROG = "omnicam"

# Exit statuses
EXIT_OK, EXIT_FAILURE, EXIT_USAGE, EXIT_INTERRUPTED = 0, 1, 2, 130

# Video containers we write, with the codec used unless --fourcc says otherwise. MJPG in AVI is
# written by OpenCV itself on every build; the others need the FFmpeg backend of the wheels.
VIDEO_FOURCC = {".avi": "MJPG", ".mp4": "mp4v", ".m4v": "mp4v", ".mov": "mp4v", ".mkv": "MJPG"}



class CliError(Exception):
    """A failure the user can act on: printed as one line, never as a traceback."""

    def __init__(self, message, status=EXIT_FAILURE):
        super().__init__(message)
        self.status = status


class _Parser(argparse.ArgumentParser):
    """argparse with one-line errors: usage problems become a :class:`CliError` (status 2)."""

    def error(self, message):
        where = self.prog[len(PROG):].strip()
        raise CliError(f"{where + ': ' if where else ''}{message} (see '{self.prog} --help')",
                       EXIT_USAGE)


# -- argument types ---------------------------------------------------------------------------
def _size(text):
    """``WxH`` -> ``(W, H)`` positive ints."""
    m = re.fullmatch(r"\s*(\d+)\s*[xX]\s*(\d+)\s*", text)
    if not m:
        raise argparse.ArgumentTypeError(f"expected WIDTHxHEIGHT such as 1024x256, got {text!r}")
    w, h = int(m.group(1)), int(m.group(2))
    if not (0 < w <= 32767 and 0 < h <= 32767):
        raise argparse.ArgumentTypeError(f"width and height must be 1..32767, got {text!r}")
    return w, h


def _finite(text):
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number, got {text!r}") from None
    if not math.isfinite(value):
        raise argparse.ArgumentTypeError(f"expected a finite number, got {text!r}")
    return value


def _positive(text):
    value = _finite(text)
    if value <= 0:
        raise argparse.ArgumentTypeError(f"expected a positive number, got {text!r}")
    return value


def _count(text):
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a positive integer, got {text!r}") from None
    if value <= 0:
        raise argparse.ArgumentTypeError(f"expected a positive integer, got {text!r}")
    return value


def _fourcc(text):
    if len(text) != 4:
        raise argparse.ArgumentTypeError(f"a FourCC has 4 characters, got {text!r}")
    return text


# -- the parser -------------------------------------------------------------------------------
def build_parser():
    """The ``argparse`` parser of the ``omnicam`` command (one sub-parser per command)."""
    parser = _Parser(prog=PROG, description="Calibrate and unwarp misaligned hyperbolic-mirror "
                     "catadioptric cameras.")
    from . import __version__
    parser.add_argument("--version", action="version", version=f"%(prog)s {__version__}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", required=True)

    p = sub.add_parser("calibrate", help="mirror posture from one image of the mirror",
                       description="Estimate the mirror posture from one image: rim ellipse, "
                       "Chen's method, far-line selection and refinement. Prints the report, "
                       "saves an overlay image and writes the calibration file.")
    p.add_argument("image", metavar="IMAGE",
                   help="image of the mirror (any format cv2.imread reads)")
    p.add_argument("--mirror", nargs=3, type=_positive, required=True, metavar=("A", "B", "RIM"),
                   help="hyperboloid parameters a, b and rim radius (mm)")
    p.add_argument("--intrinsics", required=True, metavar="K.yaml",
                   help="cv2.FileStorage file (yaml/yml/xml/json) with the camera matrix 'K' "
                   "(or 'camera_matrix'), optional distortion 'D' (or 'dist_coeffs', "
                   "'distortion_coefficients') and optional 'image_size' [w, h] (or "
                   "'image_width' and 'image_height'); K is rescaled if image_size differs "
                   "from IMAGE's size. An omnicam calibration file also works.")
    p.add_argument("--far-lines", metavar="LINES.json",
                   help="JSON list of lines, each a list of [x, y] pixels of a straight scene "
                   "line far from the camera; used to pick the right posture candidate")
    p.add_argument("-o", "--output", required=True, metavar="CALIB",
                   help="calibration file to write (.yaml, .yml, .xml or .json)")
    p.add_argument("--no-refine", dest="refine", action="store_false",
                   help="keep the closed-form posture, skip the refinement")
    p.add_argument("--overlay", metavar="PATH",
                   help="overlay image to write (default: CALIB's stem + '_overlay.png', "
                   "next to CALIB)")
    p.add_argument("--overwrite", action="store_true", help="replace existing output files")
    p.set_defaults(func=cmd_calibrate)

    p = sub.add_parser("unwarp", help="panorama or perspective view of an image or a video",
                       description="Unwarp an image, a video file, a camera index or a stream "
                       "URL into a panorama or a virtual perspective view.")
    p.add_argument("input", metavar="INPUT",
                   help="image or video file, image sequence (img_%%04d.png), camera index "
                   "(0, 1, ...) or stream URL")
    p.add_argument("-c", "--calibration", required=True, metavar="CALIB",
                   help="calibration file written by 'omnicam calibrate'")
    view = p.add_mutually_exclusive_group(required=True)
    view.add_argument("--panorama", type=_size, metavar="WxH", help="panorama of this size")
    view.add_argument("--perspective", type=_size, metavar="WxH",
                      help="virtual perspective view of this size (needs --fov)")
    p.add_argument("--elevation", nargs=2, type=_finite, metavar=("LO", "HI"),
                   help="panorama elevation range in degrees (default: what the mirror sees)")
    p.add_argument("--projection", choices=("cylindrical", "equirectangular"),
                   help="panorama rows linear in tan(elevation) or in elevation "
                   "(default cylindrical)")
    p.add_argument("--fov", type=_finite, metavar="DEG",
                   help="horizontal field of view of the perspective view, degrees")
    p.add_argument("--yaw", type=_finite, metavar="Y",
                   help="perspective view: turn right by Y degrees (default 0)")
    p.add_argument("--pitch", type=_finite, metavar="P",
                   help="perspective view: look up by P degrees (default 0)")
    p.add_argument("--roll", type=_finite, metavar="R",
                   help="perspective view: turn the image clockwise by R degrees (default 0)")
    p.add_argument("--depth", type=_positive, metavar="MM",
                   help="map the scene at this distance from the best-fit viewpoint "
                   "(default: at infinity)")
    p.add_argument("-o", "--output", required=True, metavar="OUTPUT",
                   help="output image, or video (.avi, .mp4, .m4v, .mov, .mkv) for a video input")
    p.add_argument("--overwrite", action="store_true", help="replace OUTPUT if it exists")
    p.add_argument("--max-frames", type=_count, metavar="N",
                   help="video: stop after N frames (useful with a camera)")
    p.add_argument("--fourcc", type=_fourcc, metavar="CODE",
                   help="video codec FourCC (default MJPG for .avi/.mkv, mp4v for .mp4/.mov)")
    p.add_argument("-q", "--quiet", action="store_true", help="no progress bar")
    p.set_defaults(func=cmd_unwarp)

    p = sub.add_parser("info", help="print a calibration file",
                       description="Print the mirror, K, D, the mirror posture, the best-fit "
                       "viewpoint and its RMS distance to the rays.")
    p.add_argument("calibration", metavar="CALIB")
    p.set_defaults(func=cmd_info)

    p = sub.add_parser("demo", help="the whole pipeline on built-in synthetic data",
                       description="Render a misaligned rig, calibrate it from the rendered "
                       "image, compare with the truth, and write the calibration, the mirror "
                       "image, the overlay, a panorama and a perspective view. The demo's own "
                       "files in OUTDIR are replaced.")
    p.add_argument("-o", "--output", default="omnicam-demo", metavar="OUTDIR",
                   help="folder for the results (default ./omnicam-demo)")
    p.set_defaults(func=cmd_demo)
    return parser


def main(argv=None) -> int:
    """Run the ``omnicam`` command line; return the exit status."""
    try:
        with _opencv_quiet():
            args = build_parser().parse_args(argv)
            return args.func(args) or EXIT_OK
    except CliError as e:
        _error(str(e))
        return e.status
    except SystemExit as e:  # --help, --version
        return e.code if isinstance(e.code, int) else EXIT_OK
    except KeyboardInterrupt:
        _error("interrupted")
        return EXIT_INTERRUPTED
    except Exception as e:  # a bug: still one line, unless asked for the traceback
        if os.environ.get("OMNICAM_DEBUG"):
            raise
        _error(f"unexpected {type(e).__name__}: {_one_line(e, 300)} "
               f"(set OMNICAM_DEBUG=1 for the traceback)")
        return EXIT_FAILURE


@contextlib.contextmanager
def _opencv_quiet():
    """OpenCV's and FFmpeg's own log lines are not for the user: our errors say it in one line.

    FFmpeg takes its level from ``OPENCV_FFMPEG_LOGLEVEL`` when a capture opens (so setting it
    after ``import cv2`` works; a value the user set is kept). OpenCV's level is restored after.
    """
    os.environ.setdefault("OPENCV_FFMPEG_LOGLEVEL", "-8")  # AV_LOG_QUIET
    logging = getattr(getattr(cv2, "utils", None), "logging", None)
    previous = None
    if logging is not None:
        with contextlib.suppress(Exception):
            previous = logging.getLogLevel()
            logging.setLogLevel(logging.LOG_LEVEL_SILENT)
    try:
        yield
    finally:
        if previous is not None:
            with contextlib.suppress(Exception):
                logging.setLogLevel(previous)


def _one_line(e, limit=None):
    """``str(e)`` on one line, without terminal colour codes, optionally shortened."""
    text = " ".join(re.sub(r"\x1b\[[0-9;]*m", "", str(e)).split()) or type(e).__name__
    if limit and len(text) > limit:
        text = text[:limit - 3] + "..."
    return text


def _error(message):
    print(f"{PROG}: error: {_one_line(message)}", file=sys.stderr, flush=True)


def _warn(message):
    print(f"{PROG}: warning: {_one_line(message)}", file=sys.stderr, flush=True)


# -- files ------------------------------------------------------------------------------------
def _load_camera(path):
    from .camera import MisalignedHyperbolicCamera
    try:
        return MisalignedHyperbolicCamera.load(path)
    except (FileNotFoundError, ValueError) as e:
        raise CliError(_one_line(e)) from None


def _check_output(path, overwrite, what="output"):
    """Refuse an output we must not or cannot write, before doing any work."""
    path = os.fspath(path)
    folder = os.path.dirname(os.path.abspath(path))
    if os.path.isdir(path):
        raise CliError(f"{what} {path} is a folder")
    if os.path.lexists(path) and not overwrite:
        raise CliError(f"{what} {path} exists; pass --overwrite to replace it")
    if not os.path.isdir(folder):
        raise CliError(f"{what} {path}: folder {folder} does not exist")
    if not os.access(folder, os.W_OK | os.X_OK):
        raise CliError(f"{what} {path}: folder {folder} is not writable")


def _temp_beside(path):
    """A new empty temporary file next to ``path`` with the same extension (so the same format)."""
    folder = os.path.dirname(os.path.abspath(path))
    stem, ext = os.path.splitext(os.path.basename(path))
    try:
        fd, tmp = tempfile.mkstemp(prefix=f".{stem}.", suffix=ext, dir=folder)
    except OSError as e:
        raise CliError(f"cannot write in {folder}: {e.strerror or e}") from None
    os.close(fd)
    # mkstemp makes the file private (0600); the output gets the mode a new file would get
    umask = os.umask(0)
    os.umask(umask)
    with contextlib.suppress(OSError):
        os.chmod(tmp, 0o666 & ~umask)
    return tmp


def _remove_quietly(path):
    with contextlib.suppress(OSError):
        os.remove(path)


def _publish(tmp, path, overwrite):
    """Rename the finished temporary file to ``path`` (never replacing a file without overwrite)."""
    if not overwrite and os.path.lexists(path):
        _remove_quietly(tmp)
        raise CliError(f"output {path} appeared while writing; pass --overwrite to replace it")
    try:
        os.replace(tmp, path)
    except OSError as e:
        _remove_quietly(tmp)
        raise CliError(f"cannot write {path}: {e.strerror or e}") from None


def _write_image(path, image, overwrite=True):
    """``cv2.imwrite`` through a temporary file renamed into place."""
    path = os.fspath(path)
    if not cv2.haveImageWriter(path):
        raise CliError(f"output {path}: no image writer for extension "
                       f"{os.path.splitext(path)[1] or '(none)'!r}; use .png, .jpg, .tif, ...")
    tmp = _temp_beside(path)
    try:
        try:
            ok, detail = cv2.imwrite(tmp, image), "cv2.imwrite failed"
        except cv2.error as e:
            ok, detail = False, _cv_message(e)
        if not ok:
            raise CliError(f"cannot write {path}: {detail}")
    except BaseException:
        _remove_quietly(tmp)
        raise
    _publish(tmp, path, overwrite)


def _cv_message(e):
    """The useful part of a ``cv2.error`` message."""
    lines = [ln for ln in str(e).splitlines() if ln.strip()]
    text = lines[-1] if lines else str(e)
    return re.sub(r"^.*?error: \(-?\d+:[^)]*\)\s*", "", text).strip() or text


def _read_image(path, flags=cv2.IMREAD_UNCHANGED):
    if not os.path.isfile(path):
        raise CliError(f"image {path} does not exist" if not os.path.exists(path)
                       else f"image {path} is not a file")
    try:
        image = cv2.imread(path, flags)
    except cv2.error as e:
        raise CliError(f"cannot read image {path}: {_cv_message(e)}") from None
    if image is None or image.size == 0:
        raise CliError(f"cannot read image {path}: not an image format OpenCV reads")
    return image


# -- calibrate --------------------------------------------------------------------------------
def read_intrinsics(path):
    """:func:`omnicam.io.read_intrinsics` with its errors as one-line CLI errors."""
    from .io import read_intrinsics as read
    try:
        return read(path)
    except (FileNotFoundError, ValueError) as e:
        raise CliError(_one_line(e)) from None


def read_far_lines(path):
    """:func:`omnicam.io.read_far_lines` with its errors as one-line CLI errors."""
    from .io import read_far_lines as read
    try:
        return read(path)
    except (FileNotFoundError, ValueError) as e:
        raise CliError(_one_line(e)) from None


def cmd_calibrate(args):
    from .camera import MisalignedHyperbolicCamera, scale_K
    from .io import SUFFIXES
    from .mirror import HyperbolicMirror

    calib = args.output
    if os.path.splitext(calib)[1].lower() not in SUFFIXES:
        raise CliError(f"calibration file {calib}: extension must be one of {', '.join(SUFFIXES)}")
    overlay = args.overlay or _overlay_path(calib)
    _check_output(calib, args.overwrite, "calibration file")
    _check_output(overlay, args.overwrite, "overlay")
    if not cv2.haveImageWriter(overlay):
        raise CliError(f"overlay {overlay}: no image writer for its extension; use .png or .jpg")
    if os.path.exists(overlay) and os.path.exists(args.image) and os.path.samefile(overlay,
                                                                                    args.image):
        raise CliError(f"overlay {overlay} is the input image")
    try:
        mirror = HyperbolicMirror(*args.mirror)
    except ValueError as e:
        raise CliError(f"--mirror: {e}") from None
    K, D, size = read_intrinsics(args.intrinsics)
    far_lines = read_far_lines(args.far_lines) if args.far_lines else None
    image = _read_image(args.image, cv2.IMREAD_COLOR | cv2.IMREAD_IGNORE_ORIENTATION)
    image_size = (image.shape[1], image.shape[0])
    if size is not None and size != image_size:
        _warn(f"intrinsics are for {size[0]}x{size[1]}, image is {image_size[0]}x{image_size[1]}: "
              f"K rescaled")
        K = scale_K(K, size, image_size)

    try:
        camera, report = MisalignedHyperbolicCamera.calibrate(
            K, mirror, image=image, far_lines=far_lines, D=D, image_size=image_size,
            refine=args.refine)
    except (ValueError, RuntimeError, NotImplementedError, np.linalg.LinAlgError) as e:
        raise CliError(f"calibration failed: {_one_line(e)}") from None
    print(_report_text(report), flush=True)
    _write_image(overlay, report.draw(image), args.overwrite)
    _save_camera(camera, calib, args.overwrite)
    print(f"wrote {calib} and {overlay}")
    return EXIT_OK


def _overlay_path(calib):
    stem = os.path.splitext(os.path.basename(calib))[0]
    return os.path.join(os.path.dirname(calib), f"{stem}_overlay.png")


def _report_text(report):
    summary = getattr(report, "summary", None)
    return str(summary() if callable(summary) else summary if summary is not None else report)


def _save_camera(camera, path, overwrite):
    if not overwrite and os.path.lexists(path):
        raise CliError(f"calibration file {path} exists; pass --overwrite to replace it")
    try:
        camera.save(path)
    except (ValueError, OSError) as e:
        raise CliError(f"cannot write {path}: {_one_line(e)}") from None


# -- info -------------------------------------------------------------------------------------
def posture(camera):
    """Readable posture: tilt of the mirror axis and camera offset from the lower focus.

    Returns
    -------
    tilt_deg : float
        Angle between the camera's optical axis and the mirror axis.
    tilt_azimuth_deg : float
        Direction of the tilt in the camera's x-y plane (``atan2`` of the axis' y and x).
    offset : (3,) float64 ndarray
        Camera centre minus the lower focus ``(0, 0, -c)``, mirror frame (mm).
    """
    axis = camera.R[:, 2]  # the mirror's +Z in the camera frame
    tilt = math.degrees(math.atan2(math.hypot(axis[0], axis[1]), axis[2]))
    azimuth = math.degrees(math.atan2(axis[1], axis[0])) if tilt > 0 else 0.0
    offset = np.asarray(camera.camera_center) - np.array([0.0, 0.0, -camera.mirror.c])
    return tilt, azimuth, offset


def _vec(v, fmt="{:.4f}"):
    return "(" + ", ".join(fmt.format(float(x)) for x in np.ravel(v)) + ")"


def describe_camera(camera):
    """Multi-line text of a calibration: mirror, K, D, posture, best-fit viewpoint."""
    m = camera.mirror
    K = camera.K
    tilt, az, offset = posture(camera)
    viewpoint, rms = camera.best_fit_viewpoint()
    size = camera.image_size
    rows = [
        ("mirror", f"a = {m.a:g} mm, b = {m.b:g} mm, rim radius = {m.rim_radius:g} mm "
                   f"(c = {m.c:.4f} mm, rim at Z = {m.z_rim:.4f} mm)"),
        ("image size", "unknown" if size is None else f"{size[0]} x {size[1]}"),
        ("K", f"fx = {K[0, 0]:.4f}, fy = {K[1, 1]:.4f}, cx = {K[0, 2]:.4f}, cy = {K[1, 2]:.4f}, "
              f"skew = {K[0, 1]:.4g}"),
        ("D", "none" if camera.D is None else _vec(camera.D, "{:.6g}")),
        ("rvec", _vec(camera.rvec, "{:.6f}") + "  (mirror -> camera, rad)"),
        ("tvec", _vec(camera.tvec) + "  (mm)"),
        ("axis tilt", f"{tilt:.4f} deg, towards {az:.2f} deg in the camera's x-y plane"),
        ("camera offset", f"{_vec(offset)} mm from the lower focus (mirror frame), "
                          f"|offset| = {np.linalg.norm(offset):.4f} mm"),
        ("viewpoint", f"{_vec(viewpoint)} mm, best fit to all mirror rays (mirror frame; "
                      f"the outer focus is (0, 0, {m.c:.4f}))"),
        ("viewpoint RMS", f"{rms:.4f} mm (RMS distance from the rays; 0 for a central rig)"),
    ]
    width = max(len(k) for k, _ in rows)
    return "\n".join(f"{k:<{width}}  {v}" for k, v in rows)


def cmd_info(args):
    camera = _load_camera(args.calibration)
    print(f"{'calibration':<13}  {args.calibration}")
    print(describe_camera(camera))
    return EXIT_OK


# -- unwarp -----------------------------------------------------------------------------------
def view_from_args(args):
    """The view the command line asks for: a ``PanoramaView`` or ``PerspectiveView``.

    Options of the other kind of view are refused rather than ignored; the view classes check
    the values (sizes, angle ranges, depth), and what they refuse is a usage error too.
    """
    from .views import PanoramaView, PerspectiveView

    def refuse(given, kind):
        if given:
            verb = "only apply" if len(given) > 1 else "only applies"
            raise CliError(f"{', '.join(given)} {verb} to --{kind}", EXIT_USAGE)

    try:
        if args.panorama is not None:
            refuse([o for o, v in (("--fov", args.fov), ("--yaw", args.yaw),
                                   ("--pitch", args.pitch), ("--roll", args.roll))
                    if v is not None], "perspective")
            return PanoramaView(args.panorama, elevation_range=args.elevation,
                                projection=args.projection or "cylindrical", depth=args.depth)
        refuse([o for o, v in (("--elevation", args.elevation),
                               ("--projection", args.projection)) if v is not None], "panorama")
        if args.fov is None:
            raise CliError("--perspective needs --fov DEG (horizontal field of view)", EXIT_USAGE)
        return PerspectiveView(args.perspective, fov=args.fov, yaw=args.yaw or 0.0,
                               pitch=args.pitch or 0.0, roll=args.roll or 0.0, depth=args.depth)
    except ValueError as e:
        option = "--panorama" if args.panorama is not None else "--perspective"
        raise CliError(f"{option}: {_one_line(e)}", EXIT_USAGE) from None


def _unwarper(camera, view, frame_size):
    """An :class:`~omnicam.stream.Unwarper` of ``view``, its tables for frames of ``frame_size``
    (``camera.scaled`` when the calibration was made at another resolution)."""
    from .stream import Unwarper
    size = camera.image_size
    if size is not None and size != tuple(frame_size):
        if abs(frame_size[0] * size[1] - frame_size[1] * size[0]) > 0.01 * size[0] * size[1]:
            _warn(f"frames are {frame_size[0]}x{frame_size[1]} but the calibration is for "
                  f"{size[0]}x{size[1]}, another aspect ratio: assuming the same sensor "
                  f"rescaled (not a crop)")
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

    if not (_is_device_or_url(source) or _is_sequence(source)) and cv2.haveImageReader(source):
        return _unwarp_image(args, view, camera)
    return _unwarp_video(args, view, camera)


def _unwarp_image(args, view, camera):
    if not cv2.haveImageWriter(args.output):
        ext = os.path.splitext(args.output)[1]
        hint = " (the input is an image)" if ext.lower() in VIDEO_FOURCC else ""
        raise CliError(f"output {args.output}: no image writer for extension "
                       f"{ext or '(none)'!r}{hint}")
    image = _read_image(args.input)
    out = _unwarper(camera, view, (image.shape[1], image.shape[0])).unwarp(image)["view"]
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
            text = (f"[{'#' * fill}{'.' * (bar_len - fill)}] {frames}/{self.total} frames "
                    f"{100 * done:3.0f}%  {self.fps():6.1f} fps")
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
        raise CliError(f"cannot open input {source}: not an image or video OpenCV can read")
    return cap


def _unwarp_video(args, view, camera):
    output = args.output
    ext = os.path.splitext(output)[1].lower()
    fourcc = args.fourcc or VIDEO_FOURCC.get(ext)
    if fourcc is None:
        raise CliError(f"output {output}: the input is a video; use a video extension "
                       f"({', '.join(VIDEO_FOURCC)})")
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
    if stop == "interrupted":  # Ctrl-C may have come between a frame's write and its count
        written = max(written, _frame_count(tmp))
    _publish(tmp, output, args.overwrite)
    if stop == "interrupted":
        _warn(f"interrupted: kept the {written} frames written so far in {output}")
        return EXIT_INTERRUPTED
    if stop == "truncated":
        _warn(f"input ended after {written} of its {declared} frames (truncated, or a "
              f"frame it cannot decode); kept them in {output}")
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
        raise CliError(f"video {output}: the view is {size[0]}x{size[1]}; video needs an even "
                       f"width and height (cv2.VideoWriter drops an odd last row or column)")
    try:
        writer = cv2.VideoWriter(tmp, cv2.VideoWriter_fourcc(*fourcc), fps, size)
        ok = writer.isOpened()
        writer.release()
    except cv2.error:
        ok = False
    if not ok:
        raise CliError(f"cannot write video {output} with codec {fourcc}; try --fourcc or "
                       f"another extension")


def _stream(unwarper, cap, tmp, fourcc, fps, declared, args):
    """Unwarp frames into ``tmp`` until the input ends, ``--max-frames`` or Ctrl-C.

    ``declared`` is the input's frame count (0 if unknown): ending before it is a truncation.
    Returns ``(frames_written, how)`` with ``how`` one of ``"end"``, ``"truncated"``,
    ``"interrupted"``; the writer is released (the file finalised) in every case, by
    :meth:`Unwarper.stream` when its generator ends or is closed.
    """
    total = min(declared or args.max_frames or 0, args.max_frames or declared)
    progress = Progress(total, enabled=not args.quiet)
    frames = unwarper.stream(cap, outputs={"view": tmp}, fourcc=fourcc, fps=fps,
                             max_frames=args.max_frames)
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
    if how == "end" and written < declared and not (args.max_frames and written >= args.max_frames):
        how = "truncated"
    return written, how


# -- demo -------------------------------------------------------------------------------------
#: Far straight lines of the demo scene: lines at infinity, i.e. great circles of directions,
#: each given by its plane's normal as (tilt from the mirror axis, azimuth) in degrees. Tilted
#: circles separate Chen's two physical postures far better than the vertical poles do.
DEMO_FAR_LINES = ((30.0, 0.0), (30.0, 120.0), (30.0, 240.0))
DEMO_CLICK_NOISE_PX = 0.2  # as if a user had clicked along them
DEMO_LINE_COLOR = (0, 160, 255)  # BGR orange


def great_circle(tilt_deg, azimuth_deg, n=720):
    """``(n, 3)`` unit directions of the line at infinity whose plane has the given normal."""
    t, a = math.radians(tilt_deg), math.radians(azimuth_deg)
    normal = np.array([math.sin(t) * math.cos(a), math.sin(t) * math.sin(a), math.cos(t)])
    u = np.cross(normal, (0.0, 0.0, 1.0)) if t > 1e-9 else np.array([1.0, 0.0, 0.0])
    u /= np.linalg.norm(u)
    v = np.cross(normal, u)
    th = np.linspace(0.0, 2.0 * np.pi, n, endpoint=False)
    return np.outer(np.cos(th), u) + np.outer(np.sin(th), v)


def demo_environment(lines=DEMO_FAR_LINES):
    """:func:`omnicam.synthetic.make_environment` with the demo's far lines drawn in."""
    from . import synthetic
    env = synthetic.make_environment()
    h, w = env.shape[:2]
    radius = max(1, int(round(0.3 * w / 360.0)))  # lines 0.6 deg wide, as the environment's
    for tilt, az in lines:
        x, y = synthetic.equirect_coords(great_circle(tilt, az, 8 * w), (w, h))
        for xi, yi in zip(np.round(x).astype(int), np.round(y).astype(int)):
            cv2.circle(env, (int(xi) % w, int(yi)), radius, DEMO_LINE_COLOR, -1)
    return env


def demo_far_lines(camera, lines=DEMO_FAR_LINES, max_elevation_deg=10.0, n=60,
                   noise_px=DEMO_CLICK_NOISE_PX, seed=0):
    """Pixels along the images of the demo's far lines, as a user would click them.

    The directions of each great circle up to ``max_elevation_deg`` (well inside the rim),
    projected exactly by ``camera`` (points at infinity), ``n`` per line, plus seeded Gaussian
    click noise of ``noise_px``.
    """
    rng = np.random.default_rng(seed)
    out = []
    for tilt, az in lines:
        d = great_circle(tilt, az, 16 * n)
        d = d[d[:, 2] <= math.sin(math.radians(max_elevation_deg))]
        px = camera.project_directions(d)
        px = px[np.isfinite(px).all(axis=1)]
        px = px[np.linspace(0, len(px) - 1, min(n, len(px))).astype(int)]
        out.append(px + rng.normal(scale=noise_px, size=px.shape))
    return out


def _table_rms(cam_a, cam_b, size):
    """RMS distance (px) between two cameras' float panorama tables where both see the mirror."""
    from .views import UNSEEN
    a = cam_a.init_panorama_maps(size, m1type=cv2.CV_32FC2)[0]
    b = cam_b.init_panorama_maps(size, m1type=cv2.CV_32FC2)[0]
    ok = (a[..., 0] != UNSEEN) & (b[..., 0] != UNSEEN)
    d = (a - b)[ok]
    return float(np.sqrt(np.mean(np.sum(d * d, axis=-1)))) if d.size else float("nan")


def cmd_demo(args):
    from . import synthetic
    from .camera import MisalignedHyperbolicCamera
    from .io import write_far_lines, write_intrinsics

    t_start = time.perf_counter()
    out = args.output
    if os.path.exists(out) and not os.path.isdir(out):
        raise CliError(f"output folder {out} is a file")
    try:
        os.makedirs(out, exist_ok=True)
    except OSError as e:
        raise CliError(f"cannot create output folder {out}: {e.strerror or e}") from None
    if not os.access(out, os.W_OK | os.X_OK):
        raise CliError(f"output folder {out} is not writable")

    def path(name):
        return os.path.join(out, name)

    truth = synthetic.misaligned_rig()
    m = truth.mirror
    print(f"1. a misaligned rig: mirror a = {m.a:g}, b = {m.b:g}, rim {m.rim_radius:g} mm, "
          f"{truth.image_size[0]}x{truth.image_size[1]} camera; the truth:")
    tilt, az, offset = posture(truth)
    print(f"   axis tilt {tilt:.3f} deg towards {az:.1f} deg, camera offset "
          f"{_vec(offset, '{:.3f}')} mm from the lower focus")
    image = synthetic.render_environment(truth, demo_environment(), supersample=2)
    _write_image(path("mirror.png"), image)
    write_intrinsics(path("intrinsics.yaml"), truth.K, image_size=truth.image_size)
    lines = demo_far_lines(truth)
    write_far_lines(path("far_lines.json"), [np.round(line, 2) for line in lines])
    print(f"2. rendered what it sees of a scene at infinity ({path('mirror.png')}); "
          f"{sum(map(len, lines))} pixels 'clicked' (+-{DEMO_CLICK_NOISE_PX} px) along its "
          f"{len(lines)} orange far straight lines ({path('far_lines.json')})")

    print("3. calibration from that image (rim ellipse, Chen's method, far-line selection):")
    try:
        camera, report = MisalignedHyperbolicCamera.calibrate(
            truth.K, m, image=image, far_lines=lines, image_size=truth.image_size)
    except (ValueError, RuntimeError, NotImplementedError, np.linalg.LinAlgError) as e:
        raise CliError(f"demo: calibration failed: {_one_line(e)}") from None
    print(_indent(_report_text(report)))
    _write_image(path("overlay.png"), report.draw(image))
    _save_camera(camera, path("calibration.yaml"), overwrite=True)

    e_tilt, e_az, e_offset = posture(camera)
    axis_error = math.degrees(math.acos(float(np.clip(camera.R[:, 2] @ truth.R[:, 2], -1, 1))))
    baseline = MisalignedHyperbolicCamera.aligned(m, truth.K[0, 0], truth.K[0, 2], truth.K[1, 2],
                                                  truth.image_size)
    pano_size = (1024, 256)
    print("4. posture error vs the truth:")
    print(f"   axis tilt      {e_tilt:.3f} deg (true {tilt:.3f}); axis direction off by "
          f"{axis_error:.3f} deg")
    print(f"   camera offset  {_vec(e_offset, '{:.3f}')} mm (true {_vec(offset, '{:.3f}')}); "
          f"off by {np.linalg.norm(e_offset - offset):.3f} mm")
    print(f"   panorama tables vs the true rig's, RMS: calibrated "
          f"{_table_rms(camera, truth, (256, 64)):.2f} px, uncalibrated aligned model (eqs. 2-5) "
          f"{_table_rms(baseline, truth, (256, 64)):.2f} px")

    from .views import K_from_fov, rotation_from_ypr
    views = {
        "panorama.png": camera.init_panorama_maps(pano_size),
        "panorama_uncalibrated.png": baseline.init_panorama_maps(pano_size),
        "perspective.png": camera.init_perspective_maps(
            K_from_fov(90.0, (640, 480)), (640, 480), R=rotation_from_ypr(0.0, -20.0, 0.0)),
    }
    for name, (map1, map2) in views.items():
        _write_image(path(name), cv2.remap(image, map1, map2, cv2.INTER_LINEAR))
    print(f"5. wrote {', '.join(['calibration.yaml', 'overlay.png', *views])} in {out}")
    print(f"   try: omnicam info {path('calibration.yaml')}")
    print(f"        omnicam calibrate {path('mirror.png')} --mirror {m.a:g} {m.b:g} "
          f"{m.rim_radius:g} --intrinsics {path('intrinsics.yaml')} --far-lines "
          f"{path('far_lines.json')} -o my_calibration.yaml")
    print(f"        omnicam unwarp {path('mirror.png')} -c {path('calibration.yaml')} "
          f"--perspective 640x480 --fov 70 --yaw 45 -o view.png")
    print(f"done in {time.perf_counter() - t_start:.1f} s")
    return EXIT_OK


def _indent(text, prefix="   "):
    return "\n".join(prefix + line for line in text.splitlines())


if __name__ == "__main__":
    sys.exit(main())
