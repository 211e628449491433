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

import cv2
import numpy as np

from ..raytrace import as_points

__all__ = ["RimFit", "fit_rim", "detect_rim", "conic_from_ellipse", "ellipse_from_conic",
           "conic_distance"]


# -- the result ----------------------------------------------------------------------------------
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

    def __repr__(self):
        return (f"RimFit(center=({self.center[0]:.3f}, {self.center[1]:.3f}), "
                f"axes=({self.axes[0]:.3f}, {self.axes[1]:.3f}), "
                f"angle={math.degrees(self.angle):.2f} deg, rms={self.rms:.4f} px, "
                f"points={len(self.points)} of {len(self.inliers)})")

    @property
    def shape_matrix(self):
        """(2, 2) symmetric positive definite ``S`` of ``x(t) = center + S (cos t, sin t)``."""
        c, s = math.cos(self.angle), math.sin(self.angle)
        R = np.array([[c, -s], [s, c]])
        return R @ np.diag(self.axes) @ R.T

    @property
    def diameter(self):
        """Mean diameter ``axes[0] + axes[1]``, px."""
        return float(self.axes[0] + self.axes[1])

    def distance(self, points):
        """Signed orthogonal distance of points to the ellipse (positive outside), px.

        Parameters
        ----------
        points : (N, 2) or (N, 1, 2) array_like

        Returns
        -------
        (N,) float64 ndarray
        """
        pts = np.asarray(points, dtype=np.float64).reshape(-1, 2)
        d, _, _ = _orthogonal_residuals(pts, self.center, self.shape_matrix)
        return d

    def sample(self, n=360):
        """``n`` points evenly spaced in the ellipse parameter, ``(n, 2)`` float64 (for drawing)."""
        t = np.linspace(0.0, 2.0 * np.pi, int(n), endpoint=False)
        return self.center + np.stack([np.cos(t), np.sin(t)], axis=1) @ self.shape_matrix.T


# -- conic <-> ellipse ---------------------------------------------------------------------------
def conic_from_ellipse(center, S):
    """``Q_I`` (eq. 22) of the ellipse ``center + S (cos t, sin t)``, unit norm, interior negative.

    ``(x - c)^T S^-2 (x - c) - 1 = 0`` written as ``x~^T Q_I x~ = 0`` (eq. 21).
    """
    c = np.asarray(center, dtype=np.float64)
    Sinv = np.linalg.inv(np.asarray(S, dtype=np.float64))
    A = Sinv.T @ Sinv
    A = 0.5 * (A + A.T)
    Q = np.empty((3, 3))
    Q[:2, :2] = A
    Q[:2, 2] = Q[2, :2] = -A @ c
    Q[2, 2] = c @ A @ c - 1.0
    return Q / np.linalg.norm(Q)


def ellipse_from_conic(Q):
    """Centre and shape ``S`` (symmetric positive definite) of the real ellipse ``Q_I``.

    Raises ``ValueError`` if ``Q`` is not a real, non-degenerate ellipse.
    """
    Q = np.asarray(Q, dtype=np.float64)
    if Q.shape != (3, 3):
        raise ValueError(f"a conic must be a 3x3 matrix, got shape {Q.shape}")
    Q = 0.5 * (Q + Q.T)
    A = Q[:2, :2]
    if not np.isfinite(Q).all() or np.linalg.det(A) <= 0.0:
        raise ValueError("the fitted conic is not an ellipse (degenerate, hyperbola or parabola); "
                         "give points spread along a clearly elliptic boundary")
    center = np.linalg.solve(A, -Q[:2, 2])
    F = Q[2, 2] + Q[:2, 2] @ center  # value of the conic at the centre
    if not F < 0.0 < A[0, 0] and not F > 0.0 > A[0, 0]:
        raise ValueError("the fitted conic is a point or an imaginary ellipse; give points along "
                         "the rim")
    M = A / -F
    w, V = np.linalg.eigh(M)
    if not (np.isfinite(w).all() and w[0] > 0.0):
        raise ValueError("the fitted conic is an imaginary ellipse; give points along the rim")
    S = V @ np.diag(1.0 / np.sqrt(w)) @ V.T
    return center, 0.5 * (S + S.T)


