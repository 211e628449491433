"""Non-linear refinement of the 5-DOF mirror posture (beyond the paper).

Started from the analytic posture of Chen's method (:mod:`.chen`), it minimises, in pixels, the
residuals of :mod:`.refine_residuals`: the **rim reprojection** (:class:`RimTerm`), **far
lines** (optional, :class:`FarLineTerm`) and **the camera's reflection** (optional,
:class:`ReflectionTerm`), over the posture (two small rotations of the mirror axis and the
mirror origin ``tvec``) and each term's nuisance parameters.
``scipy.optimize.least_squares`` (MINPACK's Levenberg-Marquardt) solves it, in two stages: the
lines' parameters alone at the analytic posture (its fair cost), then everything together.

What it can add: the rim ellipse has 5 parameters and so has the posture, so with a geometric
ellipse fit (:func:`.rim.fit_rim`) the analytic posture is already the best the rim allows and
the rim term alone changes nothing. Far lines constrain mostly the coplanarity of their rays,
which a rim-consistent error of the axis (a tilt with a compensating shift) barely changes,
so they shrink the axis uncertainty only slightly.

The result is kept only if its cost is lower than the cost of the analytic posture (with the
line parameters fitted to it), so refinement never makes an exact analytic result worse.
Whether a cue may join the rim at all is decided by :func:`.steps.refinement_step`.

The a posteriori uncertainty (:func:`posture_uncertainty`, :func:`profile_uncertainty`) lives in
:mod:`.uncertainty`; its names are re-exported here, as are the terms'.
"""

from __future__ import annotations

import dataclasses
import math

import cv2
import numpy as np
from scipy.optimize import least_squares

from ..gauge import gauge_rotation  # re-exported: refine.gauge_rotation
from .refine_residuals import (
    N_POSTURE,
    FarLineTerm,
    Posture,
    Problem,
    ReflectionSpec,
    ReflectionTerm,
    RimTerm,
    reflected_rays,
    reflection_spec,
)
from .uncertainty import (
    MIN_EFFECTIVE_POINTS,
    PROFILE_CHI2,
    Uncertainty,
    correlation_factor,
    perturbed_posture,
    posture_offsets,
    posture_uncertainty,
    profile_uncertainty,
    uncertainty_from_cov,
)

__all__ = [
    "posture_offsets",
    "perturbed_posture",
    "RefineResult",
    "ReflectionSpec",
    "Uncertainty",
    "RimTerm",
    "FarLineTerm",
    "ReflectionTerm",
    "refine_posture",
    "posture_uncertainty",
    "profile_uncertainty",
    "correlation_factor",
    "uncertainty_from_cov",
    "gauge_rotation",
    "MIN_EFFECTIVE_POINTS",
    "PROFILE_CHI2",
]


@dataclasses.dataclass(frozen=True, eq=False)
class RefineResult:
    """Outcome of :func:`refine_posture`.

    Attributes
    ----------
    rvec, tvec : (3,) float64 ndarray
        The posture kept (the refined one if ``accepted``, else the analytic one).
    accepted : bool
        Whether the refined posture had the lower cost and was kept.
    cost_initial, cost_final : float
        ``0.5 * sum(residual^2)`` (px^2) at the analytic posture (line parameters fitted) and at
        the refined one.
    rim_rms : float
        RMS orthogonal distance of the boundary points to the rim image of the kept posture, px.
    line_rms : float
        RMS far-line residual of the kept posture, px (NaN without lines).
    lines : list of ((3,) ndarray, (3,) ndarray)
        The fitted 3-D lines ``(Q, e)`` in the mirror frame.
    nfev : int
        Residual evaluations of the solver.
    reflection_rms : float
        RMS outline residual of the camera's reflection for the kept posture, px (NaN without).
    r, z : float
        The reflection's coaxial circle (NaN without).
    rim_cost : float
        ``0.5 * sum(rim residual^2)`` (robust weights) at the kept posture: against the rim-only
        fit's, how much the other terms moved the rim (the acceptance test of a cue).
    n_rim : int
        Number of rim rows.
    """

    rvec: np.ndarray
    tvec: np.ndarray
    accepted: bool
    cost_initial: float
    cost_final: float
    rim_rms: float
    line_rms: float
    lines: list
    nfev: int
    reflection_rms: float = math.nan
    r: float = math.nan
    z: float = math.nan
    rim_cost: float = math.nan
    n_rim: int = 0


