"""The expected-size policy of :func:`~.rim.detect_rim` (``expected=``, e.g. from ``K`` and the
mirror): which rim to take when the boundary found first is not of the expected size, the
boundaries concentric with it (:func:`_rings`), and what to say when none passes.
"""

from __future__ import annotations

import math
import typing

import cv2
import numpy as np

from .rim_coarse import HINT_RADIUS, N_TRIES, Coarse, coarse_ellipse, size_prior
from .rim_fine import MIN_SUPPORT, RimRejected, fit_from_coarse, rms_limit

__all__ = ["check_expected", "detect_expected"]

_EXPECTED_SCORE = 0.5  # else a rim of the expected size needs half the arc of one of any size
_NEXT_RATIO = 1.5  # a boundary up to 1.5x outside the expected sizes: the rim is next to it
_RING_SHIFT = 0.08  # rings about a boundary found: centres within 8 % of the expected radius
_RING_STEPS = 10  # and the strongest 10 steps along each ray vote
_RING_RMS = 0.5  # a rim found so fits within half the RMS that step 3 of detect_rim allows


class _Ring(typing.NamedTuple):
    center: np.ndarray
    px_radius: float
    share: float


def check_expected(expected):
    """``expected`` as ``(r_min, r_max)`` floats (a number: ``+-HINT_RADIUS``), or ``None``;
    ``ValueError`` naming it."""
    if expected is None:
        return None
    try:
        v = np.asarray(expected, dtype=np.float64).reshape(-1)
    except (TypeError, ValueError):
        v = np.empty(0)
    if len(v) == 1:
        v = v[0] * np.array([1.0 - HINT_RADIUS, 1.0 + HINT_RADIUS])
    if not (len(v) == 2 and np.isfinite(v).all() and 0 < v[0] <= v[1]):
        raise ValueError(
            f"expected must be the rim's radius in px or a range (r_min, r_max) "
            f"with 0 < r_min <= r_max, got {expected!r}"
        )
    return float(v[0]), float(v[1])


def detect_expected(gray, edges, expected, sigma, threshold, rng):
    """:func:`~.rim.detect_rim` with an ``expected`` size (and no hint).

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
    prior = size_prior(None, expected)
    found = {}
    error = None
    for key, kw in (("sized", {"expected": expected}), ("any", {})):
        try:
            found[key] = coarse_ellipse(edges, **kw)
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
            fit = fit_from_coarse(gray, sized, None, sigma, threshold, rng, prior)
        except ValueError as err:
            error = err
            rejected.append(err)
    if fit is None and anysize:
        try:
            fit = fit_from_coarse(gray, anysize, None, sigma, threshold, rng)
        except ValueError as err:
            error = err
            rejected.append(err)
    if fit is not None and _of_size(fit, expected):
        return fit
    # 2. of another size, or none passed: the next boundary of the expected size
    seed = fit
    if seed is None:
        seed = next((e.fit for e in rejected if isinstance(e, RimRejected)), None)
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
    followed at full resolution, best first, by steps 2-3 of :func:`~.rim.detect_rim`, starting
    from the strongest step of either sign near each (the ring is placed already; the
    outermost step would be the clutter outside it). A fit must have its mean radius in the
    expected range and, as a second look where the first found no rim, fit within
    ``_RING_RMS`` of the RMS step 3 allows (a ring of texture edges can fit loosely);
    ``ValueError`` when nothing of that size passes.
    """
    fit = fit_from_coarse(
        gray, _rings(gray, seed, expected, max(1.0, sigma)), None, sigma, threshold, rng, prior
    )
    if not _of_size(fit, expected):
        raise ValueError("the boundary found inside or outside is not of the expected size")
    if fit.rms > _RING_RMS * rms_limit(fit):  # a second look: no compromise
        raise ValueError("the boundary found inside or outside fits too loosely")
    return fit


def _rings(gray, seed, expected, sigma, n_steps=_RING_STEPS):
    """Circles of edges of the ``expected`` size about the centre of the ellipse ``seed``: up
    to ``N_TRIES`` :class:`Coarse` (polarity 0: either sign), most supported first.

    Along rays ``x = c + rho u(t)`` from the centre ``c`` of ``seed`` (``u(t) = (cos t,
    sin t)``, one ray per 2 px of arc, at most 720), the ``n_steps`` strongest local maxima of
    the radial step ``|dG/drho|`` of the image smoothed by ``sigma`` are kept. A circle of
    radius ``k`` about ``c + e`` is ``rho(t) = k + e . u(t)`` to first order in ``|e| / k``,
    so each step votes for ``k = rho - e . u`` over a grid of shifts ``e`` up to
    ``_RING_SHIFT`` of the expected radius; radii in the expected range (1 px bins, +-1 bin)
    are ranked by their votes per ray in the frame (about the share of the circle found),
    and one needs 30 %, as a rim does (step 3 of :func:`~.rim.detect_rim`). Circles, not the shape
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
    for j in np.argsort(votes, axis=None)[::-1][: 50 * N_TRIES]:
        e_i, k_i = divmod(int(j), n_k)
        share = float(votes[e_i, k_i])
        if share < MIN_SUPPORT or len(out) == N_TRIES:
            break
        radius = lo - 1.0 + k_i
        if all(abs(radius - o.px_radius) > 4.0 for o in out):  # one per ring
            out.append(_Ring(c + E[e_i], radius, share))
    if not out:
        raise ValueError("no ring of the expected size about the ellipse found")
    eye = np.eye(2)
    return [Coarse(o.center, o.px_radius * eye, step, 0.0, o.share, o.share, False) for o in out]


def _not_found_message(errors, expected):
    """The ``ValueError`` message when no rim of the ``expected`` size is found: what was found
    (the first boundary rejected: its diameter, centre, RMS and support) and what was
    expected (the range of semi-axes and of diameters, px)."""
    lo, hi = expected
    want = (
        f"none of the expected size passes (semi-axes {lo:.1f}-{hi:.1f} px, a diameter of "
        f"{2 * lo:.0f}-{2 * hi:.0f} px)"
    )
    rejected = [e for e in errors if isinstance(e, RimRejected)]
    if not rejected:
        reason = str(errors[0]) if errors and errors[0] is not None else "no ellipse found"
        return f"{reason.rstrip('.')}; {want}"
    e = rejected[0]
    f = e.fit
    return (
        f"no ellipse found: the best elliptic boundary has a diameter of {f.diameter:.1f} px "
        f"(semi-axes {f.axes[0]:.1f} and {f.axes[1]:.1f} px), centre ({f.center[0]:.1f}, "
        f"{f.center[1]:.1f}) px and {f.rms:.2f} px RMS along {100 * e.support:.0f} % of its "
        f"visible length (a rim needs <= {rms_limit(f):.2f} px RMS along >= "
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
