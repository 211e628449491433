"""Is a calibration plausible? Checks of a result against what a real rig can be.

Chen's method (eqs. 23-42) fits *any* ellipse exactly: a photo of a coffee cup, a ``K`` for
another resolution or ``a`` and ``b`` swapped all give a posture, only an absurd one. A real rig
is built close to the aligned HyperOmni design (eqs. 2-5: camera at the lower focus, axes
parallel), so with ``K`` and the mirror known we can say what to expect and warn when the result
is far from it:

- the rim's size and place in the image (:func:`expected_rim`): ``f * rim_radius / (z_rim + c)``
  for the aligned rig, and its range over the postures within the limits; it also guides
  :func:`omnicam.calibration.rim.detect_rim` (``expected=``);
- the posture (:func:`check_plausibility`): a mirror axis tilted more than ``max_tilt_deg`` from
  the optical axis, a camera centre farther than ``max_offset_mm`` from the lower focus
  ``(0, 0, -c)``, the rim centre far from the principal point;
- ``K`` against the image: a principal point outside it, a focal length absurd for its size, a
  pixel aspect ``fx / fy`` far from 1 (``K`` rescaled to another aspect ratio), a rim of another
  size than ``K`` and the mirror predict (``K`` for another resolution, wrong mirror);
- the cues after refinement: far-line or outline residuals above ``max_residual_px``;
- the mirror: ``a`` and ``b`` that fit clearly better swapped (:func:`swapped_mirror_warnings`;
  a hyperboloid's only).

Any mirror of revolution: "the lower focus" is the mirror's nominal camera position
(:func:`omnicam.mirror.nominal_camera_z`: the hyperboloid's lower focus ``-c``, an asphere's
frame origin when its vertex is above it), and ``z_rim + c`` is ``z_rim - nominal_camera_z``.
For a mirror without one (an asphere with ``vertex_z <= 0``) the checks that need it (the rim's
size and centre, the camera's offset) are left out, :func:`expected_rim` and :func:`guess_K`
raise ``ValueError`` saying so, and :func:`nominal_note` gives the report's note.

Each finding is a :class:`PlausibilityWarning` whose message says what to check.
"""

from __future__ import annotations

import dataclasses
import math

import cv2
import numpy as np

from .._validate import positive_number, refuse_complex, validate_D, validate_K
from ..mirror import HyperbolicMirror, describe_mirror, nominal_camera_z
from ..raytrace import to_pixels
from .ellipse import axes_angle, ellipse_from_conic

__all__ = [
    "DEFAULT_MAX_ASPECT_DEVIATION",
    "DEFAULT_MAX_OFFSET_MM",
    "DEFAULT_MAX_RESIDUAL_PX",
    "DEFAULT_MAX_TILT_DEG",
    "ExpectedRim",
    "PlausibilityWarning",
    "assess",
    "check_plausibility",
    "cue_costs",
    "expected_rim",
    "focal_from_rim",
    "focus_offset",
    "guess_K",
    "nominal_note",
    "rim_depth",
    "rim_radius_px",
    "swapped_mirror_warnings",
    "tilt_deg",
]

DEFAULT_MAX_TILT_DEG = 10.0
DEFAULT_MAX_OFFSET_MM = 10.0
DEFAULT_MAX_RESIDUAL_PX = 3.0
DEFAULT_MAX_ASPECT_DEVIATION = 0.05  # |fx / fy - 1|: real sensors are within ~1 %
_SIZE_SLACK = 0.05  # relative slack on the expected rim size (rim detection, K rounding)


class PlausibilityWarning(UserWarning):
    """One implausible finding; ``str(w)`` is the message (what is wrong and what to check).

    Attributes
    ----------
    kind : str
        ``"tilt"``, ``"offset"``, ``"principal_point"``, ``"intrinsics"``, ``"rim_size"``,
        ``"residual"``, ``"swapped_ab"`` or ``"choice"`` (another physical posture of Chen's
        method is within the limits while the chosen one is not).
    value, limit : float
        The measured value and the limit it broke (NaN where it does not apply).
    """

    def __init__(self, kind, message, value=math.nan, limit=math.nan):
        super().__init__(message)
        self.kind, self.message, self.value, self.limit = kind, message, value, limit

    def __str__(self):
        return self.message

    def __repr__(self):
        return f"PlausibilityWarning({self.kind!r}, {self.message!r})"


