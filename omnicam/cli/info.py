"""``omnicam info``: print a calibration file."""

from __future__ import annotations

import math

import numpy as np

from ..formats.calibration_file import read_verdict
from ..formats.central_fit import fit_omnidir
from ..mirror import HyperbolicMirror, nominal_camera_z
from ..views import default_elevation_range
from ._common import EXIT_OK, load_calibration, one_line, user_terms


def posture(camera):
    """Readable posture: tilt of the mirror axis and camera offset from the lower focus.

    Returns
    -------
    tilt_deg : float
        Angle between the camera's optical axis and the mirror axis.
    tilt_azimuth_deg : float
        Direction of the tilt in the camera's x-y plane (``atan2`` of the axis' y and x).
    offset : (3,) float64 ndarray
        Camera centre minus the lower focus ``(0, 0, -c)`` (for any mirror its nominal camera
        position, :func:`omnicam.mirror.nominal_camera_z`; NaN for a mirror without one),
        mirror frame (mm).
    """
    axis = camera.R[:, 2]  # the mirror's +Z in the camera frame
    tilt = math.degrees(math.atan2(math.hypot(axis[0], axis[1]), axis[2]))
    azimuth = math.degrees(math.atan2(axis[1], axis[0])) if tilt > 0 else 0.0
    z = nominal_camera_z(camera.mirror)
    offset = np.asarray(camera.camera_center) - np.array([0.0, 0.0, math.nan if z is None else z])
    return tilt, azimuth, offset


def vector_text(v, fmt="{:.4f}"):
    """``(x, y, z)`` of a vector, each number as ``fmt``."""
    return "(" + ", ".join(fmt.format(float(x)) for x in np.ravel(v)) + ")"


def describe_reflection(camera):
    """One line on the camera's own reflection the file records, and where a default panorama's
    lower edge comes from (:func:`omnicam.views.default_elevation_range`)."""
    body = camera.camera_reflection
    text = (
        "none recorded"
        if body is None
        else f"circle r {body.r:.3f} mm at z {body.z:.3f} mm (camera frame), as detected"
    )
    try:
        band = default_elevation_range(camera).describe()
    except ValueError as e:
        band = f"none ({one_line(e)})"
    return f"{text}; default panorama: {band}"


def describe_mirror_params(m):
    """The mirror's kind and parameters, one line."""
    if isinstance(m, HyperbolicMirror):
        return (
            f"a = {m.a:g} mm, b = {m.b:g} mm, rim radius = {m.rim_radius:g} mm "
            f"(c = {m.c:.4f} mm, rim at Z = {m.z_rim:.4f} mm)"
        )
    alpha = ", ".join(f"{a:.6g}" for a in m.alpha)
    terms = (
        f"alpha = [{alpha}] mm of (rho / {m.rho_n:g} mm)^4, ^6, ..."
        if m.alpha
        else "no polynomial terms"
    )
    return (
        f"even asphere: R = {m.R:g} mm, k = {m.k:g}, {terms}, vertex at Z = {m.vertex_z:g} mm, "
        f"rim radius = {m.rim_radius:g} mm (rim at Z = {m.z_rim:.4f} mm; format_version 2)"
    )


def _offset_text(m, offset):
    """The camera offset's row: from the lower focus (a hyperboloid) or the nominal camera
    position (any mirror), or why there is none."""
    if not np.all(np.isfinite(offset)):
        return "none: the mirror does not say where the camera sits (vertex_z <= 0)"
    where = (
        "the lower focus"
        if isinstance(m, HyperbolicMirror)
        else f"the nominal camera position (0, 0, {nominal_camera_z(m):g})"
    )
    return (
        f"{vector_text(offset)} mm from {where} (mirror frame), "
        f"|offset| = {np.linalg.norm(offset):.4f} mm"
    )


def describe_camera(camera):
    """Multi-line text of a calibration: mirror, K, D, posture, best-fit viewpoint, the camera's
    own reflection."""
    m = camera.mirror
    hyperboloid = isinstance(m, HyperbolicMirror)
    K = camera.K
    tilt, az, offset = posture(camera)
    viewpoint, rms = camera.best_fit_viewpoint()
    size = camera.image_size
    rows = [
        ("mirror", describe_mirror_params(m)),
        ("image size", "unknown" if size is None else f"{size[0]} x {size[1]}"),
        (
            "K",
            f"fx = {K[0, 0]:.4f}, fy = {K[1, 1]:.4f}, cx = {K[0, 2]:.4f}, cy = {K[1, 2]:.4f}, "
            f"skew = {K[0, 1]:.4g}",
        ),
        ("D", "none" if camera.D is None else vector_text(camera.D, "{:.6g}")),
        ("rvec", vector_text(camera.rvec, "{:.6f}") + "  (mirror -> camera, rad)"),
        ("tvec", vector_text(camera.tvec) + "  (mm)"),
        (
            "axis tilt",
            f"{tilt:.4f} deg, towards {az:.2f} deg in the camera's x-y plane",
        ),
        ("camera offset", _offset_text(m, offset)),
        (
            "viewpoint",
            f"{vector_text(viewpoint)} mm, best fit to all mirror rays (mirror frame"
            + (f"; the outer focus is (0, 0, {m.c:.4f}))" if hyperboloid else ")"),
        ),
        (
            "viewpoint RMS",
            f"{rms:.4f} mm (RMS distance from the rays; 0 for a central rig)",
        ),
        ("reflection", describe_reflection(camera)),
    ]
    width = max(len(k) for k, _ in rows)
    return "\n".join(f"{k:<{width}}  {v}" for k, v in rows)


