"""The named steps of :func:`omnicam.calibration.calibrate`, each returning a typed result.

rim (:func:`rim_step` -> :class:`RimStep`) -> candidates (:func:`candidates_step` ->
:class:`Candidates`) -> reflection cue (:func:`.cue_step.reflection_step` ->
:class:`.cue_step.ReflectionCue`, re-exported here) -> selection (:func:`selection_step` ->
:class:`.selection.Selection`) -> refinement (:func:`refinement_step` -> :class:`Refinement`)
-> warnings (:func:`warnings_step`). The options and the image come validated and made grey
once from :mod:`.inputs`.
"""

from __future__ import annotations

import dataclasses
import math

import cv2
import numpy as np

from .._validate import float_array
from ..camera import MisalignedCatadioptricCamera
from ..images import to_gray
from ..mirror import HyperbolicMirror, describe_mirror, nominal_camera_z
from ..raytrace import normalize, to_pixels
from . import chen
from .cue_step import ReflectionCue, reflection_step
from .errors import EstimationError
from .inputs import as_pixels
from .plausibility import expected_rim
from .refine import (
    ReflectionSpec,
    RimTerm,
    correlation_factor,
    perturbed_posture,
    posture_offsets,
    posture_uncertainty,
    profile_uncertainty,
    refine_posture,
)
from .reflection import (
    ReflectionCircle,
    behind_depth,
    fit_circle,
    plane_radius,
    self_reflection_pixel,
)
from .rim import check_hint, detect_rim, fit_rim
from .selection import ReflectionEvidence, select_candidate

__all__ = [
    "RimStep",
    "ReflectionCue",
    "Candidates",
    "Refinement",
    "rim_step",
    "reflection_step",
    "candidates_step",
    "selection_step",
    "refinement_step",
    "warnings_step",
    "as_pixels",
]

#: A cue joins the refinement only if the rim's chi-square rises by at most this much
#: (2 x the 99.9 % point of chi-square with 5 degrees of freedom, the posture's).
CUE_CHI2 = 2.0 * 20.515
#: Evaluations of each stage of the refinement with far lines: the lines' 4 parameters each
#: follow the posture slowly, so the rim's 15 leave exact data unconverged on some BLAS
#: kernels; 30 converge on all (``tests/test_refine.py``).
LINES_MAX_NFEV = 30
#: Rim and outline residuals are never taken as smaller than this (px): edge location limits.
SIGMA_FLOOR = 0.02
#: Above this RMS axis uncertainty (deg) the report warns: an error over 0.1 deg is then
#: within two standard deviations (the stress benchmark, ``benchmarks/bench_stress.py``, counts
#: an axis error over 0.1 deg without a warning as a silent failure).
AXIS_WARN_DEG = 0.05
#: Near alignment the report warns when the aligned posture midway between the two physical
#: postures lies beyond twice the stated axis uncertainty but within 8 standard deviations of
#: the fit: the cost rises by at most this much there (:class:`.refine.Uncertainty`'s
#: ``aligned_chi2``, in units of the observed residual variance with its correlation along
#: the contour). A low-order shape error of the rim's image falls where the posture absorbs
#: it, so the residuals cannot show it, and real rims have them larger than their residuals
#: suggest (a pixel aspect of K a little off moves the axis by degrees near alignment): the
#: warning says what one frame cannot exclude. The nearly aligned rigs of the stress renders
#: (``benchmarks/bench_stress.py``) fall within the bound, rigs a few degrees out of line far
#: beyond it (docs/CHANGELOG.md has the figures that set it).
ALIGNED_CHI2 = 64.0
#: Outline points used in the refinement (evenly subsampled; selection uses all).
MAX_REFINE_POINTS = 400