def conic_distance(Q, points):
    """Signed orthogonal distance of points to the ellipse ``x~^T Q x~ = 0`` (eq. 21), px.

    Positive outside. ``Q`` may have any scale and sign; it must be a real ellipse.

    Parameters
    ----------
    Q : (3, 3) array_like
    points : (N, 2) or (N, 1, 2) array_like

    Returns
    -------
    (N,) float64 ndarray
    """
    center, S = ellipse_from_conic(Q)
    pts = np.asarray(points, dtype=np.float64).reshape(-1, 2)
    d, _, _ = _orthogonal_residuals(pts, center, S)
    return d


def _axes_angle(S):
    w, V = np.linalg.eigh(S)
    major = V[:, 1]
    angle = math.atan2(major[1], major[0]) % math.pi
    return np.array([w[1], w[0]]), angle


# -- validation ----------------------------------------------------------------------------------
def _as_points(points, min_points):
    pts, _ = as_points(points, "points", 2)
    if not np.isfinite(pts).all():
        raise ValueError("points must be finite; drop NaN/inf rows before fitting the rim")
    if len(pts) < min_points:
        raise ValueError(f"need at least {min_points} boundary points to fit the rim ellipse, "
                         f"got {len(pts)}; give more points spread along the rim")
    return pts


# -- algebraic fits (normalised) -----------------------------------------------------------------
def _hartley(pts):
    """Similarity ``N`` moving the centroid to 0 and the mean distance to sqrt(2)."""
    m = pts.mean(axis=0)
    d = np.sqrt(((pts - m) ** 2).sum(axis=1)).mean()
    s = math.sqrt(2.0) / d if d > 0 else 1.0
    return np.array([[s, 0.0, -s * m[0]], [0.0, s, -s * m[1]], [0.0, 0.0, 1.0]])


def _coeffs_to_Q(v):
    A, B, C, D, E, F = v
    return np.array([[A, B / 2, D / 2], [B / 2, C, E / 2], [D / 2, E / 2, F]])


def _direct_ellipse(pts):
    """Fitzgibbon's direct least-squares ellipse fit, Halir-Flusser's stable form.

    ``pts`` should be normalised. Returns ``Q`` (3, 3) or ``None`` if no ellipse solution.
    """
    x, y = pts[:, 0], pts[:, 1]
    D1 = np.stack([x * x, x * y, y * y], axis=1)
    D2 = np.stack([x, y, np.ones_like(x)], axis=1)
    S1, S2, S3 = D1.T @ D1, D1.T @ D2, D2.T @ D2
    try:
        T = -np.linalg.solve(S3, S2.T)
    except np.linalg.LinAlgError:
        return None
    M = S1 + S2 @ T
    # premultiply by inv(C1), C1 = [[0, 0, 2], [0, -1, 0], [2, 0, 0]]
    M = np.stack([M[2] / 2.0, -M[1], M[0] / 2.0])
    w, V = np.linalg.eig(M)
    V = np.real(V)
    cond = 4.0 * V[0] * V[2] - V[1] ** 2
    ok = np.flatnonzero(cond > 0)
    if ok.size == 0:
        return None
    a1 = V[:, ok[np.argmin(np.abs(np.real(w[ok])))]]
    return _coeffs_to_Q(np.concatenate([a1, T @ a1]))


def _is_ellipse(Q):
    A = Q[:2, :2]
    if np.linalg.det(A) <= 0:
        return False
    try:
        center = np.linalg.solve(A, -Q[:2, 2])
    except np.linalg.LinAlgError:
        return False
    F = Q[2, 2] + Q[:2, 2] @ center
    return bool(F * A[0, 0] < 0)


# -- geometric distance and refinement -----------------------------------------------------------
def _orthogonal_residuals(pts, center, S, iters=12):
    """Signed orthogonal distances of ``pts`` to ``center + S u(t)``, their feet and outer normals.

    The foot parameter ``t`` solves ``(x(t) - p) . x'(t) = 0`` by safeguarded Newton iterations
    from the angle of ``S^-1 (p - center)``.
    """
    q = pts - center
    u0 = q @ np.linalg.inv(S).T
    t = np.arctan2(u0[:, 1], u0[:, 0])
    s11, s12, s22 = S[0, 0], S[0, 1], S[1, 1]
    for _ in range(iters):
        c, s = np.cos(t), np.sin(t)
        xx, xy = s11 * c + s12 * s, s12 * c + s22 * s        # S u
        dx, dy = -s11 * s + s12 * c, -s12 * s + s22 * c      # S u'
        ex, ey = xx - q[:, 0], xy - q[:, 1]
        f = ex * dx + ey * dy
        tt = dx * dx + dy * dy
        fp = np.maximum(tt - (ex * xx + ey * xy), 0.2 * tt)  # x'' = -S u
        step = f / fp
        t = t - np.clip(step, -0.5, 0.5)
        if np.max(np.abs(step)) < 1e-13:
            break
    c, s = np.cos(t), np.sin(t)
    foot = np.stack([s11 * c + s12 * s, s12 * c + s22 * s], axis=1)
    dx, dy = -s11 * s + s12 * c, -s12 * s + s22 * c
    nrm = np.hypot(dx, dy)
    normal = np.stack([dy / nrm, -dx / nrm], axis=1)  # outward for det S > 0
    d = np.einsum("ij,ij->i", q - foot, normal)
    return d, np.stack([c, s], axis=1), normal


