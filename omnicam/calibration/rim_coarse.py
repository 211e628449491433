"""Step 1 of :func:`~.rim.detect_rim`: the rim roughly, on a small copy of the image.

Edge pixels vote for circle centres along their gradients, radii are ranked by the arc length
they gather and the best circles are refined to ellipses (:func:`coarse_ellipse`). With a hint or
an expected size, each arc is weighted by how well its size fits (:func:`size_prior`).
"""

from __future__ import annotations

import math
import typing

import cv2
import numpy as np

from .ellipse import (
    direct_ellipse,
    ellipse_from_conic,
    hartley_normalization,
    is_ellipse,
    orthogonal_residuals,
    ransac_conic,
)

__all__ = ["Coarse", "coarse_edges", "coarse_ellipse", "size_prior"]

_COARSE_SIZE = 256  # longer side of the image used to find the rim roughly
HINT_RADIUS = 0.15  # a hinted rim's radius is within +-15 % of the hint's
HINT_CENTER = 0.15  # and its centre within 15 % of the hint's radius of the hint's centre
N_TRIES = 3  # coarse ellipses tried at full resolution, best first


class Coarse(typing.NamedTuple):
    """A rough rim: centre and shape ``S`` in full-resolution px, the size of one coarse pixel,
    the polarity (``+1`` a mirror brighter than what surrounds it, ``-1`` darker, ``0`` either
    along the rim), the score and the support (arc length)."""

    center: np.ndarray
    S: np.ndarray
    px: float
    polarity: float
    score: float
    support: float
    outermost: bool = True  # the first fine round takes each normal's outermost strong step


def size_prior(hint, expected):
    """Weight of a rim size for the guided search: ``semi (2,) px -> exp(-z^2 / 2)``, ``z`` the
    log of the mean radius over the hinted radius or the middle of the expected range, in
    units of ``HINT_RADIUS / 2`` or of a quarter of the range's log width; None unguided."""
    if hint is not None:
        nominal, spread = hint[2], HINT_RADIUS / 2.0
    elif expected is not None:  # the range's ends at two standard deviations (log radius)
        nominal = math.sqrt(expected[0] * expected[1])
        spread = max(0.25 * math.log(expected[1] / expected[0]), 0.02)
    else:
        return None

    def prior(semi):
        z = math.log(math.sqrt(float(semi[0]) * float(semi[1])) / nominal) / spread
        return math.exp(-0.5 * z * z)

    return prior


def coarse_edges(gray):
    """Edge pixels of a copy whose longer side is ``_COARSE_SIZE`` px (its shorter side at least
    3/4 of that), for :func:`coarse_ellipse`:
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


def coarse_ellipse(coarse_edges, hint=None, expected=None):
    """The rim roughly: the best few ellipses found on a copy whose longer side is
    ``_COARSE_SIZE`` px, best first, as :class:`Coarse` (centre and shape ``S`` in
    full-resolution px, the size of one coarse pixel, the polarity: ``+1`` for a mirror
    brighter than what surrounds it, ``-1`` for a darker one, ``0`` for either along the rim;
    the score and the arc length); ``coarse_edges`` is what :func:`coarse_edges` returns.

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
       radius (``sigma = HINT_RADIUS / 2``) or about the middle of the expected range (its
       ends at two sigma). A holder's outer edge, a few percent to tens of percent larger than
       the rim and often the stronger edge, then loses to the rim. (Not by the texture
       contrast across the ellipse, textured mirror inside and plain holder outside: a plain
       wall seen in the mirror and noise on a dark holder reverse it.)

    ``hint = (cx, cy, r)`` (full-resolution px) keeps centres within ``HINT_CENTER * r`` of
    ``(cx, cy)`` and radii within ``r (1 -+ HINT_RADIUS)``; ``expected = (r_min, r_max)`` keeps
    radii in that range.
    """
    p, g, (H, W), (sx, sy) = coarse_edges
    ss = 0.5 * (sx + sy)  # full-resolution px -> coarse px (the aspect is kept by resize)

    hint_c, hint_r = None, None
    if hint is not None:  # the hint overrides the default range (and ``expected``)
        hint_c = (np.array(hint[:2], np.float64) + 0.5) * (sx, sy) - 0.5
        hint_r = hint[2] * ss
        rmin, rmax = (1.0 - HINT_RADIUS) * hint_r - 1.0, (1.0 + HINT_RADIUS) * hint_r + 1.0
    elif expected is not None:
        rmin, rmax = expected[0] * ss - 1.0, expected[1] * ss + 1.0
    else:
        rmin, rmax = 0.08 * max(H, W), 0.8 * max(H, W)
    rmin = max(rmin, 3.0)
    if not rmax > rmin:
        raise ValueError("no ellipse found: the rim size asked for is too small for the image")
    prior = size_prior(hint, expected)
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
    for score, support, c, S, polarity in found[:N_TRIES]:
        # to full resolution: x = (x_small + 0.5) / s - 0.5 per axis
        AS = A @ S
        wv, V = np.linalg.eigh(AS @ AS.T)
        out.append(
            Coarse(
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
    """Steps 1-3 of :func:`coarse_ellipse` for one polarity: ``[(support, c, S), ...]``.

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
        far = np.hypot(xx - m - hint_c[0], yy - m - hint_c[1]) > HINT_CENTER * hint_r + 1.5
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
