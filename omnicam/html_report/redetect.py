"""What a report of a chessboard calibration needs, from a calibration file and the images:
each board found again and its pose fitted under the file's camera (the camera kept)."""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

import cv2
import numpy as np
from scipy.optimize import least_squares

from .._typing import ArrayLike, FloatArray
from ..chessboard.board_pose import board_pose_from_rays, object_points
from ..chessboard.detect import detect_pattern
from ..chessboard.report import PatternReport

__all__ = ["fit_board_pose", "redetected_pattern_report"]

_UNSEEN_PX = 1e3


def fit_board_pose(
    camera: Any, corners: ArrayLike, obj: FloatArray
) -> tuple[FloatArray, FloatArray, FloatArray] | None:
    """``(rvec_b, tvec_b, reprojected (N, 2))``: the board pose (mirror frame) that minimises
    the corners' reprojection error under ``camera``, started from the rays (non-central
    PnP, :func:`.board_pose.board_pose_from_rays`); None when fewer than 4 corners see the
    mirror."""
    p = np.asarray(corners, np.float64).reshape(-1, 2)
    P, d = camera.unproject(p)
    ok = np.isfinite(d).all(axis=1) & np.isfinite(P).all(axis=1)
    if ok.sum() < 4:
        return None
    rvec, tvec, _ = board_pose_from_rays(P[ok], d[ok], obj[ok], P[ok].mean(axis=0))

    def project(x):
        R = _rodrigues(x[:3])
        return camera.project(obj @ R.T + x[3:]).reshape(-1, 2)

    def residuals(x):
        r = (project(x) - p).ravel()
        return np.where(np.isfinite(r), r, _UNSEEN_PX)

    sol = least_squares(residuals, np.concatenate([rvec, tvec]), method="lm", x_scale="jac")
    return sol.x[:3].copy(), sol.x[3:].copy(), project(sol.x)


def _rodrigues(rvec):
    return cv2.Rodrigues(np.asarray(rvec, np.float64))[0]


def _rim_rms(camera, image):
    """``(rim points, RMS px)`` of the rim detected in ``image`` to the camera's rim image, or
    ``(empty, NaN)`` when no rim is found."""
    from ..calibration.rim import detect_rim

    try:
        pts = np.asarray(detect_rim(image).points, np.float64).reshape(-1, 2)
    except (ValueError, RuntimeError):
        return np.empty((0, 2)), math.nan
    curve = camera.rim_image_points(3600)
    if not (len(pts) and np.isfinite(curve).all()):
        return pts, math.nan
    d = np.full(len(pts), np.inf)
    for k in range(0, len(curve), 400):  # nearest point of the dense rim image
        c = curve[k : k + 400]
        d = np.minimum(d, np.min(np.linalg.norm(pts[:, None] - c[None], axis=2), axis=1))
    return pts, float(np.sqrt(np.mean(d * d)))


def redetected_pattern_report(
    camera: Any,
    images: Sequence[np.ndarray],
    pattern_size: tuple[int, int],
    square_size: float,
    names: Sequence[str] = (),
    verdict: Any = None,
) -> PatternReport:
    """A :class:`PatternReport` of ``camera`` (kept as it is) on ``images``: every board
    found again (:func:`detect_pattern`, with the camera's views), its pose fitted alone
    (:func:`fit_board_pose`), the residuals and per-view RMS of that fit, the rim found in the
    first image against the camera's rim. The figures the images cannot give again (the
    stated uncertainties, the held-out check, the warnings) come from ``verdict`` (the file's)
    when given.

    Returns
    -------
    PatternReport
        ``nfev`` 0 and ``start`` None (nothing was adjusted); ``found_by`` as detected.

    Raises
    ------
    ValueError
        No board is found in any image.
    """
    obj = object_points(pattern_size, square_size)
    image_points: list[np.ndarray | None] = []
    view_rms, poses, reproj, found, dropped, used = {}, {}, {}, {}, {}, {}
    errors = []
    for i, im in enumerate(images):
        det = detect_pattern(im, pattern_size, camera)
        if det is None:
            image_points.append(None)
            dropped[i] = "no board found"
            continue
        image_points.append(det.corners)
        fit = fit_board_pose(camera, det.corners, obj)
        if fit is None:
            dropped[i] = "fewer than 4 corners see the mirror"
            continue
        rvec, tvec, q = fit
        e = q - det.corners.reshape(-1, 2)
        errors.append(e)
        view_rms[i] = float(np.sqrt(np.mean(np.sum(e * e, axis=1))))
        poses[i] = (rvec, tvec)
        reproj[i] = q.reshape(-1, 1, 2)
        found[i] = det.method
        used[i] = len(obj)
    if not view_rms:
        raise ValueError(f"no {pattern_size[0]}x{pattern_size[1]} board found in the images")
    all_e = np.concatenate(errors)
    rim_points, rim_rms = _rim_rms(camera, images[0])
    std = {}
    warnings: tuple = ()
    ray = (math.nan, math.nan)
    if verdict is not None:
        if verdict.axis_std_deg is not None:
            std["axis_deg"] = verdict.axis_std_deg
        if verdict.origin_std_mm is not None:
            std["origin"] = verdict.origin_std_mm
        if verdict.ray_std_deg is not None:
            ray = tuple(verdict.ray_std_deg)
        warnings = tuple(verdict.warnings) + tuple(verdict.implausible)
    return PatternReport(
        rms=float(np.sqrt(np.mean(np.sum(all_e * all_e, axis=1)))),
        view_rms=view_rms,
        corners_used=used,
        board_poses=poses,
        image_points=image_points,
        reprojected=reproj,
        rim_points=rim_points,
        rim_rms=rim_rms,
        std=std,
        warnings=warnings,
        dropped=dropped,
        nfev=0,
        camera=camera,
        start=None,
        found_by=found,
        ray_std_deg=ray,
        names=dict(enumerate(names)),
    )
