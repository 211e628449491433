"""What every ``omnicam`` subcommand shares: one-line errors, argument types, files in and out."""

from __future__ import annotations

import argparse
import contextlib
import dataclasses
import math
import os
import re
import sys

import cv2

from .._atomic import OutputError, atomic_output
from .._quiet import opencv_silenced
from .._validate import check_readable, file_path, shown
from ..formats import calibration_file, intrinsics, point_files
from ..formats.calibration_file import read_verdict
from ..formats.other_tools import other_tool_file
from ..formats.verdict import Verdict
from ..hyperbolic_camera import MisalignedHyperbolicCamera
from ..images import file_kind, read_image
from ..mirror import HyperbolicMirror

PROG = "omnicam"

# Exit statuses
EXIT_OK, EXIT_FAILURE, EXIT_USAGE, EXIT_INTERRUPTED = 0, 1, 2, 130


class CliError(Exception):
    """A failure the user can act on: printed as one line, never as a traceback."""

    def __init__(self, message, status=EXIT_FAILURE):
        super().__init__(message)
        self.status = status


class _Parser(argparse.ArgumentParser):
    """argparse with one-line errors: usage problems become a :class:`CliError` (status 2)."""

    def error(self, message):
        where = self.prog[len(PROG) :].strip()
        raise CliError(
            f"{where + ': ' if where else ''}{message} (see '{self.prog} --help')",
            EXIT_USAGE,
        )


def size_arg(text):
    """``WxH`` -> ``(W, H)`` positive ints."""
    m = re.fullmatch(r"\s*(\d+)\s*[xX]\s*(\d+)\s*", text)
    if not m:
        raise argparse.ArgumentTypeError(f"expected WIDTHxHEIGHT such as 1024x256, got {text!r}")
    w, h = int(m.group(1)), int(m.group(2))
    if not (0 < w <= 32767 and 0 < h <= 32767):
        raise argparse.ArgumentTypeError(f"width and height must be 1..32767, got {text!r}")
    return w, h


def finite_arg(text):
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number, got {text!r}") from None
    if not math.isfinite(value):
        raise argparse.ArgumentTypeError(f"expected a finite number, got {text!r}")
    return value


def positive_arg(text):
    value = finite_arg(text)
    if value <= 0:
        raise argparse.ArgumentTypeError(f"expected a positive number, got {text!r}")
    return value


def count_arg(text):
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a positive integer, got {text!r}") from None
    if value <= 0:
        raise argparse.ArgumentTypeError(f"expected a positive integer, got {text!r}")
    return value


def fourcc_arg(text):
    if len(text) != 4:
        raise argparse.ArgumentTypeError(f"a FourCC has 4 characters, got {text!r}")
    return text


def one_line(e, limit=None):
    """``str(e)`` on one line, without terminal colour codes, optionally shortened."""
    text = " ".join(re.sub(r"\x1b\[[0-9;]*m", "", str(e)).split()) or type(e).__name__
    if limit and len(text) > limit:
        text = text[: limit - 3] + "..."
    return text


#: The library's parameters as the command line's options: the library's messages name its
#: parameters (``lens_z``), the command line's user knows options (``--lens-z``). One mapping,
#: applied to every line the command line prints from the library (:func:`user_terms`).
OPTION_OF = {
    "refine_mirror_shape": "--refine-mirror-shape",
    "rim_radius": "--rim-radius",
    "lens_z": "--lens-z",
    "lens_r": "--lens-r",
    "pattern_size": "--chessboard",
    "square_size": "--square",
    "max_tilt_deg": "--max-tilt",
    "max_offset_mm": "--max-offset",
    "rim_hint": "--rim-hint",
    "boundary_points": "--boundary-points",
    "far_lines": "--far-lines",
    "dist_model": "--dist-model",
    "image_points": "--corners",
    "lens=None": "no --lens-z",
}
_NAME = "|".join(re.escape(n) for n in sorted(OPTION_OF, key=len, reverse=True))
_EDGE_BEFORE = r"(?<![\w/.'\"-])"  # not a part of a word, a path, an option, a quoted field
_EDGE_AFTER = r"(?![\w/]|\.\w)"


def _option(name):
    return OPTION_OF[name]


