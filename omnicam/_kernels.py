"""numba kernels of the per-point work: ray tracing (eqs. 6-19) and exact forward projection.

Only arithmetic on prepared float64 arrays lives here; validation, shapes, distortion and the
public API are in :mod:`omnicam.raytrace` and :mod:`omnicam.camera`. Every cached kernel and the
helpers it inlines stay in this one module (numba's cache does not see changes in other files).
The slow, obviously correct references are :mod:`omnicam.mirror` and ``tests/naive.py``.
"""
from __future__ import annotations

import math

import numpy as np
from numba import njit, prange

_NAN = math.nan


@njit(cache=True, inline="always")
def _first_hit_k(Fx, Fy, Fz, Vx, Vy, Vz, ia2, ib2):
    """Smallest k > 0 with Z > 0 where ``F + k V`` meets the sheet (eqs. 8-11); NaN if none."""
    alpha = (Vx * Vx + Vy * Vy) * ia2 - Vz * Vz * ib2
    beta = (Vx * Fx + Vy * Fy) * ia2 - Vz * Fz * ib2
    gamma = (Fx * Fx + Fy * Fy) * ia2 - Fz * Fz * ib2 + 1.0
    disc = beta * beta - alpha * gamma
    if not disc >= 0.0:
        return _NAN
    sq = math.sqrt(disc)
    q = -(beta + math.copysign(sq, beta))
    best = math.inf
    if alpha != 0.0:
        k = q / alpha
        if k > 0.0 and Fz + k * Vz > 0.0 and k < best:
            best = k
    if q != 0.0:
        k = gamma / q
        if k > 0.0 and Fz + k * Vz > 0.0 and k < best:
            best = k
    if best == math.inf:
        return _NAN
    return best


@njit(cache=True, parallel=True)
def trace_rays(uv, Kinv, R, C, a, b, rim_radius, origins, directions):
    """Ray tracing of pixels to reflected rays, written into ``origins``/``directions``.

    ``uv`` (N, 2): pixel (or, with ``Kinv = I``, undistorted normalised) coordinates.
    Camera ray ``V_C = Kinv (u, v, 1)`` (eq. 6), ``V_M = R^T V_C`` and ``F_M = C`` (eqs. 16-17),
    first hit inside the rim (eqs. 8-12), reflection about the unit normal (eqs. 14-15).
    Rows that miss the mirror, or NaN input, are written as NaN.
    """
    ia2 = 1.0 / (a * a)
    ib2 = 1.0 / (b * b)
    b2a2 = b * b * ia2
    rim2 = rim_radius * rim_radius
    n = uv.shape[0]
    for i in prange(n):
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
        k = _first_hit_k(C[0], C[1], C[2], Vx, Vy, Vz, ia2, ib2)
        Px = C[0] + k * Vx
        Py = C[1] + k * Vy
        Pz = C[2] + k * Vz
        # unnormalised normal N = (f_X, f_Y, -1)  (eq. 14)
        Nx = b2a2 * Px / Pz
        Ny = b2a2 * Py / Pz
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


@njit(cache=True, inline="always")
def _path_length(s1, s2, Cx, Cy, Cz, Xx, Xy, Xz, at_infinity, a, b):
    """Fermat path length camera -> mirror point (s1, s2, f(s)) -> scene point (or direction)."""
    z = b * math.sqrt(1.0 + (s1 * s1 + s2 * s2) / (a * a))
    r1 = math.sqrt((Cx - s1) ** 2 + (Cy - s2) ** 2 + (Cz - z) ** 2)
    if at_infinity:
        return r1 - (Xx * s1 + Xy * s2 + Xz * z)
    return r1 + math.sqrt((Xx - s1) ** 2 + (Xy - s2) ** 2 + (Xz - z) ** 2)


