"""``omnicam calibrate --chessboard``: K, D and the posture from chessboards seen in the mirror.

::

    omnicam calibrate --chessboard 9x6 --square 25 IMAGES... [--mirror A B R | --sphere ... |
                      --paraboloid ... | --asphere ... | --equiangular ... | --mirror-file F]
                      -o rig.yaml
                      [--intrinsics K.yaml | --fx --fy --cx --cy [--dist ...]]
                      [--corners FILE] [--rim-hint CX,CY,R] [--rim-radius R]
                      [--dist-model M] [--refine-mirror-shape] [--heldout K]
                      [--overlay FOLDER] [--overwrite] [--force]

Prints a line per image as its board is looked for, a line on stderr per long step (the
adjustment's evaluations and cost every 2 s and at its end, the shape check, each held-out
fold; ``-q`` silences both), the per-view table, the held-out check
(``--heldout``, 5 folds by default) and the warnings, writes the calibration file and, for each
view, an overlay of the detected (green circles) and reprojected (red crosses) corners into
FOLDER (default: CALIB's stem + ``_views`` next to CALIB). A calibration the plausibility
checks refuse (those of one image, with the same limits ``--max-tilt``, ``--max-offset``; or
all boards on one side of the mirror) exits 1 without a file, as one from one image does
(``--force`` writes it anyway, and its verdict says so).

A mirror given (``--mirror`` for a hyperboloid, or any mirror of :mod:`.mirror_args`) is a start
and sets the scale (its rim's radius is held): its shape (a hyperboloid's ``a, b``, an
asphere's ``R``, ``k`` and terms) is held unless ``--refine-mirror-shape``, which estimates it
from the data sheet's values. Without one the mirror is estimated from the boards.

``--corners FILE`` gives the corners found by another tool, in OpenCV's order (row by row of
``COLSxROWS`` inner corners): JSON, an object ``{"image file name": [[x, y], ...] or null}`` or a
list in the order of IMAGES; or ``.npz``, one ``(N, 2)`` array per image file name (or
``arr_0``, ``arr_1``... in the order of IMAGES). Images without corners there are searched.
"""

from __future__ import annotations

import os
import re
import sys
import warnings

import cv2
import numpy as np

from ..calibration.plausibility import DEFAULT_MAX_OFFSET_MM, DEFAULT_MAX_TILT_DEG
from ..calibration.rim import check_hint, detect_rim
from ..camera import scale_K
from ..chessboard import DIST_MODELS
from ..chessboard.calibrate import calibrate_pattern
from ..chessboard.report import ONE_SIDED
from ..formats.filestorage import SUFFIXES
from ..formats.point_files import read_corners
from ..hyperbolic_camera import MisalignedHyperbolicCamera
from ..mirror import HyperbolicMirror
from ._common import (
    EXIT_OK,
    PROG,
    CliError,
    check_output,
    one_line,
    pattern_size_arg,
    positive_arg,
    read_image_file,
    read_intrinsics,
    save_calibration,
    user_terms,
    warn_user,
    write_image_file,
)
from .mirror_args import given_flags, mirror_of_args