def _limit(value, name):
    refuse_complex(value, name, "a positive number")
    return positive_number(value, name)


def tilt_deg(R) -> float:
    """Angle between the mirror axis and the camera's optical axis, degrees (``R``: mirror ->
    camera, so the mirror axis in the camera frame is ``R e_z``)."""
    axis = np.asarray(R, np.float64)[:, 2]
    return math.degrees(math.atan2(math.hypot(axis[0], axis[1]), axis[2]))


def focus_offset(camera_center, mirror) -> float:
    """Distance of the camera centre (mirror frame) from the nominal camera position
    ``(0, 0, nominal_camera_z(mirror))``: a hyperboloid's lower focus ``(0, 0, -c)``; NaN for
    a mirror without one."""
    z = nominal_camera_z(mirror)
    if z is None:
        return math.nan
    return float(np.linalg.norm(np.asarray(camera_center, np.float64) - (0.0, 0.0, z)))


def nominal_note(mirror) -> str | None:
    """The report's note for a mirror without a nominal camera position (None for others)."""
    if nominal_camera_z(mirror) is not None:
        return None
    return (
        f"the mirror ({describe_mirror(mirror)}) does not say where the camera sits (its "
        f"vertex is not above the frame's origin): the rim's expected size and centre and the "
        f"camera's offset were not checked; place the mirror frame with the camera's centre "
        f"at the origin (vertex_z > 0) to have them checked"
    )


def _aligned_depth(mirror) -> float:
    """``z_rim - nominal_camera_z``: the rim's depth from the camera of the rig built as
    designed (``z_rim + c`` for a hyperboloid); ``ValueError`` for a mirror without one."""
    z = nominal_camera_z(mirror)
    if z is None:
        raise ValueError(
            f"the mirror ({describe_mirror(mirror)}) does not say where the camera sits, so "
            f"the rim's size cannot be predicted from it: give K, or place the mirror frame "
            f"with the camera's centre at the origin (vertex_z > 0)"
        )
    return mirror.z_rim - z  # z_rim + c for a hyperboloid, to the last digit


# -- what to expect from K and the mirror --------------------------------------------------------
# The aligned rig (eqs. 2-5: camera at the lower focus, axes parallel) sees the rim circle of
# radius rim_radius at depth z_rim + c: a circle of radius r = f * rim_radius / (z_rim + c) px.
# The functions below read that one relation each way.
def rim_radius_px(rim) -> float:
    """The mean radius (px) of a rim ellipse (:class:`.rim.RimFit`): the geometric mean of its
    semi-axes."""
    return math.sqrt(float(rim.axes[0]) * float(rim.axes[1]))


def focal_from_rim(rim_px_radius, mirror) -> float:
    """The focal length (px) of the aligned rig whose image of the rim has the radius
    ``rim_px_radius`` (px): ``f = r (z_rim + c) / rim_radius`` (``z_rim - nominal_camera_z``
    for any mirror; ``ValueError`` for a mirror without a nominal camera position)."""
    return rim_px_radius * _aligned_depth(mirror) / mirror.rim_radius


def rim_depth(f, rim_px_radius, rim_radius) -> float:
    """The rim's depth ``z_rim + c`` (mirror units) in the aligned rig whose camera of focal
    length ``f`` (px) images the rim, of radius ``rim_radius``, with the radius
    ``rim_px_radius`` (px): ``z_rim + c = f rim_radius / r``."""
    return f * rim_radius / rim_px_radius