def refine_posture(
    K,
    mirror,
    rvec,
    tvec,
    rim_points,
    far_lines_normalized=(),
    line_depth=None,
    max_nfev=15,
    robust=True,
    reflection=None,
):
    """Refine a mirror posture by non-linear least squares (rim, far lines, reflection).

    Parameters
    ----------
    K : (3, 3) ndarray
        Camera matrix.
    mirror : HyperbolicMirror
    rvec, tvec : (3,) array_like
        Starting (analytic) posture.
    rim_points : (N, 2) ndarray
        Observed boundary points in undistorted pixels ``K x_n`` (N >= 5).
    far_lines_normalized : sequence of (N_i, 2) ndarray
        Undistorted normalised coordinates of the far-line pixels (may be empty).
    line_depth : float, optional
        Starting distance of the 3-D lines; default ``1000 * rim_radius``.
    max_nfev : int
        Cap on residual evaluations of each of the two solver stages.
    robust : bool
        Huber weights on the rim rows (``k = 2`` robust standard deviations) from the residuals
        of the starting posture; the costs compared to accept the result use the same weights.
    reflection : ReflectionSpec, optional
        The outline of the camera's reflection, the starting circle and which of its ``r``,
        ``z`` are known (a plain ``(xn, r, z, r_known, z_known)`` tuple is taken too).

    Returns
    -------
    RefineResult
    """
    K = np.asarray(K, np.float64)
    R0 = cv2.Rodrigues(np.asarray(rvec, np.float64).reshape(3, 1))[0]
    t0 = np.asarray(tvec, np.float64)
    rim_px = np.ascontiguousarray(np.asarray(rim_points, np.float64).reshape(-1, 2))
    lines_xn = [np.ascontiguousarray(np.asarray(x, np.float64)) for x in far_lines_normalized]
    depth = 1000.0 * mirror.rim_radius if line_depth is None else float(line_depth)
    # lines whose rays mostly miss the mirror under this posture are left out
    lines_xn = [
        x
        for x in lines_xn
        if np.isfinite(reflected_rays(mirror, R0, t0, x)[1]).all(axis=1).sum() >= 3
    ]
    rim = RimTerm(K, mirror, R0, t0, rim_px)
    if robust:
        rim.set_robust_weights(R0, t0)
    terms = [rim]
    if lines_xn:
        terms.append(FarLineTerm(K, mirror, R0, t0, lines_xn, depth))
    spec = reflection_spec(reflection)
    if spec is not None:
        terms.append(ReflectionTerm(K, mirror, R0, t0, *spec))
    prob = Problem(Posture(R0, t0), terms)
    x0 = prob.x0()
    opts = dict(method="lm", x_scale="jac", xtol=1e-8, ftol=1e-6, gtol=1e-10)
    nfev = 0
    # stage 1: the line parameters alone at the analytic posture (its fair cost)
    if lines_xn:
        lt, sl = terms[1], prob.slices[1]
        s1 = least_squares(
            lambda y: lt.residuals(R0, t0, y),
            x0[sl],
            jac=lambda y: lt.nuisance_jacobian(R0, t0, y, np.full(len(y), 1e-7)),
            max_nfev=max_nfev,
            **opts,
        )
        x0[sl] = s1.x
        nfev += s1.nfev
    r_init = prob.residuals(x0)
    cost_init = 0.5 * float(r_init @ r_init)
    # stage 2: posture and nuisances together (skipped when the start is already exact)
    x, cost_fin, accepted = x0, cost_init, False
    if cost_init > 1e-20 * len(r_init):
        sol = least_squares(prob.residuals, x0, jac=prob.jacobian, max_nfev=max_nfev, **opts)
        nfev += sol.nfev
        r_fin = prob.residuals(sol.x)
        cost_fin = 0.5 * float(r_fin @ r_fin)
        # keep the refined posture only if it is better: never worse than the analytic one
        if np.isfinite(cost_fin) and cost_fin < cost_init:
            x, accepted = sol.x, True
    R, t = prob.posture(x[:N_POSTURE])
    rim_rms = float(np.sqrt(np.mean(rim.residuals(R, t, weighted=False) ** 2)))
    line_rms, lines = math.nan, []
    if lines_xn:
        lr = terms[1].residuals(R, t, x[prob.slices[1]])
        line_rms = float(np.sqrt(np.mean(lr**2)))
        y = x[prob.slices[1]]
        lines = [terms[1].line(i, y[4 * i : 4 * i + 4]) for i in range(len(lines_xn))]
    refl_rms, r_c, z_c = math.nan, math.nan, math.nan
    if spec is not None:
        term = terms[-1]
        y = x[prob.slices[-1]]
        refl_rms = float(np.sqrt(np.mean(term.residuals(R, t, y, outline_only=True) ** 2)))
        r_c, z_c = term.circle(y)
    return RefineResult(
        rvec=cv2.Rodrigues(R)[0].ravel(),
        tvec=np.asarray(t, np.float64),
        accepted=accepted,
        cost_initial=cost_init,
        cost_final=cost_fin,
        rim_rms=rim_rms,
        line_rms=line_rms,
        lines=lines,
        nfev=int(nfev),
        reflection_rms=refl_rms,
        r=r_c,
        z=z_c,
        rim_cost=0.5 * float(np.sum(rim.residuals(R, t) ** 2)),
        n_rim=len(rim_px),
    )
