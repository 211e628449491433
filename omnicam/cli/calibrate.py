"""``omnicam calibrate``: the mirror posture from one image of the mirror."""

from __future__ import annotations

import os

import cv2
import numpy as np

from .._validate import validate_D, validate_K
from ..calibration import calibrate
from ..calibration.plausibility import guess_K, rim_radius_px
from ..calibration.rim import check_hint, detect_rim, fit_rim
from ..camera import scale_K
from ..formats.calibration_file import read_verdict
from ..formats.filestorage import SUFFIXES
from ..formats.point_files import BOUNDARY_FORMAT, read_boundary_points
from ..formats.verdict import Verdict
from ..gauge import posture_error
from ..images import aspect_note as frame_aspect_note
from ..mirror import HyperbolicMirror
from . import pattern
from . import report_pages as report_page
from ._common import (
    EXIT_OK,
    CliError,
    check_output,
    finite_arg,
    load_calibration,
    one_line,
    positive_arg,
    read_far_lines,
    read_image_file,
    read_intrinsics,
    report_text,
    rim_hint_arg,
    save_calibration,
    user_terms,
    warn_user,
    write_image_file,
)
from .mirror_args import MIRROR_FLAGS, add_mirror_options, mirror_of_args


def _check_mode(args):
    """One IMAGE of the mirror and one source of the intrinsics (the chessboard mode aside)."""
    if args.from_rig is not None:
        _refuse_beside_from(args)
    if args.guess_k:
        _refuse_beside_guess(args)
    pattern.refuse_chessboard_options(args)
    if len(args.image) != 1:
        raise CliError("calibrate: give one IMAGE (several only with --chessboard)", 2)
    given = [n for n in ("fx", "fy", "cx", "cy") if getattr(args, n) is not None]
    if args.intrinsics is not None and (given or args.dist is not None):
        raise CliError("calibrate: give --intrinsics or --fx --fy --cx --cy [--dist], not both", 2)
    if args.from_rig is None and not args.guess_k and args.intrinsics is None and len(given) != 4:
        raise CliError(
            "calibrate: give the camera's intrinsics: --intrinsics K.yaml, or all of "
            "--fx --fy --cx --cy [--dist ...], or --guess-k (K from the rim and the mirror, "
            "as if the rig were aligned: a guess, and the file says so); or use --chessboard",
            2,
        )


def _outputs(args):
    """``(calibration file, overlay, refused overlay)``, checked before any work."""
    calib = args.output
    if os.path.splitext(calib)[1].lower() not in SUFFIXES:
        raise CliError(f"calibration file {calib}: extension must be one of {', '.join(SUFFIXES)}")
    overlay = args.overlay or _overlay_path(calib)
    refused_overlay = refused_overlay_path(overlay)
    check_output(calib, args.overwrite, "calibration file")
    check_output(overlay, args.overwrite, "overlay")
    check_output(refused_overlay, True, "overlay")  # replaced by every refused attempt
    if not cv2.haveImageWriter(overlay):
        raise CliError(f"overlay {overlay}: no image writer for its extension; use .png or .jpg")
    for path in (overlay, refused_overlay):
        if (
            os.path.exists(path)
            and os.path.exists(args.image)
            and os.path.samefile(path, args.image)
        ):
            raise CliError(f"overlay {path} is the input image")
    return calib, overlay, refused_overlay


def _rig_inputs(args):
    """``(K, D, mirror, K's image size, where K came from, earlier rig or None)``; with
    ``--guess-k`` K, D and the size are None (guessed from the image later)."""
    if args.from_rig is not None:  # after a bump: K, D and the mirror of an earlier calibration
        rig = load_calibration(args.from_rig)
        return rig.K, rig.D, rig.mirror, rig.image_size, _k_from_rig(args.from_rig), rig
    mirror = mirror_of_args(args)  # any other mirror of revolution (.mirror_args)
    if mirror is None and args.mirror is None:
        raise CliError(
            "calibrate: give the mirror: --mirror A B RIM (a hyperboloid), or --sphere, "
            "--paraboloid, --asphere, --equiangular or --mirror-file (or calibrate from "
            "chessboards with --chessboard, which needs no mirror, or take K, D and the mirror "
            "of an earlier calibration with --from RIG.yaml)",
            2,
        )
    if mirror is None:
        try:
            mirror = HyperbolicMirror(*args.mirror)
        except ValueError as e:
            raise CliError(f"--mirror: {e}") from None
    if args.intrinsics is not None:
        K, D, size = read_intrinsics(args.intrinsics)
        return K, D, mirror, size, {"K_source": "file", "K_file": args.intrinsics}, None
    if args.guess_k:
        return None, None, mirror, None, None, None
    K, D, size = _intrinsics_from_numbers(args)
    return K, D, mirror, size, {"K_source": "given"}, None


