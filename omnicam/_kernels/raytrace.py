"""Ray tracing kernels: pixel -> reflected ray (eqs. 6-19) and exact forward projection.

* :func:`trace_rays`: camera ray, first hit inside the rim, reflection (eqs. 6-19).
* :func:`project_points`: scene point or direction -> pixel, through the reflection point that
  :func:`reflection_point` solves (Newton on Fermat's path length over the sheet).
* :func:`newton_warm`: the same Newton from a start already in its basin (the view tables).

The mirror is reached only through :mod:`omnicam._kernels.mirror` (the seam, ``mp``); the
references are :mod:`omnicam.mirror`, :mod:`omnicam.asphere` and ``tests/naive.py``.
"""

from __future__ import annotations

import math

from .._jit import kernel
from .mirror import (
    inside_body,
    length_scale,
    line_hit,
    normal_at,
    rim_radius,
    sheet_derivs,
    sheet_slopes,
    sheet_z,
    start_hit,
)

_NAN = math.nan

# -- Newton on Fermat's path length (reflection_point): named tolerances and counts ---------------
NEWTON_TOL_REL = 1e-10  # converged when a step is shorter than this times the mirror's scale
NEWTON_MAX_ITER = 50  # iterations from the aligned start
NEWTON_WARM_MAX_ITER = 8  # iterations from a start interpolated from solved neighbours
NEWTON_BASIN_REL = 1e-4  # steps shorter than this times the scale are taken whole (in the basin)
NEWTON_WARM_DONE_REL = 1e-6  # a warm start's full step this short leaves ~1e-12 of the scale
LINE_SEARCH_HALVINGS = 30  # backtracking halvings before giving up on a descent step
LINE_SEARCH_SLACK = 1e-15  # relative increase of the path length still taken as no increase
GRADIENT_ZERO = 1e-9  # |grad L| under which a stalled line search counts as converged
GRADIENT_STEP_REL = 0.1  # gradient step where L is not convex, times min(|C - P|, rim radius)


@kernel
def trace_rays(lo, hi, uv, Kinv, R, C, mp, origins, directions):
    """Ray tracing of pixels ``lo:hi`` to reflected rays, written into ``origins``/``directions``.

    ``uv`` (N, 2): pixel (or, with ``Kinv = I``, undistorted normalised) coordinates; ``mp``:
    the mirror (:mod:`omnicam._kernels.mirror`). Camera ray ``V_C = Kinv (u, v, 1)`` (eq. 6),
    ``V_M = R^T V_C`` and ``F_M = C`` (eqs. 16-17), first hit inside the rim (eqs. 8-12),
    reflection about the unit normal (eqs. 14-15). Rows that miss the mirror, or NaN input,
    are written as NaN.
    """
    rim = rim_radius(mp)
    rim2 = rim * rim
    for i in range(lo, hi):
        u = uv[i, 0]
        v = uv[i, 1]
        xc = Kinv[0, 0] * u + Kinv[0, 1] * v + Kinv[0, 2]
        yc = Kinv[1, 0] * u + Kinv[1, 1] * v + Kinv[1, 2]
        zc = Kinv[2, 0] * u + Kinv[2, 1] * v + Kinv[2, 2]
        # V_M = R^T V_C  (eq. 16 with R_C = R^T)
        Vx = R[0, 0] * xc + R[1, 0] * yc + R[2, 0] * zc
        Vy = R[0, 1] * xc + R[1, 1] * yc + R[2, 1] * zc
        Vz = R[0, 2] * xc + R[1, 2] * yc + R[2, 2] * zc
        nv = math.sqrt(Vx * Vx + Vy * Vy + Vz * Vz)
        Vx /= nv
        Vy /= nv
        Vz /= nv
        k = line_hit(mp, C[0], C[1], C[2], Vx, Vy, Vz)
        Px = C[0] + k * Vx
        Py = C[1] + k * Vy
        Pz = C[2] + k * Vz
        # unnormalised normal N = (f_X, f_Y, -1)  (eq. 14)
        Nx, Ny = normal_at(mp, Px, Py, Pz)
        nn = math.sqrt(Nx * Nx + Ny * Ny + 1.0)
        nx = Nx / nn
        ny = Ny / nn
        nz = -1.0 / nn
        nV = nx * Vx + ny * Vy + nz * Vz
        # visible: enters from outside (eq. 12) and inside the rim
        if k == k and nV < 0.0 and Px * Px + Py * Py <= rim2:
            origins[i, 0] = Px
            origins[i, 1] = Py
            origins[i, 2] = Pz
            # V_out = V - 2 n (n, V)  (eq. 15, unit normal)
            directions[i, 0] = Vx - 2.0 * nx * nV
            directions[i, 1] = Vy - 2.0 * ny * nV
            directions[i, 2] = Vz - 2.0 * nz * nV
        else:
            for j in range(3):
                origins[i, j] = _NAN
                directions[i, j] = _NAN