# -- 1. rim ------------------------------------------------------------------------------------
@dataclasses.dataclass(frozen=True, eq=False)
class RimStep:
    """The rim ellipse ``Q_I`` (eqs. 20-22).

    Attributes
    ----------
    fit : RimFit
        The ellipse; with ``D`` fitted to undistorted pixels ``K x_n``.
    detected : RimFit or None
        What :func:`.rim.detect_rim` found in the image (None with boundary points).
    seen : (N, 2) ndarray
        The inlier boundary points as seen (distorted).
    warnings : tuple of str
    """

    fit: object
    detected: object
    seen: np.ndarray
    warnings: tuple

    @property
    def points(self):
        """(N, 2) boundary points in undistorted pixels (the refinement's rim rows)."""
        return np.asarray(self.fit.points, np.float64)


def rim_step(
    K,
    D,
    image=None,
    boundary_points=None,
    hint=None,
    mirror=None,
    max_tilt_deg=10.0,
    max_offset_mm=10.0,
):
    """Fit (or detect) the rim ellipse; see :class:`RimStep`.

    In an image the search is guided by ``hint`` (a rough circle ``(cx, cy, r)``) and by the
    rim size that ``K`` and ``mirror`` predict for rigs within the plausibility limits
    (:func:`.plausibility.expected_rim`): the holder's outer edge is not the rim.

    Raises
    ------
    ValueError
        Too few or non-finite boundary points, points that cannot be undistorted.
    EstimationError
        No ellipse in the image or among the points.
    """
    warnings = []
    detected = None
    if boundary_points is not None:
        seen = as_pixels(boundary_points, "boundary_points")
        if len(seen) < 6:
            raise ValueError(
                f"boundary_points has {len(seen)} point(s); give at least 6 points spread "
                f"along the mirror rim (dozens are better)"
            )
        if not np.isfinite(seen).all():
            raise ValueError("boundary_points has non-finite values; drop them")
        if image is not None:
            warnings.append(
                "both image and boundary_points given: the rim was fitted to the boundary "
                "points, the image only gave the size"
            )
    else:
        gray = to_gray(image)  # bad input (shape) raises ValueError here, before the search
        if hint is not None:  # real numbers (rim.check_hint would cut complex ones)
            float_array(hint, "rim_hint", "(cx, cy, r): the rim's rough centre and radius in px")
        hint = check_hint(hint, (gray.shape[1], gray.shape[0]))  # bad hint: ValueError
        expected = None
        if mirror is not None and nominal_camera_z(mirror) is not None:
            expected = expected_rim(K, mirror, D, max_tilt_deg, max_offset_mm).radius_range
        try:
            detected = detect_rim(image, hint=hint, expected=expected)
        except ValueError as err:  # a valid image without a findable rim
            why = str(err)
            if expected is not None and hint is None:  # the size was K's and the mirror's
                why = (
                    f"{why if why.endswith(('?', '.')) else why + '.'} The expected size is "
                    f"what K (fx = {K[0, 0]:.1f}, fy = {K[1, 1]:.1f} px) and the mirror "
                    f"({describe_mirror(mirror)}) "
                    f"predict for rigs tilted up to {max_tilt_deg:g} deg and offset up to "
                    f"{max_offset_mm:g}: check fx and the mirror, or give a rim hint "
                    f"(rim_hint=(cx, cy, r); --rim-hint CX,CY,R on the command line)"
                )
            raise EstimationError(why) from None
        seen = np.asarray(detected.points, np.float64)
        fit = detected
    if boundary_points is not None or D is not None:
        xn = normalize(seen, K, D)
        ideal = to_pixels(xn, K)  # undistorted pixels, same K
        if not np.isfinite(ideal).all():
            raise ValueError("some boundary points cannot be undistorted with D; check D")
        try:
            fit = fit_rim(ideal)
        except ValueError as err:
            raise EstimationError(str(err)) from None
        seen = seen[np.asarray(fit.inliers, bool)]
    if fit.rms > 1.0:
        warnings.append(
            f"the rim fit is poor (RMS {fit.rms:.2f} px): check the boundary points (the "
            f"posture error grows by about 1 deg per px of rim noise)"
        )
    return RimStep(fit=fit, detected=detected, seen=seen, warnings=tuple(warnings))