def _refine_geometric(pts, center, S, iters=50):
    """Levenberg-Marquardt on the orthogonal distances over (cx, cy, s11, s12, s22).

    The symmetric ``S`` parametrisation has no singularity at circles. With the foot parameter
    fixed, ``d r / d theta = -n . d x / d theta`` (the foot moves along the tangent).
    """
    p = np.array([center[0], center[1], S[0, 0], S[0, 1], S[1, 1]])

    def unpack(p):
        return p[:2], np.array([[p[2], p[3]], [p[3], p[4]]])

    def evaluate(p):
        c, Sm = unpack(p)
        if np.linalg.det(Sm) <= 0 or Sm[0, 0] <= 0:
            return None, None
        r, u, n = _orthogonal_residuals(pts, c, Sm)
        J = -np.stack([n[:, 0], n[:, 1], n[:, 0] * u[:, 0],
                       n[:, 0] * u[:, 1] + n[:, 1] * u[:, 0], n[:, 1] * u[:, 1]], axis=1)
        return r, J

    r, J = evaluate(p)
    cost = r @ r
    lam = 1e-6
    for _ in range(iters):
        g = J.T @ r
        H = J.T @ J
        improved = False
        for _ in range(20):
            Hd = H + lam * np.diag(np.diag(H) + 1e-12 * np.trace(H))
            try:
                step = -np.linalg.solve(Hd, g)
            except np.linalg.LinAlgError:
                lam *= 10.0
                continue
            r_new, J_new = evaluate(p + step)
            if r_new is not None and r_new @ r_new <= cost:
                p, r, J = p + step, r_new, J_new
                new_cost = r @ r
                converged = cost - new_cost <= 1e-14 * max(cost, 1e-30) or \
                    np.max(np.abs(step)) < 1e-11 * max(1.0, np.abs(p).max())
                cost = new_cost
                lam = max(lam / 10.0, 1e-12)
                improved = True
                break
            lam *= 10.0
        if not improved or converged:
            break
    c, Sm = unpack(p)
    return c, Sm, r


# -- RANSAC --------------------------------------------------------------------------------------
def _conics_through_5(samples):
    """Conics through 5 points each: the null vectors of (B, 5, 6) design matrices."""
    x, y = samples[..., 0], samples[..., 1]
    D = np.stack([x * x, x * y, y * y, x, y, np.ones_like(x)], axis=-1)
    _, _, Vt = np.linalg.svd(D)
    v = Vt[:, -1, :]
    A, B, C, Dc, E, F = v.T
    Q = np.empty((len(v), 3, 3))
    Q[:, 0, 0], Q[:, 1, 1], Q[:, 2, 2] = A, C, F
    Q[:, 0, 1] = Q[:, 1, 0] = B / 2
    Q[:, 0, 2] = Q[:, 2, 0] = Dc / 2
    Q[:, 1, 2] = Q[:, 2, 1] = E / 2
    return Q


def _sampson(Qs, ph):
    """Sampson (first-order geometric) distances, (B, N), of homogeneous points ``ph`` (N, 3)."""
    Qp = ph @ Qs  # (B, N, 3); Q symmetric
    alg = (Qp * ph).sum(axis=-1)
    grad = 2.0 * np.sqrt(Qp[..., 0] ** 2 + Qp[..., 1] ** 2)
    return np.abs(alg) / np.maximum(grad, 1e-300)