def _image_inputs(args):
    """``(image, its size, far lines, boundary points)``, the rim hint checked."""
    far_lines = read_far_lines(args.far_lines) if args.far_lines else None
    boundary = _read_boundary_points(args.boundary_points) if args.boundary_points else None
    image = read_image_file(args.image, cv2.IMREAD_COLOR | cv2.IMREAD_IGNORE_ORIENTATION)
    image_size = (image.shape[1], image.shape[0])
    if args.rim_hint is not None:
        try:
            check_hint(args.rim_hint, image_size)
        except ValueError as e:
            raise CliError(f"--rim-hint: {one_line(e)}") from None
        if boundary is not None:
            warn_user("--rim-hint is not used with --boundary-points (the rim is fitted to them)")
    return image, image_size, far_lines, boundary


def _finish(args, camera, report, image, outputs, k_from, rig):
    """Print the report (each warning once), refuse an implausible result (its overlay under
    its own name) or write the overlay and the file with its verdict."""
    calib, overlay, refused_overlay = outputs
    implausible = [str(w) for w in getattr(report, "plausibility", ())]
    refused = bool(implausible) and not args.force
    verdict = Verdict.from_report(report, forced=bool(implausible) and args.force, **k_from)
    # the lead (the uncertainty of the rays, the verdict) as judged here
    text = report_text(report, implausible, verdict=verdict, refused=refused)
    print(user_terms(text), flush=True)
    if rig is not None:
        print(_moved_text(camera, rig, args.from_rig, report))
    for w in implausible:
        warn_user(f"implausible: {w}")
    if args.report:  # refused or not: the page shows what went wrong
        report_page.write_image_page(args.report, camera, report, image, args.overwrite)
    if refused:
        # the overlay shows what went wrong; under its own name, so that it never blocks a retry
        write_image_file(refused_overlay, report.draw(image), True)
        raise CliError(
            f"the calibration of {args.image} is implausible ({len(implausible)} warning"
            f"{'s' if len(implausible) > 1 else ''} above); {calib} not written, see "
            f"{refused_overlay}; fix the inputs, or pass --force to write it anyway"
            + aspect_note((image.shape[1], image.shape[0]))
        )
    write_image_file(overlay, report.draw(image), args.overwrite)
    save_calibration(camera, calib, args.overwrite, verdict)
    doubts = verdict.doubts()
    print(
        f"wrote {calib} and {overlay}"
        + (f" (the file records: calibrated {', '.join(doubts)})" if doubts else "")
    )
    return EXIT_OK


