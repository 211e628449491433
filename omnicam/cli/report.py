"""``omnicam report``: one self-contained HTML page on a calibration, from its file and images.

::

    omnicam report CALIB IMAGES... -o PAGE.html [--chessboard COLSxROWS --square MM]
                   [--far-lines LINES.json] [--rim-hint CX,CY,R] [--overwrite]

A chessboard calibration (its verdict says so, or ``--chessboard`` is given): every board is
found again in IMAGES and its pose fitted under the file's camera, which is kept as it is; the
residuals, per-view RMS and coverage are of that fit, the stated uncertainties and held-out
figures the file's. One image: the image is calibrated again with the file's K, D and mirror
(and its camera reflection) to show the four candidate postures and the choice; the page says
how far that run's posture is from the file's, whose camera draws the rest.

Also :func:`add_report_option` / :func:`check_report_output` / :func:`write_pattern_page` /
:func:`write_image_page`: ``omnicam calibrate --report PAGE.html``.
"""

from __future__ import annotations

import os

import cv2
import numpy as np

from ..calibration import calibrate
from ..formats.calibration_file import read_verdict
from ..gauge import posture_error
from ..html_report.redetect import redetected_pattern_report
from ._common import (
    EXIT_OK,
    CliError,
    load_calibration,
    one_line,
    pattern_size_arg,
    positive_arg,
    read_far_lines,
    read_image_file,
    rim_hint_arg,
    warn_user,
)
from .report_pages import check_report_output, write_image_page, write_pattern_page


def _images(paths, camera):
    images = [read_image_file(p, cv2.IMREAD_COLOR | cv2.IMREAD_IGNORE_ORIENTATION) for p in paths]
    size = (images[0].shape[1], images[0].shape[0])
    for p, im in zip(paths, images):
        if (im.shape[1], im.shape[0]) != size:
            raise CliError(
                f"image {p} is {im.shape[1]}x{im.shape[0]}, {paths[0]} is {size[0]}x{size[1]}: "
                f"all images must come from the same camera mode"
            )
    if camera.image_size is not None and camera.image_size != size:
        w, h = camera.image_size
        warn_user(f"the calibration is for {w}x{h}, the images are {size[0]}x{size[1]}: scaled")
        camera = camera.scaled(size)
    return images, camera


def _chessboard(args, camera, verdict, images):
    if args.square is None:
        raise CliError("report: --chessboard needs --square (side of a square, mm)", 2)
    names = [os.path.basename(p) for p in args.images]
    try:
        report = redetected_pattern_report(
            camera, images, args.chessboard, args.square, names, verdict
        )
    except ValueError as e:
        raise CliError(f"report: {one_line(e)}") from None
    for i, why in sorted(report.dropped.items()):
        warn_user(f"{names[i]}: {why}")
    notes = [
        f"From {args.calibration} and {len(images)} image(s): each board found again and its "
        f"pose fitted under the file's camera (kept as it is); the residuals, per-view RMS and "
        f"coverage are of that fit. The stated uncertainties, held-out figures and warnings "
        f"are the file's.",
    ]
    write_pattern_page(
        args.output,
        camera,
        report,
        images,
        names,
        args.chessboard,
        args.overwrite,
        say=False,
        verdict=verdict,
        notes=notes,
    )
    print(
        f"wrote {args.output}: {len(report.view_rms)} of {len(images)} boards found, corner "
        f"RMS {report.rms:.3f} px under the file's camera"
    )


