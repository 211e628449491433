"""Ellipse algebra and robust ellipse fitting, the geometry under the rim (eqs. 20-22).

A conic ``x~^T Q x~ = 0`` with ``Q = [[a, h, f], [h, b, g], [f, g, c]]`` (eqs. 20-22) and the
same ellipse as a centre and shape matrix ``S`` (``|S^-1 (p - center)| = 1``). Fitting: a
normalised direct fit, RANSAC over five-point conics with Sampson distances, and the
orthogonal (geometric) refinement used by :func:`omnicam.calibration.rim.fit_rim`.

scikit-image against the hand-written pieces: ``python benchmarks/bench_ellipse_skimage.py``
measures both in one run and prints the figures (the sections named here are the script's):

- the direct fit is scikit-image's ``measure.EllipseModel`` (:func:`direct_ellipse`): as
  accurate as the hand-written fit it replaced (section 1), and a calibration's rim and Chen's
  candidates are the same to round-off (section 5). It is slower per fit (section 5), and the
  first fit in a process imports ``scipy.optimize`` and ``scipy.spatial``, a cost a calibration
  pays anyway: its refinement loads ``scipy.optimize``, nearly all of it (section 6);
- RANSAC, the orthogonal distances and the geometric refinement stay hand-written: each says
  why.
"""

from __future__ import annotations

import math

import numpy as np
import numpy.typing as npt

from .._jit import notice_if_cold
from .._kernels.ellipse import ellipse_feet
from .._typing import FloatArray

__all__ = [
    "conic_from_ellipse",
    "ellipse_from_conic",
    "conic_distance",
    "axes_angle",
    "hartley_normalization",
    "direct_ellipse",
    "is_ellipse",
    "orthogonal_residuals",
    "refine_geometric",
    "conics_through_5",
    "sampson_distances",
    "ransac_conic",
    "coeffs_to_conic",
]


def conic_from_ellipse(center, S) -> FloatArray:
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


def ellipse_from_conic(Q) -> tuple[FloatArray, FloatArray]:
    """Centre and shape ``S`` (symmetric positive definite) of the real ellipse ``Q_I``.

    Raises ``ValueError`` if ``Q`` is not a real, non-degenerate ellipse.
    """
    Q = np.asarray(Q, dtype=np.float64)
    if Q.shape != (3, 3):
        raise ValueError(f"a conic must be a 3x3 matrix, got shape {Q.shape}")
    Q = 0.5 * (Q + Q.T)
    A = Q[:2, :2]
    if not np.isfinite(Q).all() or np.linalg.det(A) <= 0.0:
        raise ValueError(
            "the fitted conic is not an ellipse (degenerate, hyperbola or parabola); "
            "give points spread along a clearly elliptic boundary"
        )
    center = np.linalg.solve(A, -Q[:2, 2])
    F = Q[2, 2] + Q[:2, 2] @ center  # value of the conic at the centre
    if not F < 0.0 < A[0, 0] and not F > 0.0 > A[0, 0]:
        raise ValueError(
            "the fitted conic is a point or an imaginary ellipse; give points along the rim"
        )
    M = A / -F
    w, V = np.linalg.eigh(M)
    if not (np.isfinite(w).all() and w[0] > 0.0):
        raise ValueError("the fitted conic is an imaginary ellipse; give points along the rim")
    S = V @ np.diag(1.0 / np.sqrt(w)) @ V.T
    return center, 0.5 * (S + S.T)


def conic_distance(Q, points) -> FloatArray:
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
    d, _, _ = orthogonal_residuals(pts, center, S)
    return d


def axes_angle(S) -> tuple[FloatArray, float]:
    """Semi-axes ``(major, minor)`` and the major axis's angle (rad) of an ellipse's shape ``S``."""
    w, V = np.linalg.eigh(S)
    major = V[:, 1]
    angle = math.atan2(major[1], major[0]) % math.pi
    return np.array([w[1], w[0]]), angle


def hartley_normalization(pts) -> FloatArray:
    """Similarity ``N`` moving the centroid to 0 and the mean distance to sqrt(2)."""
    m = pts.mean(axis=0)
    d = np.sqrt(((pts - m) ** 2).sum(axis=1)).mean()
    s = math.sqrt(2.0) / d if d > 0 else 1.0
    return np.array([[s, 0.0, -s * m[0]], [0.0, s, -s * m[1]], [0.0, 0.0, 1.0]])


def coeffs_to_conic(v) -> FloatArray:
    """The symmetric conic matrix ``Q`` of the coefficients ``(A, B, C, D, E, F)`` of ``A x^2 + B x
    y + C y^2 + D x + E y + F = 0``."""
    A, B, C, D, E, F = v
    return np.array([[A, B / 2, D / 2], [B / 2, C, E / 2], [D / 2, E / 2, F]])