def cmd_calibrate(args):
    """``omnicam calibrate``: one image (or, with ``--chessboard``, boards: cli/pattern.py)."""
    if args.chessboard is not None:
        if args.from_rig is not None:
            _refuse_beside_from(args)
        if args.guess_k:
            _refuse_beside_guess(args)
        for flag, given in (("--choose", args.choose), ("--candidates", args.candidates)):
            if given is not None:
                raise CliError(
                    f"calibrate: {flag} is for one image (Chen's four postures); "
                    f"--chessboard has no candidates",
                    2,
                )
        report_page.check_report_output(args.report, args.overwrite)
        return pattern.cmd_calibrate_pattern(args)
    _check_mode(args)
    args.image = args.image[0]
    outputs = _outputs(args)
    report_page.check_report_output(args.report, args.overwrite)
    _check_candidates_folder(args.candidates, args.overwrite)
    K, D, mirror, size, k_from, rig = _rig_inputs(args)
    image, image_size, far_lines, boundary = _image_inputs(args)
    if args.guess_k:
        K, note = _guess_K_of_image(image, mirror, args.image, args.rim_hint, boundary)
        k_from = {"K_source": "guessed", "K_note": note}
        print(f"K guessed: {note}", flush=True)
    if size is not None and size != image_size:
        source = f"--from {args.from_rig}" if args.from_rig else "intrinsics"
        warn_user(
            f"{source}: K is for {size[0]}x{size[1]}, image is "
            f"{image_size[0]}x{image_size[1]}: K rescaled"
        )
        K = scale_K(K, size, image_size)
    try:
        camera, report = calibrate(
            K,
            mirror,
            image=image,
            boundary_points=boundary,
            far_lines=far_lines,
            D=D,
            image_size=image_size,
            refine=args.refine,
            rim_hint=args.rim_hint,
            max_tilt_deg=args.max_tilt,
            max_offset_mm=args.max_offset,
            lens_r=args.lens_r,
            lens_z=args.lens_z,
            choose=args.choose,
        )
    except (ValueError, RuntimeError, NotImplementedError, np.linalg.LinAlgError) as e:
        raise CliError(
            f"calibration of {args.image} failed: {one_line(e)}"
            f"{aspect_note(image_size, one_line(e))}"
        ) from None
    if args.candidates is not None:
        _write_candidates(args.candidates, camera, report, image, args.overwrite)
    return _finish(args, camera, report, image, outputs, k_from, rig)


def aspect_note(image_size, said=""):
    """:func:`omnicam.images.aspect_note` of ``image_size``, unless ``said`` (the library's
    message, e.g. :func:`omnicam.detect_rim`'s) says it already."""
    note = frame_aspect_note(image_size)
    return "" if note and note in said else note


def refused_overlay_path(overlay):
    """Where a refused calibration's overlay goes: ``rig_overlay.png`` ->
    ``rig_overlay_refused.png``.

    Not the overlay's own name, so a refused attempt leaves nothing that stops the next one
    (every refused attempt replaces it; no calibration file goes with it).
    """
    stem, ext = os.path.splitext(overlay)
    return f"{stem}_refused{ext}"


def _guess_K_of_image(image, mirror, name, hint, boundary):
    """``(K, note)``: :func:`guess_K` of the rim in ``image`` (or fitted to ``boundary``)."""
    try:
        rim = fit_rim(boundary) if boundary is not None else detect_rim(image, hint=hint)
    except ValueError as e:
        raise CliError(
            f"--guess-k: no rim to guess K from in {name} ({one_line(e)}); give --rim-hint "
            f"CX,CY,R or --boundary-points, or the intrinsics"
            + aspect_note((image.shape[1], image.shape[0]), one_line(e))
        ) from None
    try:
        K = guess_K(rim, mirror)
    except ValueError as e:  # a mirror that does not say where the camera sits
        raise CliError(f"--guess-k: {one_line(e)} (--vertex-z)") from None
    r = rim_radius_px(rim)
    depth = "(z_rim + c)" if isinstance(mirror, HyperbolicMirror) else "(z_rim - camera's z)"
    note = (
        f"fx = fy = {K[0, 0]:.1f} px, principal point ({K[0, 2]:.1f}, {K[1, 2]:.1f}) at the "
        f"rim's centre; f = {r:.1f} px (the rim's radius) x {depth} / rim_radius, as if the "
        f"rig were aligned (the posture is only as right as this guess)"
    )
    return K, note


def _k_from_rig(path):
    """Where the K of ``--from RIG`` came from: as its verdict says (a guess stays a guess)."""
    try:
        earlier = read_verdict(path)
    except (FileNotFoundError, ValueError):
        earlier = None
    source = "file" if earlier is None or earlier.K_source == "given" else earlier.K_source
    return {"K_source": source, "K_file": path, "K_note": "" if earlier is None else earlier.K_note}


