"""The mirror boundary (rim) in the image: a robust, geometrically accurate ellipse (eqs. 20-22).

The rim of the mirror is a circle; the camera sees it as the conic

    a x^2 + b y^2 + 2 f x + 2 g y + 2 h x y + c = 0                (eq. 20)
    x~^T Q_I x~ = 0,  x~ = (x, y, 1)^T                               (eq. 21)
    Q_I = [[a, h, f], [h, b, g], [f, g, c]]                          (eq. 22)

in pixel coordinates (centres at integers, distorted pixels as the camera sees them). Chen's
method (eqs. 23-42) starts from ``Q_I``, so its accuracy is that of this fit: an algebraic fit is
biased, so :func:`fit_rim` starts with a normalised direct ellipse fit and then minimises the
*orthogonal* (geometric) distances of the points to the ellipse.

:func:`fit_rim` fits given boundary points (RANSAC against outliers, then geometric refinement;
:mod:`.rim_fit`); :func:`detect_rim` finds the boundary in an image automatically: roughly on a
small copy (:mod:`.rim_coarse`), then at full resolution with the check that makes a boundary a
rim (:mod:`.rim_fine`), and with an expected size, its policy (:mod:`.rim_expected`).
"""

from __future__ import annotations

import math

import numpy as np

from .._validate import real_number, refuse_complex, validate_rng
from ..images import aspect_note, to_gray
from .ellipse import conic_distance, conic_from_ellipse, ellipse_from_conic
from .rim_coarse import coarse_edges, coarse_ellipse, size_prior
from .rim_expected import check_expected, detect_expected
from .rim_fine import RimRejected, fit_from_coarse
from .rim_fit import RimFit, fit_rim

__all__ = [
    "RimFit",
    "RimRejected",
    "check_hint",
    "conic_distance",
    "conic_from_ellipse",
    "detect_rim",
    "ellipse_from_conic",
    "fit_rim",
]


