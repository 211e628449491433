"""What one image tells of the mirror's shape: far lines that the model cannot make straight.

The rim alone cannot tell a paraboloid or a sphere from a hyperboloid: any of them images its
rim as an ellipse, and Chen's method (eqs. 24-29) fits every ellipse. Far lines can. Under the
right mirror the rays of a far line's pixels lie in one plane (eq. 31; exactly, a 3-D line,
:class:`~.refine.FarLineTerm`), so after the refinement the far lines' residual is at the level
of the pixels' own scatter. Under a wrong shape it is not: the lines come out bowed.

The pixels' scatter is measured on the image, with no model of the mirror: each line's pixels
about smooth curves through them (cubics in their chord length, piece by piece). The
image of a straight line is smooth under any mirror, so what that curve leaves is the clicks'
(or the edge detector's) noise, and a model residual well above it is the model's misfit.
"""

from __future__ import annotations

import math

import numpy as np

from ..mirror import HyperbolicMirror, describe_mirror

__all__ = ["BOWED_FACTOR", "BOWED_FLOOR_PX", "bowed_far_lines", "far_line_scatter"]

#: A far-line residual above this many times the pixels' own scatter is the model's misfit.
BOWED_FACTOR = 3.0
#: ... and above this many px (exact, noiseless pixels have no scatter to compare with).
BOWED_FLOOR_PX = 0.1
#: Pixels per piece of a line fitted by one cubic (a long line's image is a long arc).
PIECE = 12


def far_line_scatter(far_lines) -> float:
    """The far-line pixels' scatter about smooth curves through them, px (RMS, pooled).

    Parameters
    ----------
    far_lines : list of (N_i, 2) array_like
        Pixels along each far line, in their order along it.

    Returns
    -------
    float
        The RMS distance across the curve of the pixels from cubics in their chord length
        (what the far lines' residual measures), one a piece of
        ``PIECE`` consecutive pixels (a quadratic under 8), corrected for the degrees of freedom
        of the fits; NaN when no line has enough pixels (4 and more) to tell.
    """
    ssr, dof = 0.0, 0
    for line in far_lines:
        p = np.asarray(line, np.float64).reshape(-1, 2)
        p = p[np.isfinite(p).all(axis=1)]
        for piece in np.array_split(p, max(1, len(p) // PIECE)):
            r, d = _smooth_residuals(piece)
            ssr, dof = ssr + r, dof + d
    return math.sqrt(ssr / dof) if dof > 0 else math.nan


def _smooth_residuals(p):
    """``(sum of squares, degrees of freedom)`` of pixels about a polynomial in chord length
    (cubic; quadratic under 8 pixels; nothing under 4)."""
    deg = 3 if len(p) >= 8 else 2
    s = np.r_[0.0, np.cumsum(np.linalg.norm(np.diff(p, axis=0), axis=1))]
    if len(p) < deg + 2 or not s[-1] > 0:
        return 0.0, 0
    V = np.vander(2.0 * s / s[-1] - 1.0, deg + 1)
    coef, *_ = np.linalg.lstsq(V, p, rcond=None)
    # the chord length follows the pixels, so the residuals are across the curve: one
    # coordinate a pixel, less the cubic's coefficients
    return float(np.sum((p - V @ coef) ** 2)), len(p) - (deg + 1)


def bowed_far_lines(line_rms, far_lines, mirror) -> str | None:
    """The warning when the far lines do not come out straight under the model, else None.

    Parameters
    ----------
    line_rms : float
        The far lines' RMS residual after the refinement, px (``RefineResult.line_rms``).
    far_lines : list of (N_i, 2) array_like
        Their pixels (:func:`far_line_scatter`).
    mirror : HyperbolicMirror or AsphericMirror
        The mirror assumed, named in the message.

    Returns
    -------
    str or None
        What is wrong and what to check, when the residual is above ``BOWED_FACTOR`` times the
        pixels' scatter and above ``BOWED_FLOOR_PX``.
    """
    scatter = far_line_scatter(far_lines)
    if not (math.isfinite(line_rms) and math.isfinite(scatter)):
        return None
    if line_rms <= max(BOWED_FACTOR * scatter, BOWED_FLOOR_PX):
        return None
    return (
        f"the far lines do not come out straight: {line_rms:.2f} px RMS after refinement "
        f"against {scatter:.2f} px of their pixels' own scatter; the mirror may not be the "
        + (
            f"hyperboloid a {mirror.a:g}, b {mirror.b:g} given (a paraboloid, a sphere, or "
            f"other a and b)"
            if isinstance(mirror, HyperbolicMirror)
            else f"{describe_mirror(mirror)} given (another profile)"
        )
        + ", or a line is not straight or not far, or K and D are off"
    )