def direct_ellipse(pts) -> FloatArray | None:
    """Fitzgibbon's direct least-squares ellipse fit (Halir-Flusser's stable form) as a conic.

    scikit-image's ``measure.EllipseModel`` does the fit, the algorithm of the hand-written fit
    it replaced and as accurate (the figures are in the module's docstring). ``pts`` should be
    normalised (scikit-image normalises again).

    Parameters
    ----------
    pts : (N, 2) array_like
        At least 5 points.

    Returns
    -------
    (3, 3) float64 ndarray or None
        ``Q`` of eq. 22 in the points' frame, unit norm, negative inside the ellipse (the sign
        :func:`conic_from_ellipse` gives), or ``None`` if no real ellipse fits the points.
    """
    # lazy: skimage.measure.fit loads scipy.optimize and scipy.spatial, which only calibration
    # needs (the refinement loads scipy.optimize anyway)
    from skimage.measure import EllipseModel

    pts = np.asarray(pts, dtype=np.float64).reshape(-1, 2)
    # scikit-image 0.25 warns (0.26 fails quietly) on too few or coincident points
    if len(pts) < 5 or not np.isfinite(pts).all() or not (pts - pts.mean(axis=0)).std() > 0.0:
        return None
    # a degenerate fit's NaN (sqrt of a negative, 0 / 0) becomes 0 with a RuntimeWarning; the
    # checks below reject that result, so the warning would say nothing more
    with np.errstate(all="ignore"):
        if hasattr(EllipseModel, "from_estimate"):  # scikit-image >= 0.26
            model = EllipseModel.from_estimate(pts)
            if not model:
                return None
            center, axes, theta = model.center, model.axis_lengths, model.theta
        else:  # scikit-image 0.25, the last release for Python 3.10
            model = EllipseModel()
            if not model.estimate(pts):
                return None
            center, axes, theta = model.params[:2], model.params[2:4], model.params[4]
    center = np.asarray(center, dtype=np.float64)
    axes = np.asarray(axes, dtype=np.float64)
    theta = float(theta)
    if not (np.isfinite(center).all() and np.isfinite(axes).all() and math.isfinite(theta)):
        return None
    if not axes.min() > 0.0:
        return None
    c, s = math.cos(theta), math.sin(theta)
    R = np.array([[c, -s], [s, c]])
    return conic_from_ellipse(center, R @ np.diag(axes) @ R.T)


def is_ellipse(Q) -> bool:
    """Whether the conic ``Q`` is a real, non-degenerate ellipse."""
    A = Q[:2, :2]
    if np.linalg.det(A) <= 0:
        return False
    try:
        center = np.linalg.solve(A, -Q[:2, 2])
    except np.linalg.LinAlgError:
        return False
    F = Q[2, 2] + Q[:2, 2] @ center
    return bool(F * A[0, 0] < 0)


def orthogonal_residuals(pts, center, S, iters=12) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Signed orthogonal distances of ``pts`` to ``center + S u(t)``, their feet and outer normals.

    The foot parameter ``t`` solves ``(x(t) - p) . x'(t) = 0`` by safeguarded Newton iterations
    from the angle of ``S^-1 (p - center)`` (at most ``iters``, each clipped to 0.5 rad, until
    one is below 1e-13), with the step's derivative kept above a fifth of ``|x'|^2``; the
    per-point loop is the kernel :func:`omnicam._kernels.ellipse.ellipse_feet`.

    Returns ``(d, u, n)``: distances ``(N,)``, positive outside; the feet ``u = (cos t, sin
    t)`` ``(N, 2)``; the outer unit normals ``(N, 2)``.

    Hand-written rather than ``skimage.measure.EllipseModel.residuals`` (one
    ``scipy.optimize.leastsq`` per point, unsigned, no feet or normals): the same distances to
    far below a pixel, hundreds of times faster on the points of a 1080p rim (section 3 of
    ``python benchmarks/bench_ellipse_skimage.py`` prints both).
    """
    q = np.ascontiguousarray(np.asarray(pts, np.float64) - center)
    S = np.ascontiguousarray(S, np.float64)
    n = len(q)
    d, u, normal = np.empty(n), np.empty((n, 2)), np.empty((n, 2))
    notice_if_cold(ellipse_feet)
    ellipse_feet(q, np.linalg.inv(S), S, int(iters), d, u, normal)
    return d, u, normal


def refine_geometric(pts, center, S, iters=50) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Levenberg-Marquardt on the orthogonal distances over (cx, cy, s11, s12, s22).

    The symmetric ``S`` parametrisation has no singularity at circles. With the foot parameter
    fixed, ``d r / d theta = -n . d x / d theta`` (the foot moves along the tangent).

    scikit-image has no geometric ellipse fit (``EllipseModel`` is the algebraic direct fit).
    On short arcs the algebraic fit is biased: on a third of a rim the true rim is several times
    closer to this fit than to ``EllipseModel`` alone; on half a rim both are within noise of
    each other (section 4 of ``python benchmarks/bench_ellipse_skimage.py`` prints both).
    """
    p = np.array([center[0], center[1], S[0, 0], S[0, 1], S[1, 1]])

    def unpack(p):
        return p[:2], np.array([[p[2], p[3]], [p[3], p[4]]])

    def evaluate(p):
        c, Sm = unpack(p)
        if np.linalg.det(Sm) <= 0 or Sm[0, 0] <= 0:
            return None, None
        r, u, n = orthogonal_residuals(pts, c, Sm)
        J = -np.stack(
            [
                n[:, 0],
                n[:, 1],
                n[:, 0] * u[:, 0],
                n[:, 0] * u[:, 1] + n[:, 1] * u[:, 0],
                n[:, 1] * u[:, 1],
            ],
            axis=1,
        )
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
                converged = cost - new_cost <= 1e-14 * max(cost, 1e-30) or np.max(
                    np.abs(step)
                ) < 1e-11 * max(1.0, np.abs(p).max())
                cost = new_cost
                lam = max(lam / 10.0, 1e-12)
                improved = True
                break
            lam *= 10.0
        if not improved or converged:
            break
    c, Sm = unpack(p)
    return c, Sm, r


