"""Calibration of the mirror posture from one image (paper section 3).

:func:`calibrate` composes named steps (:mod:`.steps`), each returning a frozen dataclass:

0. **inputs** (:mod:`.inputs`): the options validated as one record
   (:class:`.inputs.ImageOptions`; the plausibility re-run is ``dataclasses.replace`` of it)
   and the image made grey once (:func:`.inputs.edge_image`);
1. **rim** (:func:`.steps.rim_step` -> ``RimStep``): the rim ellipse ``Q_I`` (eqs. 20-22),
   detected (:func:`.rim.detect_rim`) or fitted to given boundary points (undistorted with ``D``);
2. **candidates** (:func:`.steps.candidates_step` -> ``Candidates``): Chen's four postures
   (:mod:`.chen`, eqs. 23-29, 32-42), the impossible ones marked;
3. **reflection cue** (:func:`.cue_step.reflection_step` -> ``ReflectionCue``): the outline of the
   camera's own reflection (:mod:`.reflection`, beyond the paper), given, or detected around
   the candidates' self-reflection pixels;
4. **selection** (:func:`.steps.selection_step` -> :class:`.selection.Selection`): far lines
   (eq. 31) and the reflection (a coaxial circle fitted under each candidate), each cue's score
   per candidate, the combined confidence and an ``ambiguous`` flag;
5. **refinement** (:func:`.steps.refinement_step` -> ``Refinement``): rim plus every cue that
   keeps the rim at its own noise level; the others are reported as rejected; a posteriori
   uncertainty with the weakly determined direction;
6. **warnings** (:func:`.steps.warnings_step`), then a :class:`~.report.CalibrationReport`;
7. **plausibility** (:func:`.plausibility.assess`): a result no real rig could have (a tilt or
   offset beyond the limits, a ``K`` that does not fit the image or the rim, ``a`` and ``b``
   that fit better swapped, large cue residuals) is named in the warnings.

:func:`rim_posture` is steps 0-5 alone on rim points, with no uncertainty: the chessboard
route's start (:func:`omnicam.calibrate_pattern`).

:class:`~.errors.EstimationError` (a ``ValueError``) means valid input from which the posture
cannot be estimated (no rim, no physical posture); a plain ``ValueError`` means bad input.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Sequence
from typing import Any, cast

import numpy as np

from .._typing import ArrayLike, FloatArray
from ..camera import MisalignedCatadioptricCamera
from ..formats.verdict import judged
from ..mirror import Mirror
from ..raytrace import normalize, to_pixels
from . import selection, steps
from .errors import EstimationError
from .inputs import ImageOptions, edge_image
from .plausibility import assess, nominal_note
from .report import CalibrationReport
from .shape import bowed_far_lines

__all__ = ["calibrate", "recalibrate", "CalibrationReport", "EstimationError"]


def calibrate(
    K: ArrayLike,
    mirror: Mirror,
    image: np.ndarray | None = None,
    boundary_points: ArrayLike | None = None,
    far_lines: Sequence[ArrayLike] | None = None,
    D: ArrayLike | None = None,
    image_size: tuple[int, int] | None = None,
    refine: bool = True,
    lens: str | bool | ArrayLike | None = "auto",
    *,
    lens_r: float | None = None,
    lens_z: float | None = None,
    rim_hint: tuple[float, float, float] | None = None,
    max_tilt_deg: float = 10.0,
    max_offset_mm: float = 10.0,
    check_plausibility: bool = True,
    choose: int | None = None,
) -> tuple[MisalignedCatadioptricCamera, CalibrationReport]:
    """Mirror posture from one image: rim ellipse, Chen's method, far-line selection, refinement.

    Parameters
    ----------
    K : (3, 3) array_like
        Camera matrix of the calibrated camera (skew allowed), non-singular.
    mirror : HyperbolicMirror or AsphericMirror
        Known mirror (``a``, ``b``, ``rim_radius``; or any even asphere: a data sheet's, a
        chessboard calibration's). The rim is a circle on the axis for every mirror of
        revolution, so Chen's method, the candidates and the cues hold for any; the checks that
        assume a rig built as designed put the camera at
        :func:`omnicam.mirror.nominal_camera_z` (a mirror without one has them left out, with
        a note among the warnings).
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
    lens : "auto", None, False or (M, 2) / (M, 1, 2) array_like
        The camera's own reflection, modelled as a circle coaxial with the optical axis
        (:mod:`.reflection`). ``"auto"`` detects the outermost round dark silhouette around the
        image centre in ``image`` (:func:`.reflection.detect_reflection`; without an image, or
        when none is found, the calibration goes on without it and the report says why);
        ``None``/``False`` does not use it; an array gives the outline pixels (as seen, >= 8).
        It selects between the physical postures without far lines (and adds to the far lines'
        score with them), and joins the refinement if it agrees with the rim, which pins the
        mirror tilt that the rim alone determines poorly.
    lens_r, lens_z : float, optional
        Known radius and axial distance (from the camera centre, towards the mirror) of the
        circle that forms the reflection's outline, in the mirror's length unit; fitted when
        not given.
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
    choose : int, optional
        Take candidate ``choose`` (0-3, physical) instead of the cues' choice: the user's
        choice by eye (:func:`.selection.user_choice`; the report's warnings record it).

    Returns
    -------
    camera : MisalignedCatadioptricCamera
        With ``camera_reflection = (r, z)``, the circle of the camera's reflection under the
        returned posture, when the reflection was used and fits it within
        ``steps.BODY_MAX_RMS_PX`` (5 px RMS); else None.
    report : CalibrationReport

    Raises
    ------
    ValueError
        Bad input: neither image nor boundary points, too few points, ``K`` singular, a far
        line with fewer than 3 points or outside the mirror; the message says what to do.
    EstimationError
        Valid input but no estimate: no rim ellipse (in the image or among the points) or no
        physically possible posture.
    """
    options = ImageOptions(
        K=K,
        mirror=mirror,
        boundary_points=boundary_points,
        far_lines=far_lines,
        D=D,
        image_size=image_size,
        refine=refine,
        lens=lens,
        lens_r=lens_r,
        lens_z=lens_z,
        rim_hint=rim_hint,
        max_tilt_deg=max_tilt_deg,
        max_offset_mm=max_offset_mm,
        check_plausibility=check_plausibility,
        choose=choose,
    ).validated(image)
    return _calibrate(options, edge_image(image))


def rim_posture(
    K: ArrayLike,
    mirror: Mirror,
    boundary_points: ArrayLike,
    D: ArrayLike | None = None,
    image_size: tuple[int, int] | None = None,
) -> MisalignedCatadioptricCamera:
    """The posture from rim points alone, as :func:`calibrate` finds it (Chen's method, the
    candidates chosen, refined on the rim), without its report: a start (the chessboard
    route's, :func:`omnicam.calibrate_pattern`), whose uncertainty, warnings and plausibility
    nobody reads. The camera is :func:`calibrate`'s with ``lens=None``; the report's profile
    uncertainty it skips was 5.9 of the 6.6 s its 6 calls took on VMR's command (profiled)."""
    o = ImageOptions(K, mirror, boundary_points, D=D, image_size=image_size, lens=None)
    o = o.validated(None)
    ref = _posture(o, None, uncertainty=False)[-1]
    return MisalignedCatadioptricCamera(
        cast(FloatArray, o.K), o.mirror, ref.rvec, ref.tvec, D=o.D, image_size=o.image_size
    )


def _posture(o: ImageOptions, image: np.ndarray | None, uncertainty: bool = True) -> tuple:
    """Steps 1-5 of the module docstring on validated options ``o``: ``(rim, cue,
    candidates, selection, refinement)``; the refinement's uncertainty only with
    ``uncertainty``."""
    K, D, mirror, lines = cast(FloatArray, o.K), o.D, o.mirror, o.far_lines
    rim = steps.rim_step(
        K, D, image, o.boundary_points, o.rim_hint, mirror, o.max_tilt_deg, o.max_offset_mm
    )
    lines_xn = [normalize(line, K, D) for line in lines]
    # far-line pixels outside the fitted rim by more than its noise cannot see the mirror
    selection.check_lines_inside_rim(
        [rim.fit.distance(to_pixels(x, K)) for x in lines_xn],
        max(2.0, 3.0 * rim.fit.rms),
    )
    cands = steps.candidates_step(rim, K, mirror)
    cue = steps.reflection_step(
        o.lens, image, rim.detected or rim.fit, K, D, o.lens_r, o.lens_z, cands, mirror
    )

    sel, circles = steps.selection_step(cands, cue, lines, mirror, K, D, rim)
    if o.choose is not None:
        sel = selection.user_choice(sel, o.choose)
    ref = steps.refinement_step(
        K,
        mirror,
        cands.all[sel.chosen],
        rim,
        lines_xn,
        cue,
        circles.get(sel.chosen),
        o.refine,
        uncertainty=uncertainty,
    )
    return rim, cue, cands, sel, ref


def _calibrate(
    options: ImageOptions, image: np.ndarray | None
) -> tuple[MisalignedCatadioptricCamera, CalibrationReport]:
    """:func:`calibrate` of validated ``options`` on ``image`` (made grey once,
    :func:`.inputs.edge_image`): the steps of the module docstring, in order."""
    o = options
    K, D, mirror, lines = cast(FloatArray, o.K), o.D, o.mirror, o.far_lines
    rim, cue, cands, sel, ref = _posture(o, image)
    warnings = steps.warnings_step(rim, cue, sel, ref, cands)
    # the camera's reflection as detected: default panoramas leave it out
    body = steps.camera_body(cue, ref)
    camera = MisalignedCatadioptricCamera(
        K, mirror, ref.rvec, ref.tvec, D=D, image_size=o.image_size, camera_reflection=body
    )
    report = CalibrationReport.from_steps(rim, cue, cands, sel, ref, list(warnings), camera, lines)
    bowed = bowed_far_lines(getattr(ref.result, "line_rms", math.nan), lines, mirror)
    if bowed is not None:  # (.shape) the one thing one image tells of the mirror's shape
        report.warnings.append(bowed)
    if o.check_plausibility:  # (.plausibility) a second calibration only when suspicious
        # the same calibration from the rim points and the cues this one found
        rerun = dataclasses.replace(
            o,
            choose=None,  # the user chose among this mirror's candidates, not the other's
            boundary_points=rim.seen,
            lens=cue.points if cue.used else False,
            rim_hint=None,
            check_plausibility=False,
        )
        implausible = assess(
            report,
            o.image_size,
            lambda m: _calibrate(dataclasses.replace(rerun, mirror=m), None),
            max_tilt_deg=o.max_tilt_deg,
            max_offset_mm=o.max_offset_mm,
        )
        report.warnings.extend(str(w) for w in implausible)
        report = dataclasses.replace(report, plausibility=tuple(implausible))
        note = nominal_note(mirror)  # a mirror that does not say where the camera sits
        if note is not None:
            report.warnings.append(note)
    return judged(camera, report)  # the camera carries the report's verdict


def recalibrate(
    camera: MisalignedCatadioptricCamera, image: np.ndarray | None = None, **options: Any
) -> tuple[MisalignedCatadioptricCamera, CalibrationReport]:
    """The mirror posture alone from one new image, with ``camera``'s ``K``, ``D`` and mirror.

    After a bump: a rig calibrated once (from chessboards, say) and knocked out of line is
    re-calibrated from one frame of the mirror, without boards, by the single-image method
    (:func:`calibrate`, paper section 3).

    Parameters
    ----------
    camera : MisalignedCatadioptricCamera
        The rig as calibrated before: its ``K``, ``D``, mirror and ``image_size`` are kept.
    image : ndarray, optional
        A frame of the rig (grey or BGR) of the camera's ``image_size`` (when known); use
        ``camera.scaled(size)`` first for another resolution of the same sensor.
    **options
        Passed on to :func:`calibrate`: ``boundary_points``, ``far_lines``, ``refine``,
        ``lens``, ``lens_r``, ``lens_z``, ``rim_hint``, ``max_tilt_deg``, ``max_offset_mm``,
        ``check_plausibility``.

    Returns
    -------
    camera : MisalignedCatadioptricCamera
        The rig's ``K``, ``D``, mirror and ``image_size`` with the new posture.
    report : CalibrationReport
        Its stated uncertainty (``axis_std_deg``, ``origin_std_mm``) and the confidence of
        the choice of posture (``confidence``, ``ambiguous``).

    Raises
    ------
    ValueError
        ``options`` naming what the camera fixes (``K``, ``mirror``, ``D``, ``image_size``),
        or an image of another size; and whatever :func:`calibrate` raises.
    """
    fixed = sorted({"K", "mirror", "D", "image_size"} & set(options))
    if fixed:
        raise ValueError(
            f"recalibrate keeps this camera's K, D, mirror and image_size; do not pass "
            f"{', '.join(fixed)} (use omnicam.calibrate for other ones)"
        )
    size = camera.image_size
    if image is not None and size is not None and np.ndim(image) >= 2:
        seen = (int(np.shape(image)[1]), int(np.shape(image)[0]))
        if seen != size:
            raise ValueError(
                f"image is {seen[0]}x{seen[1]}, the camera was calibrated at "
                f"{size[0]}x{size[1]}; for another resolution of the same sensor use "
                f"camera.scaled({seen}).recalibrate(image)"
            )
    return calibrate(camera.K, camera.mirror, image=image, D=camera.D, image_size=size, **options)
