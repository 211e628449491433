"""The camera's-reflection cue of :func:`omnicam.calibration.calibrate` (step 3):
:func:`reflection_step` -> :class:`ReflectionCue`, the outline of the camera's own reflection
given, or detected (:mod:`.reflection`) around the candidates' self-reflection pixels."""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from ..raytrace import normalize
from .errors import EstimationError
from .inputs import as_pixels
from .reflection import detect_reflection, fit_circle, self_reflection_pixel

__all__ = ["CORELESS_MAX_RMS", "ReflectionCue", "reflection_step"]


# -- 2. the camera's reflection ----------------------------------------------------------------
@dataclasses.dataclass(frozen=True, eq=False)
class ReflectionCue:
    """The outline of the camera's reflection, if any (:mod:`.reflection`).

    Attributes
    ----------
    points : (M, 2) ndarray or None
        Outline pixels as seen (None: not used).
    normalized : (M, 2) ndarray or None
        Their undistorted normalised coordinates.
    fit : ReflectionFit or None
        The detection (``lens="auto"``).
    sigma : float
        The measurement's own scatter, px (the detection's RMS to its ellipse; NaN for given
        points).
    r, z : float or None
        Known radius and axial distance of the circle (None: fitted).
    note : str
        Whether it is used, and why not.
    """

    points: object
    normalized: object
    fit: object
    sigma: float
    r: object
    z: object
    note: str

    @property
    def used(self):
        """Whether the camera's reflection was found and is used."""
        return self.points is not None


def reflection_step(lens, image, rim, K, D, r=None, z=None, cands=None, mirror=None):
    """Detect or take the outline of the camera's reflection; see :class:`ReflectionCue`.

    With ``cands`` (and ``mirror``) the detection looks around the physical candidates' self-
    reflection pixels (their mean, within their spread plus 8 % of the rim's semi-axis): a
    tilted mirror moves the camera's reflection well away from the rim centre; then around the
    rim centre (:func:`_detect_outline`).

    ``lens`` is ``"auto"`` (detect in ``image``), ``None``/``False`` (not used) or an
    ``(M, 2)`` array of outline pixels.
    """
    for name, v in (("lens_r", r), ("lens_z", z)):
        if v is not None and not (np.isfinite(v) and (name == "lens_z" or v > 0)):
            raise ValueError(f"{name} must be a finite number (lens_r > 0) or None, got {v!r}")
    fit, px, sigma = None, None, math.nan
    if isinstance(lens, str):
        if lens != "auto":
            raise ValueError(
                f"lens must be 'auto', None, False or an (M, 2) array of outline pixels, "
                f"got {lens!r}"
            )
        if image is None:
            return ReflectionCue(
                None,
                None,
                None,
                sigma,
                r,
                z,
                "not used: no image (give lens=outline pixels to use it)",
            )
        try:
            where = {}
            if cands is not None and mirror is not None and cands.physical:
                u = np.array(
                    [
                        self_reflection_pixel(mirror, cands.all[i].R, cands.all[i].tvec, K, D)
                        for i in cands.physical
                    ]
                )
                if np.isfinite(u).all():
                    c = u.mean(axis=0)
                    spread = float(np.linalg.norm(u - c, axis=1).max()) / float(min(rim.axes))
                    where = {"center": c, "center_search": min(0.5, 0.08 + spread)}
            fit, px, xn, why = _detect_outline(image, rim, where, cands, K, D, mirror, r, z)
        except EstimationError as err:  # optional: the report says why it was not used
            return ReflectionCue(None, None, None, sigma, r, z, f"not used: {err}")
        if why is not None:
            return ReflectionCue(None, None, None, sigma, r, z, f"not used: {why}")
        sigma = float(fit.rms)
    elif lens is None or lens is False:
        return ReflectionCue(None, None, None, sigma, r, z, "not used (lens=None)")
    else:
        px = as_pixels(lens, "lens")
        if len(px) < 8 or not np.isfinite(px).all():
            raise ValueError(
                f"lens has {len(px)} point(s) or non-finite values; give at least 8 finite "
                f"pixels along the outline of the camera's reflection"
            )
        xn = _outline_normalized(px, K, D)
    note = f"used: {len(px)} outline points"
    if fit is not None and not fit.core:
        note += " (uniformly dark: a posture explains it as the camera's circle)"
    return ReflectionCue(px, xn, fit, sigma, r, z, note)


def _outline_normalized(px, K, D):
    """Undistorted normalised coordinates of outline pixels; ValueError if D cannot undistort
    some of them."""
    xn = normalize(px, K, D)
    if not np.isfinite(xn).all():
        raise ValueError("some lens outline points cannot be undistorted with D; check D")
    return xn


def _detect_outline(image, rim, where, cands, K, D, mirror, r, z):
    """The camera's reflection detected around ``where`` (the postures' predicted self-reflection
    pixel), else around the rim centre: a K or D a little off moves the predictions but not the
    reflection, which stays near the rim centre for the misalignments of real rigs (a photograph
    whose principal point was taken at the image centre, far off). A silhouette without a
    darker core counts only if :func:`_coreless_why` accepts it; one it rejects near the
    predictions (an inner ring of the glass) also leads to the rim centre's search.

    Returns ``(fit, px, xn, why)``: ``why`` (not ``None``) says why the only silhouette found
    was not taken. Raises :class:`EstimationError` when nothing is found.
    """
    rejected, failure = None, None
    for search in (where, {}) if where else ({},):
        try:
            fit = detect_reflection(image, rim, allow_coreless=True, **search)
        except EstimationError as err:
            failure = failure or err
            continue
        px = np.asarray(fit.points, np.float64)
        xn = _outline_normalized(px, K, D)
        why = None if fit.core else _coreless_why(fit, xn, cands, K, mirror, r, z)
        if why is None:
            return fit, px, xn, None
        rejected = rejected or why
    if rejected is not None:
        return None, None, None, rejected
    raise failure


#: A silhouette without a darker core (uniformly dark glass, or a dark floor) is taken for the
#: camera only if some physical posture explains it as a coaxial circle to within this many px
#: (or 3x its own scatter). A floor's edge is a cone of directions, not a circle at a finite
#: distance, and misfits by far more than a dark lens does (docs/CHANGELOG.md has the figures
#: of the renders that set it).
CORELESS_MAX_RMS = 0.5


def _coreless_why(fit, xn, cands, K, mirror, r, z):
    """Why a silhouette without a darker core is not the camera's, or None if it may be."""
    if cands is None or mirror is None or not cands.physical:
        return "the silhouette has no darker core and no posture to test it against"
    Kinv2 = np.linalg.inv(K)[:2, :2]
    best = min(
        fit_circle(mirror, cands.all[i].R, cands.all[i].tvec, xn, Kinv2, r=r, z=z).rms
        for i in cands.physical
    )
    limit = max(CORELESS_MAX_RMS, 3.0 * fit.rms)
    if best <= limit:
        return None
    return (
        f"no camera reflection found: the round dark silhouette (radius {fit.radius:.1f} px) "
        f"has no darker core and no posture explains it as the camera's circle (best RMS "
        f"{best:.2f} px, allowed {limit:.2f}): a dark floor or clutter"
    )
