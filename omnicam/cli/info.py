"""``omnicam info``: print a calibration file."""

from __future__ import annotations

import math

import numpy as np

from ._common import EXIT_OK, _load_camera


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
        (
            "mirror",
            f"a = {m.a:g} mm, b = {m.b:g} mm, rim radius = {m.rim_radius:g} mm "
            f"(c = {m.c:.4f} mm, rim at Z = {m.z_rim:.4f} mm)",
        ),
        ("image size", "unknown" if size is None else f"{size[0]} x {size[1]}"),
        (
            "K",
            f"fx = {K[0, 0]:.4f}, fy = {K[1, 1]:.4f}, cx = {K[0, 2]:.4f}, cy = {K[1, 2]:.4f}, "
            f"skew = {K[0, 1]:.4g}",
        ),
        ("D", "none" if camera.D is None else _vec(camera.D, "{:.6g}")),
        ("rvec", _vec(camera.rvec, "{:.6f}") + "  (mirror -> camera, rad)"),
        ("tvec", _vec(camera.tvec) + "  (mm)"),
        (
            "axis tilt",
            f"{tilt:.4f} deg, towards {az:.2f} deg in the camera's x-y plane",
        ),
        (
            "camera offset",
            f"{_vec(offset)} mm from the lower focus (mirror frame), "
            f"|offset| = {np.linalg.norm(offset):.4f} mm",
        ),
        (
            "viewpoint",
            f"{_vec(viewpoint)} mm, best fit to all mirror rays (mirror frame; "
            f"the outer focus is (0, 0, {m.c:.4f}))",
        ),
        (
            "viewpoint RMS",
            f"{rms:.4f} mm (RMS distance from the rays; 0 for a central rig)",
        ),
    ]
    width = max(len(k) for k, _ in rows)
    return "\n".join(f"{k:<{width}}  {v}" for k, v in rows)


def cmd_info(args):
    camera = _load_camera(args.calibration)
    print(f"{'calibration':<13}  {args.calibration}")
    print(describe_camera(camera))
    from ..export import fit_omnidir

    try:  # the central model that tools without a non-central one can take (omnicam export)
        fit = fit_omnidir(camera)
        print(
            f"{'omnidir':<13}  nearest unified (Mei) model, xi = {fit.xi:.6f}: "
            f"{fit.rms_px:.4f} px RMS, {fit.max_px:.4f} px max from this rig over the "
            f"annulus (omnicam export --to omnidir|kalibr|camodocal)"
        )
    except (ValueError, np.linalg.LinAlgError) as e:
        print(f"{'omnidir':<13}  no central approximation: {e}")
    return EXIT_OK


def add_parser(sub):
    """Register the ``info`` subcommand on ``sub`` (argparse sub-parsers)."""
    p = sub.add_parser(
        "info",
        help="print a calibration file",
        description="Print the mirror, K, D, the mirror posture, the best-fit "
        "viewpoint and its RMS distance to the rays.",
    )
    p.add_argument("calibration", metavar="CALIB")
    p.set_defaults(func=cmd_info)
    return p