def _one_image(args, camera, images):
    if len(images) != 1:
        raise CliError(
            "report: a calibration from one image takes that one IMAGE (a chessboard "
            "calibration: give --chessboard COLSxROWS --square MM)",
            2,
        )
    far_lines = read_far_lines(args.far_lines) if args.far_lines else None
    refl = camera.camera_reflection
    image = images[0]
    try:
        again, report = calibrate(
            camera.K,
            camera.mirror,
            image=image,
            far_lines=far_lines,
            D=camera.D,
            image_size=(image.shape[1], image.shape[0]),
            lens_r=None if refl is None else refl[0],
            lens_z=None if refl is None else refl[1],
            rim_hint=args.rim_hint,
        )
    except (ValueError, RuntimeError, NotImplementedError, np.linalg.LinAlgError) as e:
        raise CliError(
            f"report: {args.images[0]} cannot be calibrated again: {one_line(e)}"
        ) from None
    axis, origin = posture_error(again, camera)
    notes = [
        f"From {args.calibration} and {args.images[0]}: the image calibrated again with the "
        f"file's K, D and mirror to show the candidates and the choice; that run's posture is "
        f"{axis:.3f} deg (axis) and {origin:.3f} mm (camera centre) from the file's, whose "
        f"camera draws the rim, the panorama and the posture."
    ]
    write_image_page(args.output, camera, report, image, args.overwrite, notes, say=False)
    print(
        f"wrote {args.output}: chosen candidate {report.chosen}, confidence {report.confidence:.3f}"
    )


def cmd_report(args):
    """``omnicam report``: the module docstring."""
    check_report_output(args.output, args.overwrite)
    camera = load_calibration(args.calibration)
    try:
        verdict = read_verdict(args.calibration)
    except (FileNotFoundError, ValueError) as e:
        warn_user(f"{args.calibration}: its verdict cannot be read ({one_line(e)})")
        verdict = None
    images, camera = _images(args.images, camera)
    chessboard = args.chessboard is not None or (
        verdict is not None and verdict.method == "chessboard"
    )
    if chessboard and args.chessboard is None:
        raise CliError(
            f"report: {args.calibration} is a chessboard calibration; give the board: "
            f"--chessboard COLSxROWS --square MM (the file does not record it)",
            2,
        )
    if chessboard:
        for flag, given in (("--far-lines", args.far_lines), ("--rim-hint", args.rim_hint)):
            if given is not None:
                raise CliError(f"report: {flag} is for a calibration from one image", 2)
        _chessboard(args, camera, verdict, images)
    else:
        if args.square is not None:
            raise CliError("report: --square goes with --chessboard", 2)
        _one_image(args, camera, images)
    return EXIT_OK


def add_parser(sub):
    """Register the ``report`` subcommand on ``sub`` (argparse sub-parsers)."""
    p = sub.add_parser(
        "report",
        help="an HTML report of a calibration, from its file and images",
        description="Write one self-contained HTML page (images embedded, no external "
        "reference) on a calibration: for chessboards the coverage, residuals, per-view RMS "
        "and held-out errors, the rim, a panorama with the boards and the posture; for one "
        "image the rim, the four candidate postures as panoramas, the far lines, the choice "
        "and its confidence. The boards (or the candidates) are found again in IMAGES.",
    )
    p.add_argument("calibration", metavar="CALIB", help="omnicam calibration file")
    p.add_argument(
        "images",
        metavar="IMAGE",
        nargs="+",
        help="the images of the calibration: the chessboard views, or the one image",
    )
    p.add_argument("-o", "--output", required=True, metavar="PAGE.html", help="the page to write")
    p.add_argument(
        "--chessboard",
        type=pattern_size_arg,
        metavar="COLSxROWS",
        help="the board's inner corners per row and column (a chessboard calibration: the "
        "file does not record the board)",
    )
    p.add_argument(
        "--square", type=positive_arg, metavar="MM", help="with --chessboard: a square's side"
    )
    p.add_argument(
        "--far-lines",
        metavar="LINES.json",
        help="one image: the far lines of the calibration (JSON list of lines of [x, y] "
        "pixels), drawn in the candidates' panoramas and used for the choice",
    )
    p.add_argument(
        "--rim-hint",
        type=rim_hint_arg,
        metavar="CX,CY,R",
        help="one image: the rough centre and radius of the rim (px), as for calibrate",
    )
    p.add_argument("--overwrite", action="store_true", help="replace an existing page")
    p.set_defaults(func=cmd_report)
    return p
