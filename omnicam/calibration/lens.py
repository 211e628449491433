"""The camera's own reflection (the dark lens/body blob near the image centre) as a measurement.

The camera sees itself where its ray meets the mirror along the normal: the **self-reflection
pixel** is the pinhole image of the mirror point nearest to the camera centre ``C`` (Fermat's
principle with the scene point ``X = C``). It moves by about twice the mirror's tilt as seen
from the camera, which is the direction the rim ellipse pins worst (a tilt with a compensating
shift keeps the ellipse).

Model: the camera body is a ball of radius ``rho`` about ``C`` (what
:mod:`omnicam.synthetic` renders, and a fair model of a lens seen nearly face-on). The blob's
outline is then the set of pixels whose reflected ray ``(P, V)`` (eqs. 6-19) passes at the
distance ``rho`` from ``C``:

    d(u) = |(C - P(u)) x V(u)| = rho          (V unit)

which holds exactly at the true posture on exact data; ``rho`` is a nuisance parameter. The
residual of an outline pixel is ``(d(u) - rho) / |grad_u d|`` (pixels, the gradient taken once
at the starting posture). The outline of a ball's reflection is close to an ellipse; the
ellipse is only used to reject outliers when detecting it (:func:`detect_lens`), never as the
model.

Functions: :func:`detect_lens` (image -> :class:`LensFit`), :func:`self_reflection_point`,
:func:`ray_distances` (``d`` and its pixel gradient), :func:`fit_rho` (closed form) and
:func:`outline_pixels` (the exact outline of a ball, by bisection; for tests and overlays).
"""
from __future__ import annotations

import dataclasses
import math

import cv2
import numpy as np

from .rim import RimFit, _as_gray, _edge_points_along_normals, _fit_with_mask, _hartley, fit_rim

__all__ = ["LensFit", "detect_lens", "self_reflection_point", "ray_distances", "fit_rho",
           "outline_score", "outline_pixels"]


# -- geometry --------------------------------------------------------------------------------
def self_reflection_point(mirror, C, iters=20):
    """The mirror point nearest to ``C`` (mirror frame): where the camera sees itself.

    Newton's method on ``f(X, Y) = |P(X, Y) - C|^2`` with ``P = (X, Y, Z(X, Y))`` on the sheet
    ``Z = b sqrt(1 + (X^2 + Y^2) / a^2)`` (eq. 1), started below ``C`` on the sheet.

    Returns
    -------
    (3,) float64 ndarray
    """
    a2, b2 = mirror.a ** 2, mirror.b ** 2
    C = np.asarray(C, np.float64)
    q = C[:2].copy()

    def grad(q):
        Z = math.sqrt(b2 * (1.0 + (q @ q) / a2))
        Zq = b2 * q / (a2 * Z)  # dZ/d(X, Y)
        return (q - C[:2]) + (Z - C[2]) * Zq

    for _ in range(iters):
        g = grad(q)
        h = 1e-6 * max(1.0, float(np.abs(q).max()))
        H = np.stack([(grad(q + h * e) - g) / h for e in np.eye(2)], axis=1)
        step = np.linalg.solve(H, g)
        q = q - step
        if float(np.abs(step).max()) < 1e-13 * max(1.0, mirror.a):
            break
    return np.array([q[0], q[1], math.sqrt(b2 * (1.0 + (q @ q) / a2))])


def _rays(mirror, R, t, xn):
    """Reflected rays ``(P, V)`` (mirror frame) of undistorted normalised coordinates."""
    C = -R.T @ t  # F_M (eq. 17)
    V = np.concatenate([xn, np.ones((len(xn), 1))], axis=1) @ R  # V_M = R^T V_C (eq. 16)
    V /= np.linalg.norm(V, axis=1, keepdims=True)
    P = mirror.intersect(C, V)  # eqs. 8-12
    return P, mirror.reflect(V, mirror.unit_normal(P))  # eqs. 14-15