@kernel
def _path_length(mp, s1, s2, C, X, at_infinity):
    """Fermat path length camera C -> mirror point (s1, s2, f(s)) -> scene point (or direction)
    X; ``C``, ``X`` are 3-tuples."""
    Cx, Cy, Cz = C
    Xx, Xy, Xz = X
    z = sheet_z(mp, s1, s2)
    r1 = math.sqrt((Cx - s1) ** 2 + (Cy - s2) ** 2 + (Cz - z) ** 2)
    if at_infinity:
        return r1 - (Xx * s1 + Xy * s2 + Xz * z)
    return r1 + math.sqrt((Xx - s1) ** 2 + (Xy - s2) ** 2 + (Xz - z) ** 2)


@kernel
def _newton_step(mp, s1, s2, C, X, at_infinity):
    """Newton step on Fermat's path length ``L(s) = |C - P(s)| + |X - P(s)|`` at ``s``.

    ``P(s) = (s1, s2, f(s))`` on the sheet (:func:`sheet_derivs`); for a direction at infinity
    ``|X - P|`` reads ``-(X, P)``. Returns ``(d1, d2, g1, g2, r1, convex)``: the step
    ``-H^-1 g`` (valid when ``convex``, i.e. H positive definite), the gradient ``g`` and the
    distance ``|C - P|``.
    """
    Cx, Cy, Cz = C
    Xx, Xy, Xz = X
    z, fx, fy, fxx, fyy, fxy = sheet_derivs(mp, s1, s2)
    u1x = Cx - s1
    u1y = Cy - s2
    u1z = Cz - z
    r1 = math.sqrt(u1x * u1x + u1y * u1y + u1z * u1z)
    e1x = u1x / r1
    e1y = u1y / r1
    e1z = u1z / r1
    if at_infinity:
        e2x, e2y, e2z = Xx, Xy, Xz
        ir2 = 0.0
    else:
        u2x = Xx - s1
        u2y = Xy - s2
        u2z = Xz - z
        r2 = math.sqrt(u2x * u2x + u2y * u2y + u2z * u2z)
        e2x = u2x / r2
        e2y = u2y / r2
        e2z = u2z / r2
        ir2 = 1.0 / r2
    hx = e1x + e2x
    hy = e1y + e2y
    hz = e1z + e2z
    # tangents t1 = (1, 0, f_X), t2 = (0, 1, f_Y); gradient g_i = -(t_i, h)
    g1 = -(hx + fx * hz)
    g2 = -(hy + fy * hz)
    t1e1 = e1x + fx * e1z
    t2e1 = e1y + fy * e1z
    t1e2 = e2x + fx * e2z
    t2e2 = e2y + fy * e2z
    t11 = 1.0 + fx * fx
    t22 = 1.0 + fy * fy
    t12 = fx * fy
    ir1 = 1.0 / r1
    # Hessian H_ij = -f_ij h_z + t_i^T [(I - e1 e1^T)/r1 + (I - e2 e2^T)/r2] t_j
    H11 = -fxx * hz + (t11 - t1e1 * t1e1) * ir1 + (t11 - t1e2 * t1e2) * ir2
    H22 = -fyy * hz + (t22 - t2e1 * t2e1) * ir1 + (t22 - t2e2 * t2e2) * ir2
    H12 = -fxy * hz + (t12 - t1e1 * t2e1) * ir1 + (t12 - t1e2 * t2e2) * ir2
    det = H11 * H22 - H12 * H12
    if H11 > 0.0 and det > 0.0:
        return -(H22 * g1 - H12 * g2) / det, -(H11 * g2 - H12 * g1) / det, g1, g2, r1, True
    return 0.0, 0.0, g1, g2, r1, False