def _ransac(pts_n, thr_n, rng, max_trials, confidence=0.999, batch=64):
    """Consensus ellipse of normalised points: returns the inlier mask of the best hypothesis."""
    n = len(pts_n)
    ph_all = np.concatenate([pts_n, np.ones((n, 1))], axis=1)
    # hypotheses are scored on at most 1000 points (plenty to rank them), the winner on all
    ph = ph_all if n <= 1000 else ph_all[rng.choice(n, 1000, replace=False)]
    m_eval = len(ph)
    best_count, best_Q = 0, None
    needed, trials = max_trials, 0
    while trials < min(needed, max_trials):
        b = min(batch, max_trials - trials)
        idx = np.argsort(rng.random((b, n)), axis=1)[:, :5] if n <= 64 else \
            rng.integers(0, n, size=(b, 5))
        Qs = _conics_through_5(pts_n[idx])
        A = Qs[:, :2, :2]
        ell = (A[:, 0, 0] * A[:, 1, 1] - A[:, 0, 1] ** 2) > 0
        trials += b
        if not ell.any():
            continue
        Qs = Qs[ell]
        masks = _sampson(Qs, ph) < thr_n
        counts = masks.sum(axis=1)
        k = int(np.argmax(counts))
        if counts[k] > best_count:
            best_count, best_Q = int(counts[k]), Qs[k]
            w = best_count / m_eval
            denom = math.log(max(1e-12, 1.0 - w ** 5)) if w < 1.0 else -np.inf
            needed = 0 if w >= 1.0 else int(math.ceil(math.log(1.0 - confidence) / denom))
    if best_Q is None:
        return None
    return _sampson(best_Q[None], ph_all)[0] < thr_n


# -- public fit ----------------------------------------------------------------------------------
def fit_rim(points, robust=True, threshold=2.0, max_trials=2000, rng=0):
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
    N = _hartley(pts)
    s = N[0, 0]
    pts_n = pts * s + N[:2, 2]
    mask = np.ones(len(pts), bool)
    if robust:
        rng = rng if isinstance(rng, np.random.Generator) else np.random.default_rng(rng)
        m = _ransac(pts_n, threshold * s, rng, int(max_trials))
        if m is None or m.sum() < 5:
            raise ValueError("no ellipse found among the boundary points; give points along the "
                             "rim (at least 5 on a common ellipse)")
        mask = m
    return _fit_with_mask(pts, N, mask, robust, threshold)


def _fit_with_mask(pts, N, mask, robust, threshold):
    """Steps 3-5 of :func:`fit_rim` from an initial inlier ``mask``; ``N`` normalises ``pts``."""
    pts_n = pts * N[0, 0] + N[:2, 2]
    Qn = _direct_ellipse(pts_n[mask])
    if Qn is None or not _is_ellipse(Qn):
        raise ValueError("the boundary points do not determine an ellipse (collinear, too few or "
                         "a non-elliptic curve); give points spread along the rim")
    Q = N.T @ Qn @ N  # back to pixels
    center, S = ellipse_from_conic(Q)
    for _ in range(10):
        center, S, _ = _refine_geometric(pts[mask], center, S)
        if not robust:
            break
        d, _, _ = _orthogonal_residuals(pts, center, S, iters=6)  # to classify
        ad = np.abs(d)
        sigma = 1.4826 * np.median(ad[mask])
        new = ad <= max(threshold, 3.5 * sigma)
        if new.sum() < 5:
            raise ValueError("no ellipse found among the boundary points; give points along the "
                             "rim (at least 5 on a common ellipse)")
        if np.array_equal(new, mask):
            break
        mask = new
    if not (np.isfinite(S).all() and np.linalg.det(S) > 0):
        raise ValueError("the fitted rim is not an ellipse; give points spread along the rim")
    used = pts[mask]
    axes, angle = _axes_angle(S)
    extent = float(np.ptp(used, axis=0).max())
    if not (axes[1] > 1e-3 * axes[0] and axes[0] < 20.0 * extent):
        raise ValueError(f"the boundary points fit only a degenerate ellipse (semi-axes "
                         f"{axes[0]:.3g} and {axes[1]:.3g} px for points spanning {extent:.3g} px: "
                         f"collinear or nearly flat); give points spread along the rim")
    d, _, _ = _orthogonal_residuals(used, center, S)
    return RimFit(conic=conic_from_ellipse(center, S), points=used,
                  rms=float(np.sqrt(np.mean(d * d))), center=center, axes=axes, angle=angle,
                  inliers=mask)


# -- detection in an image ----------------------------------------------------------------------
_COARSE_SIZE = 256  # longer side of the image used to find the rim roughly