# -- 3. candidates -----------------------------------------------------------------------------
@dataclasses.dataclass(frozen=True, eq=False)
class Candidates:
    """The four postures of Chen's method (eqs. 23-29, 32-42) and which are physical."""

    all: tuple
    physical: tuple


def candidates_step(rim, K, mirror):
    """Chen's candidates for the rim ellipse; see :class:`Candidates`."""
    Qe = chen.normalized_conic(rim.fit.conic, K)  # Q_e = K^T Q_I K  (eq. 24)
    cands = tuple(chen.chen_candidates(Qe, mirror))
    return Candidates(cands, tuple(i for i, c in enumerate(cands) if c.physical))


# -- 4. selection ------------------------------------------------------------------------------
def reflection_circles(cands, cue, K, mirror, D=None):
    """The best coaxial circle (and the self-reflection pixel) under each physical candidate."""
    Kinv2 = np.linalg.inv(K)[:2, :2]
    circles, self_px = {}, {}
    for i in cands.physical:
        c = cands.all[i]
        circles[i] = fit_circle(mirror, c.R, c.tvec, cue.normalized, Kinv2, r=cue.r, z=cue.z)
        if cue.fit is not None:
            u0 = self_reflection_pixel(mirror, c.R, c.tvec, K, D)
            self_px[i] = float(np.linalg.norm(u0 - cue.fit.center))
    return circles, self_px


def _effective_points(cands, cue, circles, K, mirror):
    """How many independent points the outline is worth under its best candidate.

    ``N / tau`` with ``tau`` the integrated autocorrelation time of that candidate's residuals
    along the outline, over every lag (:func:`.refine.correlation_factor`), at most ``N / 2``. A
    model that misfits leaves a smooth residual field, worth far fewer points than it has:
    counted as independent, a small gap between two postures' fits on a real photograph with a
    guessed K would read as many sigma.
    """
    n = len(cue.normalized)
    finite = {i: c for i, c in circles.items() if np.isfinite(c.rms)}
    if not finite:
        return 0.5 * n
    i = min(finite, key=lambda k: finite[k].rms)
    c, circ = cands.all[i], finite[i]
    rho, g = plane_radius(mirror, c.R, c.tvec, cue.normalized, circ.z, np.linalg.inv(K)[:2, :2])
    f = correlation_factor((rho - circ.r) / g, SIGMA_FLOOR)
    return min(0.5 * n, n / (f * f))


def _predictions(cands, rim, K, mirror, D):
    """Each physical candidate's self-reflection pixel and its variance (px^2, summed over the
    image axes) from the uncertainty of its posture given the rim alone
    (:func:`.refine.posture_uncertainty`, propagated by difference quotients): the predicted
    outline is only as sure as the posture."""
    dx = np.array([1e-5, 1e-5, 1e-3, 1e-3, 1e-3])  # radians, then the mirror's length unit
    out = {}
    for i in cands.physical:
        c = cands.all[i]
        unc = posture_uncertainty(K, mirror, c.rvec, c.tvec, rim.points, rim.fit.rms)
        if unc.cov is None or not np.isfinite(unc.cov).all():
            continue
        u0 = self_reflection_pixel(mirror, *perturbed_posture(c.R, c.tvec, np.zeros(5)), K, D)
        J = np.stack(
            [
                (self_reflection_pixel(mirror, *perturbed_posture(c.R, c.tvec, h * e), K, D) - u0)
                / h
                for h, e in zip(dx, np.eye(5))
            ],
            axis=1,
        )
        out[i] = (u0, float(np.trace(J @ unc.cov @ J.T)))
    return out


def candidate_cameras(candidates, K, D, mirror, image_size=None):
    """The rig under each physical candidate posture (None at the others)."""
    return [
        MisalignedCatadioptricCamera(K, mirror, c.rvec, c.tvec, D=D, image_size=image_size)
        if c.physical
        else None
        for c in candidates
    ]