def add_arguments(parser):
    """The chessboard options of ``omnicam calibrate``, as one group of its ``--help``."""
    p = parser.add_argument_group(
        "chessboard mode", "several IMAGES of a chessboard seen through the mirror"
    )
    p.add_argument(
        "--chessboard",
        type=pattern_size_arg,
        metavar="COLSxROWS",
        help="calibrate K, D and the posture from chessboard IMAGES seen through the "
        "mirror: inner corners per row and per column, as OpenCV (e.g. 9x6); "
        "--intrinsics is then optional (a start for K and D)",
    )
    p.add_argument(
        "--square",
        type=positive_arg,
        metavar="MM",
        help="with --chessboard: side of a square, in the mirror's unit (mm)",
    )
    p.add_argument(
        "--dist-model",
        choices=[*sorted(DIST_MODELS), "auto"],
        default=None,
        help="with --chessboard: distortion coefficients to estimate (default k1k2; p1, p2 "
        "trade against the mirror's tilt; rational and radial6: OpenCV's rational model, a "
        "wide-angle lens; auto: the simplest that predicts held-out views as well as the best)",
    )
    p.add_argument(
        "--corners",
        metavar="FILE",
        help="with --chessboard: corners per image from another tool (JSON or .npz, OpenCV's "
        "order; see the docs of omnicam calibrate --chessboard)",
    )
    p.add_argument(
        "--heldout",
        type=int,
        default=None,
        metavar="K",
        help="with --chessboard: K-fold held-out check of the calibration, cv2.omnidir's beside "
        "it (default 5; 0 skips it)",
    )
    p.add_argument(
        "--rim-radius",
        type=float,
        default=None,
        metavar="R",
        help="with --chessboard and no mirror given: the rim's radius (mm), which fixes the "
        "mirror's scale (default 30, nominal; the report says so)",
    )
    p.add_argument(
        "--refine-mirror-shape",
        action="store_true",
        help="with --chessboard and a mirror given: also estimate its shape (a hyperboloid's "
        "a and b, an asphere's R, k and terms; its rim's radius fixes the scale)",
    )


#: The options of chessboard mode alone (refused without --chessboard, never ignored).
CHESSBOARD_ONLY = (
    "square",
    "corners",
    "heldout",
    "dist_model",
    "rim_radius",
    "refine_mirror_shape",
)


def refuse_chessboard_options(args):
    """One readable refusal (exit 2) of an option of chessboard mode given without it."""
    for name in CHESSBOARD_ONLY:
        if getattr(args, name) not in (None, False):
            flag = "--" + name.replace("_", "-")
            raise CliError(f"calibrate: {flag} is an option of --chessboard mode", 2)


def _read_corners(path, image_paths, n_corners):
    """:func:`omnicam.formats.point_files.read_corners` of ``--corners``, errors as CLI errors."""
    try:
        return read_corners(path, image_paths, n_corners, what="--corners")
    except (FileNotFoundError, ValueError) as e:
        raise CliError(one_line(e)) from None


def _start_intrinsics(args, size):
    """``(K, D)`` starts from --intrinsics or --fx --fy --cx --cy [--dist], or None."""
    given = [n for n in ("fx", "fy", "cx", "cy") if getattr(args, n) is not None]
    if args.intrinsics is not None and (given or args.dist is not None):
        raise CliError("calibrate: give --intrinsics or --fx --fy --cx --cy [--dist], not both", 2)
    if given and len(given) != 4:
        raise CliError("calibrate: --fx --fy --cx --cy go together (a start for K)", 2)
    if args.dist is not None and not given:
        raise CliError("calibrate: --dist is a start for D with --fx --fy --cx --cy", 2)
    K = D = None
    if given:
        K = np.array([[args.fx, 0.0, args.cx], [0.0, args.fy, args.cy], [0.0, 0.0, 1.0]])
        D = None if args.dist is None else np.asarray(args.dist, np.float64)
    elif args.intrinsics:
        K, D, k_size = read_intrinsics(args.intrinsics)
        if k_size is not None and k_size != size:
            warn_user(f"intrinsics are for {k_size[0]}x{k_size[1]}: K rescaled to the images")
            K = scale_K(K, k_size, size)
    if D is not None and np.size(D) not in (4, 5, 8):
        warn_user("the distortion start: only k1 k2 p1 p2 k3 k4 k5 k6 of D are used")
        D = np.ravel(D)[: 8 if np.size(D) > 8 else 5]
    return K, D