@dataclasses.dataclass(frozen=True)
class ExpectedRim:
    """The rim in the image as ``K`` and the mirror predict it.

    Attributes
    ----------
    center : (2,) float64 ndarray
        Rim centre of the aligned rig (eqs. 2-5), px: the principal point (distortion aside).
    radius : float
        Rim radius of the aligned rig, ``f * rim_radius / (z_rim + c)`` px (``f`` the mean of
        ``fx`` and ``fy``).
    radius_range : (float, float)
        Smallest semi-minor and largest semi-major axis of the rim ellipse over the postures
        within the limits (tilt up to ``max_tilt_deg``, camera centre up to ``max_offset_mm``
        from the lower focus), px: the ``expected`` argument of ``detect_rim``.
    max_center_offset : float
        Largest distance of the rim centre from ``center`` over those postures, px.
    max_tilt_deg, max_offset_mm : float
        The limits used.
    """

    center: np.ndarray
    radius: float
    radius_range: tuple
    max_center_offset: float
    max_tilt_deg: float
    max_offset_mm: float


def _rim_ellipse(K, D, rim, R, t):
    """Centre and semi-axes (px) of the image of the rim circle (points ``rim``, mirror frame)
    for the posture ``R, t``."""
    X = rim @ R.T + t  # camera frame
    if not (X[:, 2] > 1e-9).all():
        return None
    if D is None:
        x = X[:, :2] / X[:, 2:]
        px = to_pixels(x, K)
    else:
        px, _ = cv2.projectPoints(
            X.reshape(-1, 1, 3), np.zeros(3), np.zeros(3), K, np.asarray(D, np.float64)
        )
        px = px.reshape(-1, 2)
    (cx, cy), (d1, d2), _ = cv2.fitEllipse(px.astype(np.float32))
    return np.array([cx, cy]), 0.5 * min(d1, d2), 0.5 * max(d1, d2)


def guess_K(rim, mirror):
    """The ``K`` of the aligned rig that images ``rim`` as found: a guess without intrinsics.

    An aligned rig (the paper's eqs. 2-5: camera at the lower focus, axes parallel) images the
    rim circle of radius ``rim_radius`` at depth ``z_rim + c`` as a circle of radius
    ``f rim_radius / (z_rim + c)`` px about the principal point
    (:func:`omnicam.calibration.plausibility.expected_rim`). So ``f = r (z_rim + c) /
    rim_radius`` with ``r`` the rim's mean radius (the geometric mean of its semi-axes),
    square pixels, no skew and the principal point at the rim's centre. The rim's centre moves
    with the rig's tilt and offset (and the guess takes it for the principal point), and a
    camera of another pixel aspect sees the rim as an ellipse, which reads as a tilt: the
    posture found is only as right as the guess.

    Parameters
    ----------
    rim : RimFit
        The rim ellipse in the image (:func:`omnicam.detect_rim`, :func:`.rim.fit_rim`).
    mirror : HyperbolicMirror or AsphericMirror
        The aligned rig's camera at :func:`omnicam.mirror.nominal_camera_z`.

    Returns
    -------
    K : (3, 3) float64 ndarray

    Raises
    ------
    ValueError
        A mirror without a nominal camera position (no aligned rig to guess from).
    """
    f = focal_from_rim(rim_radius_px(rim), mirror)
    cx, cy = (float(v) for v in rim.center)
    return np.array([[f, 0.0, cx], [0.0, f, cy], [0.0, 0.0, 1.0]])