def selection_step(cands, cue, lines, mirror, K, D, rim=None):
    """Score every physical candidate by every cue and choose (:func:`.selection.select_candidate`).

    With ``rim`` the outline's scores allow for the uncertainty of each posture's prediction
    (:func:`_predictions`, :func:`.selection.prediction_limited`): a rim that pins the posture
    poorly cannot make a choice by the reflection decisive.

    Returns
    -------
    selection : Selection
    circles : dict
        ``{index: ReflectionCircle}`` under each physical candidate (empty without the cue).
    """
    circles, evidence = {}, None
    if cue.used:
        circles, self_px = reflection_circles(cands, cue, K, mirror, D)
        evidence = ReflectionEvidence(
            rms={i: c.rms for i, c in circles.items()},
            n=_effective_points(cands, cue, circles, K, mirror),
            pred=_predictions(cands, rim, K, mirror, D) if rim is not None else {},
            sigma=cue.sigma,
            self_px=self_px,
            # the reflection must fit some posture: within 5x its own scatter, at least 2 px
            # (the analytic posture is off along the rim's weak direction, which moves the
            # predicted outline by a pixel or two; a wrong K moves it by several)
            limit=max(2.0, 5.0 * cue.sigma) if np.isfinite(cue.sigma) else 2.0,
        )
    cameras = candidate_cameras(cands.all, K, D, mirror) if lines else None
    z = nominal_camera_z(mirror)  # -c: the hyperboloid's lower focus
    nominal = None if z is None else (0.0, 0.0, z)
    name = "lower focus" if isinstance(mirror, HyperbolicMirror) else "nominal camera position"
    sel = select_candidate(cands.all, cameras, lines, nominal, evidence, name)
    return sel, circles


# -- 5. refinement -----------------------------------------------------------------------------
@dataclasses.dataclass(frozen=True, eq=False)
class Refinement:
    """The refined posture, which cues joined the rim, and its a posteriori uncertainty.

    Attributes
    ----------
    rvec, tvec : (3,) ndarray
        The final posture.
    result : RefineResult or None
        The refinement kept (None with ``refine=False``).
    accepted_cues : tuple of str
    rejected_cues : tuple of (str, str)
        ``(cue, why)``: the rim's chi-square rise when the cue joined, or its own residual.
    skipped_cues : tuple of (str, str)
        ``(cue, why)``: cues not tried in the refinement (not a disagreement).
    uncertainty : Uncertainty or None
        A posteriori (:func:`.refine.profile_uncertainty`): rows weighted by their observed RMS
        and its correlation; first order, widened to the cost's own region where that reaches
        farther (near alignment), bounded by the chosen posture's twin. None for a start
        (:func:`refinement_step` with ``uncertainty=False``).
    circle : ReflectionCircle or None
        The reflection's circle under the final posture (when the cue was given).
    """

    rvec: np.ndarray
    tvec: np.ndarray
    result: object
    accepted_cues: tuple
    rejected_cues: tuple
    uncertainty: object
    circle: object
    skipped_cues: tuple = ()


def _subsample(x, n):
    if len(x) <= n:
        return x
    return x[np.linspace(0, len(x) - 1, n).astype(int)]


def _z_range(mirror, res):
    """Where the reflection's circle may lie: from ``-c / 2`` behind the camera centre (a
    hyperboloid; :func:`.reflection.behind_depth` for any mirror) to the mirror vertex's
    distance (as :func:`.reflection.fit_circle` searches, up to the vertex)."""
    R = cv2.Rodrigues(np.asarray(res.rvec, np.float64).reshape(3, 1))[0]
    vertex = float(np.linalg.norm(R @ np.array([0.0, 0.0, mirror.vertex_z]) + res.tvec))
    return -behind_depth(mirror, vertex), vertex


#: The reflection joins only if the posture it moves to is consistent with the rim alone:
#: ``d^T (C_rim - C_joint)^+ d <= CUE_SHIFT_CHI2`` for the shift ``d`` of the mirror axis (a
#: Hausman test on the two axis angles: the 99 % point of chi-square with 2 degrees of
#: freedom). The rim's chi-square rise alone lets a biased outline move the axis by several
#: times the uncertainty then reported (``benchmarks/bench_stress.py`` with lens_z given).
CUE_SHIFT_CHI2 = 9.21