def _check_options(args):
    """The options of chessboard mode, checked; returns the mirror start (or None)."""
    if args.square is None:
        raise CliError("calibrate: --chessboard needs --square (side of a square, mm)", 2)
    if args.far_lines:
        raise CliError("calibrate: --far-lines is not used with --chessboard", 2)
    if args.lens_r is not None:
        raise CliError(
            "calibrate: --lens-r is for one image; --chessboard fits the reflection's radius "
            "from its outline (give --lens-z, its plane)",
            2,
        )
    args.heldout = 5 if args.heldout is None else args.heldout
    args.dist_model = args.dist_model or "k1k2"
    if args.heldout < 0 or args.heldout == 1:
        raise CliError("calibrate: --heldout K needs K >= 2 folds (0 skips the check)", 2)
    sheet = mirror_of_args(args)  # --sphere, --asphere, ...: a data sheet of any mirror
    if args.mirror is None and sheet is None:
        return None
    if args.rim_radius is not None:
        flag = "--mirror" if sheet is None else given_flags(args)[0]
        raise CliError(
            f"calibrate: --rim-radius is for --chessboard without a mirror; {flag} gives the "
            f"rim's radius",
            2,
        )
    if sheet is not None:
        return sheet
    try:
        return HyperbolicMirror(*args.mirror)
    except ValueError as e:
        raise CliError(f"--mirror: {e}") from None


def _outputs(args):
    """``(calibration file, overlay folder)``, checked before any work."""
    calib = args.output
    if os.path.splitext(calib)[1].lower() not in SUFFIXES:
        raise CliError(f"calibration file {calib}: extension must be one of {', '.join(SUFFIXES)}")
    check_output(calib, args.overwrite, "calibration file")
    stem = os.path.splitext(os.path.basename(calib))[0]
    folder = args.overlay or os.path.join(os.path.dirname(calib), f"{stem}_views")
    if os.path.exists(folder) and not os.path.isdir(folder):
        raise CliError(f"overlay folder {folder} is a file")
    return calib, folder


def _read_views(paths):
    """The images, all of one size: ``(images, (width, height))``."""
    images = [read_image_file(p, cv2.IMREAD_COLOR | cv2.IMREAD_IGNORE_ORIENTATION) for p in paths]
    size = (images[0].shape[1], images[0].shape[0])
    for path, im in zip(paths, images):
        if (im.shape[1], im.shape[0]) != size:
            raise CliError(
                f"image {path} is {im.shape[1]}x{im.shape[0]}, {paths[0]} is "
                f"{size[0]}x{size[1]}: all images must come from the same camera mode"
            )
    return images, size


def _hinted_rim(args, images, size):
    """The rim points found with ``--rim-hint`` in the first image, or None without it."""
    if args.rim_hint is None:
        return None
    try:
        check_hint(args.rim_hint, size)
        return detect_rim(images[0], hint=args.rim_hint).points
    except ValueError as e:
        raise CliError(f"--rim-hint: {one_line(e)}") from None


def _cli_terms(text, names):
    """A library message in the command's words: ``pattern_size=(7, 11)`` as ``--chessboard
    7x11``, ``images[i]`` as the image's file name."""
    text = re.sub(r"pattern_size=\((\d+), (\d+)\)", r"--chessboard \1x\2", text)
    return re.sub(
        r"images\[(\d+)\]",
        lambda m: names[int(m[1])] if int(m[1]) < len(names) else m[0],
        text,
    )


def _print_report(camera, report, names, caught, verdict, refused):
    """What users use first (:meth:`PatternReport.lead`: the viewing directions, the held-out
    check, the verdict, what boards cannot fix), then the per-view table and the figures; the
    notes on stdout, every alarm and implausible finding once on stderr."""
    for line in report.lead(verdict, refused):
        print(user_terms(line), flush=True)
    print(report.table(names), flush=True)
    print(
        f"RMS {report.rms:.3f} px over {len(report.view_rms)} views; rim RMS "
        f"{report.rim_rms:.3f} px; K fx {camera.K[0, 0]:.2f} fy {camera.K[1, 1]:.2f} "
        f"cx {camera.K[0, 2]:.2f} cy {camera.K[1, 2]:.2f} (std {report.std['fx']:.2f}, "
        f"{report.std['fy']:.2f}, {report.std['cx']:.2f}, {report.std['cy']:.2f}); axis std "
        f"{report.std['axis_deg']:.3f} deg, origin std {report.std['origin']:.3f} mm; "
        f"viewing directions std {report.ray_std_deg[0]:.3f} deg (worst "
        f"{report.ray_std_deg[1]:.3f})",
        flush=True,
    )
    for line in report.lens_lines():
        print(line, flush=True)
    if report.lens_note:
        print(user_terms(f"camera's reflection: {report.lens_note}"), flush=True)
    for w in report.notes:
        print(user_terms(f"note (by nature, not a doubt): {w}"), flush=True)
    for w in report.alarms:
        warn_user(_cli_terms(w, names))
    for w in report.implausible:
        warn_user(f"implausible: {w}")
    for w in caught:
        if not any(str(w.message) == r for r in report.warnings):
            warn_user(_cli_terms(str(w.message), names))


