"""Levenberg-Marquardt with geodesic acceleration, for least squares whose minimum lies at the
end of a long, curved valley (beyond the paper).

The adjustment with the mirror's shape free (:meth:`.adjustment.BundleAdjustment.solve`) has
such a valley: the focal length, the camera's distance to the mirror, the shape and the
distortion trade against one another (every ``f`` has a profile that sees the central model's
directions, :mod:`.profile`), and only the rig's small non-centrality picks one. MINPACK's
Levenberg-Marquardt walks it in steps the valley's curvature keeps short: 338 evaluations on
OCamCalib's KaidanOmni (``f`` from 2510 to 672 px). Transtrum & Sethna ("Improvements to the
Levenberg-Marquardt algorithm for nonlinear least-squares minimization", arXiv:1201.5885, 2012,
sections 3-4) add to the step ``d1 = -(J'J + lam D)^-1 J'z`` the second-order correction

    d2 = -(J'J + lam D)^-1 J' z_vv,   z_vv = (2 / h) ((z(x + h d1) - z(x)) / h - J d1),

the residuals' second directional derivative along ``d1`` by one more evaluation (``h`` =
:data:`_H`), and take ``d1 + d2 / 2`` while ``2 |d2| <= alpha |d1|`` (:data:`_ALPHA`, in the
scaled norm): the step then follows the valley's bend instead of leaving it. The damping is
Nielsen's (``lam`` times ``max(1/3, 1 - (2 rho - 1)^3)`` after a step of gain ratio ``rho``,
times 2, 4, 8... after failures); ``D`` is Marquardt's scaling, the largest ``diag(J'J)`` met
(MINPACK's ``x_scale="jac"``). On KaidanOmni: 38 Jacobians and 109 evaluations to the same
minimum, where MINPACK takes 309 and 338 (``benchmarks/bench_chessboard_real.py``).

The stopping rules are MINPACK's, with one tolerance ``tol``: a step that lowers the cost by no
more than ``tol`` times it, as its linear model predicted (``ftol``); a step no longer than
``tol`` times ``x`` (``xtol``, scaled norm); a gradient whose scaled components are all below
``tol`` times the residuals' norm (``gtol``).
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
from scipy.linalg import cho_factor, cho_solve
from scipy.optimize import OptimizeResult

from .._typing import FloatArray

__all__ = ["geodesic_lm"]

#: The finite-difference step (a fraction of ``d1``) of the second directional derivative.
_H = 0.1
#: The acceleration is taken while ``2 |d2| <= _ALPHA |d1|`` (Transtrum & Sethna's 0.75).
_ALPHA = 0.75
#: The first damping, relative to the scaling ``D`` (Nielsen's ``tau``).
_LAM0 = 1e-3
#: Damping past which no step lowers the cost: the minimum, to the residuals' rounding.
_LAM_MAX = 1e16

_MESSAGES = {
    0: "The maximum number of function evaluations is exceeded.",
    1: "`gtol` termination condition is satisfied.",
    2: "`ftol` termination condition is satisfied.",
    3: "`xtol` termination condition is satisfied.",
    4: "No step lowers the cost: the minimum, to the residuals' rounding.",
}


#: Multiply-adds of one product below which OpenBLAS's GEMM runs on one thread (its
#: ``SMP_THRESHOLD_MIN * GEMM_MULTITHREAD_THRESHOLD``).
_ONE_THREAD_MNK = 65536 * 4


def _blocks(J):
    """Slices of ``J``'s rows whose products with ``J``'s columns stay below
    :data:`_ONE_THREAD_MNK`: on a machine whose cores are busy OpenBLAS's threaded product of
    KaidanOmni's 2824 x 110 Jacobian waits 120 ms for them, the blocks take 3 ms (and sum in
    the same order on every run, so a fit is repeatable)."""
    n = J.shape[1]
    rows = max(8, _ONE_THREAD_MNK // max(n * n, 1))
    return [slice(i, i + rows) for i in range(0, len(J), rows)]


def _normal(J, z) -> tuple[FloatArray, FloatArray]:
    """``(J' J, J' z)`` (:func:`_blocks`)."""
    n = J.shape[1]
    A, g = np.zeros((n, n)), np.zeros(n)
    for rows in _blocks(J):
        A += J[rows].T @ J[rows]
        g += J[rows].T @ z[rows]
    return A, g


def _times(J, d) -> FloatArray:
    """``J d`` (:func:`_blocks`)."""
    return np.concatenate([J[rows] @ d for rows in _blocks(J)])


def _times_t(J, v) -> FloatArray:
    """``J' v`` (:func:`_blocks`)."""
    return sum(J[rows].T @ v[rows] for rows in _blocks(J))


