"""``omnicam calibrate --chessboard``: K, D and the posture from chessboards seen in the mirror.

::

    omnicam calibrate --chessboard 9x6 --square 25 IMAGES... [--mirror A B R] -o rig.yaml
                      [--intrinsics K.yaml] [--dist-model M] [--refine-mirror-shape]
                      [--overlay FOLDER] [--overwrite]

Prints the per-view table and the warnings, writes the calibration file and, for each view, an
overlay of the detected (green circles) and reprojected (red crosses) corners into FOLDER
(default: CALIB's stem + ``_views`` next to CALIB).
"""

from __future__ import annotations

import argparse
import os
import re
import warnings

import cv2
import numpy as np

from ._common import (
    EXIT_OK,
    CliError,
    _check_output,
    _one_line,
    _positive,
    _read_image,
    _save_camera,
    _warn,
    _write_image,
    read_intrinsics,
)


def _pattern_size(text):
    m = re.fullmatch(r"\s*(\d+)\s*[xX]\s*(\d+)\s*", text)
    if not m or int(m.group(1)) < 2 or int(m.group(2)) < 2:
        raise argparse.ArgumentTypeError(
            f"expected COLSxROWS of inner corners such as 9x6, got {text!r}"
        )
    return int(m.group(1)), int(m.group(2))


def add_arguments(p):
    """The chessboard options of ``omnicam calibrate``."""
    from ..calibration.pattern import DIST_MODELS

    p.add_argument(
        "--chessboard",
        type=_pattern_size,
        metavar="COLSxROWS",
        help="calibrate K, D and the posture from chessboard IMAGES seen through the "
        "mirror: inner corners per row and per column, as OpenCV (e.g. 9x6); "
        "--intrinsics is then optional (a start for K and D)",
    )
    p.add_argument(
        "--square",
        type=_positive,
        metavar="MM",
        help="with --chessboard: side of a square, in the mirror's unit (mm)",
    )
    p.add_argument(
        "--dist-model",
        choices=sorted(DIST_MODELS),
        default="k1k2p1p2",
        help="with --chessboard: distortion coefficients to estimate (default k1k2p1p2)",
    )
    p.add_argument(
        "--rim-radius",
        type=float,
        default=None,
        metavar="R",
        help="with --chessboard and no --mirror: the rim's radius (mm), which fixes the "
        "mirror's scale (default 30, nominal; the report says so)",
    )
    p.add_argument(
        "--refine-mirror-shape",
        action="store_true",
        help="with --chessboard: also estimate the mirror's a and b (RIM fixes the scale)",
    )


def cmd_calibrate_pattern(args):
    from ..camera import MisalignedHyperbolicCamera, scale_K
    from ..io import SUFFIXES
    from ..mirror import HyperbolicMirror

    if args.square is None:
        raise CliError("calibrate: --chessboard needs --square (side of a square, mm)", 2)
    if args.far_lines:
        raise CliError("calibrate: --far-lines is not used with --chessboard", 2)
    calib = args.output
    if os.path.splitext(calib)[1].lower() not in SUFFIXES:
        raise CliError(f"calibration file {calib}: extension must be one of {', '.join(SUFFIXES)}")
    _check_output(calib, args.overwrite, "calibration file")
    stem = os.path.splitext(os.path.basename(calib))[0]
    folder = args.overlay or os.path.join(os.path.dirname(calib), f"{stem}_views")
    if os.path.exists(folder) and not os.path.isdir(folder):
        raise CliError(f"overlay folder {folder} is a file")
    mirror = None
    if args.mirror is not None:
        try:
            mirror = HyperbolicMirror(*args.mirror)
        except ValueError as e:
            raise CliError(f"--mirror: {e}") from None
        if args.rim_radius is not None:
            raise CliError("calibrate: --rim-radius is for --chessboard without --mirror", 2)
    images = [_read_image(p, cv2.IMREAD_COLOR | cv2.IMREAD_IGNORE_ORIENTATION) for p in args.image]
    size = (images[0].shape[1], images[0].shape[0])
    for path, im in zip(args.image, images):
        if (im.shape[1], im.shape[0]) != size:
            raise CliError(
                f"image {path} is {im.shape[1]}x{im.shape[0]}, {args.image[0]} is "
                f"{size[0]}x{size[1]}: all images must come from the same camera mode"
            )
    K = D = None
    if args.intrinsics:
        K, D, k_size = read_intrinsics(args.intrinsics)
        if k_size is not None and k_size != size:
            _warn(f"intrinsics are for {k_size[0]}x{k_size[1]}: K rescaled to the images")
            K = scale_K(K, k_size, size)
        if D is not None and np.size(D) not in (4, 5):
            _warn("--intrinsics: only k1 k2 p1 p2 k3 of D are used as a start")
            D = np.ravel(D)[:5]
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always", RuntimeWarning)
        try:
            camera, report = MisalignedHyperbolicCamera.calibrate_pattern(
                images,
                args.chessboard,
                args.square,
                mirror,
                K=K,
                D=D,
                refine_mirror_shape=args.refine_mirror_shape,
                dist_model=args.dist_model,
                rim_radius=args.rim_radius,
            )
        except (ValueError, RuntimeError, np.linalg.LinAlgError) as e:
            raise CliError(f"calibration failed: {_one_line(e)}") from None
    print(report.table(), flush=True)
    print(
        f"RMS {report.rms:.3f} px over {len(report.view_rms)} views; rim RMS "
        f"{report.rim_rms:.3f} px; K fx {camera.K[0, 0]:.2f} fy {camera.K[1, 1]:.2f} "
        f"cx {camera.K[0, 2]:.2f} cy {camera.K[1, 2]:.2f} (std {report.std['fx']:.2f}, "
        f"{report.std['fy']:.2f}, {report.std['cx']:.2f}, {report.std['cy']:.2f}); axis std "
        f"{report.std['axis_deg']:.3f} deg, origin std {report.std['origin']:.3f} mm",
        flush=True,
    )
    for w in report.warnings:
        _warn(w)
    for w in caught:
        if not any(str(w.message) == r for r in report.warnings):
            _warn(str(w.message))
    os.makedirs(folder, exist_ok=True)
    for i, path in enumerate(args.image):
        name = os.path.splitext(os.path.basename(path))[0]
        out = os.path.join(folder, f"{i:03d}_{name}.png")
        if os.path.lexists(out) and not args.overwrite:
            raise CliError(f"overlay {out} exists; pass --overwrite to replace it")
        _write_image(out, report.draw(images[i], i), args.overwrite)
    _save_camera(camera, calib, args.overwrite)
    print(f"wrote {calib} and {len(images)} overlays in {folder}")
    return EXIT_OK