def detect_rim(
    image: np.ndarray,
    *,
    hint: tuple[float, float, float] | None = None,
    expected: float | tuple[float, float] | None = None,
    sigma: float = 0.7,
    threshold: float = 2.0,
    rng=0,
) -> RimFit:
    """Find the mirror rim (where the mirror's reflection meets its holder) in an image.

    1. Coarse, on a copy 256 px wide (:func:`~.rim_coarse.coarse_ellipse`): Canny edge pixels
       vote along their gradient for the centre of a circle whose inside is brighter; radii
       are ranked by the arc length they gather, the best circles are refined to ellipses and
       the longest arc wins. The camera's dark reflection in the middle has the opposite
       polarity, and a long clipped rim beats a small complete circle (lens rings, horizon circles).
       With a ``hint`` or an ``expected`` size the search also takes mirrors darker than their
       holder (a white holder ring) and rims whose contrast changes sign along them (a grey
       or metal holder), keeps to the sizes asked for, and weights each arc by how well its
       size fits; the holder's outer edge then loses to the rim. The best three ellipses are
       tried in turn in step 2.
    2. Fine, at full resolution: along the normals of the current ellipse, the strongest
       intensity step of the chosen polarity (guided: of either sign, when one polarity does
       not make a rim) in the image smoothed by ``sigma`` is located to
       subpixel precision (profiles leaving the image are dropped, so a clipped rim gives an
       arc), and :func:`fit_rim` (RANSAC, then orthogonal-distance refinement) fits ``Q_I``
       (eqs. 20-22). Three rounds with shrinking search windows; the first takes the
       outermost strong step of each profile (the mirror's edge rather than scene edges inside).
    3. Check: the ellipse must be found along at least 30 % of its in-frame length and fit its
       points to ``max(1.5 px, 0.5 % of the major semi-axis)`` RMS, otherwise
       :class:`RimRejected` (a ``ValueError``);
       with a ``hint`` it must also lie within the hinted ranges.
    4. With an ``expected`` size, when the ellipse taken is not of that size (its mean radius
       outside the range, up to 1.5x off: a white holder's outer edge) or none passes step 3 (a
       rough first fit in clutter), the search goes on to the boundaries concentric with it, inside
       and outside: circles of the expected size about its centre, ranked by the share of their
       length on which an intensity step lies (:func:`~.rim_expected._rings`), each followed by
       steps 2-3 from the strongest step of either sign. Only when none of them passes is the
       ellipse of another size taken, or the ``ValueError`` raised; its message then names what was
       found (diameter, centre, RMS and support of the best boundary) and what was expected (the
       range of semi-axes and diameters, px).

    Without ``hint`` or ``expected`` it assumes the mirror is brighter than its housing along
    most of the rim (a black holder) and a rim at least ~8 % of the image's longer side in
    radius. :func:`omnicam.calibration.calibrate` passes ``expected`` from ``K`` and the mirror.

    Parameters
    ----------
    image : (H, W) or (H, W, 3|4) ndarray, uint8, uint16 or float
        Grey or BGR(A) catadioptric image.
    hint : (cx, cy, r) tuple of float, optional
        A rough circle on the rim (px; pixel centres at integers): only ellipses whose centre is
        within ``0.15 r`` of ``(cx, cy)`` and whose radii are within ``r (1 -+ 0.15)`` are
        considered. The centre must be inside the image, ``r`` positive and at most the image
        diagonal.
    expected : float or (r_min, r_max), optional
        The rim's expected radius in px (a number: ``+-15 %``), or the range of its semi-axes,
        e.g. from ``K`` and the mirror with
        :func:`omnicam.calibration.plausibility.expected_rim` (``.radius_range``). The rim of
        that size is taken unless the unguided search (step 1) finds an ellipse of another
        size with more than twice its arc length and no boundary of the expected size lies
        next to it (step 4), as with a ``K`` for another resolution
        (:func:`.plausibility.check_plausibility` then reports the size mismatch). Ignored
        with a ``hint``.
    sigma : float
        Gaussian smoothing before locating the edge, px.
    threshold : float
        Minimum inlier cut of the robust fit, px (see :func:`fit_rim`).
    rng : int or numpy.random.Generator
        Seed of the RANSAC sampling (the result is deterministic by default).

    Returns
    -------
    RimFit
        ``points`` are the subpixel edge points used; ``inliers`` flags them among all the edge
        points found in the last round.

    Raises
    ------
    ValueError
        Not an image, a bad ``hint`` or ``expected``, or no elliptic rim found (near the hint;
        with ``expected``, the message names the best boundary found and the size expected;
        in an image too wide or too tall for a camera's frame of a mirror, it says so:
        :func:`omnicam.images.aspect_note`, as ``omnicam calibrate`` does).
    RimRejected
        (a ``ValueError``) The best elliptic boundary is too short or too rough to be a rim; its
        ``fit`` and ``support`` say what was found.
    """
    # arguments first (ValueError naming them); sigma bounded so the blur cannot run for hours
    sigma = real_number(sigma, "sigma", 0.0, 25.0, expected="a number of pixels in [0, 25]")
    threshold = real_number(
        threshold, "threshold", 0.0, 1e4, lo_open=True, expected="a positive number of pixels"
    )
    rng = validate_rng(rng)
    gray = to_gray(image, "range")
    if min(gray.shape) < 32:
        raise ValueError(
            f"image is too small to hold a mirror rim: {gray.shape[1]}x{gray.shape[0]} px "
            f"(need at least 32x32)"
        )
    if not gray.max() > 0:
        raise ValueError(
            "no ellipse found: the image is uniform (no mirror rim visible)"
            + aspect_note((gray.shape[1], gray.shape[0]))
        )
    if sigma > max(1.0, min(gray.shape) / 8):
        raise ValueError(
            f"sigma must be at most 1/8 of the image's shorter side "
            f"({max(1.0, min(gray.shape) / 8):g} px), got {sigma!r}"
        )
    hint = check_hint(hint, (gray.shape[1], gray.shape[0]))
    expected = check_expected(expected)
    try:
        edges = coarse_edges(gray)
        if hint is not None:
            return fit_from_coarse(
                gray,
                coarse_ellipse(edges, hint, None),
                hint,
                sigma,
                threshold,
                rng,
                size_prior(hint, None),
            )
        if expected is None:
            return fit_from_coarse(gray, coarse_ellipse(edges), None, sigma, threshold, rng)
        return detect_expected(gray, edges, expected, sigma, threshold, rng)
    except RimRejected:
        raise  # a boundary was found and judged: its message says why, whatever the frame
    except ValueError as e:  # no rim: an 8:1 strip is no camera's frame of a mirror, say so
        note = aspect_note((gray.shape[1], gray.shape[0]))
        if not note:
            raise
        raise ValueError(f"{e}{note}") from None


def check_hint(hint, image_size) -> tuple[float, float, float] | None:
    """``hint`` as a ``(cx, cy, r)`` tuple of floats, or ``None``; ``ValueError`` naming it."""
    if hint is None:
        return None
    refuse_complex(hint, "hint", "(cx, cy, r): the rim's rough centre and radius in px")
    try:
        cx, cy, r = (float(v) for v in np.asarray(hint, dtype=np.float64).reshape(-1))
    except (TypeError, ValueError):
        raise ValueError(
            f"hint must be (cx, cy, r): the rim's rough centre and radius in px, got {hint!r}"
        ) from None
    w, h = image_size
    if not (math.isfinite(cx) and math.isfinite(cy) and math.isfinite(r)):
        raise ValueError(f"hint must be finite (cx, cy, r) in px, got {hint!r}")
    if not r > 0:
        raise ValueError(f"hint radius must be positive, got r = {r!r}")
    if not (-0.5 <= cx <= w - 0.5 and -0.5 <= cy <= h - 0.5):
        raise ValueError(
            f"hint centre ({cx:g}, {cy:g}) is outside the {w}x{h} image; give the "
            f"rim's centre in image pixels"
        )
    if r > math.hypot(w, h):
        raise ValueError(
            f"hint radius {r:g} px is larger than the image diagonal "
            f"({math.hypot(w, h):.0f} px); give the rim's radius in image pixels"
        )
    return cx, cy, r