def ray_distances(mirror, R, t, xn, Kinv2=None, h=1e-3):
    """Distance ``d`` of each pixel's reflected ray to the camera centre, and ``|grad d|``.

    Parameters
    ----------
    mirror : HyperbolicMirror
    R, t : (3, 3), (3,) ndarray
        Mirror posture (``X_cam = R X_mirror + t``).
    xn : (N, 2) ndarray
        Undistorted normalised coordinates of the pixels.
    Kinv2 : (2, 2) ndarray, optional
        ``inv(K)[:2, :2]``; with it the gradient is also returned, per pixel (forward
        differences of ``h`` px).

    Returns
    -------
    d : (N,) ndarray
        ``|(C - P) x V|`` (NaN where the ray misses the mirror or points away from ``C``).
    g : (N,) ndarray
        ``|grad_u d|`` per pixel (only with ``Kinv2``).
    """
    C = -R.T @ t

    def dist(x):
        P, V = _rays(mirror, R, t, x)
        w = C - P
        d = np.linalg.norm(np.cross(w, V), axis=1)
        return np.where((w * V).sum(axis=1) > 0, d, np.nan)

    d = dist(xn)
    if Kinv2 is None:
        return d
    gx = (dist(xn + h * Kinv2[:, 0]) - d) / h
    gy = (dist(xn + h * Kinv2[:, 1]) - d) / h
    return d, np.hypot(gx, gy)


def fit_rho(d, g):
    """``rho`` minimising ``sum(((d - rho) / g)^2)`` (closed form) over the finite rows."""
    ok = np.isfinite(d) & np.isfinite(g) & (g > 0)
    if ok.sum() < 3:
        return math.nan
    w = 1.0 / g[ok] ** 2
    return float((w * d[ok]).sum() / w.sum())


def outline_score(mirror, R, t, xn, Kinv2):
    """RMS outline residual (px) of the blob ``xn`` under a posture, and the fitted ``rho``.

    ``inf`` when fewer than 3 rays reach back towards the camera.
    """
    d, g = ray_distances(mirror, R, t, xn, Kinv2)
    rho = fit_rho(d, g)
    if not np.isfinite(rho):
        return math.inf, math.nan
    r = (d - rho) / g
    r = r[np.isfinite(r)]
    if len(r) < 0.8 * len(xn):  # most of the outline must see the camera
        return math.inf, rho
    return float(np.sqrt(np.mean(r * r))), rho


def outline_pixels(camera, rho, n=90, tol=1e-10):
    """Exact outline of a ball of radius ``rho`` about the camera centre, as the camera sees it.

    Along ``n`` rays (evenly spaced angles) from the self-reflection pixel, the pixel whose
    reflected ray passes at the distance ``rho`` from the camera centre, by bisection (the
    distance grows along each ray from 0 at the self-reflection pixel). For tests and overlays.

    Returns
    -------
    outline : (n, 2) float64 ndarray
        Pixels (distorted, as seen); NaN where the outline leaves the mirror.
    centre : (2,) float64 ndarray
        The self-reflection pixel.
    """
    C = camera.camera_center
    P0 = self_reflection_point(camera.mirror, C)
    u0 = _project_pixel(camera, P0[None])[0]

    def dist(u):
        P, V = camera.unproject(u)
        w = C - P
        return np.linalg.norm(np.cross(w, V), axis=1)

    ang = np.linspace(0.0, 2.0 * np.pi, int(n), endpoint=False)
    e = np.stack([np.cos(ang), np.sin(ang)], axis=1)
    lo = np.zeros(len(e))
    hi = np.ones(len(e))
    for _ in range(60):  # grow until beyond the outline
        d = dist(u0 + hi[:, None] * e)
        grow = np.isfinite(d) & (d < rho)
        if not grow.any():
            break
        hi = np.where(grow, 2.0 * hi, hi)
    while (hi - lo).max() > tol:
        mid = 0.5 * (lo + hi)
        d = dist(u0 + mid[:, None] * e)
        inside = d < rho
        lo = np.where(inside, mid, lo)
        hi = np.where(inside, hi, mid)
    out = u0 + (0.5 * (lo + hi))[:, None] * e
    ok = np.isfinite(dist(out))
    out[~ok] = np.nan
    return out, u0