@kernel
def _damped_step(mp, s1, s2, C, X, at_infinity, d1, d2):
    """Backtracking on L along ``(d1, d2)`` from ``s``: ``(n1, n2, t, accepted)``."""
    L = _path_length(mp, s1, s2, C, X, at_infinity)
    t = 1.0
    for _ls in range(LINE_SEARCH_HALVINGS):
        n1 = s1 + t * d1
        n2 = s2 + t * d2
        Ln = _path_length(mp, n1, n2, C, X, at_infinity)
        if Ln <= L + LINE_SEARCH_SLACK * abs(L):
            return n1, n2, t, True
        t *= 0.5
    return s1, s2, t, False


@kernel
def reflection_point(mp, C, X, at_infinity, tol, max_iter):
    """Mirror point whose reflection joins the camera centre C and the scene point X.

    Fermat: the reflection point is a stationary point of the path length
    ``L(s) = |C - P(s)| + |X - P(s)|`` over the sheet ``P(s) = (s1, s2, f(s))``; on a convex
    mirror it is a minimum. Damped Newton on ``s``, started by the seam's
    :func:`~omnicam._kernels.mirror.start_hit` (for the hyperboloid where the line from the
    outer focus ``(0, 0, c)`` to X leaves the mirror: exact for the aligned rig, eqs. 2-5), or
    on the rim at X's azimuth. For a direction at infinity ``|X - P|`` becomes ``-(X, P)`` with
    X the unit direction. ``C``, ``X`` are 3-tuples. Returns (s1, s2, ok).
    """
    Xx, Xy, Xz = X
    rim = rim_radius(mp)
    scale = length_scale(mp)
    s1, s2 = start_hit(mp, C[2], Xx, Xy, Xz, at_infinity)
    if not (s1 == s1 and s2 == s2):  # looks above the mirror's horizon: start on the rim
        h = math.sqrt(Xx * Xx + Xy * Xy)
        if h == 0.0:
            return _NAN, _NAN, False
        s1 = rim * Xx / h
        s2 = rim * Xy / h
    converged = False
    for _ in range(max_iter):
        d1, d2, g1, g2, r1, convex = _newton_step(mp, s1, s2, C, X, at_infinity)
        if not convex:  # not convex here: a gradient step of the local length scale
            gn = math.sqrt(g1 * g1 + g2 * g2) + 1e-300
            step = GRADIENT_STEP_REL * min(r1, rim)
            d1 = -g1 / gn * step
            d2 = -g2 / gn * step
        dn = math.sqrt(d1 * d1 + d2 * d2)
        if convex and dn < NEWTON_BASIN_REL * scale:
            # in Newton's basin: full steps (L changes below float precision here)
            s1 += d1
            s2 += d2
            if dn < tol:
                converged = True
                break
            continue
        # far from the solution: backtracking on L keeps the iteration a descent
        n1, n2, t, accepted = _damped_step(mp, s1, s2, C, X, at_infinity, d1, d2)
        if not accepted:
            # no descent left at float precision: the gradient must vanish already
            converged = math.sqrt(g1 * g1 + g2 * g2) < GRADIENT_ZERO
            break
        s1 = n1
        s2 = n2
        if dn * t < tol:
            converged = True
            break
    return s1, s2, converged