def user_terms(text):
    """``text`` with the library's parameter names as the command line's options.

    ``refine_mirror_shape=True (--refine-mirror-shape)`` and ``give lens_z, or --lens-z on the
    command line`` read ``--refine-mirror-shape`` and ``give --lens-z``; ``rim_radius = 30``
    reads ``--rim-radius 30``; ``image_points[2]`` reads ``--corners (image 2, from 0)``.
    Paths are left alone (a name inside a path or a file name is not a parameter).
    """
    text = re.sub(r"\bpattern_size \((\d+), (\d+)\)", r"--chessboard \1x\2", str(text))
    text = re.sub(  # the mirror as a start: the option that gives it
        r"the mirror \(a, b, rim_radius\)|its a, b and rim_radius", "--mirror A B RIM", text
    )
    text = re.sub(  # a parameter followed by its option already: the option alone
        rf"{_EDGE_BEFORE}({_NAME})(?:=\w+)? \((--[\w-]+)\)",
        lambda m: m.group(2) if m.group(2) == _option(m.group(1)) else m.group(0),
        text,
    )
    text = re.sub(
        rf"{_EDGE_BEFORE}({_NAME}), or (--[\w-]+) on the command line",
        lambda m: m.group(2) if m.group(2) == _option(m.group(1)) else m.group(0),
        text,
    )
    text = re.sub(
        rf"{_EDGE_BEFORE}({_NAME})\[(\d+)\]",
        lambda m: (
            f"{_option(m.group(1))} (image {m.group(2)}, from 0)"
            if m.group(1) == "image_points"
            else f"{_option(m.group(1))} (line {m.group(2)}, from 0)"
        ),
        text,
    )
    text = re.sub(
        rf"{_EDGE_BEFORE}({_NAME})(?: ?= ?(True|[-+\d.]+))?{_EDGE_AFTER}",
        lambda m: (
            _option(m.group(1)) + (f" {m.group(2)}" if m.group(2) and m.group(2) != "True" else "")
        ),
        text,
    )
    return text


def print_error(message):
    print(f"{PROG}: error: {user_terms(one_line(message))}", file=sys.stderr, flush=True)


def warn_user(message):
    print(f"{PROG}: warning: {user_terms(one_line(message))}", file=sys.stderr, flush=True)


def load_calibration(path, say_doubt=False):
    """The camera of a calibration file; with ``say_doubt``, one warning line when its verdict
    records a doubt (:func:`doubt_line`). Any mirror's file (format 1 or 2; a hyperboloid's as
    the design's class). Another tool's camera file (a Kalibr camchain, a ROS camera_info, an
    OCamCalib or cv2.omnidir calibration) is refused naming what it is and the option that
    reads it (:func:`omnicam.formats.other_tools.other_tool_file`)."""
    try:
        camera = calibration_file.load_camera(path)
        if isinstance(camera.mirror, HyperbolicMirror):
            camera = MisalignedHyperbolicCamera.of(camera)
    except FileNotFoundError as e:
        raise CliError(one_line(e)) from None
    except ValueError as e:
        other = other_tool_file(path)  # another tool's file, named for what it is
        if other is not None:
            raise CliError(
                f"{shown(path)} is {other[0]}, not an omnicam calibration; {other[1]}"
            ) from None
        raise CliError(one_line(e)) from None
    if say_doubt:
        line = doubt_line(path)
        if line:
            warn_user(line)
    return camera


def doubt_line(path):
    """One line on what the calibration file ``path`` records as doubtful, or None.

    E.g. ``rig.yaml: calibrated with a guessed K, ambiguous (confidence 0.00): its views may
    be skewed ('omnicam info rig.yaml' says why)``, or ``rig.yaml: calibrated with 2 warnings
    ('omnicam info rig.yaml' lists them)``; a verdict that cannot be read says so.
    """
    try:
        verdict = read_verdict(path)
    except (FileNotFoundError, ValueError) as e:
        return f"{path}: its verdict cannot be read ({one_line(e)})"
    doubts = () if verdict is None else verdict.doubts()
    if not doubts:
        return None
    if verdict.serious():
        return (
            f"{path}: calibrated {', '.join(doubts)}: its views may be skewed "
            f"('omnicam info {path}' says why)"
        )
    return f"{path}: calibrated {', '.join(doubts)} ('omnicam info {path}' lists them)"