def _disagreement(K, mirror, rim_px, base, res, spec):
    """How far the joint fit ``res`` moved from the rim-only fit ``base``, against the rim.

    ``spec`` is the reflection's :class:`.refine.ReflectionSpec` of the joint fit.

    Returns
    -------
    H : float
        Hausman statistic of the axis shift ``d``: ``d^T (C_rim - C_joint)^+ d`` (2 axis
        angles; ``C`` the a posteriori covariances).
    shift_deg : float
        ``|d|`` in degrees.
    bias_cov : (5, 5) ndarray
        The part of the shift the statistics do not explain, as a covariance to add to the
        joint fit's: ``s D D^T`` with ``D`` the posture's shift (axis angles and origin) and
        ``s = max(0, 1 - tr(C_rim - C_joint)_axis / |d|^2)``. A consistent cue moves the axis
        by ``tr(C_rim - C_joint)_axis`` in the mean square and adds (about) nothing; a biased
        outline the test cannot tell apart from a consistent one adds what it moved beyond
        that, so the reported uncertainty comes from the shift actually observed.
    """

    def cov(fit, refl):
        sig = fit.reflection_rms if refl is not None else None
        u = posture_uncertainty(
            K, mirror, fit.rvec, fit.tvec, rim_px, fit.rim_rms, refl, sig, floor=SIGMA_FLOOR
        )
        return u.cov

    c_rim = cov(base, None)
    c_joint = cov(res, spec._replace(r=res.r, z=res.z))
    D = posture_offsets(base.rvec, base.tvec, res.rvec, res.tvec)
    d = D[:2]
    shift_deg = math.degrees(float(np.linalg.norm(d)))
    if c_rim is None or c_joint is None:
        return math.inf, shift_deg, np.zeros((5, 5))
    dc = c_rim[:2, :2] - c_joint[:2, :2]
    lam, E = np.linalg.eigh(dc)
    # directions where the joint fit is not better than the rim: the rim's own variance there
    lam = np.maximum(lam, 0.05 * float(np.trace(c_rim[:2, :2])) / 2)
    q = E.T @ d
    s = max(0.0, 1.0 - max(float(np.trace(dc)), 0.0) / max(float(d @ d), 1e-300))
    return float(np.sum(q * q / lam)), shift_deg, s * np.outer(D, D)


def _rim_verdict(res, base, var, own, cap):
    """Why the joint fit ``res`` of a cue with the rim does not keep the rim at its own noise
    level or the cue within ``cap`` px (its own RMS ``own``), or None if it does
    (:func:`refinement_step`)."""
    chi2 = 2.0 * (res.rim_cost - base.rim_cost) / var
    if chi2 > CUE_CHI2:
        return (
            f"joining it raised the rim's RMS from {base.rim_rms:.3f} to {res.rim_rms:.3f} px "
            f"(chi-square +{chi2:.0f}, allowed {CUE_CHI2:.0f})"
        )
    if not own <= cap:
        return f"its own RMS residual after the joint fit is {own:.2f} px (allowed {cap:.2f})"
    return None


def _reflection_verdict(res, base, var, cap, K, mirror, rim_px, spec):
    """Whether the reflection's joint fit ``res`` may join: its circle between the camera and
    the mirror, :func:`_rim_verdict`, and an axis shift the rim allows (:func:`_disagreement`).
    ``(None, bias_cov)`` if it may, ``(why, None)`` if not."""
    lo, hi = _z_range(mirror, res)
    if not lo <= res.z <= hi:
        return (
            f"the fitted circle lies at z = {res.z:.1f}, not between the camera and the "
            f"mirror ({lo:.1f} to {hi:.1f})",
            None,
        )
    why = _rim_verdict(res, base, var, res.reflection_rms, cap)
    if why is not None:
        return why, None
    H, shift_deg, bias_cov = _disagreement(K, mirror, rim_px, base, res, spec)
    if H > CUE_SHIFT_CHI2:
        return (
            f"it moved the mirror axis by {shift_deg:.3f} deg, {math.sqrt(H):.1f} times what "
            f"the rim alone allows there (a bias in one of them: an outline of another circle, "
            f"a blurred or clipped edge)",
            None,
        )
    return None, bias_cov


