"""Calibration of the mirror posture from one image (paper section 3).

Pipeline of :func:`calibrate`:

1. the rim ellipse ``Q_I`` (eqs. 20-22): :func:`omnicam.calibration.rim.detect_rim` on an image
   or :func:`omnicam.calibration.rim.fit_rim` on given boundary points (with ``D`` the points
   are undistorted first and the conic is fitted to undistorted pixels ``K x_n``);
2. Chen's method (:mod:`.chen`, eqs. 23-29, 32-42): four candidate postures, the physically
   impossible ones marked;
3. the camera's own reflection (:mod:`.lens`, beyond the paper): the outline of the dark blob
   near the image centre, found by :func:`omnicam.calibration.lens.detect_lens` or given;
4. selection by far lines (:mod:`.selection`, section 3.2, eq. 31) and by the lens outline;
5. optional non-linear refinement (:mod:`.refine`, beyond the paper) with rim, far-line and
   lens-outline residuals;
6. a :class:`~.report.CalibrationReport`.

Modules: ``rim`` (ellipse), ``chen`` (posture), ``lens`` (the camera's reflection),
``selection`` (choice), ``refine``
(refinement), ``report`` (report and overlay), ``intrinsics`` (the camera alone).
"""
from __future__ import annotations

import dataclasses
import math

import numpy as np

__all__ = ["calibrate", "CalibrationReport"]


def __getattr__(name):
    if name == "CalibrationReport":  # lazily, so ``import omnicam`` stays light
        from .report import CalibrationReport
        return CalibrationReport
    raise AttributeError(f"module 'omnicam.calibration' has no attribute {name!r}")


def _as_pixels(points, name):
    try:
        arr = np.asarray(points, dtype=np.float64)
    except (TypeError, ValueError):
        raise ValueError(f"{name} must be an (N, 2) or (N, 1, 2) array of pixels") from None
    if arr.ndim == 3 and arr.shape[1:] == (1, 2):
        arr = arr.reshape(-1, 2)
    if arr.ndim != 2 or arr.shape[1] != 2:
        raise ValueError(f"{name} must be an (N, 2) or (N, 1, 2) array of pixels, "
                         f"got shape {arr.shape}")
    return arr


def _normalize(pixels, K, D):
    """Pixels -> undistorted normalised coordinates (``inv(K)`` with skew, tight undistortion)."""
    from ..raytrace import undistort_normalized
    if D is None:
        Ki = np.linalg.inv(K)
        return pixels @ Ki[:2, :2].T + Ki[:2, 2]
    return undistort_normalized(np.ascontiguousarray(pixels), K, D)