def _refuse_beside_guess(args):
    """``--guess-k`` makes K: an option that gives K contradicts it."""
    fx = any(getattr(args, n) is not None for n in ("fx", "fy", "cx", "cy"))
    for flag, given, why in (
        ("--chessboard", args.chessboard is not None, "--chessboard fits K to the boards"),
        ("--fx/--fy/--cx/--cy", fx, "they give K"),
        ("--dist", args.dist is not None, "the guess has no distortion"),
    ):
        if given:
            raise CliError(
                f"calibrate: --guess-k makes K from the rim and the mirror; do not give {flag} "
                f"with it ({why})",
                2,
            )


# the options whose values --from takes from its file (K, D and the mirror)
_NOT_WITH_FROM = (
    ("mirror", "--mirror", "the mirror"),
    *((dest, flag, "the mirror") for dest, flag in MIRROR_FLAGS),
    ("alpha", "--alpha", "the mirror"),
    ("vertex_z", "--vertex-z", "the mirror"),
    ("fx", "--fx", "K"),
    ("fy", "--fy", "K"),
    ("cx", "--cx", "K"),
    ("cy", "--cy", "K"),
    ("dist", "--dist", "D"),
)


def _refuse_beside_from(args):
    """``--from`` gives K, D and the mirror: an option that gives them too is a contradiction."""
    if args.chessboard is not None:
        raise CliError(
            "calibrate: --from is not used with --chessboard (--from re-estimates the posture "
            "alone from one IMAGE of the mirror; --chessboard calibrates K, D, the mirror and "
            "the posture from boards)",
            2,
        )
    for field, flag, what in _NOT_WITH_FROM:
        if getattr(args, field) is not None:
            raise CliError(
                f"calibrate: --from {args.from_rig} gives {what}; do not give {flag} with it "
                f"(to change {what}, calibrate without --from)",
                2,
            )


def _moved_text(camera, rig, name, report):
    """One line: how far the new posture is from the earlier one, beside its uncertainty."""
    axis, origin = posture_error(camera, rig)
    return (
        f"  K, D and the mirror from {name}; the posture differs from its by: mirror axis "
        f"{axis:.3f} deg (this image's stated uncertainty {report.axis_std_deg:.3g} deg), "
        f"camera centre {origin:.3f} (stated {report.origin_std_mm:.3g})"
    )


def _read_boundary_points(path):
    """:func:`omnicam.formats.point_files.read_boundary_points` with its errors as CLI errors."""
    try:
        return read_boundary_points(path)
    except (FileNotFoundError, ValueError) as e:
        raise CliError(one_line(e)) from None


def _candidate_path(folder, i):
    return os.path.join(folder, f"candidate_{i}.jpg")


def _check_candidates_folder(folder, overwrite):
    """``--candidates DIR``: a folder (made if missing) whose panoramas we may write."""
    if folder is None:
        return
    if os.path.exists(folder) and not os.path.isdir(folder):
        raise CliError(f"--candidates {folder} is a file, not a folder")
    for i in range(4):
        path = _candidate_path(folder, i)
        if os.path.lexists(path) and not overwrite:
            raise CliError(f"--candidates: {path} exists; pass --overwrite to replace it")


def _write_candidates(folder, camera, report, image, overwrite):
    """Each candidate's panorama (far lines drawn) into ``folder``, to choose by eye."""
    from ..html_report.image import candidate_panoramas

    try:
        os.makedirs(folder, exist_ok=True)
    except OSError as e:
        raise CliError(f"--candidates: cannot create {folder}: {e.strerror or e}") from None
    panos, _ = candidate_panoramas(camera, report, image, width=1200)
    for i, pano, why in panos:
        path = _candidate_path(folder, i)
        if pano is None:
            print(f"  candidate {i}: {why}")
            continue
        write_image_file(path, pano, overwrite)
        mark = " (chosen)" if i == report.chosen else ""
        print(f"  candidate {i}{mark}: wrote {path}")
    print("  (look at them, then --choose N takes candidate N)", flush=True)


def _overlay_path(calib):
    stem = os.path.splitext(os.path.basename(calib))[0]
    return os.path.join(os.path.dirname(calib), f"{stem}_overlay.png")