def _rim_variance(K, mirror, base, rim_px):
    """The rim's a posteriori variance (px^2) at the rim-only fit ``base``: ``2 cost / (N - 5)``,
    at least ``SIGMA_FLOOR^2``, inflated by the correlation of the edge points along the rim as
    in the reported uncertainty (so the test and the uncertainty agree)."""
    R0 = cv2.Rodrigues(np.asarray(base.rvec, np.float64).reshape(3, 1))[0]
    f = correlation_factor(
        RimTerm(K, mirror, R0, base.tvec, rim_px).residuals(R0, base.tvec), SIGMA_FLOOR
    )
    return max(2.0 * base.rim_cost / max(len(rim_px) - 5, 1), SIGMA_FLOOR**2) * f * f


@dataclasses.dataclass
class _CueTrials:
    """What the refinement with cues found (:func:`_refine_with_cues`)."""

    kept: object = None
    accepted: list = dataclasses.field(default_factory=list)
    rejected: list = dataclasses.field(default_factory=list)
    skipped: list = dataclasses.field(default_factory=list)
    bias_cov: object = None


def _refine_with_cues(K, mirror, cand, rim_px, lines_xn, cue, spec):
    """The rim-only fit, then the reflection (with ``spec``, if its r or z is known), then far
    lines if the reflection did not join, each kept if its verdict lets it join."""
    rvec, tvec = cand.rvec, cand.tvec
    base = refine_posture(K, mirror, rvec, tvec, rim_px)
    out = _CueTrials(kept=base)
    var = _rim_variance(K, mirror, base, rim_px)
    if spec is not None and cue.r is None and cue.z is None:
        # with r and z both unknown the circle trades its z with the mirror's tilt along a
        # valley the linear uncertainty does not see (the axis errors grow several times
        # beyond the reported uncertainty): it chose the candidate; the posture rests on the
        # rim (and far lines)
        out.skipped.append(
            (
                "reflection",
                "its circle's r and z are both unknown and z trades "
                "with the tilt; give lens_z or lens_r to refine with it",
            )
        )
    elif spec is not None:
        res = refine_posture(K, mirror, rvec, tvec, rim_px, reflection=spec, max_nfev=200)
        cap = max(1.0, 3.0 * cue.sigma) if np.isfinite(cue.sigma) else 1.0
        why, bias = _reflection_verdict(res, base, var, cap, K, mirror, rim_px, spec)
        if why is not None:
            out.rejected.append(("reflection", why))
        else:
            out.accepted.append("reflection")
            out.kept, out.bias_cov = res, bias
    elif cue.used:
        out.rejected.append(
            ("reflection", "its outline does not reach the camera under this posture")
        )
    if lines_xn and "reflection" not in out.accepted:
        res = refine_posture(K, mirror, rvec, tvec, rim_px, lines_xn, max_nfev=LINES_MAX_NFEV)
        why = _rim_verdict(res, base, var, res.line_rms, 3.0)
        if why is not None:
            out.rejected.append(("far lines", why))
        else:
            out.accepted.append("far lines")
            out.kept = res
    return out


def _final_circle(K, mirror, R, tvec, cue, trials):
    """The reflection's circle under the final posture: the joint fit's if the reflection
    joined, else the best coaxial circle (None without the cue)."""
    if not cue.used:
        return None
    if "reflection" in trials.accepted:
        kept = trials.kept
        return ReflectionCircle(kept.r, kept.z, kept.reflection_rms)
    return fit_circle(mirror, R, tvec, cue.normalized, np.linalg.inv(K)[:2, :2], r=cue.r, z=cue.z)


