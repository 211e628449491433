"""The a posteriori uncertainty of the refined posture.

:func:`posture_uncertainty` gives the first-order a posteriori covariance and its weakest
direction, :func:`profile_uncertainty` the one stated: widened to the region of the cost itself
where that reaches farther (near alignment, where the rim depends on the tilt only to second
order). Both weight each source by its observed residuals and their correlation along the
contour over every lag (:func:`correlation_factor`).
"""

from __future__ import annotations

import dataclasses
import math

import cv2
import numpy as np

from ..gauge import perpendicular_basis
from .refine_residuals import (
    N_POSTURE,
    Posture,
    Problem,
    ReflectionTerm,
    RimTerm,
    reflection_spec,
)

__all__ = [
    "MIN_EFFECTIVE_POINTS",
    "PROFILE_CHI2",
    "Uncertainty",
    "correlation_factor",
    "perturbed_posture",
    "posture_offsets",
    "posture_uncertainty",
    "profile_uncertainty",
    "uncertainty_from_cov",
]


@dataclasses.dataclass(frozen=True)
class Uncertainty:
    """A posteriori uncertainty of the posture (:func:`posture_uncertainty`,
    :func:`profile_uncertainty`).

    Attributes
    ----------
    axis_std_deg : float
        RMS error of the mirror axis direction, degrees.
    origin_std : float
        Square root of the trace of the origin's covariance, length unit.
    weak_tilt_deg, weak_shift : float
        The least determined combination of the posture (the covariance's principal direction,
        angles scaled by the camera's distance to the mirror): one standard deviation along it
        is a tilt of ``weak_tilt_deg`` with a shift of the origin of ``weak_shift``.
    weak_share : float
        Fraction of the posture's variance along that direction.
    cov : (5, 5) ndarray or None
        The posture's covariance: two small rotations of the mirror axis (radians, about the
        axes of :func:`posture_offsets`) and the origin's shift (length unit).
    first_order_axis_std_deg : float
        ``axis_std_deg`` of the first-order covariance at the estimate (what the Jacobian
        alone says; NaN when that is all there is).
    aligned_chi2 : float
        How much the cost (in units of the observed residual variance, every parameter but
        the two axis angles fitted) rises from the estimate to the aligned posture, midway
        between it and its twin (the other physical posture of the same rim), where the rim's
        image depends on the tilt only to second order (NaN without a twin).
    aligned_px : float
        The RMS change of the rim's image between the estimate and that aligned posture, px.
    twin_deg : float
        The angle between the mirror axes of the estimate and its twin, degrees.
    widened : bool
        Whether the cost itself widened the first-order uncertainty of the axis.
    """

    axis_std_deg: float
    origin_std: float
    weak_tilt_deg: float = math.nan
    weak_shift: float = math.nan
    weak_share: float = math.nan
    cov: object = dataclasses.field(default=None, compare=False, repr=False)
    first_order_axis_std_deg: float = math.nan
    aligned_chi2: float = math.nan
    aligned_px: float = math.nan
    twin_deg: float = math.nan
    widened: bool = False

    def with_cov(self, cov, tvec):
        """The same, with the covariance ``cov`` (at the posture with ``tvec``) in place of
        this one's: the axis and origin uncertainties and the weak direction follow it."""
        new = uncertainty_from_cov(cov, tvec)
        return dataclasses.replace(
            self,
            **{k: getattr(new, k) for k in ("axis_std_deg", "origin_std", "cov")},
            **{k: getattr(new, k) for k in ("weak_tilt_deg", "weak_shift", "weak_share")},
        )

    def describe(self):
        """The weakly determined direction in words."""
        if not np.isfinite(self.weak_tilt_deg):
            return "unknown"
        return (
            f"a tilt of {self.weak_tilt_deg:.3g} deg with a compensating shift of "
            f"{self.weak_shift:.3g} (one standard deviation; {100 * self.weak_share:.0f} % "
            f"of the posture's variance)"
        )