def _intrinsics_from_numbers(args):
    """``K, D, None`` from ``--fx --fy --cx --cy [--dist ...]`` (the image gives the size)."""
    K = [[args.fx, 0.0, args.cx], [0.0, args.fy, args.cy], [0.0, 0.0, 1.0]]
    try:
        return validate_K(K), validate_D(args.dist), None
    except ValueError as e:
        raise CliError(f"--fx --fy --cx --cy --dist: {one_line(e)}") from None


def add_parser(sub):
    """Register the ``calibrate`` subcommand on ``sub`` (argparse sub-parsers)."""
    p = sub.add_parser(
        "calibrate",
        help="mirror posture from one image of the mirror",
        description="Estimate the mirror posture from one image: rim ellipse, "
        "Chen's method, far-line selection and refinement. Prints the report, "
        "saves an overlay image and writes the calibration file. A result no real rig "
        "gives (tilt or offset above the limits, K inconsistent with the image or the "
        "rim, a and b fitting better swapped, large residuals) is printed with what to "
        "check and NOT written (exit status 1) unless --force.",
    )
    p.add_argument(
        "image",
        metavar="IMAGE",
        nargs="+",
        help="image of the mirror (any format cv2.imread reads); with --chessboard, "
        "the images of the board",
    )
    mirror = p.add_argument_group("the mirror")
    mirror.add_argument(
        "--mirror",
        nargs=3,
        type=positive_arg,
        metavar=("A", "B", "RIM"),
        help="the mirror (mm): A, B and the rim's radius RIM of the hyperboloid "
        "(X^2+Y^2)/A^2 - Z^2/B^2 = -1 (the paper's eq. 1), Z along the mirror's axis. B is "
        "the semi-axis ALONG the axis (the mirror's apex is B from the hyperboloid's centre, "
        "its foci are sqrt(A^2+B^2) from it); A is the semi-axis ACROSS it (the asymptotes "
        "rise B/A per unit of radius). Data sheets name them either way: one that writes "
        "Z^2/a^2 - (X^2+Y^2)/b^2 = 1 means --mirror b a RIM. One image needs it or another mirror "
        "option below (unless "
        "--from); with --chessboard optional (a start; without it the mirror is estimated "
        "from the boards)",
    )
    add_mirror_options(mirror)  # any other mirror of revolution: --sphere, --asphere, ...
    k = p.add_argument_group(
        "the camera's intrinsics",
        "one of --intrinsics, --fx/--fy/--cx/--cy [--dist], --guess-k or --from; with "
        "--chessboard optional (a start)",
    )
    one = k.add_mutually_exclusive_group()
    one.add_argument(
        "--from",
        dest="from_rig",
        metavar="RIG.yaml",
        help="after a bump: take K, D and the mirror from an earlier omnicam calibration file "
        "(e.g. one made with --chessboard) and estimate only the mirror posture from IMAGE; "
        "prints how far it moved. Not with --mirror, --intrinsics, --fx/--fy/--cx/--cy/--dist "
        "or --chessboard",
    )
    one.add_argument(
        "--intrinsics",
        metavar="K.yaml",
        help="cv2.FileStorage file (yaml/yml/xml/json) with the camera matrix 'K' "
        "(or 'camera_matrix'), optional distortion 'D' (or 'dist_coeffs', "
        "'distortion_coefficients') and optional 'image_size' [w, h] (or "
        "'image_width' and 'image_height'); K is rescaled if image_size differs "
        "from IMAGE's size. An omnicam calibration file also works.",
    )
    one.add_argument(
        "--guess-k",
        action="store_true",
        help="no intrinsics: guess K from the rim and the mirror, as if the rig were aligned "
        "(f = the rim's radius in px x (z_rim + c) / RIM, square pixels, the principal point "
        "at the rim's centre); the posture is then only as right as that guess. The "
        "calibration file records K as guessed, and 'omnicam info' and 'omnicam unwarp' say "
        "so. Not with --intrinsics, --fx..., --from or --chessboard",
    )
    k.add_argument(
        "--fx",
        type=positive_arg,
        metavar="PX",
        help="focal length in x, px (with --fy --cx --cy instead of --intrinsics)",
    )
    k.add_argument("--fy", type=positive_arg, metavar="PX", help="focal length in y, px")
    k.add_argument("--cx", type=finite_arg, metavar="PX", help="principal point x, px")
    k.add_argument("--cy", type=finite_arg, metavar="PX", help="principal point y, px")
    k.add_argument(
        "--dist",
        type=finite_arg,
        nargs="+",
        metavar="D",
        help="OpenCV distortion coefficients k1 k2 p1 p2 [k3 ...] (4, 5, 8, 12 or "
        "14 values) with --fx --fy --cx --cy",
    )
    rim = p.add_argument_group("the rim and the choice of posture")
    rim.add_argument(
        "--far-lines",
        metavar="LINES.json",
        help="JSON list of lines, each a list of [x, y] pixels of a straight scene "
        "line far from the camera; used to pick the right posture candidate",
    )
    rim.add_argument(
        "--candidates",
        metavar="DIR",
        help="write each of Chen's four postures as a panorama (far lines drawn) into DIR, "
        "candidate_N.jpg, to choose by eye (the impossible ones are named, not drawn)",
    )
    rim.add_argument(
        "--choose",
        type=int,
        choices=range(4),
        metavar="N",
        help="take candidate N (0-3, a physically possible one) instead of the cues' choice; "
        "the report and the file's verdict record it as the user's choice",
    )
    rim.add_argument(
        "--rim-hint",
        type=rim_hint_arg,
        metavar="CX,CY,R",
        help="rough centre and radius of the mirror rim in IMAGE (px): the rim is searched "
        "only within 15%% of R of that circle (use it when the overlay shows another "
        "ellipse, e.g. the holder's outer edge)",
    )
    rim.add_argument(
        "--boundary-points",
        metavar="FILE",
        help=f"pixels on the mirror rim instead of detecting it: {BOUNDARY_FORMAT}",
    )
    lens = p.add_argument_group(
        "the camera's reflection",
        "the outline of the lens barrel's front edge, a circle coaxial with the optical axis, "
        "seen in the mirror; with its plane known it pins the mirror's tilt",
    )
    lens.add_argument(
        "--lens-z",
        type=finite_arg,
        metavar="MM",
        help="the circle's distance from the camera centre along the optical axis, towards "
        "the mirror (mm; about the lens's front edge). One image: fitted when not given. "
        "With --chessboard the reflection is used only with it (with the plane unknown the "
        "outline trades against the tilt)",
    )
    lens.add_argument(
        "--lens-r",
        type=positive_arg,
        metavar="MM",
        help="the circle's radius (mm); one image only: fitted when not given (--chessboard "
        "fits it from the outline)",
    )
    checks = p.add_argument_group("plausibility")
    checks.add_argument(
        "--max-tilt",
        type=positive_arg,
        default=10.0,
        metavar="DEG",
        help="plausibility limit on the angle between the mirror axis and the optical axis "
        "(default %(default)g)",
    )
    checks.add_argument(
        "--max-offset",
        type=positive_arg,
        default=10.0,
        metavar="MM",
        help="plausibility limit on the distance of the camera centre from the mirror's "
        "lower focus (another mirror: its nominal camera position, see --vertex-z), in the "
        "mirror's unit (default %(default)g)",
    )
    checks.add_argument(
        "--force",
        action="store_true",
        help="write the calibration file even when it is implausible (the warnings are "
        "printed either way; without --force an implausible result exits with status 1). "
        "One image and --chessboard are checked alike, with the same limits",
    )
    out = p.add_argument_group("outputs")
    out.add_argument(
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
    out.add_argument(
        "--overlay",
        metavar="PATH",
        help="overlay image to write (default: CALIB's stem + '_overlay.png', next to CALIB)",
    )
    report_page.add_report_option(out)
    out.add_argument("--overwrite", action="store_true", help="replace existing output files")
    out.add_argument(
        "-q",
        "--quiet",
        action="store_true",
        help="no progress lines (--chessboard: the line per image and, on stderr, per long "
        "step: the adjustment, the shape check, each held-out fold)",
    )
    pattern.add_arguments(p)
    p.set_defaults(func=cmd_calibrate)
    return p