def check_output(path, overwrite, what="output"):
    """Refuse an output we must not or cannot write, before doing any work."""
    try:  # a name that is not UTF-8 would crash OpenCV's writers
        path = file_path(path, what)
    except ValueError as e:
        raise CliError(str(e)) from None
    folder = os.path.dirname(os.path.abspath(path))
    if os.path.isdir(path):
        raise CliError(f"{what} {path} is a folder")
    if os.path.lexists(path) and not overwrite:
        raise CliError(f"{what} {path} exists; pass --overwrite to replace it")
    if not os.path.isdir(folder):
        parent = folder
        while parent and not os.path.exists(parent):
            parent = os.path.dirname(parent) if os.path.dirname(parent) != parent else ""
        if parent and not os.path.isdir(parent):
            raise CliError(f"{what} {path}: {parent} is a file, not a folder")
        raise CliError(f"{what} {path}: folder {folder} does not exist")
    if not os.access(folder, os.W_OK | os.X_OK):
        raise CliError(f"{what} {path}: folder {folder} is not writable")


def write_image_file(path, image, overwrite=True):
    """``cv2.imwrite`` through :func:`omnicam._atomic.atomic_output` (checked by reading back)."""
    try:
        path = file_path(path, "output")
    except ValueError as e:
        raise CliError(str(e)) from None
    if not cv2.haveImageWriter(path):
        raise CliError(
            f"output {path}: no image writer for extension "
            f"{os.path.splitext(path)[1] or '(none)'!r}; use .png, .jpg, .tif, ..."
        )

    def verify(tmp):
        back = cv2.imread(tmp, cv2.IMREAD_UNCHANGED)
        return back is not None and back.shape[:2] == image.shape[:2]

    try:
        with (
            opencv_silenced(),
            atomic_output(path, what="image", overwrite=overwrite, verify=verify) as tmp,
        ):
            try:
                ok, detail = cv2.imwrite(tmp, image), None
            except cv2.error as e:
                ok, detail = False, _cv_message(e)
            if not ok:
                raise CliError(f"cannot write {path}: {detail or _why_not_written(tmp)}")
    except OutputError as e:
        raise CliError(str(e)) from None


def _why_not_written(tmp):
    """What most likely stopped ``cv2.imwrite`` (it says only False): a full disk, else a
    format the encoder refused."""
    try:
        st = os.statvfs(os.path.dirname(os.path.abspath(tmp)))
        if st.f_bavail * st.f_frsize < 1 << 20:
            return "the disk is full (less than 1 MB free); free some space and retry"
    except (OSError, AttributeError):
        pass
    return "OpenCV's encoder refused it (an image type or size this format cannot hold?)"


def _cv_message(e):
    """The useful part of a ``cv2.error`` message."""
    lines = [ln for ln in str(e).splitlines() if ln.strip()]
    text = lines[-1] if lines else str(e)
    return re.sub(r"^.*?error: \(-?\d+:[^)]*\)\s*", "", text).strip() or text


IMAGE_EXTENSIONS = (
    ".png",
    ".jpg",
    ".jpeg",
    ".jpe",
    ".bmp",
    ".dib",
    ".tif",
    ".tiff",
    ".webp",
    ".pbm",
    ".pgm",
    ".ppm",
    ".pxm",
    ".pnm",
    ".sr",
    ".ras",
    ".exr",
    ".hdr",
    ".pic",
    ".jp2",
    ".avif",
)


def is_image_input(path):
    """An input to read as one image: an image extension, or content OpenCV recognises.

    By name first, so an empty or corrupt ``.png`` is reported as an unreadable image (not
    treated as a video). A name that is not UTF-8 is refused (:class:`CliError`).
    """
    try:  # OpenCV (imread, VideoCapture) crashes with SIGSEGV on such a name
        path = file_path(path, "input")
    except ValueError as e:
        raise CliError(str(e)) from None
    if os.path.splitext(path)[1].lower() in IMAGE_EXTENSIONS:
        return True
    with contextlib.suppress(OSError):  # unreadable: check_video_input says so
        kind = file_kind(path)
        if kind is not None and kind.endswith("video"):  # cv2's HEIF reader claims any MP4
            return False
    with opencv_silenced():
        return cv2.haveImageReader(path)


def read_image_file(path, flags=cv2.IMREAD_UNCHANGED):
    """:func:`omnicam.images.read_image` with its errors as one-line CLI errors."""
    try:
        return read_image(path, flags)
    except (FileNotFoundError, ValueError) as e:
        raise CliError(str(e)) from None