def _as_gray(image):
    """Grey float32 image scaled to about [0, 1]; BGR(A) is converted with OpenCV's weights."""
    if not isinstance(image, np.ndarray):
        raise ValueError(f"image must be a numpy array (grey or BGR), got {type(image).__name__}")
    if image.ndim == 3 and image.shape[2] == 1:
        image = image[:, :, 0]
    if image.ndim not in (2, 3) or (image.ndim == 3 and image.shape[2] not in (3, 4)):
        raise ValueError(f"image must be grey (H, W) or BGR/BGRA (H, W, 3|4), got shape "
                         f"{image.shape}")
    if min(image.shape[:2]) < 32:
        raise ValueError(f"image is too small to hold a mirror rim: {image.shape[1]}x"
                         f"{image.shape[0]} px (need at least 32x32)")
    if image.dtype == np.bool_ or not (np.issubdtype(image.dtype, np.integer)
                                       or np.issubdtype(image.dtype, np.floating)):
        raise ValueError(f"image must be uint8, uint16 or float, got dtype {image.dtype}")
    img = image.astype(np.float32, copy=False)
    if img.ndim == 3:
        img = cv2.cvtColor(img, cv2.COLOR_BGRA2GRAY if img.shape[2] == 4 else cv2.COLOR_BGR2GRAY)
    if not np.isfinite(img).all():
        img = np.nan_to_num(img, nan=0.0, posinf=0.0, neginf=0.0)
    lo, hi = float(img.min()), float(img.max())
    if not hi > lo:
        raise ValueError("no ellipse found: the image is uniform (no mirror rim visible)")
    return (img - lo) * np.float32(1.0 / (hi - lo))


def _coarse_ellipse(gray):
    """The rim roughly: centre and shape ``S`` (full-resolution px) of the best bright-inside
    ellipse found on a copy whose longer side is ``_COARSE_SIZE`` px.

    1. Canny edge pixels vote for a centre along their gradient direction (towards the brighter
       side: the inside of a bright mirror in a dark housing; a dark blob such as the camera's
       reflection votes away from its own centre).
    2. For the strongest centres, radii are ranked by the arc length of edge pixels at that
       distance whose gradient points at the centre: a long rim beats a small complete circle,
       and clipping only shortens the arc.
    3. The best few circles are refined to ellipses (RANSAC on the edge pixels near them with the
       right polarity, then again on those near the ellipse and aligned with its normal); the
       ellipse supported by the longest arc wins.
    """
    h, w = gray.shape
    s = min(1.0, _COARSE_SIZE / max(h, w))
    small = cv2.resize(gray, (max(8, round(w * s)), max(8, round(h * s))),
                       interpolation=cv2.INTER_AREA) if s < 1.0 else gray
    sy, sx = small.shape[0] / h, small.shape[1] / w
    small = cv2.GaussianBlur(small, (0, 0), 1.0)
    gx = cv2.Sobel(small, cv2.CV_32F, 1, 0, ksize=3)
    gy = cv2.Sobel(small, cv2.CV_32F, 0, 1, ksize=3)
    mag = np.hypot(gx, gy)
    # Canny's high threshold: the strongest 8 % of the gradients, but at least a tenth of the
    # strong ones (a small rim on a flat background has few edge pixels)
    hi = max(float(np.percentile(mag, 92)), 0.1 * float(np.percentile(mag, 99.9)))
    if not hi > 0:
        raise ValueError("no ellipse found: the image has no edges")
    scale = 255.0 / float(mag.max())
    edges = cv2.Canny((gx * scale).astype(np.int16), (gy * scale).astype(np.int16),
                      0.5 * hi * scale, hi * scale, L2gradient=True)
    edges[:2, :] = edges[-2:, :] = 0  # the image border is not the rim
    edges[:, :2] = edges[:, -2:] = 0
    ys, xs = np.nonzero(edges)
    if len(xs) < 20:
        raise ValueError("no ellipse found: too few edges in the image; is the mirror in view?")
    g = np.stack([gx[ys, xs], gy[ys, xs]], axis=1).astype(np.float64)
    g /= np.linalg.norm(g, axis=1, keepdims=True)
    p = np.stack([xs, ys], axis=1).astype(np.float64)
    H, W = small.shape

    # 1. centre votes along +g, centres up to a quarter of the image outside it
    rmin, rmax = 0.08 * max(H, W), 0.8 * max(H, W)
    vote = np.arange(len(p))
    if len(vote) > 4000:  # enough votes for a clear peak; keeps the time bounded
        vote = np.random.default_rng(0).choice(len(p), 4000, replace=False)
    m = max(H, W) // 4
    acc_w, acc_h = W + 2 * m, H + 2 * m
    t = np.arange(rmin, rmax, 1.0, dtype=np.float32)
    pv, gv = p[vote].astype(np.float32), g[vote].astype(np.float32)
    cx = (pv[:, :1] + gv[:, :1] * t + (m + 0.5)).astype(np.int32)
    cy = (pv[:, 1:] + gv[:, 1:] * t + (m + 0.5)).astype(np.int32)
    ok = (cx >= 0) & (cx < acc_w) & (cy >= 0) & (cy < acc_h)
    acc = np.bincount((cy[ok] * acc_w + cx[ok]), minlength=acc_w * acc_h).astype(np.float32)
    acc = cv2.GaussianBlur(acc.reshape(acc_h, acc_w), (0, 0), 1.5)
    peaks = []
    for _ in range(4):  # the strongest centres, with non-maximum suppression
        j = int(np.argmax(acc))
        v = acc.flat[j]
        if v <= 0 or (peaks and v < 0.2 * peaks[0][1]):
            break
        y0, x0 = divmod(j, acc_w)
        peaks.append((np.array([x0 - m, y0 - m], np.float64), v))
        acc[max(0, y0 - 6):y0 + 7, max(0, x0 - 6):x0 + 7] = 0

    # 2. radii by supported arc length (1 px radius bins, +-1 bin; 1 px of arc per bin)
    candidates = []
    for c, _ in peaks:
        d = p - c
        r = np.linalg.norm(d, axis=1)
        inward = -(d * g).sum(axis=1) / np.maximum(r, 1e-9)  # gradient towards the centre
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
            if arc3[k] >= 0.5 * k and all(abs(k - k2) > 4 or np.any(c != c2)
                                           for _, c2, k2 in candidates):
                candidates.append((arc3[k], c, int(k)))
    candidates.sort(key=lambda item: -item[0])

    # 3. refine the best few to ellipses; the longest supported arc wins
    best = None
    for _, c, k in candidates[:3]:
        refined = _refine_coarse(p, g, c, float(k))
        if refined is not None and (best is None or refined[0] > best[0]):
            best = refined
    if best is None or best[0] < 0.5 * np.linalg.eigvalsh(best[2])[1]:  # arc < ~8 % of the rim
        raise ValueError("no ellipse found: no bright-inside elliptic boundary in the image; is "
                         "the mirror rim in view (bright mirror against a darker housing)?")
    _, c, S = best
    # to full resolution: x = (x_small + 0.5) / s - 0.5 per axis
    A = np.diag([1.0 / sx, 1.0 / sy])
    center = A @ (c + 0.5) - 0.5
    AS = A @ S
    wv, V = np.linalg.eigh(AS @ AS.T)
    return center, V @ np.diag(np.sqrt(wv)) @ V.T, 1.0 / min(sx, sy)