def _project_pixel(camera, points_mirror):
    """Pinhole pixels of mirror-frame points (with ``D``), no reflection."""
    Xc = points_mirror @ camera.R.T + camera.tvec
    D = camera.D
    img, _ = cv2.projectPoints(Xc.reshape(-1, 1, 3), np.zeros(3), np.zeros(3), np.eye(3),
                               None if D is None else np.asarray(D, np.float64))
    xy = img.reshape(-1, 2)
    K = camera.K
    return xy @ K[:2, :2].T + K[:2, 2]


# -- detection -------------------------------------------------------------------------------
@dataclasses.dataclass(frozen=True, eq=False)
class LensFit:
    """The camera's reflection (dark blob) found by :func:`detect_lens`.

    Attributes
    ----------
    points : (N, 2) float64 ndarray
        Subpixel outline points (the blob's outer edge, inliers of the ellipse fit), px.
    center : (2,) float64 ndarray
        Rough centre (the fitted ellipse's), px.
    radius : float
        Mean semi-axis of the fitted ellipse, px.
    rms : float
        RMS distance of ``points`` to the fitted ellipse, px (the outline of a ball's reflection
        is close to, not exactly, an ellipse: this is a quality figure, not the model's residual).
    quality : float
        Fraction of the search rays that gave an inlier edge point, in [0, 1].
    """

    points: np.ndarray
    center: np.ndarray
    radius: float
    rms: float
    quality: float

    def __post_init__(self):
        for name in ("points", "center"):
            arr = np.array(getattr(self, name), np.float64)
            arr.flags.writeable = False
            object.__setattr__(self, name, arr)

    def __repr__(self):
        return (f"LensFit(center=({self.center[0]:.2f}, {self.center[1]:.2f}), radius="
                f"{self.radius:.2f} px, points={len(self.points)}, rms={self.rms:.3f} px, "
                f"quality={self.quality:.2f})")


def _dark_blob(gray, rim, search):
    """Centre and shape ``S`` of the most compact dark component near the rim centre."""
    h, w = gray.shape
    r_rim = float(rim.axes[1])
    R = search * r_rim
    cx, cy = float(rim.center[0]), float(rim.center[1])
    x0, x1 = max(0, int(cx - R)), min(w, int(cx + R) + 1)
    y0, y1 = max(0, int(cy - R)), min(h, int(cy + R) + 1)
    if x1 - x0 < 8 or y1 - y0 < 8:
        return None
    roi = cv2.GaussianBlur(gray[y0:y1, x0:x1], (0, 0), 0.7)
    yy, xx = np.mgrid[y0:y1, x0:x1]
    inside = (xx - cx) ** 2 + (yy - cy) ** 2 <= R * R
    vals = roi[inside]
    lo, med = float(np.percentile(vals, 0.5)), float(np.median(vals))
    if not med - lo > 0.05:
        return None
    min_area = max(12.0, (0.01 * r_rim) ** 2 * math.pi)
    best = None
    for frac in (0.3, 0.5):  # the lens is the darkest thing there; the body a little lighter
        mask = ((roi <= lo + frac * (med - lo)) & inside).astype(np.uint8)
        mask = cv2.morphologyEx(mask, cv2.MORPH_OPEN, np.ones((3, 3), np.uint8))
        n, lab, stats, cent = cv2.connectedComponentsWithStats(mask, connectivity=8)
        for k in range(1, n):
            area = float(stats[k, cv2.CC_STAT_AREA])
            if area < min_area:
                continue
            ys, xs = np.nonzero(lab == k)
            pts = np.stack([xs + x0, ys + y0], axis=1).astype(np.float64)
            c = pts.mean(axis=0)
            cov = np.cov(pts.T) + np.eye(2) / 12.0
            wv, V = np.linalg.eigh(cov)
            if wv[0] <= 0:
                continue
            # a filled ellipse of semi-axes (A, B) has variances A^2/4, B^2/4
            S = V @ np.diag(2.0 * np.sqrt(wv)) @ V.T
            fill = area / (math.pi * 4.0 * math.sqrt(wv[0] * wv[1]))
            elong = math.sqrt(wv[1] / wv[0])
            if fill < 0.75 or elong > 1.6:
                continue
            off = float(np.hypot(*(c - rim.center))) / r_rim
            score = fill - off - 0.2 * (elong - 1.0)
            if best is None or score > best[0]:
                best = (score, c, S)
        if best is not None:
            break
    return None if best is None else (best[1], best[2])