#: The camera records the circle of its reflection (``camera_reflection``, from which default
#: panoramas start) when the outline fits it within this many px RMS: looser than the
#: plausibility checks' 3 px, because a guessed K fits a real outline worse and its circle
#: still leaves the lens out of the default panorama (``benchmarks/bench_real_photo.py``).
BODY_MAX_RMS_PX = 5.0


def camera_body(cue, refinement, max_rms=BODY_MAX_RMS_PX):
    """``(r, z)`` of the camera's reflection as detected, for the camera to record
    (``camera_reflection``), or None: the circle under the final posture when the cue was used
    and its outline fits it within ``max_rms`` px RMS (a circle that misfits more does not
    describe the outline the camera saw)."""
    c = refinement.circle
    if not cue.used or c is None:
        return None
    if not (np.isfinite(c.r) and c.r > 0 and np.isfinite(c.z) and c.rms <= max_rms):
        return None
    return float(c.r), float(c.z)


def _twin(K, mirror, cand, rim):
    """The other physical posture of the rim (Chen's; the one nearest to ``cand`` in axis
    angle if there are more), as ``(rvec, tvec)``, or None."""
    others = [
        c
        for c in candidates_step(rim, K, mirror).all
        if c.physical and (c.l, c.m) != (cand.l, cand.m)
    ]
    if not others:
        return None
    best = max(others, key=lambda c: float(c.axis @ cand.axis))
    return best.rvec, best.tvec


def refinement_step(K, mirror, cand, rim, lines_xn, cue, circle, refine=True, uncertainty=True):
    """Refine on the rim and every cue that agrees with it; see :class:`Refinement`
    (its ``uncertainty`` None without ``uncertainty``: a start, whose report nobody reads).

    A cue joins only if the joint fit keeps the rim at its own noise level: with ``sigma^2``
    the rim's a posteriori variance alone (``2 cost / (N - 5)``, at least ``SIGMA_FLOOR``^2,
    inflated by the correlation of the residuals as the reported uncertainty is), the
    rim's chi-square may rise by at most ``CUE_CHI2`` (the shift the cue causes must be within
    the rim's own uncertainty ellipsoid), and the cue's own RMS must stay within
    3x its measured scatter (1 px at least for the outline, 3 px for far lines), and the
    reflection's circle must lie between the camera and the mirror. The reflection is tried
    first, and only with its ``r`` or ``z`` known (otherwise it only chose the candidate: see
    ``skipped_cues``); far lines join only when it did not join (they then add nothing
    measurable but time, ``benchmarks/bench_calibrate.py``).
    """
    rim_px = rim.points
    spec = None
    if cue.used and circle is not None and np.isfinite(circle.rms):
        xn_r = _subsample(cue.normalized, MAX_REFINE_POINTS)
        # an unknown z stays free: it trades with the tilt, and the uncertainty must say so
        spec = ReflectionSpec(xn_r, circle.r, circle.z, cue.r is not None, cue.z is not None)
    if refine:
        trials = _refine_with_cues(K, mirror, cand, rim_px, lines_xn, cue, spec)
        rvec, tvec = trials.kept.rvec, trials.kept.tvec
    else:
        trials = _CueTrials()
        rvec, tvec = cand.rvec, cand.tvec
    # the candidates (chen) and refine_posture (gauge_rotation) already return the gauge
    R = cv2.Rodrigues(np.asarray(rvec, np.float64).reshape(3, 1))[0]
    final_circle = _final_circle(K, mirror, R, tvec, cue, trials)
    known = cue.r is not None or cue.z is not None  # else z trades with the tilt (above)
    use_refl = "reflection" in trials.accepted or (not refine and spec is not None and known)
    unc = (
        None
        if not uncertainty
        else _uncertainty(K, mirror, cand, rim, rvec, tvec, spec, final_circle, use_refl, trials)
    )
    return Refinement(
        np.asarray(rvec, np.float64),
        np.asarray(tvec, np.float64),
        trials.kept,
        tuple(trials.accepted),
        tuple(trials.rejected),
        unc,
        final_circle,
        tuple(trials.skipped),
    )