def _norm(D, v) -> float:
    """The scaled norm ``|D^1/2 v|``."""
    return float(np.sqrt(np.sum(D * v * v)))


def geodesic_lm(
    fun: Callable[[FloatArray], FloatArray],
    jac: Callable[[FloatArray], FloatArray],
    x0: FloatArray,
    max_nfev: int,
    tol: float = 1e-10,
) -> OptimizeResult:
    """Minimise ``sum z(x)^2`` from ``x0`` (module docstring).

    Parameters
    ----------
    fun : callable
        ``z(x)``, the residuals ``(m,)``.
    jac : callable
        ``J(x)``, their Jacobian ``(m, n)``; asked only where ``fun`` was last evaluated.
    x0 : (n,) ndarray
    max_nfev : int
        Evaluations of ``fun`` at most (the accelerations' included).
    tol : float
        ``ftol``, ``xtol`` and ``gtol`` (module docstring).

    Returns
    -------
    OptimizeResult
        ``x``, ``cost`` (``sum z^2 / 2``), ``fun``, ``nfev``, ``njev``, ``status`` (0: out of
        evaluations; 1, 2, 3: ``gtol``, ``ftol``, ``xtol``; 4: no step lowers the cost),
        ``success`` (``status > 0``) and ``message``, as scipy's ``least_squares``.
    """
    x = np.array(x0, np.float64)
    z = fun(x)
    nfev, njev, status = 1, 0, 0
    cost = float(z @ z)
    lam, nu, D = _LAM0, 2.0, None
    while status == 0 and nfev + 2 <= max_nfev:  # (a trial costs 2 evaluations)
        J = jac(x)
        njev += 1
        A, g = _normal(J, z)
        D = np.diag(A).copy() if D is None else np.maximum(D, np.diag(A))
        D[D <= 0] = 1.0  # (a parameter no residual sees: held by the damping)
        if np.max(np.abs(g) / np.sqrt(D)) <= tol * np.sqrt(cost):
            status = 1
            break
        while status == 0 and nfev + 2 <= max_nfev:
            try:  # (LAPACK's Cholesky: np.linalg.solve's LU costs 50 ms, not 0.1, when
                # OpenBLAS's threads wait for busy cores)
                c = cho_factor(A + lam * np.diag(D))
            except (np.linalg.LinAlgError, ValueError):  # (not positive definite, not finite)
                lam, nu = lam * nu, 2.0 * nu
                status = 4 if lam > _LAM_MAX else 0
                continue

            def solve(b, c=c):
                return cho_solve(c, b)

            d1 = -solve(g)
            step = d1
            pred = -float(2.0 * g @ d1 + d1 @ A @ d1)  # the linear model's decrease
            zh = fun(x + _H * d1)
            nfev += 1
            d2 = -solve(_times_t(J, (2.0 / _H) * ((zh - z) / _H - _times(J, d1))))
            if np.all(np.isfinite(d2)) and 2.0 * _norm(D, d2) <= _ALPHA * _norm(D, d1):
                step = d1 + 0.5 * d2
            zn = fun(x + step)
            nfev += 1
            cn = float(zn @ zn)
            if cn < cost:
                rho = (cost - cn) / max(pred, 1e-300)
                small = cost - cn <= tol * cost and pred <= tol * cost
                x, z, cost = x + step, zn, cn
                lam *= max(1.0 / 3.0, 1.0 - (2.0 * min(rho, 1.0) - 1.0) ** 3)
                nu = 2.0
                if small:
                    status = 2
                elif _norm(D, step) <= tol * (_norm(D, x) + tol):
                    status = 3
                break
            lam, nu = lam * nu, 2.0 * nu
            if _norm(D, step) <= tol * (_norm(D, x) + tol):
                status = 3
            elif lam > _LAM_MAX:
                status = 4
    return OptimizeResult(
        x=x,
        cost=0.5 * cost,
        fun=z,
        nfev=nfev,
        njev=njev,
        status=status,
        success=status > 0,
        message=_MESSAGES[status],
    )