def _two_step_edges(gray, center, S, r_in, r_out, blur=0.45, step=0.25, iters=12):
    """Subpixel outer edges of a dark blob with a darker core: a two-step model per ray.

    Along the ``n`` normals of the ellipse ``center + S (cos t, sin t)`` the unsmoothed image
    is sampled (bilinear) from ``-r_in`` to ``+r_out`` px and fitted by

        f(s) = L + (B - L) Phi((s - p1) / w) + (O_k - B) Phi((s - p2) / w)

    (``Phi`` the normal CDF, ``w = blur``): the lens's own edge ``p1`` (level ``L`` inside),
    the body's silhouette ``p2`` (level ``B`` between, shared by all rays), and the local scene
    level ``O_k`` outside. A symmetric blur leaves ``p2`` unbiased whatever the scene's
    brightness, where the peak or centroid of the derivative is pulled towards the lens edge
    (up to 0.4 px at 500x500, where the two are 2 px apart). Gauss-Newton per ray for
    ``(p1, p2, O_k)``, alternated with linear least squares for ``(L, B)``.

    Returns ``(points, rms, n_tried)``: the (M, 2) edge points ``e + p2 n`` of the rays kept
    (in the image, converged inside the window, outer step at least twice the model's RMS),
    each ray's RMS model residual, and the number of rays in the image.
    """
    from scipy.special import erf
    h, w = gray.shape
    axes = np.sqrt(np.linalg.eigvalsh(S @ S.T))
    n = int(max(64, min(4000, 2.0 * np.pi * axes[1])))
    tt = np.linspace(0.0, 2 * np.pi, n, endpoint=False)
    e = center + np.stack([np.cos(tt), np.sin(tt)], axis=1) @ S.T
    der = np.stack([-np.sin(tt), np.cos(tt)], axis=1) @ S.T
    nrm = np.stack([der[:, 1], -der[:, 0]], axis=1)
    nrm /= np.linalg.norm(nrm, axis=1, keepdims=True)
    tau = np.arange(-r_in, r_out + 0.5 * step, step)
    inside = np.ones(n, bool)
    for end in (tau[0], tau[-1]):
        q = e + end * nrm
        inside &= (q[:, 0] >= 1) & (q[:, 0] <= w - 2) & (q[:, 1] >= 1) & (q[:, 1] <= h - 2)
    e, nrm = e[inside], nrm[inside]
    if len(e) < 12:
        return np.empty((0, 2)), np.empty(0), len(e)
    mx = (e[:, :1] + nrm[:, :1] * tau).astype(np.float32)
    my = (e[:, 1:] + nrm[:, 1:] * tau).astype(np.float32)
    f = cv2.remap(gray, mx, my, cv2.INTER_LINEAR).astype(np.float64)
    m = len(e)
    # start: silhouette on the ellipse, lens edge 0.2 radii inside it
    p2 = np.zeros(m)
    p1 = np.full(m, -min(0.2 * float(axes.mean()), 0.6 * r_in))
    L = float(np.percentile(f[:, tau < p1[0] - 0.5], 5)) if (tau < p1[0] - 0.5).any() \
        else float(f.min())
    O = np.median(f[:, tau > 1.0], axis=1) if (tau > 1.0).any() else f[:, -1].copy()
    mid = (tau > p1[0] + 0.5) & (tau < -0.5)
    B = float(np.median(f[:, mid])) if mid.any() else 0.5 * (L + float(np.median(O)))
    s2 = math.sqrt(2.0)

    def model(p1, p2, O, L, B):
        z1, z2 = (tau - p1[:, None]) / blur, (tau - p2[:, None]) / blur
        F1, F2 = 0.5 * (1 + erf(z1 / s2)), 0.5 * (1 + erf(z2 / s2))
        g1, g2 = np.exp(-0.5 * z1 * z1) / (blur * math.sqrt(2 * math.pi)), \
            np.exp(-0.5 * z2 * z2) / (blur * math.sqrt(2 * math.pi))
        return L + (B - L) * F1 + (O[:, None] - B) * F2, F1, F2, g1, g2

    for _ in range(iters):
        fm, F1, F2, g1, g2 = model(p1, p2, O, L, B)
        r = f - fm
        J = np.stack([-(B - L) * g1, -(O[:, None] - B) * g2, F2], axis=2)  # d f / d(p1, p2, O)
        JtJ = np.einsum("nki,nkj->nij", J, J) + 1e-9 * np.eye(3)
        Jtr = np.einsum("nki,nk->ni", J, r)
        JtJ[:, 0, 0] += 1e-6 * (B - L) ** 2  # keeps p1 defined when the lens step is faint
        d = np.linalg.solve(JtJ, Jtr[..., None])[..., 0]
        p1 = p1 + np.clip(d[:, 0], -0.5, 0.5)
        p2 = p2 + np.clip(d[:, 1], -0.5, 0.5)
        O = O + d[:, 2]
        p1 = np.minimum(p1, p2 - 0.25)
        # (L, B) by linear least squares: f - O F2 = L (1 - F1) + B (F1 - F2)
        _, F1, F2, _, _ = model(p1, p2, O, L, B)
        A = np.stack([(1 - F1).ravel(), (F1 - F2).ravel()], axis=1)
        sol = np.linalg.lstsq(A, (f - O[:, None] * F2).ravel(), rcond=None)[0]
        L, B = float(sol[0]), float(sol[1])
    fm = model(p1, p2, O, L, B)[0]
    rms = np.sqrt(np.mean((f - fm) ** 2, axis=1))
    ok = (p2 > tau[0] + 1.0) & (p2 < tau[-1] - 1.0) & (np.abs(O - B) > 2.0 * rms) & (O > B)
    return e[ok] + p2[ok, None] * nrm[ok], rms[ok], m