def check_video_input(path):
    """Refuse, naming what it is, an input that is no image and that OpenCV cannot open as a
    video (a text file, a broken or empty video), before any output is checked or written."""
    try:
        check_readable(path, f"input {shown(path)}")
    except ValueError as e:
        raise CliError(str(e)) from None
    kind = file_kind(path)
    if kind == "a text file":
        raise CliError(f"input {shown(path)} is a text file, not an image or a video")
    with opencv_silenced(ffmpeg=True):
        try:
            cap = cv2.VideoCapture(path)
            opened = cap.isOpened()
            cap.release()
        except cv2.error:
            opened = False
    if not opened:
        size = os.stat(path).st_size
        if kind is not None and kind.endswith("video"):
            raise CliError(
                f"input {shown(path)} is {kind} OpenCV cannot open ({size} bytes): "
                f"truncated or corrupt"
            )
        raise CliError(
            f"input {shown(path)} is not a video OpenCV can open ({size} bytes"
            + (f", {kind} by its first bytes)" if kind else ")")
        )


def read_intrinsics(path):
    """:func:`omnicam.read_intrinsics` with its errors as one-line CLI errors."""
    try:
        return intrinsics.read_intrinsics(path)
    except (FileNotFoundError, ValueError) as e:
        raise CliError(one_line(e)) from None


def read_far_lines(path):
    """:func:`omnicam.read_far_lines` with its errors as one-line CLI errors."""
    try:
        return point_files.read_far_lines(path)
    except (FileNotFoundError, ValueError) as e:
        raise CliError(one_line(e)) from None


def report_text(report, leave_out=(), **lead):
    """The report's summary; ``leave_out``: warnings the caller prints itself (on stderr), left
    out of it so that each is printed once; ``lead``: the ``verdict`` and ``refused`` of its
    first lines (:meth:`CalibrationReport.lead`), default the report's own."""
    leave_out = {str(w) for w in leave_out}
    if leave_out and dataclasses.is_dataclass(report) and hasattr(report, "warnings"):
        kept = [w for w in report.warnings if str(w) not in leave_out]
        report = dataclasses.replace(report, warnings=kept)
        if not kept:  # "no warnings" would be wrong: the caller's follow
            lines = report_text(report, **lead).splitlines()
            return "\n".join(lines[:-1] if lines[-1].strip() == "no warnings" else lines)
    summary = getattr(report, "summary", None)
    return str(summary(**lead) if callable(summary) else summary if summary is not None else report)


def save_calibration(camera, path, overwrite, report=None, **verdict):
    """Write the calibration file, with a verdict when ``report`` is given: an
    :class:`omnicam.Verdict`, or a report taken with the keywords of
    :meth:`~omnicam.Verdict.from_report` (``K_source``, ``K_file``, ``K_note``, ``forced``,
    ``implausible``)."""
    if not overwrite and os.path.lexists(path):
        raise CliError(f"calibration file {path} exists; pass --overwrite to replace it")
    try:
        if report is None:
            calibration_file.save_camera(camera, path)
        else:
            calibration_file.save_camera(
                camera,
                path,
                report if isinstance(report, Verdict) else Verdict.from_report(report, **verdict),
            )
    except (ValueError, OSError) as e:
        why = one_line(e)  # the library's message names the file already
        message = why if why.startswith("cannot write") else f"cannot write {path}: {why}"
        raise CliError(message) from None


def indent_lines(text, prefix="   "):
    return "\n".join(prefix + line for line in text.splitlines())


def pattern_size_arg(text):
    """``COLSxROWS`` of inner corners -> ``(cols, rows)``, each at least 2."""
    m = re.fullmatch(r"\s*(\d+)\s*[xX]\s*(\d+)\s*", text)
    if not m or int(m.group(1)) < 2 or int(m.group(2)) < 2:
        raise argparse.ArgumentTypeError(
            f"expected COLSxROWS of inner corners such as 9x6, got {text!r}"
        )
    return int(m.group(1)), int(m.group(2))


def rim_hint_arg(text):
    """``CX,CY,R`` -> three floats, ``R`` positive."""
    parts = text.replace(" ", "").split(",")
    try:
        cx, cy, r = (float(v) for v in parts)
    except ValueError:
        raise argparse.ArgumentTypeError(
            f"expected CX,CY,R (the rim's centre and radius in px) such as 640,360,300, "
            f"got {text!r}"
        ) from None
    if not all(math.isfinite(v) for v in (cx, cy, r)) or r <= 0:
        raise argparse.ArgumentTypeError(f"expected finite CX,CY and a positive R, got {text!r}")
    return cx, cy, r
