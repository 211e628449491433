"""The rim ellipse fitted to boundary points: :class:`RimFit` and :func:`fit_rim` (eqs. 20-22).

The rim of the mirror is a circle; the camera sees it as the conic

    a x^2 + b y^2 + 2 f x + 2 g y + 2 h x y + c = 0                (eq. 20)
    x~^T Q_I x~ = 0,  x~ = (x, y, 1)^T                               (eq. 21)
    Q_I = [[a, h, f], [h, b, g], [f, g, c]]                          (eq. 22)

in pixel coordinates (centres at integers, distorted pixels as the camera sees them). Chen's
method (eqs. 23-42) starts from ``Q_I``, so its accuracy is that of this fit: an algebraic fit is
biased, so :func:`fit_rim` starts with a normalised direct ellipse fit and then minimises the
*orthogonal* (geometric) distances of the points to the ellipse.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from .._typing import ArrayLike, FloatArray
from ..raytrace import as_points
from .ellipse import (
    axes_angle,
    conic_from_ellipse,
    direct_ellipse,
    ellipse_from_conic,
    hartley_normalization,
    is_ellipse,
    orthogonal_residuals,
    ransac_conic,
    refine_geometric,
)
from .robust import mad_sigma

__all__ = ["RimFit", "fit_rim", "fit_with_mask"]


@dataclasses.dataclass(frozen=True, eq=False)
class RimFit:
    """An ellipse fitted to the mirror rim in the image.

    The ellipse is ``x(t) = center + S (cos t, sin t)^T`` with ``S`` symmetric positive definite;
    equivalently ``x~^T Q_I x~ = 0`` (eqs. 20-22).

    Attributes
    ----------
    conic : (3, 3) float64 ndarray
        ``Q_I`` of eq. 22 in pixel coordinates: symmetric, unit Frobenius norm, sign fixed so that
        ``x~^T Q_I x~ < 0`` inside the ellipse (so ``Q_I[:2, :2]`` is positive definite and
        ``Q_I`` has exactly one negative eigenvalue).
    points : (N, 2) float64 ndarray
        The boundary points used for the final fit (the inliers).
    rms : float
        Root mean square orthogonal (geometric) distance of ``points`` to the ellipse, px.
    center : (2,) float64 ndarray
        Centre of the ellipse, px.
    axes : (2,) float64 ndarray
        Semi-axes ``(major, minor)``, px.
    angle : float
        Direction of the major axis, radians from +x towards +y (image y points down), in
        ``[0, pi)``.
    inliers : (M,) bool ndarray
        Which of the input points (of :func:`fit_rim`; the edge points for :func:`~.rim.detect_rim`)
        were used.
    """

    conic: np.ndarray
    points: np.ndarray
    rms: float
    center: np.ndarray
    axes: np.ndarray
    angle: float
    inliers: np.ndarray

    def __post_init__(self):
        for name in ("conic", "points", "center", "axes", "inliers"):
            arr = np.array(getattr(self, name))
            arr.flags.writeable = False
            object.__setattr__(self, name, arr)

    def __repr__(self) -> str:
        return (
            f"RimFit(center=({self.center[0]:.3f}, {self.center[1]:.3f}), "
            f"axes=({self.axes[0]:.3f}, {self.axes[1]:.3f}), "
            f"angle={math.degrees(self.angle):.2f} deg, rms={self.rms:.4f} px, "
            f"points={len(self.points)} of {len(self.inliers)})"
        )

    @property
    def shape_matrix(self) -> FloatArray:
        """(2, 2) symmetric positive definite ``S`` of ``x(t) = center + S (cos t, sin t)``."""
        c, s = math.cos(self.angle), math.sin(self.angle)
        R = np.array([[c, -s], [s, c]])
        return R @ np.diag(self.axes) @ R.T

    @property
    def diameter(self) -> float:
        """Mean diameter ``axes[0] + axes[1]``, px."""
        return float(self.axes[0] + self.axes[1])

    def distance(self, points) -> FloatArray:
        """Signed orthogonal distance of points to the ellipse (positive outside), px.

        Parameters
        ----------
        points : (N, 2) or (N, 1, 2) array_like

        Returns
        -------
        (N,) float64 ndarray
        """
        pts = np.asarray(points, dtype=np.float64).reshape(-1, 2)
        d, _, _ = orthogonal_residuals(pts, self.center, self.shape_matrix)
        return d

    def sample(self, n=360) -> FloatArray:
        """``n`` points evenly spaced in the ellipse parameter, ``(n, 2)`` float64 (for drawing)."""
        t = np.linspace(0.0, 2.0 * np.pi, int(n), endpoint=False)
        return self.center + np.stack([np.cos(t), np.sin(t)], axis=1) @ self.shape_matrix.T


def _as_points(points, min_points):
    pts, _ = as_points(points, "points", 2)
    if not np.isfinite(pts).all():
        raise ValueError("points must be finite; drop NaN/inf rows before fitting the rim")
    if len(pts) < min_points:
        raise ValueError(
            f"need at least {min_points} boundary points to fit the rim ellipse, "
            f"got {len(pts)}; give more points spread along the rim"
        )
    return pts


def fit_rim(
    points: ArrayLike, robust: bool = True, threshold: float = 2.0, max_trials: int = 2000, rng=0
) -> RimFit:
    """Fit the rim ellipse ``Q_I`` (eqs. 20-22) to boundary points, robustly and geometrically.

    1. Hartley normalisation (centroid to 0, mean distance sqrt(2)).
    2. With ``robust``: RANSAC over 5-point conics, inliers by Sampson distance < ``threshold``.
    3. Fitzgibbon's direct ellipse fit (Halir-Flusser form) on the (inlier) points.
    4. Levenberg-Marquardt on the orthogonal point-to-ellipse distances.
    5. With ``robust``: points are re-classified with the cut ``max(threshold, 3.5 sigma)``,
       ``sigma = 1.4826 MAD`` of the residuals, and the fit is repeated until the set is stable.

    Parameters
    ----------
    points : (N, 2) or (N, 1, 2) array_like
        Boundary points in pixels (distorted, as seen). At least 5 (6 with ``robust``).
    robust : bool
        Reject outliers (RANSAC, then a robust scale cut). Without it every point is used.
    threshold : float
        Minimum inlier cut, px (the cut grows with the noise level of the consensus set).
    max_trials : int
        Cap on RANSAC hypotheses.
    rng : int or numpy.random.Generator
        Seed or generator for RANSAC (deterministic by default).

    Returns
    -------
    RimFit

    Raises
    ------
    ValueError
        Too few or non-finite points, or no ellipse fits them (collinear points, a hyperbola, ...).
    """
    pts = _as_points(points, 6 if robust else 5)
    if not (np.isfinite(threshold) and threshold > 0):
        raise ValueError(f"threshold must be a positive number of pixels, got {threshold!r}")
    if robust and not (int(max_trials) == max_trials and max_trials >= 1):
        raise ValueError(f"max_trials must be a positive integer, got {max_trials!r}")
    N = hartley_normalization(pts)
    s = N[0, 0]
    pts_n = pts * s + N[:2, 2]
    mask = np.ones(len(pts), bool)
    if robust:
        rng = rng if isinstance(rng, np.random.Generator) else np.random.default_rng(rng)
        m = ransac_conic(pts_n, threshold * s, rng, int(max_trials))
        if m is None or m.sum() < 5:
            raise ValueError(
                "no ellipse found among the boundary points; give points along the "
                "rim (at least 5 on a common ellipse)"
            )
        mask = m
    return fit_with_mask(pts, N, mask, robust, threshold)


def fit_with_mask(pts, N, mask, robust, threshold):
    """Steps 3-5 of :func:`fit_rim` from an initial inlier ``mask``; ``N`` normalises ``pts``."""
    pts_n = pts * N[0, 0] + N[:2, 2]
    Qn = direct_ellipse(pts_n[mask])
    if Qn is None or not is_ellipse(Qn):
        raise ValueError(
            "the boundary points do not determine an ellipse (collinear, too few or "
            "a non-elliptic curve); give points spread along the rim"
        )
    Q = N.T @ Qn @ N  # back to pixels
    center, S = ellipse_from_conic(Q)
    for _ in range(10):
        center, S, _ = refine_geometric(pts[mask], center, S)
        if not robust:
            break
        d, _, _ = orthogonal_residuals(pts, center, S, iters=6)  # to classify
        ad = np.abs(d)
        sigma = mad_sigma(ad[mask])
        new = ad <= max(threshold, 3.5 * sigma)
        if new.sum() < 5:
            raise ValueError(
                "no ellipse found among the boundary points; give points along the "
                "rim (at least 5 on a common ellipse)"
            )
        if np.array_equal(new, mask):
            break
        mask = new
    if not (np.isfinite(S).all() and np.linalg.det(S) > 0):
        raise ValueError("the fitted rim is not an ellipse; give points spread along the rim")
    used = pts[mask]
    axes, angle = axes_angle(S)
    extent = float(np.ptp(used, axis=0).max())
    if not (axes[1] > 1e-3 * axes[0] and axes[0] < 20.0 * extent):
        raise ValueError(
            f"the boundary points fit only a degenerate ellipse (semi-axes "
            f"{axes[0]:.3g} and {axes[1]:.3g} px for points spanning {extent:.3g} px: "
            f"collinear or nearly flat); give points spread along the rim"
        )
    d, _, _ = orthogonal_residuals(used, center, S)
    return RimFit(
        conic=conic_from_ellipse(center, S),
        points=used,
        rms=float(np.sqrt(np.mean(d * d))),
        center=center,
        axes=axes,
        angle=angle,
        inliers=mask,
    )