def conics_through_5(samples) -> FloatArray:
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


def sampson_distances(Qs, ph) -> FloatArray:
    """Sampson (first-order geometric) distances, (B, N), of homogeneous points ``ph`` (N, 3)."""
    Qp = ph @ Qs  # (B, N, 3); Q symmetric
    alg = (Qp * ph).sum(axis=-1)
    grad = 2.0 * np.sqrt(Qp[..., 0] ** 2 + Qp[..., 1] ** 2)
    return np.abs(alg) / np.maximum(grad, 1e-300)


def ransac_conic(
    pts_n, thr_n, rng, max_trials, confidence=0.999, batch=64
) -> npt.NDArray[np.bool_] | None:
    """Consensus ellipse of normalised points: returns the inlier mask of the best hypothesis.

    Hand-written rather than ``skimage.measure.ransac`` (one hypothesis per Python iteration):
    ``batch`` five-point conics are solved and scored per numpy call, on at most 1000 points.
    With the same model and Sampson distance in ``skimage.measure.ransac`` the accuracy is the
    same on 1080p rims (clutter and holder arms as outliers) but its time grows much faster
    with the share of outliers: faster with few, several to ten times slower with
    many, and the real 1080p photograph's calibration takes longer with it (sections 2 and 5
    of ``python benchmarks/bench_ellipse_skimage.py`` print the times). With most points
    outliers ``max_trials`` may be fewer than ``confidence`` needs, and either may miss the
    rim (section 2 counts the failures).
    """
    n = len(pts_n)
    ph_all = np.concatenate([pts_n, np.ones((n, 1))], axis=1)
    # hypotheses are scored on at most 1000 points (plenty to rank them), the winner on all
    ph = ph_all if n <= 1000 else ph_all[rng.choice(n, 1000, replace=False)]
    m_eval = len(ph)
    best_count, best_Q = 0, None
    needed, trials = max_trials, 0
    while trials < min(needed, max_trials):
        b = min(batch, max_trials - trials)
        idx = (
            np.argsort(rng.random((b, n)), axis=1)[:, :5]
            if n <= 64
            else rng.integers(0, n, size=(b, 5))
        )
        Qs = conics_through_5(pts_n[idx])
        A = Qs[:, :2, :2]
        ell = (A[:, 0, 0] * A[:, 1, 1] - A[:, 0, 1] ** 2) > 0
        trials += b
        if not ell.any():
            continue
        Qs = Qs[ell]
        masks = sampson_distances(Qs, ph) < thr_n
        counts = masks.sum(axis=1)
        k = int(np.argmax(counts))
        if counts[k] > best_count:
            best_count, best_Q = int(counts[k]), Qs[k]
            w = best_count / m_eval
            denom = math.log(max(1e-12, 1.0 - w**5)) if w < 1.0 else -np.inf
            needed = 0 if w >= 1.0 else int(math.ceil(math.log(1.0 - confidence) / denom))
    if best_Q is None:
        return None
    return sampson_distances(best_Q[None], ph_all)[0] < thr_n