@kernel
def newton_warm(mp, C, s1, s2, X, at_infinity, tol):
    """Newton's full steps of :func:`reflection_point` from a start already in its basin.

    The start comes from the interpolated neighbours, so the step is small from the first
    iteration; the same gradient and Hessian of the path length. Stops at its step tolerance
    ``tol`` or after a full step shorter than ``NEWTON_WARM_DONE_REL`` times the mirror's
    scale: Newton converges quadratically in the basin, so the error left is of the order of
    that step squared over the scale, ~1e-12 of it, below the tolerance of 1e-10. Returns
    ``(s1, s2, ok)``; not ok (the caller then solves from the aligned start) if a step is not a
    full Newton step of that basin or ``NEWTON_WARM_MAX_ITER`` pass.
    """
    scale = length_scale(mp)
    for _ in range(NEWTON_WARM_MAX_ITER):
        d1, d2, _g1, _g2, _r1, convex = _newton_step(mp, s1, s2, C, X, at_infinity)
        if not convex:
            return s1, s2, False
        dn = math.sqrt(d1 * d1 + d2 * d2)
        if not dn < NEWTON_BASIN_REL * scale:
            return s1, s2, False
        s1 += d1
        s2 += d2
        # quadratic convergence: the error left after a full step of dn is ~ dn^2 / scale
        if dn < tol or dn < NEWTON_WARM_DONE_REL * scale:
            return s1, s2, True
    return s1, s2, False


@kernel
def _seen_from(mp, s1, s2, C, X, at_infinity):
    """The reflection point's height z and whether the camera C and the target X are on the
    outer side of its tangent plane (eqs. 12 and 15)."""
    z, Nx, Ny = sheet_slopes(mp, s1, s2)
    if Nx * (C[0] - s1) + Ny * (C[1] - s2) - (C[2] - z) <= 0.0:
        return z, False
    Xx, Xy, Xz = X
    if at_infinity:
        side = Nx * Xx + Ny * Xy - Xz
    else:
        side = Nx * (Xx - s1) + Ny * (Xy - s2) - (Xz - z)
    return z, side > 0.0


@kernel
def project_points(lo, hi, X, at_infinity, R, t, C, mp, K, out):
    """Exact non-central projection of scene points ``lo:hi`` (or directions) to ``out`` (N, 2).

    ``out = K * (x/z, y/z)`` of the reflection point in the camera frame (pass ``K = I`` to get
    normalised coordinates). NaN for: NaN input, a zero direction, a point inside the mirror
    body, no converged reflection point, a reflection point outside the rim, the camera or the
    target behind the tangent plane there (eqs. 12, 15), the reflection point behind the camera.
    """
    rim = rim_radius(mp)
    rim2 = rim * rim
    tol = NEWTON_TOL_REL * length_scale(mp)
    Cc = (C[0], C[1], C[2])
    for i in range(lo, hi):
        Xx = X[i, 0]
        Xy = X[i, 1]
        Xz = X[i, 2]
        out[i, 0] = _NAN
        out[i, 1] = _NAN
        if not (Xx == Xx and Xy == Xy and Xz == Xz):
            continue
        if at_infinity:
            nrm = math.sqrt(Xx * Xx + Xy * Xy + Xz * Xz)
            if nrm == 0.0:
                continue
            Xx /= nrm
            Xy /= nrm
            Xz /= nrm
        elif inside_body(mp, Xx, Xy, Xz):
            continue
        target = (Xx, Xy, Xz)
        s1, s2, ok = reflection_point(mp, Cc, target, at_infinity, tol, NEWTON_MAX_ITER)
        if not ok or s1 * s1 + s2 * s2 > rim2:
            continue
        z, seen = _seen_from(mp, s1, s2, Cc, target, at_infinity)
        if not seen:
            continue
        xc = R[0, 0] * s1 + R[0, 1] * s2 + R[0, 2] * z + t[0]
        yc = R[1, 0] * s1 + R[1, 1] * s2 + R[1, 2] * z + t[1]
        zc = R[2, 0] * s1 + R[2, 1] * s2 + R[2, 2] * z + t[2]
        if zc <= 0.0:
            continue
        xn = xc / zc
        yn = yc / zc
        out[i, 0] = K[0, 0] * xn + K[0, 1] * yn + K[0, 2]
        out[i, 1] = K[1, 0] * xn + K[1, 1] * yn + K[1, 2]