def _refine_coarse(p, g, c, r):
    """Ellipse through the edge pixels ``p`` (gradients ``g``) near the circle ``(c, r)``.

    Returns ``(support, center, S)`` with ``support`` the number of edge pixels (about the arc
    length, px) within 2 px of the ellipse with a gradient along its inward normal, or ``None``.
    """
    d = p - c
    rr = np.linalg.norm(d, axis=1)
    inward = -(d * g).sum(axis=1) / np.maximum(rr, 1e-9)
    sel = (inward > 0.8) & (np.abs(rr - r) < max(4.0, 0.08 * r))
    rng = np.random.default_rng(0)
    for thr in (1.5, 1.0):  # algebraic fits are plenty at this scale
        if sel.sum() < 12:
            return None
        q = p[sel]
        N = _hartley(q)
        q_n = q * N[0, 0] + N[:2, 2]
        mask = _ransac(q_n, thr * N[0, 0], rng, 300)
        if mask is None or mask.sum() < 6:
            return None
        Qn = _direct_ellipse(q_n[mask])
        if Qn is None or not _is_ellipse(Qn):
            return None
        try:
            center, S = ellipse_from_conic(N.T @ Qn @ N)
        except ValueError:
            return None
        dist, _, nrm = _orthogonal_residuals(p, center, S, iters=4)
        sel = (np.abs(dist) < 2.0 * thr) & (-(g * nrm).sum(axis=1) > 0.8)
    return int(sel.sum()), center, S