_K_SOURCES = {
    "given": "given (typed or passed in)",
    "file": "read from a file",
    "guessed": "GUESSED from the rim and the mirror",
    "chessboard": "fitted to the chessboards",
}


def _number(v, fmt, unit=""):
    return "unknown" if v is None else f"{v:{fmt}}{unit}"


def describe_verdict(verdict, width=13):
    """Multi-line text of a calibration file's verdict (:class:`omnicam.Verdict`): what the
    calibration's report said when the file was written; None gives the line that says none
    was recorded."""
    if verdict is None:
        return (
            f"{'verdict':<{width}}  none recorded (written without one, e.g. by camera.save(path) "
            f"or omnicam 0.3.0; camera.save(path, report) records it)"
        )
    v = verdict
    doubts = v.doubts()
    method = "one image of the mirror" if v.method == "image" else "chessboards"
    rows = [
        (
            "verdict",
            (f"DOUBTFUL: calibrated {', '.join(doubts)}" if doubts else "no doubt recorded")
            + f" (from {method})",
        ),
        (
            "K from",
            _K_SOURCES[v.K_source]
            + (f": {v.K_file}" if v.K_file else "")
            + (f"; {v.K_note}" if v.K_note else ""),
        ),
    ]
    if v.method == "image":
        rows.append(
            (
                "posture",
                f"chosen with confidence {_number(v.confidence, '.4f')}"
                + (" AMBIGUOUS (the other physical posture fits as well)" if v.ambiguous else ""),
            )
        )
    rows.append(
        (
            "uncertainty",
            f"mirror axis {_number(v.axis_std_deg, '.3g', ' deg')}, camera centre "
            f"{_number(v.origin_std_mm, '.3g', ' mm')} (RMS, as stated when calibrated)",
        )
    )
    if v.method == "chessboard":
        fit = f"corner RMS {_number(v.rms_px, '.3f', ' px')}"
        if v.rim_rms_px is not None:
            fit += f", rim RMS {v.rim_rms_px:.3f} px"
        rows.append(("fit", fit))
        if v.heldout_median_px is not None:
            rows.append(
                (
                    "held-out",
                    f"corner RMS median {v.heldout_median_px:.3f} px, max "
                    f"{_number(v.heldout_max_px, '.3f', ' px')} ({v.heldout_folds or '?'}-fold)",
                )
            )
        if v.ray_std_deg is not None:
            rows.append(
                (
                    "rays",
                    f"viewing directions std {v.ray_std_deg[0]:.3f} deg (worst "
                    f"{v.ray_std_deg[1]:.3f})",
                )
            )
    elif v.rim_rms_px is not None:
        rows.append(("fit", f"rim RMS {v.rim_rms_px:.3f} px"))
    if v.forced:
        rows.append(("forced", "written with --force although implausible"))
    rows += [("implausible", f"- {w}") for w in v.implausible]
    rows += [("warning", f"- {w}") for w in v.warnings]
    rows += [("note", f"- {w}") for w in v.notes]
    # the texts as the command line says them (options, not the library's parameters)
    return "\n".join(f"{k:<{width}}  {user_terms(text)}" for k, text in rows)


def cmd_info(args):
    """``omnicam info``: the module docstring."""
    camera = load_calibration(args.calibration)
    try:
        verdict = describe_verdict(read_verdict(args.calibration))
    except (FileNotFoundError, ValueError) as e:
        verdict = f"{'verdict':<13}  cannot be read: {one_line(e)}"
    print(f"{'calibration':<13}  {args.calibration}")
    print(describe_camera(camera))
    try:  # the central model that tools without a non-central one can take (omnicam export)
        fit = fit_omnidir(camera)
        print(
            f"{'omnidir':<13}  nearest unified (Mei) model, xi = {fit.xi:.6f}: "
            f"{fit.rms_px:.4f} px RMS, {fit.max_px:.4f} px max from this rig over the "
            f"annulus (omnicam export --to omnidir|kalibr|camodocal)"
        )
    except (ValueError, np.linalg.LinAlgError) as e:
        print(f"{'omnidir':<13}  no central approximation: {e}")
    print(verdict)
    return EXIT_OK


def add_parser(sub):
    """Register the ``info`` subcommand on ``sub`` (argparse sub-parsers)."""
    p = sub.add_parser(
        "info",
        help="print a calibration file",
        description="Print the mirror, K, D, the mirror posture, the best-fit "
        "viewpoint and its RMS distance to the rays, the camera's own reflection the file "
        "records (and where a default panorama's lower edge comes from), and the verdict the "
        "file records: where "
        "K came from (given, a file, guessed, chessboards), the confidence of the posture, "
        "--force, the stated uncertainty and the warnings (chessboards: the RMS, the "
        "held-out check, the viewing directions' uncertainty).",
    )
    p.add_argument("calibration", metavar="CALIB")
    p.set_defaults(func=cmd_info)
    return p