@njit(cache=True, inline="always")
def _reflection_point(Cx, Cy, Cz, Xx, Xy, Xz, at_infinity, a, b, rim_radius, tol, max_iter):
    """Mirror point whose reflection joins the camera centre C and the scene point X.

    Fermat: the reflection point is a stationary point of the path length
    ``L(s) = |C - P(s)| + |X - P(s)|`` over the sheet ``P(s) = (s1, s2, f(s))`` (eq. 13); on a
    convex mirror it is a minimum. Damped Newton on ``s``, started where the line from the outer
    focus ``(0, 0, c)`` to X leaves the mirror (exact for the aligned rig, eqs. 2-5). For a
    direction at infinity ``|X - P|`` becomes ``-(X, P)`` with X the unit direction.
    Returns (s1, s2, ok).
    """
    a2 = a * a
    b2 = b * b
    c = math.sqrt(a2 + b2)
    # start: where the ray from the outer focus towards X leaves the sheet
    if at_infinity:
        Wx, Wy, Wz = Xx, Xy, Xz
    else:
        Wx, Wy, Wz = Xx, Xy, Xz - c
    k = _first_hit_k(0.0, 0.0, c, Wx, Wy, Wz, 1.0 / a2, 1.0 / b2)
    if k == k:
        s1 = k * Wx
        s2 = k * Wy
    else:  # looks above the mirror's horizon: start on the rim at X's azimuth
        h = math.sqrt(Wx * Wx + Wy * Wy)
        if h == 0.0:
            return _NAN, _NAN, False
        s1 = rim_radius * Wx / h
        s2 = rim_radius * Wy / h
    converged = False
    for _ in range(max_iter):
        z = b * math.sqrt(1.0 + (s1 * s1 + s2 * s2) / a2)
        fx = b2 * s1 / (a2 * z)
        fy = b2 * s2 / (a2 * z)
        kk = b2 / (a2 * z)
        fxx = kk * (1.0 - s1 * fx / z)
        fyy = kk * (1.0 - s2 * fy / z)
        fxy = -kk * s1 * fy / z
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
            d1 = -(H22 * g1 - H12 * g2) / det
            d2 = -(H11 * g2 - H12 * g1) / det
        else:  # not convex here: a gradient step of the local length scale
            gn = math.sqrt(g1 * g1 + g2 * g2) + 1e-300
            step = 0.1 * min(r1, rim_radius)
            d1 = -g1 / gn * step
            d2 = -g2 / gn * step
        t = 1.0
        dn = math.sqrt(d1 * d1 + d2 * d2)
        if H11 > 0.0 and det > 0.0 and dn < 1e-4 * (a + b):
            # in Newton's basin: full steps (L changes below float precision here)
            s1 += d1
            s2 += d2
            if dn < tol:
                converged = True
                break
            continue
        # far from the solution: backtracking on L keeps the iteration a descent
        L = _path_length(s1, s2, Cx, Cy, Cz, Xx, Xy, Xz, at_infinity, a, b)
        accepted = False
        for _ls in range(30):
            n1 = s1 + t * d1
            n2 = s2 + t * d2
            Ln = _path_length(n1, n2, Cx, Cy, Cz, Xx, Xy, Xz, at_infinity, a, b)
            if Ln <= L + 1e-15 * abs(L):
                accepted = True
                break
            t *= 0.5
        if not accepted:
            # no descent left at float precision: the gradient must vanish already
            converged = math.sqrt(g1 * g1 + g2 * g2) < 1e-9
            break
        s1 = n1
        s2 = n2
        if dn * t < tol:
            converged = True
            break
    return s1, s2, converged


@njit(cache=True, parallel=True)
def project_points(X, at_infinity, R, t, C, a, b, rim_radius, K, out):
    """Exact non-central projection of scene points (or unit directions) to ``out`` (N, 2).

    ``out = K * (x/z, y/z)`` of the reflection point in the camera frame (pass ``K = I`` to get
    normalised coordinates). Unseen points, points that do not converge and NaN input give NaN.
    """
    a2 = a * a
    b2 = b * b
    rim2 = rim_radius * rim_radius
    tol = 1e-10 * (a + b)
    n = X.shape[0]
    for i in prange(n):
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
        elif Xz > 0.0 and (Xx * Xx + Xy * Xy) / a2 - Xz * Xz / b2 + 1.0 < 0.0:
            continue  # inside the mirror body
        s1, s2, ok = _reflection_point(C[0], C[1], C[2], Xx, Xy, Xz, at_infinity,
                                       a, b, rim_radius, tol, 50)
        if not ok or s1 * s1 + s2 * s2 > rim2:
            continue
        z = b * math.sqrt(1.0 + (s1 * s1 + s2 * s2) / a2)
        # visibility: the camera meets the mirror from outside (eq. 12) and X is in front of it
        Nx = b2 * s1 / (a2 * z)
        Ny = b2 * s2 / (a2 * z)
        if Nx * (C[0] - s1) + Ny * (C[1] - s2) - (C[2] - z) <= 0.0:
            continue
        if at_infinity:
            side = Nx * Xx + Ny * Xy - Xz
        else:
            side = Nx * (Xx - s1) + Ny * (Xy - s2) - (Xz - z)
        if side <= 0.0:
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