def expected_rim(
    K, mirror, D=None, max_tilt_deg=DEFAULT_MAX_TILT_DEG, max_offset_mm=DEFAULT_MAX_OFFSET_MM
) -> ExpectedRim:
    """The rim's expected place and size in the image from ``K`` and the mirror.

    The aligned rig (eqs. 2-5) sees the rim circle (radius ``rim_radius`` at height ``z_rim``)
    at depth ``z_rim + c`` from the camera at the lower focus: a circle of radius
    ``f * rim_radius / (z_rim + c)`` px about the principal point. The range covers the rigs
    whose mirror axis is tilted up to ``max_tilt_deg`` (8 directions) and whose camera centre is
    up to ``max_offset_mm`` from the lower focus (the 6 axis directions), each projected with
    ``K`` and ``D``.

    Parameters
    ----------
    K : (3, 3) array_like
    mirror : HyperbolicMirror or AsphericMirror
        Any mirror: the lower focus is :func:`omnicam.mirror.nominal_camera_z`.
    D : array_like or None
    max_tilt_deg, max_offset_mm : float
        Positive limits.

    Returns
    -------
    ExpectedRim

    Raises
    ------
    ValueError
        A mirror without a nominal camera position (:func:`nominal_note`).
    """
    K = validate_K(K)
    D = validate_D(D)
    max_tilt_deg = _limit(max_tilt_deg, "max_tilt_deg")
    max_offset_mm = _limit(max_offset_mm, "max_offset_mm")
    _aligned_depth(mirror)  # a mirror without a nominal camera position: ValueError
    focus = np.array([0.0, 0.0, nominal_camera_z(mirror)])  # (0, 0, -c) for a hyperboloid
    rim = mirror.rim_points(36)
    aligned = _rim_ellipse(K, D, rim, np.eye(3), -focus)
    if aligned is None:
        raise ValueError("K and the mirror put the rim behind the camera; check K")
    center = aligned[0]
    offsets = [np.zeros(3)] + [s * max_offset_mm * e for e in np.eye(3) for s in (1.0, -1.0)]
    tilts = [np.zeros(3)] + [
        math.radians(max_tilt_deg) * np.array([-math.sin(p), math.cos(p), 0.0])
        for p in np.linspace(0.0, 2.0 * np.pi, 8, endpoint=False)
    ]
    lo, hi, off = math.inf, 0.0, 0.0
    for rvec in tilts:
        R = cv2.Rodrigues(rvec.reshape(3, 1))[0]
        for o in offsets:
            e = _rim_ellipse(K, D, rim, R, -R @ (focus + o))  # X_cam = R (X - C)
            if e is None:
                continue
            lo, hi = min(lo, e[1]), max(hi, e[2])
            off = max(off, float(np.linalg.norm(e[0] - center)))
    radius = 0.5 * (aligned[1] + aligned[2])
    return ExpectedRim(
        center=center,
        radius=float(radius),
        radius_range=(float(lo), float(hi)),
        max_center_offset=off,
        max_tilt_deg=max_tilt_deg,
        max_offset_mm=max_offset_mm,
    )


# -- the checks ----------------------------------------------------------------------------------
def _has_nominal(mirror) -> bool:
    return nominal_camera_z(mirror) is not None


def _params(mirror) -> str:
    """The mirror's parameters to check, as a message names them."""
    if isinstance(mirror, HyperbolicMirror):
        return "a, b and rim radius"
    return "R, k, polynomial terms, vertex height and rim radius"


def _nominal_name(mirror) -> str:
    """What the nominal camera position is, as a message names it."""
    if isinstance(mirror, HyperbolicMirror):
        return "lower focus"
    return f"nominal camera position (0, 0, {nominal_camera_z(mirror):g})"


def _rim_geometry(rim):
    """``(center, (major, minor))`` of a RimFit or of a (3, 3) conic."""
    if hasattr(rim, "center") and hasattr(rim, "axes"):
        return np.asarray(rim.center, np.float64), np.asarray(rim.axes, np.float64)
    Q = np.asarray(rim, np.float64)
    if Q.shape != (3, 3) or not np.isfinite(Q).all():
        raise ValueError("rim must be a RimFit or the (3, 3) rim conic Q_I")
    center, S = ellipse_from_conic(Q)
    return center, np.asarray(axes_angle(S)[0], np.float64)


