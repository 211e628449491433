"""The mirror boundary (rim) in the image: a robust, geometrically accurate ellipse (eqs. 20-22).

The rim of the mirror is a circle; the camera sees it as the conic

    a x^2 + b y^2 + 2 f x + 2 g y + 2 h x y + c = 0                (eq. 20)
    x~^T Q_I x~ = 0,  x~ = (x, y, 1)^T                               (eq. 21)
    Q_I = [[a, h, f], [h, b, g], [f, g, c]]                          (eq. 22)

in pixel coordinates (centres at integers, distorted pixels as the camera sees them). Chen's
method (eqs. 23-42) starts from ``Q_I``, so its accuracy is that of this fit: an algebraic fit is
biased, so :func:`fit_rim` starts with a normalised direct ellipse fit and then minimises the
*orthogonal* (geometric) distances of the points to the ellipse.

:func:`fit_rim` fits given boundary points (RANSAC against outliers, then geometric refinement);
:func:`detect_rim` finds the boundary in an image automatically.
"""

from __future__ import annotations

import dataclasses
import math
import typing

import cv2
import numpy as np

from .._typing import ArrayLike, FloatArray
from .._validate import real_number, refuse_complex, validate_rng
from ..images import aspect_note, to_gray
from ..raytrace import as_points
from .edges import edge_points_along_normals
from .ellipse import (
    axes_angle,
    conic_distance,
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

__all__ = [
    "RimFit",
    "check_hint",
    "conic_distance",
    "conic_from_ellipse",
    "detect_rim",
    "ellipse_from_conic",
    "fit_rim",
]


_COARSE_SIZE = 256  # longer side of the image used to find the rim roughly
_HINT_RADIUS = 0.15  # a hinted rim's radius is within +-15 % of the hint's
_HINT_CENTER = 0.15  # and its centre within 15 % of the hint's radius of the hint's centre
_EXPECTED_SCORE = 0.5  # else a rim of the expected size needs half the arc of one of any size
_N_TRIES = 3  # coarse ellipses tried at full resolution, best first
_NEXT_RATIO = 1.5  # a boundary up to 1.5x outside the expected sizes: the rim is next to it
_RING_SHIFT = 0.08  # rings about a boundary found: centres within 8 % of the expected radius
_RING_STEPS = 10  # and the strongest 10 steps along each ray vote
_RING_RMS = 0.5  # a rim found so fits within half the RMS that step 3 of detect_rim allows


_MIN_SUPPORT = 0.3  # a rim is found along at least 30 % of its in-frame length


def _rms_limit(fit) -> float:
    """The largest RMS (px) of a rim's edge points about its ellipse: 1.5 px or 0.5 % of its
    major semi-axis, whichever is larger (step 3 of :func:`detect_rim`)."""
    return max(1.5, 0.005 * float(fit.axes[0]))


class _Rejected(ValueError):
    """An elliptic boundary that is not a rim (too short or too rough): ``fit`` and ``support``
    (the fraction of its in-frame length found) say what was found."""

    def __init__(self, message, fit, support):
        super().__init__(message)
        self.fit, self.support = fit, float(support)


class _Ring(typing.NamedTuple):
    center: np.ndarray
    px_radius: float
    share: float


class _Coarse(typing.NamedTuple):
    center: np.ndarray
    S: np.ndarray
    px: float
    polarity: float
    score: float
    support: float
    outermost: bool = True  # the first fine round takes each normal's outermost strong step


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
        Which of the input points (of :func:`fit_rim`; the edge points for :func:`detect_rim`)
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
    return _fit_with_mask(pts, N, mask, robust, threshold)


def _fit_with_mask(pts, N, mask, robust, threshold):
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


def _coarse_edges(gray):
    """Edge pixels of a copy whose longer side is ``_COARSE_SIZE`` px (its shorter side at least
    3/4 of that), for :func:`_coarse_ellipse`:
    ``(p, g, (H, W), (sx, sy))``: pixels, unit gradients, the copy's shape and its scale per
    axis."""
    h, w = gray.shape
    # the longer side to _COARSE_SIZE, but the shorter (where a clipped rim spans the frame) to
    # at least 3/4 of it: a 16:9 frame otherwise shrinks its rim more than a 4:3 one
    s = min(1.0, max(_COARSE_SIZE / max(h, w), 0.75 * _COARSE_SIZE / min(h, w)))
    small = (
        cv2.resize(gray, (max(8, round(w * s)), max(8, round(h * s))), interpolation=cv2.INTER_AREA)
        if s < 1.0
        else gray
    )
    sy, sx = small.shape[0] / h, small.shape[1] / w
    small = cv2.GaussianBlur(small, (0, 0), 1.0)
    gx = cv2.Sobel(small, cv2.CV_32F, 1, 0, ksize=3)
    gy = cv2.Sobel(small, cv2.CV_32F, 0, 1, ksize=3)
    mag = np.hypot(gx, gy)
    # Canny's high threshold: the strongest 20 % of the gradients (a weak rim against a white
    # holder next to a textured scene needs that many), but at least a tenth of the strong ones
    # (a small rim on a flat background has few edge pixels)
    hi = max(float(np.percentile(mag, 80)), 0.1 * float(np.percentile(mag, 99.9)))
    if not hi > 0:
        raise ValueError("no ellipse found: the image has no edges")
    scale = 255.0 / float(mag.max())
    edges = cv2.Canny(
        (gx * scale).astype(np.int16),
        (gy * scale).astype(np.int16),
        0.5 * hi * scale,
        hi * scale,
        L2gradient=True,
    )
    edges[:2, :] = edges[-2:, :] = 0  # the image border is not the rim
    edges[:, :2] = edges[:, -2:] = 0
    ys, xs = np.nonzero(edges)
    if len(xs) < 20:
        raise ValueError("no ellipse found: too few edges in the image; is the mirror in view?")
    g = np.stack([gx[ys, xs], gy[ys, xs]], axis=1).astype(np.float64)
    g /= np.linalg.norm(g, axis=1, keepdims=True)
    p = np.stack([xs, ys], axis=1).astype(np.float64)
    return p, g, small.shape, (sx, sy)


def _coarse_ellipse(coarse_edges, hint=None, expected=None):
    """The rim roughly: the best few ellipses found on a copy whose longer side is
    ``_COARSE_SIZE`` px, best first, as :class:`_Coarse` (centre and shape ``S`` in
    full-resolution px, the size of one coarse pixel, the polarity: ``+1`` for a mirror
    brighter than what surrounds it, ``-1`` for a darker one, ``0`` for either along the rim;
    the score and the arc length); ``coarse_edges`` is what :func:`_coarse_edges` returns.

    1. Canny edge pixels vote for a centre along their gradient direction towards the brighter
       side (a bright mirror in a dark housing; a dark blob such as the camera's reflection
       votes away from its own centre).
    2. For the strongest centres, radii are ranked by the arc length of edge pixels at that
       distance whose gradient points at the centre: a long rim beats a small complete circle,
       and clipping only shortens the arc.
    3. The best few circles are refined to ellipses (RANSAC on the edge pixels near them, then
       again on those near the ellipse and aligned with its normal); the longest arc wins.
    4. Only with a ``hint`` or an ``expected`` size: steps 1-3 are repeated for a mirror darker
       than its holder (a white holder ring) and for gradients of either sign (a grey or metal
       holder whose contrast with the mirror changes sign along the rim), and each arc length
       is weighted by how well the ellipse's size fits: a log-normal prior about the hinted
       radius (``sigma = _HINT_RADIUS / 2``) or about the middle of the expected range (its
       ends at two sigma). A holder's outer edge, a few percent to tens of percent larger than
       the rim and often the stronger edge, then loses to the rim. (Weighting by the texture
       contrast across the ellipse, textured mirror inside and plain holder outside, was
       tried and dropped: on renders of rooms with plain walls the true rim's contrast was
       negative, noise on a dark holder looks like texture.)

    ``hint = (cx, cy, r)`` (full-resolution px) keeps centres within ``_HINT_CENTER * r`` of
    ``(cx, cy)`` and radii within ``r (1 -+ _HINT_RADIUS)``; ``expected = (r_min, r_max)`` keeps
    radii in that range.
    """
    p, g, (H, W), (sx, sy) = coarse_edges
    ss = 0.5 * (sx + sy)  # full-resolution px -> coarse px (the aspect is kept by resize)

    hint_c, hint_r = None, None
    if hint is not None:  # the hint overrides the default range (and ``expected``)
        hint_c = (np.array(hint[:2], np.float64) + 0.5) * (sx, sy) - 0.5
        hint_r = hint[2] * ss
        rmin, rmax = (1.0 - _HINT_RADIUS) * hint_r - 1.0, (1.0 + _HINT_RADIUS) * hint_r + 1.0
    elif expected is not None:
        rmin, rmax = expected[0] * ss - 1.0, expected[1] * ss + 1.0
    else:
        rmin, rmax = 0.08 * max(H, W), 0.8 * max(H, W)
    rmin = max(rmin, 3.0)
    if not rmax > rmin:
        raise ValueError("no ellipse found: the rim size asked for is too small for the image")
    prior = _size_prior(hint, expected)
    guided = prior is not None
    found = []
    for polarity in (1.0, -1.0, 0.0) if guided else (1.0,):
        for support, c, S in _coarse_candidates(
            p,
            (polarity or 1.0) * g,
            (H, W),
            rmin,
            rmax,
            hint_c,
            hint_r,
            unsigned=polarity == 0.0,
            n_refine=2 if guided else 3,
        ):
            semi = np.linalg.eigvalsh(S)
            # an ellipse must be supported along >= ~8 % of its length to count, and keep to
            # the sizes asked for (a refinement may have slid to a neighbouring circle)
            if support < 0.5 * semi[1] or not (rmin <= semi[0] and semi[1] <= rmax):
                continue
            score = float(support)
            if guided:  # of about the size asked for
                score *= prior(semi / ss)
            found.append((score, support, c, S, polarity))
    if not found:
        where = "" if hint is None else f" near the hint {tuple(float(v) for v in hint)}"
        raise ValueError(
            f"no ellipse found{where}: no elliptic boundary between the mirror "
            f"and its housing; is the mirror rim in view?"
        )
    found.sort(key=lambda f: -f[0])
    distinct = []
    for f in found:  # the same ellipse refined from neighbouring circles counts once
        if all(
            np.abs(f[2] - d[2]).max() > 1.0 or np.abs(f[3] - d[3]).max() > 1.0 for d in distinct
        ):
            distinct.append(f)
    found = distinct
    out = []
    A = np.diag([1.0 / sx, 1.0 / sy])
    for score, support, c, S, polarity in found[:_N_TRIES]:
        # to full resolution: x = (x_small + 0.5) / s - 0.5 per axis
        AS = A @ S
        wv, V = np.linalg.eigh(AS @ AS.T)
        out.append(
            _Coarse(
                A @ (c + 0.5) - 0.5,
                V @ np.diag(np.sqrt(wv)) @ V.T,
                1.0 / min(sx, sy),
                polarity,
                score,
                support,
            )
        )
    return out


def _coarse_candidates(
    p, g, shape, rmin, rmax, hint_c=None, hint_r=None, unsigned=False, n_refine=3
):
    """Steps 1-3 of :func:`_coarse_ellipse` for one polarity: ``[(support, c, S), ...]``.

    ``p`` edge pixels, ``g`` unit gradients pointing into the rim (towards its centre); with
    ``unsigned`` gradients of either sign count (a rim whose contrast changes sign).
    """
    H, W = shape
    # 1. centre votes along +g, centres up to a quarter of the image outside it
    vote = np.arange(len(p))
    if len(vote) > 4000:  # enough votes for a clear peak; keeps the time bounded
        vote = np.random.default_rng(0).choice(len(p), 4000, replace=False)
    m = max(H, W) // 4
    acc_w, acc_h = W + 2 * m, H + 2 * m
    t = np.arange(rmin, rmax, 1.0, dtype=np.float32)
    pv, gv = p[vote].astype(np.float32), g[vote].astype(np.float32)
    if unsigned:
        pv, gv = np.concatenate([pv, pv]), np.concatenate([gv, -gv])
    cx = (pv[:, :1] + gv[:, :1] * t + (m + 0.5)).astype(np.int32)
    cy = (pv[:, 1:] + gv[:, 1:] * t + (m + 0.5)).astype(np.int32)
    ok = (cx >= 0) & (cx < acc_w) & (cy >= 0) & (cy < acc_h)
    acc = np.bincount((cy[ok] * acc_w + cx[ok]), minlength=acc_w * acc_h).astype(np.float32)
    acc = cv2.GaussianBlur(acc.reshape(acc_h, acc_w), (0, 0), 1.5)
    if hint_c is not None:  # centres near the hinted one only
        yy, xx = np.mgrid[0:acc_h, 0:acc_w]
        far = np.hypot(xx - m - hint_c[0], yy - m - hint_c[1]) > _HINT_CENTER * hint_r + 1.5
        acc[far] = 0
    peaks = []
    for _ in range(4):  # the strongest centres, with non-maximum suppression
        j = int(np.argmax(acc))
        v = acc.flat[j]
        if v <= 0 or (peaks and v < 0.2 * peaks[0][1]):
            break
        y0, x0 = divmod(j, acc_w)
        peaks.append((np.array([x0 - m, y0 - m], np.float64), v))
        acc[max(0, y0 - 6) : y0 + 7, max(0, x0 - 6) : x0 + 7] = 0

    # 2. radii by supported arc length (1 px radius bins, +-1 bin; 1 px of arc per bin)
    candidates = []
    for c, _ in peaks:
        d = p - c
        r = np.linalg.norm(d, axis=1)
        inward = -(d * g).sum(axis=1) / np.maximum(r, 1e-9)  # gradient towards the centre
        if unsigned:
            inward = np.abs(inward)
        sel = (inward > 0.9) & (r > rmin) & (r < rmax)
        if sel.sum() < 10:
            continue
        rr, ang = r[sel], np.arctan2(d[sel, 1], d[sel, 0])
        rbin = np.rint(rr).astype(np.int64)
        abin = np.rint((ang + np.pi) * rr).astype(np.int64)  # position along the arc, px
        keys = np.unique(rbin * 100000 + abin)
        arc = np.bincount(keys // 100000, minlength=int(rmax) + 3).astype(np.float64)
        arc3 = np.convolve(arc, np.ones(3), mode="same")
        for k in np.argsort(arc3)[::-1][:6]:
            if arc3[k] >= 0.5 * k and all(
                abs(k - k2) > 4 or np.any(c != c2) for _, c2, k2 in candidates
            ):
                candidates.append((arc3[k], c, int(k)))
    candidates.sort(key=lambda item: -item[0])

    # 3. refine the best few to ellipses
    out = []
    for _, c, k in candidates[:n_refine]:
        refined = _refine_coarse(p, g, c, float(k), unsigned)
        if refined is not None:
            out.append(refined)
    return out


def _refine_coarse(p, g, c, r, unsigned=False):
    """Ellipse through the edge pixels ``p`` (gradients ``g``) near the circle ``(c, r)``.

    Returns ``(support, center, S)`` with ``support`` the number of edge pixels (about the arc
    length, px) within 2 px of the ellipse with a gradient along its inward normal, or ``None``.
    """
    d = p - c
    rr = np.linalg.norm(d, axis=1)
    inward = -(d * g).sum(axis=1) / np.maximum(rr, 1e-9)
    if unsigned:
        inward = np.abs(inward)
    sel = (inward > 0.8) & (np.abs(rr - r) < max(4.0, 0.08 * r))
    # the ellipse stays near the circle: only pixels in a wide band can support it
    near = np.flatnonzero((inward > 0.5) & (np.abs(rr - r) < max(8.0, 0.3 * r)))
    rng = np.random.default_rng(0)
    for thr in (1.5, 1.0):  # algebraic fits are plenty at this scale
        if sel.sum() < 12:
            return None
        q = p[sel]
        N = hartley_normalization(q)
        q_n = q * N[0, 0] + N[:2, 2]
        mask = ransac_conic(q_n, thr * N[0, 0], rng, 300)
        if mask is None or mask.sum() < 6:
            return None
        Qn = direct_ellipse(q_n[mask])
        if Qn is None or not is_ellipse(Qn):
            return None
        try:
            center, S = ellipse_from_conic(N.T @ Qn @ N)
        except ValueError:
            return None
        dist, _, nrm = orthogonal_residuals(p[near], center, S, iters=4)
        sel = np.zeros(len(p), bool)
        align = -(g[near] * nrm).sum(axis=1)
        sel[near] = (np.abs(dist) < 2.0 * thr) & ((np.abs(align) if unsigned else align) > 0.8)
    return int(sel.sum()), center, S


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

    1. Coarse, on a copy 256 px wide (:func:`_coarse_ellipse`): Canny edge pixels vote along
       their gradient for the centre of a circle whose inside is brighter; radii are ranked by
       the arc length they gather, the best circles are refined to ellipses and the longest
       arc wins. The camera's dark reflection in the middle has the opposite polarity, and a
       long clipped rim beats a small complete circle (lens rings, horizon circles).
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
       points to ``max(1.5 px, 0.5 % of the major semi-axis)`` RMS, otherwise ``ValueError``;
       with a ``hint`` it must also lie within the hinted ranges.
    4. With an ``expected`` size, when the ellipse taken is not of that size (its mean radius
       outside the range, up to 1.5x off: a white holder's outer edge) or none passes step 3
       (a rough first fit in clutter), the search goes on to the boundaries concentric with
       it, inside and outside: circles of the expected size about its centre, ranked by the
       share of their length on which an intensity step lies (:func:`_rings`), each followed
       by steps 2-3 from the strongest step of either sign. Only when none of them passes is
       the ellipse of another size taken, or the ``ValueError`` raised; its message then names
       what was found (diameter, centre, RMS and support of the best boundary) and what was
       expected (the range of semi-axes and diameters, px).

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
    expected = _check_expected(expected)
    try:
        edges = _coarse_edges(gray)
        if hint is not None:
            return _detect(
                gray,
                _coarse_ellipse(edges, hint, None),
                hint,
                sigma,
                threshold,
                rng,
                _size_prior(hint, None),
            )
        if expected is None:
            return _detect(gray, _coarse_ellipse(edges), None, sigma, threshold, rng)
        return _detect_expected(gray, edges, expected, sigma, threshold, rng)
    except ValueError as e:  # no rim: an 8:1 strip is no camera's frame of a mirror, say so
        note = aspect_note((gray.shape[1], gray.shape[0]))
        if not note:
            raise
        raise ValueError(f"{e}{note}") from None


def _detect_expected(gray, edges, expected, sigma, threshold, rng):
    """:func:`detect_rim` with an ``expected`` size (and no hint).

    1. The rim of the expected size, unless one of any size has a far longer arc (a wrong K).
    2. If what step 1 takes is not of the expected size (its mean radius outside the range,
       e.g. a white holder's outer edge) or no boundary passes the checks (a rough first fit
       in clutter), the boundaries concentric with it inside and outside are searched for one
       of the expected size (:func:`_next_boundary`); the first that passes is taken. Only
       for a boundary up to ``_NEXT_RATIO`` times larger (or smaller) than the expected
       range: a holder plate is rarely wider, while a ``K`` for another resolution is off by
       more, and the rings of its size inside the rim would be the scene or the camera.
    3. Otherwise an ellipse of another size that passed is taken as before (a K for another
       resolution: :func:`.plausibility.check_plausibility` reports the size), and when none
       passed the ``ValueError`` names what was found (diameter, centre, RMS) and what was
       expected (:func:`_not_found_message`).
    """
    prior = _size_prior(None, expected)
    found = {}
    error = None
    for key, kw in (("sized", {"expected": expected}), ("any", {})):
        try:
            found[key] = _coarse_ellipse(edges, **kw)
        except ValueError as err:
            found[key], error = [], err
    sized, anysize = found["sized"], found["any"]
    fit, rejected = None, []
    if sized and (
        not anysize
        or _fits(anysize[0].S, expected)
        or sized[0].support >= _EXPECTED_SCORE * anysize[0].support
    ):
        try:
            fit = _detect(gray, sized, None, sigma, threshold, rng, prior)
        except ValueError as err:
            error = err
            rejected.append(err)
    if fit is None and anysize:
        try:
            fit = _detect(gray, anysize, None, sigma, threshold, rng)
        except ValueError as err:
            error = err
            rejected.append(err)
    if fit is not None and _of_size(fit, expected):
        return fit
    # 2. of another size, or none passed: the next boundary of the expected size
    seed = fit
    if seed is None:
        seed = next((e.fit for e in rejected if isinstance(e, _Rejected)), None)
    if seed is not None and _of_size(seed, expected, _NEXT_RATIO):
        try:
            return _next_boundary(gray, seed, expected, sigma, threshold, rng, prior)
        except ValueError:
            pass
    if fit is not None:  # 3. accepted anyway, as without a search
        return fit
    raise ValueError(_not_found_message(rejected or [error], expected)) from None


def _next_boundary(gray, seed, expected, sigma, threshold, rng, prior):
    """The boundary of the ``expected`` size concentric with the ellipse ``seed``.

    A mirror in a white holder whose outer edge was taken has its rim inside; a rough fit of
    a rim in clutter has it nearby. The rings concentric with ``seed`` (:func:`_rings`) are
    followed at full resolution, best first, by steps 2-3 of :func:`detect_rim`, starting
    from the strongest step of either sign near each (the ring is placed already; the
    outermost step would be the clutter outside it). A fit must have its mean radius in the
    expected range and, as a second look where the first found no rim, fit within
    ``_RING_RMS`` of the RMS step 3 allows (a ring of texture edges can fit loosely);
    ``ValueError`` when nothing of that size passes.
    """
    fit = _detect(
        gray, _rings(gray, seed, expected, max(1.0, sigma)), None, sigma, threshold, rng, prior
    )
    if not _of_size(fit, expected):
        raise ValueError("the boundary found inside or outside is not of the expected size")
    if fit.rms > _RING_RMS * _rms_limit(fit):  # a second look: no compromise
        raise ValueError("the boundary found inside or outside fits too loosely")
    return fit


def _rings(gray, seed, expected, sigma, n_steps=_RING_STEPS):
    """Circles of edges of the ``expected`` size about the centre of the ellipse ``seed``: up
    to ``_N_TRIES`` :class:`_Coarse` (polarity 0: either sign), most supported first.

    Along rays ``x = c + rho u(t)`` from the centre ``c`` of ``seed`` (``u(t) = (cos t,
    sin t)``, one ray per 2 px of arc, at most 720), the ``n_steps`` strongest local maxima of
    the radial step ``|dG/drho|`` of the image smoothed by ``sigma`` are kept. A circle of
    radius ``k`` about ``c + e`` is ``rho(t) = k + e . u(t)`` to first order in ``|e| / k``,
    so each step votes for ``k = rho - e . u`` over a grid of shifts ``e`` up to
    ``_RING_SHIFT`` of the expected radius; radii in the expected range (1 px bins, +-1 bin)
    are ranked by their votes per ray in the frame (about the share of the circle found),
    and one needs 30 %, as a rim does (step 3 of :func:`detect_rim`). Circles, not the shape
    of ``seed``: a rim within the plausibility limits is close to one (semi-axes within a few
    percent), while a rough fit's shape or a holder plate's is not the rim's.
    """
    lo, hi = expected
    c = np.asarray(seed.center, np.float64)
    nominal = math.sqrt(lo * hi)
    shift = _RING_SHIFT * nominal
    step = max(1.0, shift / 12.0)  # of the shift grid, px
    t = np.linspace(0.0, 2.0 * np.pi, int(np.clip(np.pi * nominal, 180, 720)), endpoint=False)
    u = np.stack([np.cos(t), np.sin(t)], axis=1)
    rho = np.arange(max(2.0, lo - shift - 3.0), hi + shift + 3.0, 0.5)
    mx = (c[0] + u[:, :1] * rho).astype(np.float32)
    my = (c[1] + u[:, 1:] * rho).astype(np.float32)
    h, w = gray.shape
    inside = (mx >= 1) & (mx <= w - 2) & (my >= 1) & (my <= h - 2)
    n_seen = int(inside[:, int(np.argmin(np.abs(rho - nominal)))].sum())  # rays in the frame
    if n_seen < 12:
        raise ValueError("no ring: the expected rim is outside the image")
    G = cv2.GaussianBlur(gray, (0, 0), float(sigma))
    prof = cv2.remap(G, mx, my, cv2.INTER_LINEAR)
    a = np.zeros(prof.shape, np.float32)
    a[:, 1:-1] = np.abs(prof[:, :-2] - prof[:, 2:])
    a[:, 1:-1] *= inside[:, :-2] & inside[:, 1:-1] & inside[:, 2:]
    peak = np.zeros(a.shape, bool)
    peak[:, 1:-1] = (a[:, 1:-1] >= a[:, :-2]) & (a[:, 1:-1] > a[:, 2:]) & (a[:, 1:-1] > 0)
    a = np.where(peak, a, 0.0)
    kth = -np.partition(-a, n_steps - 1, axis=1)[:, n_steps - 1 : n_steps]
    ri, ci = np.nonzero(peak & (a >= kth) & (a > 0.02 * float(a.max())))
    # votes: k = rho - e . u for every shift e of the grid
    grid = np.arange(-shift, shift + 1e-9, step)
    E = np.stack(np.meshgrid(grid, grid), axis=-1).reshape(-1, 2).astype(np.float32)
    k = rho[ci].astype(np.float32) - E @ u[ri].T.astype(np.float32)
    n_k = int(hi - lo) + 3
    b = np.rint(k - (lo - 1.0)).astype(np.int32)
    ok = (b >= 0) & (b < n_k)
    cell = (np.arange(len(E), dtype=np.int32)[:, None] * n_k + b)[ok]
    votes = np.bincount(cell, minlength=len(E) * n_k).reshape(len(E), n_k).astype(np.float64)
    votes[:, 1:-1] = votes[:, :-2] + votes[:, 1:-1] + votes[:, 2:]
    votes[:, [0, -1]] = 0.0
    votes /= n_seen  # a ring found on every ray in the frame: about 1
    out = []
    for j in np.argsort(votes, axis=None)[::-1][: 50 * _N_TRIES]:
        e_i, k_i = divmod(int(j), n_k)
        share = float(votes[e_i, k_i])
        if share < _MIN_SUPPORT or len(out) == _N_TRIES:
            break
        radius = lo - 1.0 + k_i
        if all(abs(radius - o.px_radius) > 4.0 for o in out):  # one per ring
            out.append(_Ring(c + E[e_i], radius, share))
    if not out:
        raise ValueError("no ring of the expected size about the ellipse found")
    eye = np.eye(2)
    return [_Coarse(o.center, o.px_radius * eye, step, 0.0, o.share, o.share, False) for o in out]


def _not_found_message(errors, expected):
    """The ``ValueError`` message when no rim of the ``expected`` size is found: what was found
    (the first boundary rejected: its diameter, centre, RMS and support) and what was
    expected (the range of semi-axes and of diameters, px)."""
    lo, hi = expected
    want = (
        f"none of the expected size passes (semi-axes {lo:.1f}-{hi:.1f} px, a diameter of "
        f"{2 * lo:.0f}-{2 * hi:.0f} px)"
    )
    rejected = [e for e in errors if isinstance(e, _Rejected)]
    if not rejected:
        reason = str(errors[0]) if errors and errors[0] is not None else "no ellipse found"
        return f"{reason.rstrip('.')}; {want}"
    e = rejected[0]
    f = e.fit
    return (
        f"no ellipse found: the best elliptic boundary has a diameter of {f.diameter:.1f} px "
        f"(semi-axes {f.axes[0]:.1f} and {f.axes[1]:.1f} px), centre ({f.center[0]:.1f}, "
        f"{f.center[1]:.1f}) px and {f.rms:.2f} px RMS along {100 * e.support:.0f} % of its "
        f"visible length (a rim needs <= {_rms_limit(f):.2f} px RMS along >= "
        f"30 %), and {want}; is the whole mirror in view, differing from its holder and in "
        f"focus?"
    )


def _fits(S, expected):
    """Whether the semi-axes of an ellipse of shape ``S`` lie in the ``expected`` range (5 %
    slack)."""
    semi = np.linalg.eigvalsh(S)
    return 0.95 * expected[0] <= semi[0] and semi[1] <= 1.05 * expected[1]


def _of_size(fit, expected, ratio=1.0):
    """Whether the mean radius of a :class:`RimFit` lies in the ``expected`` range widened by
    the factor ``ratio`` at both ends."""
    r = math.sqrt(float(fit.axes[0]) * float(fit.axes[1]))
    return expected[0] / ratio <= r <= ratio * expected[1]


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


def _check_expected(expected):
    if expected is None:
        return None
    try:
        v = np.asarray(expected, dtype=np.float64).reshape(-1)
    except (TypeError, ValueError):
        v = np.empty(0)
    if len(v) == 1:
        v = v[0] * np.array([1.0 - _HINT_RADIUS, 1.0 + _HINT_RADIUS])
    if not (len(v) == 2 and np.isfinite(v).all() and 0 < v[0] <= v[1]):
        raise ValueError(
            f"expected must be the rim's radius in px or a range (r_min, r_max) "
            f"with 0 < r_min <= r_max, got {expected!r}"
        )
    return float(v[0]), float(v[1])


def _size_prior(hint, expected):
    """Weight of a rim size for the guided search: ``semi (2,) px -> exp(-z^2 / 2)``, ``z`` the
    log of the mean radius over the hinted radius or the middle of the expected range, in
    units of ``_HINT_RADIUS / 2`` or of a quarter of the range's log width; None unguided."""
    if hint is not None:
        nominal, spread = hint[2], _HINT_RADIUS / 2.0
    elif expected is not None:  # the range's ends at two standard deviations (log radius)
        nominal = math.sqrt(expected[0] * expected[1])
        spread = max(0.25 * math.log(expected[1] / expected[0]), 0.02)
    else:
        return None

    def prior(semi):
        z = math.log(math.sqrt(float(semi[0]) * float(semi[1])) / nominal) / spread
        return math.exp(-0.5 * z * z)

    return prior


def _detect(gray, coarses, hint, sigma, threshold, rng, prior=None):
    """Steps 2-3 of :func:`detect_rim` from the coarse ellipses.

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
                fit, support = _detect_one(gray, coarse, hint, sigma, threshold, rng, absolute)
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


def _detect_one(gray, coarse, hint, sigma, threshold, rng, absolute=False):
    """Steps 2-3 of :func:`detect_rim` from one coarse ellipse."""
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
                fit = _fit_with_mask(pts, hartley_normalization(pts), mask, True, cut_floor)
        except ValueError as err:
            raise ValueError(f"no ellipse found in the image: {err}") from None
        center, S = fit.center, fit.shape_matrix
    # a rim is a long, clean ellipse: most normals in the frame find it, and it fits tightly
    support = fit.inliers.sum() / max(n_tried, 1)
    if support < _MIN_SUPPORT or fit.rms > _rms_limit(fit):
        raise _Rejected(
            f"no ellipse found: the best elliptic boundary is supported along "
            f"{100 * support:.0f} % of its visible length with {fit.rms:.2f} px RMS "
            f"(a rim needs >= 30 % and <= {_rms_limit(fit):.2f} px); is "
            f"the whole mirror in view, differing from its holder and in focus?",
            fit,
            support,
        )
    if hint is not None:
        off = float(np.linalg.norm(fit.center - hint[:2]))
        if (
            off > (_HINT_CENTER + 0.02) * hint[2]
            or not (1.0 - _HINT_RADIUS - 0.02) * hint[2] <= fit.axes[1]
            or not fit.axes[0] <= (1.0 + _HINT_RADIUS + 0.02) * hint[2]
        ):
            raise ValueError(
                f"no ellipse found near the hint {hint}: the nearest rim found has "
                f"centre ({fit.center[0]:.1f}, {fit.center[1]:.1f}) and semi-axes "
                f"{fit.axes[0]:.1f}, {fit.axes[1]:.1f} px; check the hint"
            )
    return fit, support