def _write_overlays(args, report, images, folder):
    """One overlay per image (detected and reprojected corners, the rim) into ``folder``."""
    os.makedirs(folder, exist_ok=True)
    for i, path in enumerate(args.image):
        name = os.path.splitext(os.path.basename(path))[0]
        out = os.path.join(folder, f"{i:03d}_{name}.png")
        if os.path.lexists(out) and not args.overwrite:
            raise CliError(f"overlay {out} exists; pass --overwrite to replace it")
        write_image_file(out, report.draw(images[i], i), args.overwrite)


def cmd_calibrate_pattern(args):
    """``omnicam calibrate --chessboard``: the module docstring."""
    mirror = _check_options(args)
    calib, folder = _outputs(args)
    images, size = _read_views(args.image)
    K, D = _start_intrinsics(args, size)
    cols, rows = args.chessboard
    points = None if args.corners is None else _read_corners(args.corners, args.image, cols * rows)
    boundary = _hinted_rim(args, images, size)
    names = [os.path.basename(p) for p in args.image]

    def progress(i, text):
        if args.quiet:
            return
        if i is None:  # a long step (the adjustment, the shape check, a held-out fold)
            print(f"{PROG}: {user_terms(text)}", file=sys.stderr, flush=True)
        else:
            print(f"[{i + 1}/{len(names)}] {names[i]}: {text}", flush=True)

    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always", RuntimeWarning)
        try:
            camera, report = calibrate_pattern(
                images,
                args.chessboard,
                args.square,
                mirror,
                K=K,
                D=D,
                image_points=points,
                boundary_points=boundary,
                refine_mirror_shape=args.refine_mirror_shape,
                dist_model=args.dist_model,
                rim_radius=args.rim_radius,
                lens_z=args.lens_z,
                heldout=args.heldout if len(images) >= 4 else 0,
                progress=progress,
            )
        except (ValueError, RuntimeError, np.linalg.LinAlgError) as e:
            raise CliError(f"calibration failed: {_cli_terms(one_line(e), names)}") from None
    if isinstance(camera.mirror, HyperbolicMirror):  # (an asphere stays the generic camera)
        camera, report = MisalignedHyperbolicCamera._with_report(camera, report)
    if (args.max_tilt, args.max_offset) != (DEFAULT_MAX_TILT_DEG, DEFAULT_MAX_OFFSET_MM):
        report = report.with_limits(args.max_tilt, args.max_offset)
    implausible = report.implausible
    refused = bool(implausible) and not args.force
    verdict = report.verdict(forced=bool(implausible) and args.force)
    camera = camera.replace(verdict=verdict)
    _print_report(camera, report, names, caught, verdict, refused)
    if refused:  # as an implausible calibration from one image
        raise CliError(
            f"the calibration is implausible ({len(implausible)} finding"
            f"{'s' if len(implausible) > 1 else ''} above"
            + (
                ": the boards are all on one side of the mirror, so the views cannot tell the "
                "principal point from the tilt; add views on the other side"
                if any(w.startswith(ONE_SIDED) for w in implausible)
                else ""
            )
            + f"); {calib} not written; fix the inputs, or pass --force to write it anyway"
        )
    _write_overlays(args, report, images, folder)
    if args.report:  # omnicam calibrate --report (cli/report.py)
        from .report_pages import write_pattern_page

        write_pattern_page(
            args.report, camera, report, images, names, args.chessboard, args.overwrite
        )
    save_calibration(camera, calib, args.overwrite, verdict)
    print(f"wrote {calib} and {len(images)} overlays in {folder}")
    return EXIT_OK