def check_plausibility(
    camera,
    rim,
    image_size=None,
    *,
    max_tilt_deg=DEFAULT_MAX_TILT_DEG,
    max_offset_mm=DEFAULT_MAX_OFFSET_MM,
    max_residual_px=DEFAULT_MAX_RESIDUAL_PX,
    max_aspect_deviation=DEFAULT_MAX_ASPECT_DEVIATION,
    residuals=None,
) -> list[PlausibilityWarning]:
    """Warnings for a calibration no real rig would give; an empty list when it is plausible.

    Parameters
    ----------
    camera : MisalignedHyperbolicCamera
        The calibrated camera (``K``, ``D``, mirror, posture).
    rim : RimFit or (3, 3) array_like
        The rim ellipse the posture was computed from (in the pixels ``K`` maps to, i.e.
        undistorted pixels when ``D`` is given: the report's ``conic``).
    image_size : (int, int), optional
        ``(width, height)``; defaults to ``camera.image_size``. Without either, the checks of
        ``K`` against the image are skipped.
    max_tilt_deg : float
        Largest plausible angle between the mirror axis and the optical axis (default 10).
    max_offset_mm : float
        Largest plausible distance of the camera centre from the lower focus ``(0, 0, -c)``
        in the mirror's length unit (default 10).
    max_residual_px : float
        Largest plausible RMS residual of a cue after refinement (default 3 px).
    max_aspect_deviation : float
        Largest plausible ``|fx / fy - 1|`` (default 0.05).
    residuals : dict, optional
        ``{name: RMS px}`` of the cues after refinement, e.g. ``{"far lines": 0.4,
        "camera's reflection outline": 0.3}``; NaN entries are skipped.

    Returns
    -------
    list of PlausibilityWarning
        In the order: rim size, intrinsics, principal point, units, tilt, offset, residuals.
    """
    max_tilt_deg = _limit(max_tilt_deg, "max_tilt_deg")
    max_offset_mm = _limit(max_offset_mm, "max_offset_mm")
    max_residual_px = _limit(max_residual_px, "max_residual_px")
    max_aspect_deviation = _limit(max_aspect_deviation, "max_aspect_deviation")
    image_size = camera.image_size if image_size is None else image_size
    K, mirror = np.asarray(camera.K, np.float64), camera.mirror
    center, axes = _rim_geometry(rim)
    out = []
    fx, fy, cx, cy = K[0, 0], K[1, 1], K[0, 2], K[1, 2]
    hyperboloid = isinstance(mirror, HyperbolicMirror)
    # rim is in ideal pixels; a mirror without a nominal camera position predicts no rim, and
    # then nothing (any size, any centre) is implausible
    exp = (
        expected_rim(K, mirror, None, max_tilt_deg, max_offset_mm)
        if _has_nominal(mirror)
        else ExpectedRim(np.zeros(2), math.nan, (0.0, math.inf), math.inf, math.nan, math.nan)
    )
    limits = f"tilt <= {max_tilt_deg:g} deg, offset <= {max_offset_mm:g}"

    # the rim's size against K and the mirror
    lo, hi = exp.radius_range
    if axes[1] < (1 - _SIZE_SLACK) * lo or axes[0] > (1 + _SIZE_SLACK) * hi:
        ratio = math.sqrt(axes[0] * axes[1]) / exp.radius
        why = (
            f" (about {ratio:.2f}x: a K calibrated at another resolution?)"
            if ratio < 0.7 or ratio > 1.4
            else ""
        )
        out.append(
            PlausibilityWarning(
                "rim_size",
                f"the rim found has semi-axes {axes[0]:.1f} and {axes[1]:.1f} px, but K (f = "
                f"{0.5 * (fx + fy):.1f} px) and the mirror ({describe_mirror(mirror)}) "
                f"predict {exp.radius:.1f} px for an aligned "
                f"rig and {lo:.1f}-{hi:.1f} px within {limits}{why}: check K, the mirror "
                f"parameters and "
                f"that the ellipse found is the mirror's rim (see the overlay; --rim-hint)",
                math.sqrt(axes[0] * axes[1]),
                exp.radius,
            )
        )

    # K against the image
    if image_size is not None:
        w, h = (int(v) for v in image_size)
        if not (-0.5 <= cx <= w - 0.5 and -0.5 <= cy <= h - 0.5):
            out.append(
                PlausibilityWarning(
                    "intrinsics",
                    f"the principal point ({cx:.1f}, {cy:.1f}) of K is outside the {w}x{h} image: "
                    f"check K (is it for this image size? K for another resolution is rescaled "
                    f"only when the intrinsics file gives its image_size)",
                    math.nan,
                    math.nan,
                )
            )
        diag = math.hypot(w, h)
        f = 0.5 * (fx + fy)
        if not 0.05 * diag <= f <= 50.0 * diag:
            out.append(
                PlausibilityWarning(
                    "intrinsics",
                    f"the focal length of K ({f:.1f} px) is absurd for a {w}x{h} image (a lens "
                    f"gives {0.05 * diag:.0f}-{50 * diag:.0f} px): check K's units and image size",
                    f,
                    math.nan,
                )
            )
        aspect = fx / fy
        if abs(aspect - 1.0) > max_aspect_deviation:
            out.append(
                PlausibilityWarning(
                    "intrinsics",
                    f"K has fx / fy = {aspect:.3f} (real sensors have square pixels to about 1 %): "
                    f"was K rescaled to another aspect ratio? The image is {w}x{h} "
                    f"({w / h:.3f}:1); scale K to a crop or resize of the image it was "
                    f"calibrated on, not by (width, height) separately",
                    aspect,
                    1.0 + max_aspect_deviation,
                )
            )

    # the rim centre against the principal point (aligned centre)
    d = float(np.linalg.norm(center - exp.center))
    allowed = 1.25 * exp.max_center_offset + 2.0
    if d > allowed:
        out.append(
            PlausibilityWarning(
                "principal_point",
                f"the rim centre ({center[0]:.1f}, {center[1]:.1f}) is {d:.1f} px "
                f"({d / math.sqrt(axes[0] * axes[1]):.2f} rim radii) from the principal point "
                f"({exp.center[0]:.1f}, {exp.center[1]:.1f}) where an aligned rig puts it, more "
                f"than {allowed:.1f} px ({limits}): check cx, cy of K (for this image, not a crop "
                f"of it?) and that the ellipse found is the mirror's rim",
                d,
                allowed,
            )
        )

    # the mirror's unit: the limits are in millimetres
    if mirror.rim_radius < 1.0:
        out.append(
            PlausibilityWarning(
                "units",
                f"the mirror's rim radius is {mirror.rim_radius:g}: in metres? omnicam's "
                f"lengths and limits (max_offset_mm = {max_offset_mm:g}) are in millimetres; "
                + (
                    f"give a, b and the rim radius in mm (e.g. {1000 * mirror.a:g} "
                    f"{1000 * mirror.b:g} {1000 * mirror.rim_radius:g})"
                    if hyperboloid
                    else "give the mirror's lengths in mm"
                ),
                mirror.rim_radius,
                1.0,
            )
        )

    # the posture
    tilt = tilt_deg(camera.R)
    if tilt > max_tilt_deg:
        out.append(
            PlausibilityWarning(
                "tilt",
                f"the mirror axis is tilted {tilt:.1f} deg from the optical axis (limit "
                f"{max_tilt_deg:g} deg; real rigs are within a few degrees): check K (resolution, "
                f"aspect ratio), the mirror's {_params(mirror)}, and that the ellipse found is "
                f"the mirror's rim (see the overlay); raise the limit (--max-tilt) only for a rig "
                f"built tilted",
                tilt,
                max_tilt_deg,
            )
        )
    off = focus_offset(camera.camera_center, mirror)
    if off > max_offset_mm:
        out.append(
            PlausibilityWarning(
                "offset",
                f"the camera centre is {off:.1f} from the mirror's {_nominal_name(mirror)} "
                f"(limit {max_offset_mm:g}, mirror units): check K (resolution, focal length), "
                f"the mirror's "
                + ("a, b (swapped?) and rim radius" if hyperboloid else _params(mirror))
                + ", and that the ellipse found is the "
                "mirror's rim; raise the limit (--max-offset) only for a rig built that way",
                off,
                max_offset_mm,
            )
        )

    # the cues after refinement
    for name, rms in (residuals or {}).items():
        if rms is not None and math.isfinite(rms) and rms > max_residual_px:
            out.append(
                PlausibilityWarning(
                    "residual",
                    f"the {name} residual after refinement is {rms:.2f} px RMS (limit "
                    f"{max_residual_px:g} px): check those points (a line that is not "
                    f"straight or not far, an outline that is not the camera's), K and the mirror",
                    rms,
                    max_residual_px,
                )
            )
    return out