#: Fewest independent residuals a contour is taken to be worth (:func:`correlation_factor`):
#: twice the posture's 5 parameters.
MIN_EFFECTIVE_POINTS = 10


def correlation_factor(res, floor=0.0):
    """``sqrt(tau)``: how much the correlation of residuals along a contour (in the order
    given) inflates a standard deviation computed as if they were independent, with
    ``tau = N / N_eff = 1 + 2 sum_k rho_k`` the integrated autocorrelation time over every lag.

    Edge points share blur and interpolation, and a misfit of the model or of the edge detector
    leaves a smooth residual field whose correlation lasts for a hundred points and more (the
    rims of real photographs stay correlated over tens of lags), which lag 1 alone does not
    see. The sum is Geyer's initial monotone sequence estimator (the sums
    ``rho_2j + rho_2j+1`` of neighbouring lags, taken while positive and made non-increasing;
    ``(1 + rho) / (1 - rho)`` for an AR(1) sequence), and ``N_eff`` is at least
    ``MIN_EFFECTIVE_POINTS``.

    The noise is taken as the residuals observed plus an independent part of standard
    deviation ``floor`` px (the edge-location limit), so every ``rho_k`` is the residuals' own
    times ``m / (m + floor^2)``, ``m`` their mean square. Residuals far below the floor
    (round-off on exact data) then count as independent, whatever order their round-off
    happens to fall in (which differs between BLAS kernels); residuals far above it keep their
    own correlation.
    """
    r = np.asarray(res, np.float64)
    r = r[np.isfinite(r)] - np.mean(r[np.isfinite(r)]) if np.isfinite(r).sum() > 8 else None
    if r is None or not np.any(r):
        return 1.0
    n = len(r)
    ss = float(r @ r)
    m = ss / n
    f = np.fft.rfft(r, 2 * n)  # zero-padded: the sequence is not circular
    rho = np.fft.irfft(f * np.conj(f), 2 * n)[:n] / ss
    rho[1:] *= m / (m + float(floor) ** 2)
    rho[0] = 1.0
    pairs = rho[: 2 * (n // 2)].reshape(-1, 2).sum(axis=1)
    stop = int(np.argmax(pairs <= 0.0)) if np.any(pairs <= 0.0) else len(pairs)
    tau = -1.0 + 2.0 * float(np.sum(np.minimum.accumulate(pairs[:stop])))
    return math.sqrt(min(max(tau, 1.0), max(n / MIN_EFFECTIVE_POINTS, 1.0)))


def _weighted_problem(K, mirror, R, t, rim_px, rim_sigma, reflection, reflection_sigma, floor):
    """The rim's (and the reflection's) problem at ``(R, t)`` and each row's weight
    ``1 / (sigma f)``: ``sigma`` the source's observed RMS residual (at least ``floor``), ``f``
    its :func:`correlation_factor`; the free ``z``'s weak pull carries (almost) no weight."""
    terms = [RimTerm(K, mirror, R, t, rim_px)]
    sig = [max(float(rim_sigma), floor)]
    spec = reflection_spec(reflection)
    if spec is not None and reflection_sigma is not None and np.isfinite(reflection_sigma):
        terms.append(ReflectionTerm(K, mirror, R, t, *spec))
        sig.append(max(float(reflection_sigma), floor))
    prob = Problem(Posture(R, t), terms)
    w = []
    for term, s in zip(terms, sig):
        res = term.residuals(R, t, term.x0())
        n_out = len(res) - (getattr(term, "prior", None) is not None)
        w.append(np.full(len(res), 1.0 / (s * correlation_factor(res[:n_out], floor))))
    w = np.concatenate(w)
    if len(terms) > 1 and terms[-1].prior is not None:
        w[-1] = 1e-3  # the weak pull on z is not a measurement: (almost) no information
    return prob, w


def _covariance_at(
    K, mirror, rvec, tvec, rim_points, rim_sigma, reflection, reflection_sigma, floor
):
    """At the posture ``(rvec, tvec)``: the weighted refinement problem, its row weights ``w``,
    its Jacobian ``J``, ``tvec`` as an array and the inverse of the information
    ``(J^T W J)^-1`` (None when singular)."""
    K = np.asarray(K, np.float64)
    R = cv2.Rodrigues(np.asarray(rvec, np.float64).reshape(3, 1))[0]
    t = np.asarray(tvec, np.float64)
    rim_px = np.ascontiguousarray(np.asarray(rim_points, np.float64).reshape(-1, 2))
    prob, w = _weighted_problem(
        K, mirror, R, t, rim_px, rim_sigma, reflection, reflection_sigma, floor
    )
    J = prob.jacobian(prob.x0()) * w[:, None]
    try:
        return prob, w, J, t, np.linalg.inv(J.T @ J)
    except np.linalg.LinAlgError:
        return prob, w, J, t, None


def posture_uncertainty(
    K, mirror, rvec, tvec, rim_points, rim_sigma, reflection=None, reflection_sigma=None, floor=0.02
):
    """First-order a posteriori covariance of the posture from the rim (and the reflection).

    With ``J`` the Jacobian of the residuals (px) with respect to the posture (two axis angles,
    ``tvec``) and the nuisance parameters, each source's rows weighted by ``1 / sigma`` with
    ``sigma`` its observed RMS residual (at least ``floor`` px) times the inflation that the
    correlation of the residuals along the contour implies (:func:`correlation_factor`; edge
    points share blur and interpolation), the covariance is ``(J^T J)^-1``; the posture block is
    reported. The rim pins the axis only weakly (a tilt of the mirror and a lateral shift keep
    the ellipse almost unchanged), which the weak direction names. Near alignment the rim's
    image depends on that tilt only to second order and this is too small:
    :func:`profile_uncertainty` states it from the cost itself.

    Parameters
    ----------
    rim_sigma : float
        Observed RMS of the rim residuals, px.
    reflection : ReflectionSpec, optional
        As for :func:`refine_posture`; joins with ``reflection_sigma`` (its observed RMS, px).

    Returns
    -------
    Uncertainty
    """
    *_, t, full = _covariance_at(
        K, mirror, rvec, tvec, rim_points, rim_sigma, reflection, reflection_sigma, floor
    )
    if full is None:
        return Uncertainty(math.inf, math.inf)
    return uncertainty_from_cov(full[:N_POSTURE, :N_POSTURE], t)


#: The stated region of the axis (:func:`profile_uncertainty`): where the profile cost rises
#: by at most the 95 % point of chi-square with 2 degrees of freedom (the two axis angles).
PROFILE_CHI2 = -2.0 * math.log(0.05)
#: The first-order covariance is kept when the profile cost at the edge of its region, along
#: the twin's direction and across it, is at least this share of ``PROFILE_CHI2`` (the region
#: reaches at most 1 / sqrt(0.8) = 1.12 times as far).
LINEAR_SHARE = 0.8
#: Directions searched for the region's reach, and the farthest tilt searched (radians).
PROFILE_DIRECTIONS = 12
MAX_REACH = math.radians(20.0)


class _TiltProfile:
    """The weighted cost (``sum (w r)^2``) with the axis turned by ``a`` (two angles, radians)
    from the estimate and every other parameter fitted, less the estimate's: Gauss-Newton
    from the first-order compensation, with the Jacobian of the estimate."""

    def __init__(self, prob, w, J):
        self.prob, self.w, self.x0 = prob, w, prob.x0()
        self.Jt = J[:, :2]
        self.pinv = np.linalg.pinv(J[:, 2:])
        self.c0, self.x = 0.0, self.x0
        self.c0 = self(np.zeros(2))

    def __call__(self, a, iters=6):
        a = np.asarray(a, np.float64)
        y = -self.pinv @ (self.Jt @ a)
        best, best_x = math.inf, None
        for _ in range(iters):
            x = self.x0.copy()
            x[:2] = a
            x[2:] += y
            r = self.w * self.prob.residuals(x)
            c = float(r @ r) if np.isfinite(r).all() else math.inf
            if not c < best - 1e-4:
                break
            best, best_x = c, x
            y = y - self.pinv @ r
        self.x = best_x if best_x is not None else self.x0
        return best - self.c0

    def rim_ms(self):
        """Mean square of the rim residuals at the last posture evaluated, px^2."""
        return float(np.mean(self.prob.parts(self.x)[0] ** 2))


def _reach(profile, d, start, cap, q):
    """How far from the estimate along ``d`` the profile cost stays within ``q`` (doubling
    from ``start``, then bisecting; the region is taken to be star-shaped about the estimate),
    at most ``cap``."""
    lo, s = 0.0, min(start, cap)
    while True:
        if not profile(s * d) <= q:
            hi = s
            break
        lo = s
        if s >= cap:
            return cap
        s = min(2.0 * s, cap)
    for _ in range(5):
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if profile(mid * d) <= q else (lo, mid)
    return 0.5 * (lo + hi)


def profile_uncertainty(
    K,
    mirror,
    rvec,
    tvec,
    rim_points,
    rim_sigma,
    reflection=None,
    reflection_sigma=None,
    floor=0.02,
    twin=None,
):
    """The posture's uncertainty with the axis's stated from the cost itself.

    :func:`posture_uncertainty` is first order: near alignment (the camera close to the
    mirror's axis) the rim's image depends on the tilt, with its compensating shift, only to
    second order (the two physical postures of a rim merge there), so the noise pushes the
    estimated tilt away from the aligned posture, where the Jacobian is larger than at the
    truth, and the first-order uncertainty is too small (``benchmarks/bench_calibrate.py`` and
    ``bench_stress.py`` print stated against found). Here the region of the two
    axis angles where the profile cost (every other parameter fitted; rows weighted as for
    :func:`posture_uncertainty`, by the residuals observed) rises by at most ``PROFILE_CHI2``
    is found, on this posture's side of its ``twin`` (the bisector between them: beyond it
    lies the other posture, a matter of the choice). Where that region reaches farther from
    the estimate than the first-order ellipse of the same level, ``D`` against ``D_1``, the
    covariance's axis block is widened by ``(D / D_1)^2``, with the origin's shift that
    compensates the tilt; else the first-order covariance stands (exact in the linear limit).

    Parameters
    ----------
    twin : (rvec, tvec), optional
        The other physical posture of the same rim (Chen's); without it the region is not
        bounded by the choice and ``aligned_chi2`` is NaN.

    Other parameters are those of :func:`posture_uncertainty`.

    Returns
    -------
    Uncertainty
        With ``first_order_axis_std_deg`` and, with a twin, ``aligned_chi2``, ``aligned_px``
        and ``twin_deg``.
    """
    prob, w, J, t, full = _covariance_at(
        K, mirror, rvec, tvec, rim_points, rim_sigma, reflection, reflection_sigma, floor
    )
    if full is None:
        return Uncertainty(math.inf, math.inf)
    cov = full[:N_POSTURE, :N_POSTURE]
    first = uncertainty_from_cov(cov, t)
    C = cov[:2, :2]
    lam, E = np.linalg.eigh(C)
    if not (np.isfinite(cov).all() and lam[0] > 0):
        return first
    profile = _TiltProfile(prob, w, J)
    q = PROFILE_CHI2
    Ci = np.linalg.inv(C)
    extra = {"first_order_axis_std_deg": first.axis_std_deg}
    half, u = math.inf, E[:, -1]
    if twin is not None:
        off = posture_offsets(np.asarray(rvec, np.float64), t, *twin)[:2]
        sep = float(np.linalg.norm(off))
        if sep > 0:
            u, half = off / sep, 0.5 * sep
            profile(np.zeros(2))
            ms0 = profile.rim_ms()
            chi2 = profile(0.5 * off)
            extra.update(
                aligned_chi2=max(chi2, 0.0),
                aligned_px=math.sqrt(max(profile.rim_ms() - ms0, 0.0)),
                twin_deg=math.degrees(sep),
            )
    v = np.array([-u[1], u[0]])

    def cap(d):  # this posture's side of the bisector with its twin, and MAX_REACH
        along = float(d @ u)
        return min(MAX_REACH, half / along) if along > 1e-12 else MAX_REACH

    def first_order_reach(d):
        return math.sqrt(q / float(d @ Ci @ d))

    probes = [u, -u, v, -v]
    linear = all(profile(min(first_order_reach(d), cap(d)) * d) >= LINEAR_SHARE * q for d in probes)
    if linear:
        return dataclasses.replace(first, **extra)
    angles = np.arange(PROFILE_DIRECTIONS) * (2.0 * math.pi / PROFILE_DIRECTIONS)
    reach = max(
        _reach(profile, d, first_order_reach(d), cap(d), q)
        for d in (math.cos(a) * u + math.sin(a) * v for a in angles)
    )
    scale = reach**2 / (q * lam[-1])  # (D / D_1)^2
    if not scale > 1.0:
        return dataclasses.replace(first, **extra)
    wide = cov + (scale - 1.0) * cov[:, :2] @ Ci @ cov[:2, :]
    return dataclasses.replace(uncertainty_from_cov(wide, t), widened=True, **extra)


def uncertainty_from_cov(cov, tvec):
    """The :class:`Uncertainty` of a (5, 5) posture covariance at the posture with ``tvec``."""
    cov = np.asarray(cov, np.float64)
    t = np.asarray(tvec, np.float64)
    axis_std = math.degrees(math.sqrt(max(cov[0, 0] + cov[1, 1], 0.0)))
    origin_std = math.sqrt(max(float(np.trace(cov[2:5, 2:5])), 0.0))
    L = float(np.linalg.norm(t))  # angles -> lengths at the camera's distance
    S = np.diag([L, L, 1.0, 1.0, 1.0])
    lam, E = np.linalg.eigh(S @ cov @ S)
    v = E[:, -1] * math.sqrt(max(lam[-1], 0.0))
    share = float(lam[-1] / max(lam.sum(), 1e-300))
    return Uncertainty(
        axis_std,
        origin_std,
        math.degrees(float(np.hypot(v[0], v[1])) / L),
        float(np.linalg.norm(v[2:5])),
        share,
        cov,
    )


def perturbed_posture(R0, t0, x):
    """The posture ``x`` away from ``(R0, t0)`` in the 5 parameters of :class:`Uncertainty`:
    ``(R, t)``, the mirror axis turned by ``x[:2]`` (radians) and the origin moved by ``x[2:]``."""
    return Posture(np.asarray(R0, np.float64), t0)(np.asarray(x, np.float64))


def posture_offsets(rvec0, tvec0, rvec1, tvec1):
    """The second posture in the 5 parameters of the first's covariance (:class:`Uncertainty`).

    Returns
    -------
    (5,) ndarray
        The rotation taking the first mirror axis to the second, on the two axes perpendicular
        to the first (radians), and ``tvec1 - tvec0``.
    """
    R0 = cv2.Rodrigues(np.asarray(rvec0, np.float64).reshape(3, 1))[0]
    R1 = cv2.Rodrigues(np.asarray(rvec1, np.float64).reshape(3, 1))[0]
    a0, a1 = R0[:, 2], R1[:, 2]
    w = np.cross(a0, a1)
    s = float(np.linalg.norm(w))
    w = w * (math.atan2(s, float(a0 @ a1)) / s) if s > 0 else w
    b1, b2 = perpendicular_basis(a0)
    return np.concatenate([[w @ b1, w @ b2], np.asarray(tvec1, np.float64) - tvec0])
