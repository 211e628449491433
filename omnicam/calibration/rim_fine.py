"""Steps 2-3 of :func:`~.rim.detect_rim`: from a coarse ellipse to the rim at full resolution.

Subpixel intensity steps along the normals of the current ellipse, fitted by
:func:`~.rim_fit.fit_rim` in rounds of shrinking windows, then the check that makes a boundary a
rim: found along enough of its in-frame length and fitting tightly (:class:`RimRejected` when
not).
"""

from __future__ import annotations

import cv2
import numpy as np

from .edges import edge_points_along_normals
from .ellipse import hartley_normalization
from .errors import EstimationError
from .rim_coarse import HINT_CENTER, HINT_RADIUS
from .rim_fit import fit_rim, fit_with_mask
from .robust import mad_sigma

__all__ = ["MIN_SUPPORT", "RimRejected", "fit_from_coarse", "rms_limit"]

MIN_SUPPORT = 0.3  # a rim is found along at least 30 % of its in-frame length


def rms_limit(fit) -> float:
    """The largest RMS (px) of a rim's edge points about its ellipse: 1.5 px or 0.5 % of its
    major semi-axis, whichever is larger (step 3 of :func:`~.rim.detect_rim`)."""
    return max(1.5, 0.005 * float(fit.axes[0]))


class RimRejected(EstimationError):
    """No rim found: the best elliptic boundary in the image is too short or too rough to be one.

    Raised by :func:`~.rim.detect_rim` (an :class:`~.errors.EstimationError`, so a
    ``ValueError``); the message says what was found and what a rim needs.

    Attributes
    ----------
    fit : RimFit
        The boundary found.
    support : float
        The fraction of its in-frame length along which it was found.
    """

    def __init__(self, message, fit, support):
        super().__init__(message)
        self.fit, self.support = fit, float(support)


def fit_from_coarse(gray, coarses, hint, sigma, threshold, rng, prior=None):
    """Steps 2-3 of :func:`~.rim.detect_rim` from the coarse ellipses.

    Unguided (``prior`` None) the first that passes is returned. Guided (a hint or an
    expected size; ``prior`` weights a size), when the steps of an ellipse's polarity do not
    make a rim, steps of either sign are tried (a rim whose contrast with a grey or metal
    holder changes sign along it), and unless a rim is found along >= 90 % of its in-frame
    length every coarse ellipse is followed and the fit with the largest ``support * prior``
    wins (a coarse ellipse that mixes the rim and the holder's edge converges to one of them
    or to a poorly supported compromise)."""
    error, best = None, None
    for coarse in coarses:
        for absolute in (
            (True,) if coarse.polarity == 0 else ((False, True) if prior is not None else (False,))
        ):
            try:
                fit, support = _fit_from_one(gray, coarse, hint, sigma, threshold, rng, absolute)
            except ValueError as err:
                error = error or err
                continue
            if prior is None:
                return fit
            score = support * prior(fit.axes)
            if best is None or score > best[0]:
                best = (score, fit)
            if support >= 0.9:
                return best[1]
            break
    if best is None:
        raise error
    return best[1]


def _fit_from_one(gray, coarse, hint, sigma, threshold, rng, absolute=False):
    """Steps 2-3 of :func:`~.rim.detect_rim` from one coarse ellipse."""
    center, S, coarse_px, polarity = coarse[:4]
    G = cv2.GaussianBlur(gray, (0, 0), float(sigma)) if sigma > 0 else gray
    if polarity < 0 and not absolute:  # a mirror darker than its holder: rises as drops
        G = 1.0 - G
    cw = 3.0 * max(sigma, 0.5)  # half-width of the centroid window
    fit = None
    for i in range(3):
        # search window: the coarse ellipse's uncertainty, then the spread of the last fit
        hw = max(6.0, 3.0 * coarse_px) if i == 0 else cw + max(1.5, 3.0 * fit.rms)
        pts, n_tried = edge_points_along_normals(
            G,
            center,
            S,
            hw,
            outermost=(i == 0 and coarse.outermost),
            centroid=0.0 if i == 0 else cw,
            absolute=absolute,
        )
        if len(pts) < 6:
            raise ValueError(
                "no ellipse found: the rim is not visible along enough of its length "
                "(too much of it outside the image?)"
            )
        try:
            if fit is None:
                fit = fit_rim(pts, threshold=threshold, rng=rng)
            else:  # seeded by the previous ellipse instead of RANSAC
                d = np.abs(fit.distance(pts))
                # the points are now precise: a tighter floor for the cut (0.5 px) drops
                # partial edges, e.g. where a holder arm meets the rim
                cut_floor = min(threshold, 0.5)
                mask = d <= max(cut_floor, 3.5 * mad_sigma(d))
                if mask.sum() < 6:
                    raise ValueError("too few edge points near the rim found in the last round")
                fit = fit_with_mask(pts, hartley_normalization(pts), mask, True, cut_floor)
        except ValueError as err:
            raise ValueError(f"no ellipse found in the image: {err}") from None
        center, S = fit.center, fit.shape_matrix
    # a rim is a long, clean ellipse: most normals in the frame find it, and it fits tightly
    support = fit.inliers.sum() / max(n_tried, 1)
    if support < MIN_SUPPORT or fit.rms > rms_limit(fit):
        raise RimRejected(
            f"no ellipse found: the best elliptic boundary is supported along "
            f"{100 * support:.0f} % of its visible length with {fit.rms:.2f} px RMS "
            f"(a rim needs >= 30 % and <= {rms_limit(fit):.2f} px); is "
            f"the whole mirror in view, differing from its holder and in focus?",
            fit,
            support,
        )
    if hint is not None:
        off = float(np.linalg.norm(fit.center - hint[:2]))
        if (
            off > (HINT_CENTER + 0.02) * hint[2]
            or not (1.0 - HINT_RADIUS - 0.02) * hint[2] <= fit.axes[1]
            or not fit.axes[0] <= (1.0 + HINT_RADIUS + 0.02) * hint[2]
        ):
            raise ValueError(
                f"no ellipse found near the hint {hint}: the nearest rim found has "
                f"centre ({fit.center[0]:.1f}, {fit.center[1]:.1f}) and semi-axes "
                f"{fit.axes[0]:.1f}, {fit.axes[1]:.1f} px; check the hint"
            )
    return fit, support