def _uncertainty(K, mirror, cand, rim, rvec, tvec, spec, final_circle, use_refl, trials):
    """The refined posture's a posteriori uncertainty (:class:`Refinement`), with the bias
    the cues' trials measured."""
    rim_px = rim.points
    rim_sigma = trials.kept.rim_rms if trials.kept is not None else rim.fit.rms
    unc = profile_uncertainty(
        K,
        mirror,
        rvec,
        tvec,
        rim_px,
        rim_sigma,
        spec._replace(r=final_circle.r, z=final_circle.z) if use_refl else None,
        final_circle.rms if use_refl else None,
        floor=1e-9,
        twin=_twin(K, mirror, cand, rim),
    )
    bias_cov = trials.bias_cov
    if bias_cov is not None and unc.cov is not None and np.any(bias_cov):
        unc = unc.with_cov(unc.cov + bias_cov, tvec)
    return unc


# -- 6. warnings -------------------------------------------------------------------------------
def warnings_step(rim, cue, selection, refinement, cands):
    """Everything a user must know before trusting the result, as a tuple of sentences."""
    out = list(rim.warnings) + list(selection.warnings)
    for name, why in refinement.rejected_cues:
        out.append(
            f"the {name} disagree(s) with the rim and was left out of the refinement: "
            f"{why}; check it (the posture rests on the rim alone)"
        )
    unc = refinement.uncertainty
    if AXIS_WARN_DEG < unc.axis_std_deg <= 0.5:
        out.append(
            f"the mirror axis is uncertain by about {unc.axis_std_deg:.2f} deg (RMS; "
            f"errors of {2 * unc.axis_std_deg:.2f} deg are plausible), mostly "
            f"{unc.describe()}; the camera's reflection pins it when its circle's z or r "
            f"is given (lens_z, lens_r)"
        )
    if unc.axis_std_deg > 0.5:
        out.append(
            f"the posture is poorly determined: about {unc.axis_std_deg:.2f} deg (RMS) "
            f"on the mirror axis and {unc.origin_std:.2f} on the origin, mostly "
            f"{unc.describe()}; improve the boundary points or show the camera's "
            f"reflection"
        )
    half = 0.5 * unc.twin_deg
    if unc.aligned_chi2 <= ALIGNED_CHI2 and half > 2 * unc.axis_std_deg:
        out.append(
            f"the rig is nearly aligned (the camera close to the mirror's axis), where the "
            f"rim's image depends on the tilt only to second order: with the rim's image as "
            f"fitted the axis is known to {unc.axis_std_deg:.2f} deg (RMS), but a low-order "
            f"shape error of that image (or a pixel aspect ratio of K a little off), which "
            f"this fit cannot see, could put it up to {half:.2f} deg off: the aligned posture "
            f"midway between the two physical postures changes the rim's image by only "
            f"{unc.aligned_px:.2f} px RMS (chi-square +{unc.aligned_chi2:.0f} with the "
            f"residuals' correlation). That is a bound over the shapes of the rim's image the "
            f"data cannot rule out, not an error estimate; the camera's reflection with its z "
            f"or r given (lens_z, lens_r) pins the tilt"
        )
    others = [i for i in cands.physical if i != selection.chosen]
    if others and not selection.ambiguous and selection.costs_per_cue:
        a, b = cands.all[selection.chosen], cands.all[others[0]]
        d_axis = math.degrees(
            math.atan2(np.linalg.norm(np.cross(a.axis, b.axis)), float(a.axis @ b.axis))
        )
        if d_axis > 0.01 and d_axis < 3.0 * unc.axis_std_deg:
            out.append(
                f"the posture's uncertainty ({unc.axis_std_deg:.3f} deg on the axis) is "
                f"comparable with the separation of the two physical postures "
                f"({d_axis:.3f} deg): the choice may be wrong; improve the boundary "
                f"points"
            )
    return tuple(out)