def swapped_mirror_warnings(
    mirror,
    given,
    swapped,
    *,
    max_tilt_deg=DEFAULT_MAX_TILT_DEG,
    max_offset_mm=DEFAULT_MAX_OFFSET_MM,
    ratio=10.0,
    use_posture=True,
) -> list[PlausibilityWarning]:
    """Whether the mirror fits clearly better with ``a`` and ``b`` swapped.

    The rim alone fits any mirror exactly (Chen's method has as many unknowns as the ellipse),
    so the evidence is what else the two calibrations explain: the far lines' score (eq. 31),
    the outline of the camera's reflection, and the posture's plausibility.

    Parameters
    ----------
    mirror : HyperbolicMirror
        The mirror as given.
    given, swapped : dict
        For the calibration with the given mirror and with ``a`` and ``b`` swapped:
        ``{"camera": camera, "costs": {cue name: cost}}``, a cost being anything where lower
        is better and that is comparable between the two (far-line score of eq. 31, outline
        RMS in px); NaN or missing costs are skipped. ``swapped`` may be ``None`` (the swapped
        calibration failed: no evidence).
    ratio : float
        How many times lower a swapped cost must be to count as clearly better.
    use_posture : bool
        Also count an implausible posture that becomes plausible swapped.

    Returns
    -------
    list of PlausibilityWarning
        At most one, of kind ``"swapped_ab"``.
    """
    if swapped is None or not isinstance(mirror, HyperbolicMirror) or mirror.a == mirror.b:
        return []  # a swap of a and b is a hyperboloid's mistake
    better = []
    for name, cost in given.get("costs", {}).items():
        other = swapped.get("costs", {}).get(name)
        if cost is None or other is None or not math.isfinite(cost) or not math.isfinite(other):
            continue
        if cost > ratio * max(other, 1e-300):
            better.append(f"{name} {cost:.3g} vs {other:.3g} swapped")

    def plausible(cam):
        return (
            tilt_deg(cam.R) <= max_tilt_deg
            and focus_offset(cam.camera_center, cam.mirror) <= max_offset_mm
        )

    cam_g, cam_s = given["camera"], swapped["camera"]
    posture = None
    if use_posture and not plausible(cam_g) and plausible(cam_s):
        posture = (
            f"tilt {tilt_deg(cam_g.R):.1f} deg and offset "
            f"{focus_offset(cam_g.camera_center, mirror):.1f} as given, "
            f"{tilt_deg(cam_s.R):.1f} deg and "
            f"{focus_offset(cam_s.camera_center, cam_s.mirror):.1f} swapped"
        )
    swap = f"a = {mirror.b:g}, b = {mirror.a:g}"
    check = (
        "check the mirror parameters (a and b as in the paper's eq. 1, "
        "(X^2+Y^2)/a^2 - Z^2/b^2 = -1: the apex is at Z = b)"
    )
    if better:
        detail = "; ".join(better + ([f"posture {posture}"] if posture else []))
        return [
            PlausibilityWarning(
                "swapped_ab",
                f"the mirror fits clearly better with a and b swapped ({swap}): {detail}; {check}",
            )
        ]
    if posture:  # the rim alone cannot tell a swap from a wrong K or a wrong ellipse
        return [
            PlausibilityWarning(
                "swapped_ab",
                f"the posture would be plausible with a and b swapped ({swap}): "
                f"{posture}; {check}, K and the rim (the rim alone cannot tell which is wrong; "
                f"far lines can)",
            )
        ]
    return []