def calibrate(K, mirror, image=None, boundary_points=None, far_lines=None, D=None,
              image_size=None, refine=True, camera_cls=None, lens="auto", rim_hint=None,
              max_tilt_deg=10.0, max_offset_mm=10.0, check_plausibility=True):
    """Mirror posture from one image: rim ellipse, Chen's method, far-line selection, refinement.

    Parameters
    ----------
    K : (3, 3) array_like
        Camera matrix of the calibrated camera (skew allowed), non-singular.
    mirror : HyperbolicMirror
        Known mirror (``a``, ``b``, ``rim_radius``).
    image : ndarray, optional
        Grey or BGR image (uint8, uint16 or float); the rim is found by ``detect_rim``.
    boundary_points : (N, 2) or (N, 1, 2) array_like, optional
        Pixels on the rim (as seen, distorted), instead of ``image``; fitted by ``fit_rim``
        (robust). Takes precedence over ``image`` for the rim when both are given.
    far_lines : sequence of (N_i, 2) or (N_i, 1, 2) array_like, optional
        Pixels along the images of far straight lines (>= 3 each, inside the rim), used as given
        to choose between the postures (eq. 31) and, with ``refine``, as 3-D lines. A pixel
        more than ``max(2, 3 * rim RMS)`` px outside the fitted rim is an error; one just
        outside whose ray misses the mirror is left out with a warning.
    D : array_like, optional
        OpenCV distortion coefficients of the camera.
    image_size : (int, int), optional
        ``(width, height)``; defaults to the image's size.
    refine : bool
        Refine the chosen posture non-linearly (kept only if it lowers the cost).
    camera_cls : type, optional
        Camera class to build (default :class:`omnicam.MisalignedHyperbolicCamera`).
    lens : "auto", None, False or (M, 2) / (M, 1, 2) array_like
        The camera's own reflection (a dark blob near the image centre, modelled as a ball of
        unknown radius about the camera centre; :mod:`.lens`). ``"auto"`` detects its outline
        in ``image`` (:func:`.lens.detect_lens`; without an image, or when no blob is found,
        the calibration goes on without it and the report says why); ``None``/``False`` does
        not use it; an array gives the outline pixels (as seen, >= 8). It selects between the
        physical postures without far lines (and joins the far lines' score with them), and
        adds the outline residual to the refinement, which pins the mirror tilt that the rim
        alone determines poorly.
    rim_hint : (cx, cy, r), optional
        A rough circle on the rim in ``image`` (px), passed to ``detect_rim(hint=...)``
        (unused with ``boundary_points``).
    max_tilt_deg, max_offset_mm : float
        Plausibility limits (:mod:`.plausibility`): the largest mirror-axis tilt and distance
        of the camera centre from the lower focus of a real rig. They also set the rim size
        ``detect_rim`` expects from ``K`` and the mirror.
    check_plausibility : bool
        Check the result (:func:`.plausibility.assess`): implausible findings are added to the
        report's ``warnings`` and listed in its ``plausibility``.

    Returns
    -------
    camera : MisalignedHyperbolicCamera
    report : CalibrationReport

    Raises
    ------
    ValueError
        Neither image nor boundary points, too few points, no ellipse, a degenerate or
        non-elliptic conic, ``K`` singular, a far line with fewer than 3 points or outside the
        mirror, or no physically possible posture; the message says what to do.
    """
    from ..camera import MisalignedHyperbolicCamera, validate_D, validate_image_size, validate_K
    from ..mirror import HyperbolicMirror
    from . import chen, selection
    from .refine import posture_uncertainty, refine_posture
    from .report import CalibrationReport
    from .rim import detect_rim, fit_rim

    camera_cls = MisalignedHyperbolicCamera if camera_cls is None else camera_cls
    K = validate_K(K)
    D = validate_D(D)
    if not isinstance(mirror, HyperbolicMirror):
        raise ValueError(f"mirror must be a HyperbolicMirror, got {type(mirror).__name__}")
    if image is None and boundary_points is None:
        raise ValueError("give the image (the rim is detected) or boundary_points (pixels on the "
                         "mirror rim)")
    if image_size is None and image is not None:
        shape = np.shape(image)
        if len(shape) >= 2:
            image_size = (int(shape[1]), int(shape[0]))
    image_size = validate_image_size(image_size)
    warnings = []

    # 1. the rim ellipse (eqs. 20-22); with D fitted to undistorted pixels K x_n
    if boundary_points is not None:
        seen = _as_pixels(boundary_points, "boundary_points")
        if len(seen) < 6:
            raise ValueError(f"boundary_points has {len(seen)} point(s); give at least 6 points "
                             f"spread along the mirror rim (dozens are better)")
        if not np.isfinite(seen).all():
            raise ValueError("boundary_points has non-finite values; drop them")
        if image is not None:
            warnings.append("both image and boundary_points given: the rim was fitted to the "
                            "boundary points, the image only gave the size")
    else:
        from .plausibility import expected_rim  # the rim size K and the mirror predict
        detected = detect_rim(image, hint=rim_hint, expected=expected_rim(
            K, mirror, D, max_tilt_deg, max_offset_mm).radius_range)
        seen = np.asarray(detected.points, np.float64)
        if D is None:
            fit = detected
    if boundary_points is not None or D is not None:
        xn = _normalize(seen, K, D)
        ideal = xn @ K[:2, :2].T + K[:2, 2]  # undistorted pixels, same K
        if not np.isfinite(ideal).all():
            raise ValueError("some boundary points cannot be undistorted with D; check D")
        fit = fit_rim(ideal)
        seen = seen[np.asarray(fit.inliers, bool)]
    rim_px = np.asarray(fit.points, np.float64)
    if fit.rms > 1.0:
        warnings.append(f"the rim fit is poor (RMS {fit.rms:.2f} px): check the boundary points "
                        f"(the posture error grows by about 1 deg per px of rim noise)")

    # the camera's own reflection: the outline of the dark blob near the centre
    lens_fit, lens_px, lens_note = None, None, "not used (lens=None)"
    if isinstance(lens, str):
        if lens != "auto":
            raise ValueError(f"lens must be 'auto', None, False or an (M, 2) array of outline "
                             f"pixels, got {lens!r}")
        if image is None:
            lens_note = "not used: no image (give lens=outline pixels to use it)"
        else:
            from .lens import detect_lens
            try:
                lens_fit = detect_lens(image, detected if boundary_points is None else fit)
                lens_px = np.asarray(lens_fit.points, np.float64)
            except ValueError as err:  # optional: the report says why it was not used
                lens_note = f"not used: {err}"
    elif lens is not None and lens is not False:
        lens_px = _as_pixels(lens, "lens")
        if len(lens_px) < 8 or not np.isfinite(lens_px).all():
            raise ValueError(f"lens has {len(lens_px)} point(s) or non-finite values; give at "
                             f"least 8 finite pixels along the outline of the camera's reflection")
    lens_xn = None
    if lens_px is not None:
        lens_xn = _normalize(lens_px, K, D)
        if not np.isfinite(lens_xn).all():
            raise ValueError("some lens outline points cannot be undistorted with D; check D")

    # 2. Chen's method (eqs. 23-29, 32-42)
    # Q_e = K^T Q_I K  (eq. 24)
    Qe = chen.normalized_conic(fit.conic, K)
    candidates = chen.chen_candidates(Qe, mirror)

    # 3. selection with far lines (section 3.2)
    lines = selection.validate_far_lines(far_lines)
    lines_xn = [_normalize(line, K, D) for line in lines]
    # pixels outside the fitted rim by more than its noise cannot see the mirror
    selection.check_lines_inside_rim(
        [fit.distance(x @ K[:2, :2].T + K[:2, 2]) for x in lines_xn], max(2.0, 3.0 * fit.rms))

    def make_camera(c):
        return camera_cls(K, mirror, c.rvec, c.tvec, D=D, image_size=image_size)

    lens_scores = None
    if lens_xn is not None:
        from .lens import outline_score
        Ki2 = np.linalg.inv(K)[:2, :2]
        lens_scores = {i: outline_score(mirror, c.R, c.tvec, lens_xn, Ki2)[0]
                       for i, c in enumerate(candidates) if c.physical}
    candidates, chosen, confidence, sel_warnings = selection.select_candidate(
        candidates, make_camera, lines, (0.0, 0.0, -mirror.c), lens_scores)
    warnings.extend(sel_warnings)
    # 4. refinement (beyond the paper)
    cand = candidates[chosen]
    rvec, tvec = cand.rvec, cand.tvec
    refinement = None
    if refine:
        # With the camera's reflection the refinement uses the rim and the lens outline: the
        # outline fixes the tilt the rim cannot see, and far lines (4 nuisance parameters each,
        # badly conditioned in depth) then add nothing measurable to the posture but make LM
        # four times slower (benchmarks/bench_calibrate.py). They still chose the candidate.
        refinement = refine_posture(K, mirror, rvec, tvec, rim_px,
                                    lines_xn if lens_xn is None else (),
                                    lens_normalized=lens_xn)
        rvec, tvec = refinement.rvec, refinement.tvec
    lens_rms = rho = math.nan
    if lens_xn is not None:
        from .lens import outline_score
        R_fin = camera_cls(K, mirror, rvec, tvec).R
        lens_rms, rho = outline_score(mirror, R_fin, np.asarray(tvec, np.float64), lens_xn,
                                      np.linalg.inv(K)[:2, :2])
        lens_note = (f"used: {len(lens_xn)} outline points, RMS {lens_rms:.3f} px to the "
                     f"ball model, rho {rho:.3f}")
        if not lens_rms <= max(1.0, 3.0 * fit.rms):
            warnings.append(f"the outline of the camera's reflection fits the ball model poorly "
                            f"(RMS {lens_rms:.2f} px): check the lens outline points")
    camera = camera_cls(K, mirror, rvec, tvec, D=D, image_size=image_size)
    axis_std, origin_std = posture_uncertainty(
        K, mirror, camera.rvec, camera.tvec, rim_px, max(fit.rms, 1e-12), lens_xn,
        max(lens_rms, 1e-12) if np.isfinite(lens_rms) else None)
    if axis_std > 0.5:
        warnings.append(f"the rim determines the posture poorly: about {axis_std:.2f} deg "
                        f"(RMS) on the mirror axis and {origin_std:.2f} on the origin; "
                        f"improve the boundary points (more of the rim, less noise)")
    # never a doubtful posture without a warning
    others = [i for i, c in enumerate(candidates) if c.physical and i != chosen]
    if others:
        a, b = candidates[chosen], candidates[others[0]]
        d_axis = math.degrees(math.atan2(np.linalg.norm(np.cross(a.axis, b.axis)),
                                         float(a.axis @ b.axis)))
        d_origin = float(np.linalg.norm(a.tvec - b.tvec))
        distinct = d_axis > 0.01 or d_origin > 1e-3 * mirror.rim_radius
        threshold = (selection.AMBIGUOUS_CONFIDENCE if lines else
                     selection.LENS_AMBIGUOUS_CONFIDENCE)
        already = any("barely separates" in w for w in warnings)  # said by the selection
        if (lines or lens_scores) and distinct and confidence < threshold and not already:
            by = "far lines (and the camera's reflection)" if lines else "camera's reflection"
            warnings.append(f"the {by} barely separate the two physical postures "
                            f"(confidence {confidence:.3f}; they differ by {d_axis:.3f} deg "
                            f"and {d_origin:.3f} in origin): the choice may be wrong; give "
                            f"more or longer far lines, far from the image centre")
        elif (lines or lens_scores) and distinct and d_axis < 3.0 * axis_std:
            warnings.append(f"the rim noise ({axis_std:.3f} deg on the axis) is comparable "
                            f"with the separation of the two physical postures ({d_axis:.3f} "
                            f"deg): the choice may be wrong; improve the boundary points")
    report = CalibrationReport(conic=np.asarray(fit.conic, np.float64), boundary_points=seen,
                               rim_rms=float(fit.rms), candidates=candidates, chosen=chosen,
                               confidence=float(confidence), warnings=warnings, camera=camera,
                               refinement=refinement, axis_std_deg=axis_std,
                               origin_std_mm=origin_std, far_lines=lines,
                               lens_points=lens_px, lens_fit=lens_fit, lens_scores=lens_scores,
                               lens_rms=lens_rms, rho=rho, lens_note=lens_note)
    if check_plausibility:  # (.plausibility) a second calibration only when suspicious
        from .plausibility import assess
        implausible = assess(report, image_size, lambda m: calibrate(
            K, m, boundary_points=seen, far_lines=lines or None, D=D, image_size=image_size,
            refine=refine, camera_cls=camera_cls, lens=False if lens_px is None else lens_px,
            check_plausibility=False), max_tilt_deg=max_tilt_deg, max_offset_mm=max_offset_mm)
        warnings.extend(str(w) for w in implausible)  # the report's list
        report = dataclasses.replace(report, plausibility=tuple(implausible))
    return camera, report