def detect_lens(image, rim, *, search=0.3, sigma=0.3, threshold=0.5, blur=0.4, rng=0):
    """Find the outline of the camera's own reflection (a dark blob near the rim centre).

    1. The most compact dark connected component (the lens; the body around it is a little
       lighter) within ``search`` times the rim's minor semi-axis of the rim centre; its
       moments give a rough ellipse.
    2. Along rays from the blob centre (the normals of that ellipse, at least 64), the outermost
       strong dark-to-bright rise of the image smoothed by ``sigma`` is located to subpixel
       precision (the helpers of :mod:`.rim`, on the negated image), and a robust ellipse
       (RANSAC, :func:`.rim.fit_rim`) rejects points on scene edges.
    3. Two more rounds along the fitted ellipse's normals in a narrower window, again the
       outermost strong rise at the peak of the derivative (parabola through the logs).
    4. The final points: a two-step edge model per ray (:func:`_two_step_edges`: the dark
       lens, the lighter body, the scene), since the peak or centroid of the derivative is
       pulled towards the lens's own edge, only ~0.2 blob radii inside the body's silhouette
       (2 px at 500x500); points off the ellipse by more than 3.5 robust sigmas are dropped.

    The ellipse only rejects outliers; :func:`ray_distances` gives the exact model.

    Parameters
    ----------
    image : (H, W) or (H, W, 3|4) ndarray
        Grey or BGR(A) image, uint8, uint16 or float.
    rim : RimFit
        The rim (its centre and size bound the search).
    search : float
        Search radius about the rim centre, in units of the rim's minor semi-axis.
    sigma : float
        Gaussian smoothing before locating the edge, px.
    threshold : float
        Minimum inlier cut of the ellipse fit, px.
    blur : float
        Standard deviation of the image's own edge blur, px, for the final edge model (0.4
        suits a sharp render or photograph: pixel area plus interpolation).
    rng : int or numpy.random.Generator
        Seed of the RANSAC sampling.

    Returns
    -------
    LensFit

    Raises
    ------
    ValueError
        No compact dark blob near the rim centre, too few edge points on it, or an outline that
        is not close to an ellipse (the camera's reflection is not visible, or hidden by a
        holder or clutter): the calibration then proceeds without it.
    """
    if not isinstance(rim, RimFit):
        raise ValueError(f"rim must be a RimFit (from detect_rim or fit_rim), got "
                         f"{type(rim).__name__}")
    gray = _as_gray(image)
    found = _dark_blob(gray, rim, float(search))
    if found is None:
        raise ValueError("no lens found: no compact dark blob near the rim centre (the camera's "
                         "reflection)")
    center, S = found
    G = cv2.GaussianBlur(gray, (0, 0), float(sigma)) if sigma > 0 else gray
    negG = -G
    r0 = float(np.sqrt(np.linalg.det(S)))
    cw = max(1.0, 2.0 * sigma)  # half-width of the later search windows beyond the spread
    fit = None
    n_tried = 0
    for i in range(3):
        hw = max(3.0, 0.6 * r0) if i == 0 else cw + max(1.0, 3.0 * fit.rms)
        pts, n_tried = _edge_points_along_normals(negG, center, S, hw, outermost=True)
        if len(pts) < 12:
            raise ValueError(f"no lens found: only {len(pts)} edge points around the dark blob at "
                             f"({center[0]:.0f}, {center[1]:.0f})")
        try:
            if fit is None:
                fit = fit_rim(pts, threshold=max(threshold, 0.05 * r0), rng=rng)
            else:
                d = np.abs(fit.distance(pts))
                mask = d <= max(threshold, 3.5 * 1.4826 * float(np.median(d)))
                if mask.sum() < 12:
                    raise ValueError("too few edge points near the blob's ellipse")
                fit = _fit_with_mask(pts, _hartley(pts), mask, True, threshold)
        except ValueError as err:
            raise ValueError(f"no lens found: the dark blob's edge is not elliptic ({err})") \
                from None
        center, S = fit.center, fit.shape_matrix
    radius = float(np.mean(fit.axes))
    pts, _, n_tried = _two_step_edges(gray, center, S, 0.45 * radius + 1.0, 2.0, blur=blur)
    if len(pts) >= 12:
        d = np.abs(fit.distance(pts))
        mask = d <= max(0.1, 3.5 * 1.4826 * float(np.median(d)))
        if mask.sum() >= 12:
            try:
                fit = _fit_with_mask(pts, _hartley(pts), mask, True, 0.1)
            except ValueError:
                pass
    quality = float(len(fit.points)) / max(n_tried, 1)
    if quality < 0.5 or fit.rms > max(0.5, 0.05 * radius) or fit.axes[0] > 1.6 * fit.axes[1]:
        raise ValueError(f"no lens found: the dark blob's outline is found along "
                         f"{100 * quality:.0f} % of it with {fit.rms:.2f} px RMS to an ellipse "
                         f"(need >= 50 % and <= {max(0.5, 0.05 * radius):.2f} px)")
    return LensFit(points=fit.points, center=fit.center, radius=radius, rms=float(fit.rms),
                   quality=quality)