def cue_costs(report) -> dict[str, float]:
    """The costs of the cues besides the rim in a calibration report, for comparing mirrors:
    ``{"far-line score (eq. 31)": score of the chosen candidate, "outline RMS (px)": ...}``
    (NaN when the cue was not used)."""
    chosen = report.candidates[report.chosen]
    return {
        "far-line score (eq. 31)": float(getattr(chosen, "score", math.nan)),
        "outline RMS (px)": float(getattr(report, "lens_rms", math.nan)),
    }


def assess(
    report,
    image_size=None,
    recalibrate=None,
    *,
    max_tilt_deg=DEFAULT_MAX_TILT_DEG,
    max_offset_mm=DEFAULT_MAX_OFFSET_MM,
    max_residual_px=DEFAULT_MAX_RESIDUAL_PX,
    max_aspect_deviation=DEFAULT_MAX_ASPECT_DEVIATION,
) -> list[PlausibilityWarning]:
    """Every plausibility warning for a finished calibration (what ``calibrate`` runs).

    :func:`check_plausibility` on the report's camera and rim, with the residuals of the far
    lines and of the camera's reflection after refinement; then, when something is suspicious
    (an implausible posture, or cue residuals above about 1 px), the calibration is repeated
    with ``a`` and ``b`` swapped through ``recalibrate(mirror) -> (camera, report)`` and
    compared (:func:`swapped_mirror_warnings`). A good rig costs no second calibration. When
    the chosen posture is implausible but another physical candidate of Chen's method is
    within the limits, that is said instead (kind ``"choice"``), and no swap is suspected.

    Returns
    -------
    list of PlausibilityWarning
    """
    camera = report.camera
    refinement = getattr(report, "refinement", None)
    residuals = {
        "far lines": getattr(refinement, "line_rms", math.nan),
        "camera's reflection outline": getattr(report, "lens_rms", math.nan),
    }
    limits = {"max_tilt_deg": max_tilt_deg, "max_offset_mm": max_offset_mm}
    out = check_plausibility(
        camera,
        report.conic,
        image_size,
        residuals=residuals,
        max_residual_px=max_residual_px,
        max_aspect_deviation=max_aspect_deviation,
        **limits,
    )
    mirror = camera.mirror
    implausible_posture = any(w.kind in ("tilt", "offset") for w in out)
    others = []  # other physical candidates of Chen's method within the limits
    for i, cand in enumerate(getattr(report, "candidates", ())):
        if i == getattr(report, "chosen", None) or not getattr(cand, "physical", False):
            continue
        R = cv2.Rodrigues(np.asarray(cand.rvec, np.float64).reshape(3, 1))[0]
        tilt = tilt_deg(R)
        off = focus_offset(-R.T @ np.asarray(cand.tvec, np.float64), mirror)
        if tilt <= max_tilt_deg and off <= max_offset_mm:
            others.append(f"candidate {i}: tilt {tilt:.1f} deg, offset {off:.1f}")
    if implausible_posture and others:
        out.append(
            PlausibilityWarning(
                "choice",
                f"another physical posture is within the limits ({'; '.join(others)}): the choice "
                f"between the postures may be wrong; give far lines (--far-lines) or check the "
                f"camera's reflection in the overlay",
            )
        )
    if recalibrate is None or not isinstance(mirror, HyperbolicMirror) or mirror.a == mirror.b:
        return out  # a swap of a and b is a hyperboloid's mistake
    costs = cue_costs(report)
    f = 0.5 * (camera.K[0, 0] + camera.K[1, 1])
    # eq. 31's score is a mean squared sine between the rays and their plane: sqrt * f ~ px
    line_px = math.sqrt(max(costs["far-line score (eq. 31)"], 0.0)) * f
    # a wrong choice explains an implausible posture better than a swap
    suspicious = (
        (implausible_posture and not others)
        or (math.isfinite(line_px) and line_px > 1.0)
        or costs["outline RMS (px)"] > 1.0
    )
    if not suspicious:
        return out
    try:
        cam_s, rep_s = recalibrate(HyperbolicMirror(mirror.b, mirror.a, mirror.rim_radius))
        swapped = {"camera": cam_s, "costs": cue_costs(rep_s)}
    except (ValueError, RuntimeError, np.linalg.LinAlgError):
        swapped = None  # no posture with the swapped mirror: no evidence for it
    return out + swapped_mirror_warnings(
        mirror, {"camera": camera, "costs": costs}, swapped, use_posture=not others, **limits
    )
