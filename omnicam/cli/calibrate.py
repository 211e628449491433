"""``omnicam calibrate``: the mirror posture from one image of the mirror."""

from __future__ import annotations

import os

import cv2
import numpy as np

from . import pattern
from ._common import (
    EXIT_OK,
    CliError,
    _check_output,
    _one_line,
    _positive,
    _read_image,
    _report_text,
    _save_camera,
    _warn,
    _write_image,
    read_far_lines,
    read_intrinsics,
)


def cmd_calibrate(args):
    from ..camera import MisalignedHyperbolicCamera, scale_K
    from ..io import SUFFIXES
    from ..mirror import HyperbolicMirror

    # chessboards seen through the mirror: K, D and the posture (cli/pattern.py)
    if args.chessboard is not None:
        return pattern.cmd_calibrate_pattern(args)
    if len(args.image) != 1:
        raise CliError("calibrate: give one IMAGE (several only with --chessboard)", 2)
    if args.intrinsics is None:
        raise CliError("calibrate: --intrinsics is required (or use --chessboard)", 2)
    args.image = args.image[0]

    calib = args.output
    if os.path.splitext(calib)[1].lower() not in SUFFIXES:
        raise CliError(
            f"calibration file {calib}: extension must be one of {', '.join(SUFFIXES)}"
        )
    overlay = args.overlay or _overlay_path(calib)
    _check_output(calib, args.overwrite, "calibration file")
    _check_output(overlay, args.overwrite, "overlay")
    if not cv2.haveImageWriter(overlay):
        raise CliError(
            f"overlay {overlay}: no image writer for its extension; use .png or .jpg"
        )
    if (
        os.path.exists(overlay)
        and os.path.exists(args.image)
        and os.path.samefile(overlay, args.image)
    ):
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
        _warn(
            f"intrinsics are for {size[0]}x{size[1]}, image is {image_size[0]}x{image_size[1]}: "
            f"K rescaled"
        )
        K = scale_K(K, size, image_size)

    try:
        camera, report = MisalignedHyperbolicCamera.calibrate(
            K,
            mirror,
            image=image,
            far_lines=far_lines,
            D=D,
            image_size=image_size,
            refine=args.refine,
        )
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


def add_parser(sub):
    """Register the ``calibrate`` subcommand on ``sub`` (argparse sub-parsers)."""
    p = sub.add_parser(
        "calibrate",
        help="mirror posture from one image of the mirror",
        description="Estimate the mirror posture from one image: rim ellipse, "
        "Chen's method, far-line selection and refinement. Prints the report, "
        "saves an overlay image and writes the calibration file.",
    )
    p.add_argument(
        "image",
        metavar="IMAGE",
        nargs="+",
        help="image of the mirror (any format cv2.imread reads); with --chessboard, "
        "the images of the board",
    )
    p.add_argument(
        "--mirror",
        nargs=3,
        type=_positive,
        required=True,
        metavar=("A", "B", "RIM"),
        help="hyperboloid parameters a, b and rim radius (mm)",
    )
    p.add_argument(
        "--intrinsics",
        metavar="K.yaml",
        help="cv2.FileStorage file (yaml/yml/xml/json) with the camera matrix 'K' "
        "(or 'camera_matrix'), optional distortion 'D' (or 'dist_coeffs', "
        "'distortion_coefficients') and optional 'image_size' [w, h] (or "
        "'image_width' and 'image_height'); K is rescaled if image_size differs "
        "from IMAGE's size. An omnicam calibration file also works.",
    )
    p.add_argument(
        "--far-lines",
        metavar="LINES.json",
        help="JSON list of lines, each a list of [x, y] pixels of a straight scene "
        "line far from the camera; used to pick the right posture candidate",
    )
    p.add_argument(
        "-o",
        "--output",
        required=True,
        metavar="CALIB",
        help="calibration file to write (.yaml, .yml, .xml or .json)",
    )
    p.add_argument(
        "--no-refine",
        dest="refine",
        action="store_false",
        help="keep the closed-form posture, skip the refinement",
    )
    p.add_argument(
        "--overlay",
        metavar="PATH",
        help="overlay image to write (default: CALIB's stem + '_overlay.png', "
        "next to CALIB)",
    )
    p.add_argument(
        "--overwrite", action="store_true", help="replace existing output files"
    )
    pattern.add_arguments(p)
    p.set_defaults(func=cmd_calibrate)
    return p