def _edge_points_along_normals(G, center, S, half_width, step=0.25, outermost=False,
                               centroid=0.0):
    """Subpixel rim points: strongest outward intensity drop along the ellipse normals.

    The ellipse is sampled every pixel of arc length; along each outward normal the smoothed
    image ``G`` is sampled (bilinear) over ``+-half_width`` px and differentiated; the maximum of
    the outward drop is located by a parabola through the log of the three samples around it.
    With ``centroid > 0`` that position is then refined to the centroid of the drop under a
    triangular window of that half-width centred on it (four fixed-point steps): the drop of an
    edge blurred by any symmetric kernel is symmetric about the edge, so the centroid is unbiased,
    whereas the peak of a bilinearly interpolated profile is pulled towards pixel centres
    (~0.15 px per point against ~0.02 px with the centroid on rendered rims). Profiles that
    leave the image, whose maximum lies at the window ends or that find no drop are dropped.

    Returns ``(points, n_tried)``: the (M, 2) edge points and the number of normals whose whole
    profile was inside the image.
    """
    h, w = G.shape
    axes, _ = _axes_angle(S)
    n_pts = int(max(64, min(20000, 2 * np.pi * axes[0])))
    tt = np.linspace(0.0, 2 * np.pi, n_pts, endpoint=False)
    u = np.stack([np.cos(tt), np.sin(tt)], axis=1)
    e = center + u @ S.T
    der = np.stack([-np.sin(tt), np.cos(tt)], axis=1) @ S.T
    nrm = np.stack([der[:, 1], -der[:, 0]], axis=1)
    nrm /= np.linalg.norm(nrm, axis=1, keepdims=True)
    tau = np.arange(-half_width - step, half_width + 1.5 * step, step)
    margin = 2.0
    inside = np.ones(len(e), bool)
    for end in (tau[0], tau[-1]):  # a segment is inside the (convex) frame iff its ends are
        q = e + end * nrm
        inside &= ((q[:, 0] >= margin) & (q[:, 0] <= w - 1 - margin) &
                   (q[:, 1] >= margin) & (q[:, 1] <= h - 1 - margin))
    if inside.sum() < 6:
        return np.empty((0, 2)), 0
    e, nrm = e[inside], nrm[inside]
    tau32 = tau.astype(np.float32)
    mx = e[:, :1].astype(np.float32) + nrm[:, :1].astype(np.float32) * tau32
    my = e[:, 1:].astype(np.float32) + nrm[:, 1:].astype(np.float32) * tau32
    prof = cv2.remap(G, mx, my, cv2.INTER_LINEAR).astype(np.float64)
    drop = (prof[:, :-2] - prof[:, 2:]) / (2 * step)  # outward drop at tau[1:-1]
    if outermost:
        # the outermost local maximum at least half as strong as the strongest one
        dmax = drop.max(axis=1, keepdims=True)
        locmax = np.zeros_like(drop, bool)
        locmax[:, 1:-1] = (drop[:, 1:-1] >= drop[:, :-2]) & (drop[:, 1:-1] > drop[:, 2:])
        cand = locmax & (drop >= 0.5 * dmax)
        k = np.where(cand.any(axis=1), drop.shape[1] - 1 - np.argmax(cand[:, ::-1], axis=1),
                     np.argmax(drop, axis=1))
    else:
        k = np.argmax(drop, axis=1)
    rows = np.arange(len(k))
    ok = (k > 0) & (k < drop.shape[1] - 1)
    k = np.clip(k, 1, drop.shape[1] - 2)
    d0, d1, d2 = drop[rows, k - 1], drop[rows, k], drop[rows, k + 1]
    strength = d1
    pos = d0 > 0
    pos &= d2 > 0
    l0, l1, l2 = (np.log(np.where(pos, v, 1.0)) for v in (d0, d1, d2))
    den_log = l0 - 2 * l1 + l2
    den_lin = d0 - 2 * d1 + d2
    off = np.where(pos & (den_log < 0), 0.5 * (l0 - l2) / np.where(den_log < 0, den_log, -1.0),
                   0.5 * (d0 - d2) / np.where(den_lin < 0, den_lin, -1.0))
    off = np.clip(off, -1.0, 1.0)
    where = tau[1:-1][k] + off * step
    ok &= strength > 0
    if centroid > 0:
        tc = tau[1:-1]
        pos_drop = np.maximum(drop, 0.0)
        for _ in range(4):
            wgt = np.maximum(0.0, 1.0 - np.abs(tc[None, :] - where[:, None]) / centroid) * pos_drop
            total = wgt.sum(axis=1)
            where = np.where(total > 0, (wgt @ tc) / np.where(total > 0, total, 1.0), where)
        ok &= (where - centroid >= tc[0]) & (where + centroid <= tc[-1])
    return e[ok] + where[ok, None] * nrm[ok], int(inside.sum())


def detect_rim(image, *, sigma=0.7, threshold=2.0, rng=0):
    """Find the mirror rim (its outer bright-mirror / dark-housing boundary) in an image.

    1. Coarse, on a copy 256 px wide (:func:`_coarse_ellipse`): Canny edge pixels vote along
       their gradient for the centre of a bright-inside circle, radii are ranked by the arc
       length they gather, and the best circles are refined to ellipses; the longest supported
       arc wins. The camera's dark reflection in the middle has the opposite polarity, and a long
       clipped rim beats a small complete circle (lens rings, horizon circles).
    2. Fine, at full resolution: along the normals of the current ellipse, the strongest
       outward intensity drop of the image smoothed by ``sigma`` is located to subpixel
       precision (profiles leaving the image are dropped, so a clipped rim gives an arc), and
       :func:`fit_rim` (RANSAC, then orthogonal-distance refinement) fits ``Q_I``
       (eqs. 20-22). Three rounds with shrinking search windows; the first takes the
       outermost strong drop of each profile (the mirror's edge rather than scene edges inside).
    3. Check: the ellipse must be found along at least 30 % of its in-frame length and fit its
       points to ``max(1.5 px, 0.5 % of the major semi-axis)`` RMS, otherwise ``ValueError``.

    Assumes the mirror is brighter than the housing around it along most of the rim (true of
    every catadioptric image we know: a mirror reflects the lit scene, the holder is black), and
    a rim at least ~8 % of the image's longer side in radius.

    Parameters
    ----------
    image : (H, W) or (H, W, 3|4) ndarray, uint8, uint16 or float
        Grey or BGR(A) catadioptric image with the mirror brighter than its housing.
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
        Not an image, or no elliptic bright-inside boundary found.
    """
    if not (np.isfinite(sigma) and sigma >= 0):
        raise ValueError(f"sigma must be a non-negative number of pixels, got {sigma!r}")
    gray = _as_gray(image)
    center, S, coarse_px = _coarse_ellipse(gray)
    G = cv2.GaussianBlur(gray, (0, 0), float(sigma)) if sigma > 0 else gray
    cw = 3.0 * max(sigma, 0.5)  # half-width of the centroid window
    fit = None
    for i in range(3):
        # search window: the coarse ellipse's uncertainty, then the spread of the last fit
        hw = max(6.0, 3.0 * coarse_px) if i == 0 else cw + max(1.5, 3.0 * fit.rms)
        pts, n_tried = _edge_points_along_normals(G, center, S, hw, outermost=(i == 0),
                                                  centroid=0.0 if i == 0 else cw)
        if len(pts) < 6:
            raise ValueError("no ellipse found: the rim is not visible along enough of its length "
                             "(too much of it outside the image?)")
        try:
            if fit is None:
                fit = fit_rim(pts, threshold=threshold, rng=rng)
            else:  # seeded by the previous ellipse instead of RANSAC
                d = np.abs(fit.distance(pts))
                # the points are now precise: a tighter floor for the cut (0.5 px) drops
                # partial edges, e.g. where a holder arm meets the rim
                cut_floor = min(threshold, 0.5)
                mask = d <= max(cut_floor, 3.5 * 1.4826 * float(np.median(d)))
                if mask.sum() < 6:
                    raise ValueError("too few edge points near the rim found in the last round")
                fit = _fit_with_mask(pts, _hartley(pts), mask, True, cut_floor)
        except ValueError as err:
            raise ValueError(f"no ellipse found in the image: {err}") from None
        center, S = fit.center, fit.shape_matrix
    # a rim is a long, clean ellipse: most normals in the frame find it, and it fits tightly
    support = fit.inliers.sum() / max(n_tried, 1)
    if support < 0.3 or fit.rms > max(1.5, 0.005 * fit.axes[0]):
        raise ValueError(f"no ellipse found: the best elliptic boundary is supported along "
                         f"{100 * support:.0f} % of its visible length with {fit.rms:.2f} px RMS "
                         f"(a rim needs >= 30 % and <= {max(1.5, 0.005 * fit.axes[0]):.2f} px); is "
                         f"the whole mirror in view, brighter than its housing and in focus?")
    return fit
