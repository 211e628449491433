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
def _newton_step(s1, s2, Cx, Cy, Cz, Xx, Xy, Xz, at_infinity, a, b):
    """Newton step on Fermat's path length ``L(s) = |C - P(s)| + |X - P(s)|`` at ``s``.

    ``P(s) = (s1, s2, f(s))`` on the sheet (eq. 13); for a direction at infinity ``|X - P|``
    reads ``-(X, P)``. Returns ``(d1, d2, g1, g2, r1, convex)``: the step ``-H^-1 g`` (valid when
    ``convex``, i.e. H positive definite), the gradient ``g`` and the distance ``|C - P|``.
    """
    a2 = a * a
    b2 = b * b
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
        return -(H22 * g1 - H12 * g2) / det, -(H11 * g2 - H12 * g1) / det, g1, g2, r1, True
    return 0.0, 0.0, g1, g2, r1, False


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
        d1, d2, g1, g2, r1, convex = _newton_step(s1, s2, Cx, Cy, Cz, Xx, Xy, Xz, at_infinity,
                                                  a, b)
        if not convex:  # not convex here: a gradient step of the local length scale
            gn = math.sqrt(g1 * g1 + g2 * g2) + 1e-300
            step = 0.1 * min(r1, rim_radius)
            d1 = -g1 / gn * step
            d2 = -g2 / gn * step
        t = 1.0
        dn = math.sqrt(d1 * d1 + d2 * d2)
        if convex and dn < 1e-4 * (a + b):
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


# -- view tables (omnicam.views): exact nodes, cubic interpolation with a verified error ----------
#
# A remap table entry is the exact projection (project_points) of the direction, or the point at
# a given distance from a viewpoint, that an output pixel looks along. ``view_table`` solves the
# reflection point exactly (``_reflection_point``, the same Newton as project_points) on a coarse
# grid of nodes every ``step`` output pixels, on the mirror sheet extended beyond the rim, so the
# mirror point s = (s1, s2) is a smooth function of the output pixel even across the edge of what
# the mirror sees. Each cell is interpolated by the tensor-product cubic Lagrange polynomial of its
# 4x4 nodes; its error (~ h^4 f^(4) w(t), largest mid-cell) is measured against the exact answer at
# the cell centre and the middle of its four edges. A cell whose estimate exceeds ``tol / 2`` (or
# that has a node without a solution) is refined once: the same construction on a grid ``_FINE``
# times finer inside it; a sub-cell that still fails is computed exactly pixel by pixel.
# Cells wholly and clearly seen interpolate the pixel itself; cells wholly and clearly unseen are
# written unseen; in the others visibility (rim, eqs. 12 and 15, in front of the camera) is
# decided per pixel from the interpolated mirror point with a margin, and pixels inside the
# margin are solved exactly.

_VIEW_RIM_MARGIN = 2e-3    # relative margin on s1^2 + s2^2 against rim_radius^2
_VIEW_COS_MARGIN = 1e-3    # margin on the cosines of the other visibility tests
_UNSEEN = -10.0            # omnicam.views.UNSEEN


@njit(cache=True)
def _view_direction(kind, A, p0, p1, az_step, u, v):
    """Unit mirror-frame direction of output pixel (u, v) (conventions.md, "Views").

    kind 0: perspective, ``d = A (u, v, 1)`` with ``A = R^T K_new^-1``.
    kind 1: cylindrical panorama, azimuth ``az_step u``, ``tan(elevation) = p0 + p1 v``.
    kind 2: equirectangular panorama, elevation ``p0 + p1 v`` (radians). For panoramas ``A = R^T``.
    """
    if kind == 0:
        x = A[0, 0] * u + A[0, 1] * v + A[0, 2]
        y = A[1, 0] * u + A[1, 1] * v + A[1, 2]
        z = A[2, 0] * u + A[2, 1] * v + A[2, 2]
    else:
        az = az_step * u
        ca = math.cos(az)
        sa = math.sin(az)
        if kind == 1:
            x0 = ca
            y0 = sa
            z0 = p0 + p1 * v
        else:
            el = p0 + p1 * v
            ce = math.cos(el)
            x0 = ce * ca
            y0 = ce * sa
            z0 = math.sin(el)
        x = A[0, 0] * x0 + A[0, 1] * y0 + A[0, 2] * z0
        y = A[1, 0] * x0 + A[1, 1] * y0 + A[1, 2] * z0
        z = A[2, 0] * x0 + A[2, 1] * y0 + A[2, 2] * z0
    n = math.sqrt(x * x + y * y + z * z)
    return x / n, y / n, z / n


@njit(cache=True)
def _view_target(dx, dy, dz, at_infinity, depth, vp):
    """The scene target of a unit direction: itself at infinity, else ``vp + depth d``."""
    if at_infinity:
        return dx, dy, dz
    return vp[0] + depth * dx, vp[1] + depth * dy, vp[2] + depth * dz


@njit(cache=True)
def _view_pixel(s1, s2, Xx, Xy, Xz, at_infinity, C, Rc, tc, a, b, K, dist, tilt, has_dist):
    """Pixel of the mirror point (s1, s2, f(s)) and the smallest visibility cosine.

    The pixel is the pinhole image (eq. 6) of the mirror point, with OpenCV's distortion model
    (``cv2.projectPoints``: k1..k6, p1, p2, s1..s4, tilt), then ``K`` with skew, as
    :func:`omnicam.raytrace.project` does. The cosine is the least of: camera on the outer side
    of the tangent plane (eq. 12), target on the outer side (eq. 15), mirror point in front of
    the camera; all positive means project_points' tests pass. NaN pixel behind the camera.
    """
    a2 = a * a
    b2 = b * b
    z = b * math.sqrt(1.0 + (s1 * s1 + s2 * s2) / a2)
    Nx = b2 * s1 / (a2 * z)
    Ny = b2 * s2 / (a2 * z)
    nn2 = Nx * Nx + Ny * Ny + 1.0
    wx = C[0] - s1
    wy = C[1] - s2
    wz = C[2] - z
    mc = (Nx * wx + Ny * wy - wz) / math.sqrt(nn2 * (wx * wx + wy * wy + wz * wz))
    if at_infinity:
        ms = (Nx * Xx + Ny * Xy - Xz) / math.sqrt(nn2)
    else:
        ex = Xx - s1
        ey = Xy - s2
        ez = Xz - z
        ms = (Nx * ex + Ny * ey - ez) / math.sqrt(nn2 * (ex * ex + ey * ey + ez * ez))
    xc = Rc[0, 0] * s1 + Rc[0, 1] * s2 + Rc[0, 2] * z + tc[0]
    yc = Rc[1, 0] * s1 + Rc[1, 1] * s2 + Rc[1, 2] * z + tc[1]
    zc = Rc[2, 0] * s1 + Rc[2, 1] * s2 + Rc[2, 2] * z + tc[2]
    mz = zc / math.sqrt(xc * xc + yc * yc + zc * zc)
    m = min(mc, min(ms, mz))
    if not zc > 0.0:
        return _NAN, _NAN, m
    xn = xc / zc
    yn = yc / zc
    if has_dist:
        r2 = xn * xn + yn * yn
        r4 = r2 * r2
        r6 = r4 * r2
        cdist = 1.0 + dist[0] * r2 + dist[1] * r4 + dist[4] * r6
        icdist = 1.0 / (1.0 + dist[5] * r2 + dist[6] * r4 + dist[7] * r6)
        a1 = 2.0 * xn * yn
        a2_ = r2 + 2.0 * xn * xn
        a3 = r2 + 2.0 * yn * yn
        xd = xn * cdist * icdist + dist[2] * a1 + dist[3] * a2_ + dist[8] * r2 + dist[9] * r4
        yd = yn * cdist * icdist + dist[2] * a3 + dist[3] * a1 + dist[10] * r2 + dist[11] * r4
        vx = tilt[0, 0] * xd + tilt[0, 1] * yd + tilt[0, 2]
        vy = tilt[1, 0] * xd + tilt[1, 1] * yd + tilt[1, 2]
        vz = tilt[2, 0] * xd + tilt[2, 1] * yd + tilt[2, 2]
        ip = 1.0 / vz if vz != 0.0 else 1.0
        xn = ip * vx
        yn = ip * vy
    return K[0, 0] * xn + K[0, 1] * yn + K[0, 2], K[1, 0] * xn + K[1, 1] * yn + K[1, 2], m


@njit(cache=True)
def _view_solve(C, Xx, Xy, Xz, at_infinity, a, b, rim_radius, tol):
    """``_reflection_point`` for the camera centre C (compiled once, called from three places)."""
    return _reflection_point(C[0], C[1], C[2], Xx, Xy, Xz, at_infinity, a, b, rim_radius, tol, 50)


@njit(cache=True)
def _view_exact(dx, dy, dz, sin_reject, at_infinity, depth, vp, C, Rc, tc, a, b, rim_radius,
                K, dist, tilt, has_dist, tol):
    """Exact table entry of a unit direction: project_points' answer (NaN if unseen).

    ``dz > sin_reject`` is above every elevation the rig can see (proved in omnicam.views):
    unseen without solving.
    """
    if not dz <= sin_reject:
        return _NAN, _NAN
    Xx, Xy, Xz = _view_target(dx, dy, dz, at_infinity, depth, vp)
    if not at_infinity and Xz > 0.0 and (Xx * Xx + Xy * Xy) / (a * a) - Xz * Xz / (b * b) + 1.0 < 0.0:
        return _NAN, _NAN  # inside the mirror body
    s1, s2, ok = _view_solve(C, Xx, Xy, Xz, at_infinity, a, b, rim_radius, tol)
    if not ok or s1 * s1 + s2 * s2 > rim_radius * rim_radius:
        return _NAN, _NAN
    x, y, m = _view_pixel(s1, s2, Xx, Xy, Xz, at_infinity, C, Rc, tc, a, b, K, dist, tilt,
                          has_dist)
    if not m > 0.0:
        return _NAN, _NAN
    return x, y


@njit(cache=True)
def _lagrange4(t):
    """Cubic Lagrange weights of nodes at -1, 0, 1, 2 for 0 <= t <= 1."""
    return (-t * (t - 1.0) * (t - 2.0) / 6.0, (t + 1.0) * (t - 1.0) * (t - 2.0) / 2.0,
            -(t + 1.0) * t * (t - 2.0) / 2.0, (t + 1.0) * t * (t - 1.0) / 6.0)


@njit(cache=True)
def _interp_cell(S, r, k, tv, tu):
    """Tensor cubic Lagrange interpolation of node values S (NY, NX, 2) in cell (r, k)."""
    v0, v1, v2, v3 = _lagrange4(tv)
    u0, u1, u2, u3 = _lagrange4(tu)
    o1 = 0.0
    o2 = 0.0
    for m in range(4):
        wv = v0 if m == 0 else (v1 if m == 1 else (v2 if m == 2 else v3))
        row1 = u0 * S[r + m, k, 0] + u1 * S[r + m, k + 1, 0] + u2 * S[r + m, k + 2, 0] \
            + u3 * S[r + m, k + 3, 0]
        row2 = u0 * S[r + m, k, 1] + u1 * S[r + m, k + 1, 1] + u2 * S[r + m, k + 2, 1] \
            + u3 * S[r + m, k + 3, 1]
        o1 += wv * row1
        o2 += wv * row2
    return o1, o2


@njit(cache=True, inline="always")
def _view_store(i, j, x, y, mode, outx, outy, out16, outf16):
    """Write one entry: float maps (mode 0) or cv2.convertMaps' CV_16SC2 fixed point (mode 1)."""
    if not (x == x and y == y):
        x = _UNSEEN
        y = _UNSEEN
    fx = np.float32(x)
    fy = np.float32(y)
    if mode == 0:
        outx[i, j] = fx
        outy[i, j] = fy
    else:
        # cv2.convertMaps: cvRound(x * 32) (to nearest, ties to even), integer part >> 5 and
        # the fraction & 31; the float32 entry times 32 is exact in float64
        ix = int(np.rint(np.float64(fx) * 32.0))
        iy = int(np.rint(np.float64(fy) * 32.0))
        out16[i, j, 0] = max(-32768, min(32767, ix >> 5))
        out16[i, j, 1] = max(-32768, min(32767, iy >> 5))
        outf16[i, j] = (iy & 31) * 32 + (ix & 31)


_VIEW_CLEAR = 0.05         # margins (relative rim, cosines, body) of cells wholly seen or unseen
_FINE = 4                  # refinement factor of failing cells
_CELL_BAD = 0              # refined, else computed exactly pixel by pixel
_CELL_SEEN = 1             # pixels interpolated directly from the nodes' pixels
_CELL_UNSEEN = 2           # every pixel unseen
_CELL_EDGE = 3             # mirror point interpolated, visibility decided per pixel


@njit(cache=True)
def _newton_warm(s1, s2, C, Xx, Xy, Xz, at_infinity, a, b, tol, max_iter):
    """Newton's full steps of ``_reflection_point`` from a start already in its basin.

    The start comes from the interpolated neighbours, so the step is small from the first
    iteration; the same gradient and Hessian of the path length and the same stopping rule as
    ``_reflection_point``. Returns ``(s1, s2, ok)``; not ok (the caller then solves from the
    aligned start) if a step is not a full Newton step of that basin or ``max_iter`` pass.
    """
    Cx = C[0]
    Cy = C[1]
    Cz = C[2]
    for _ in range(max_iter):
        d1, d2, _g1, _g2, _r1, convex = _newton_step(s1, s2, Cx, Cy, Cz, Xx, Xy, Xz, at_infinity,
                                                     a, b)
        if not convex:
            return s1, s2, False
        dn = math.sqrt(d1 * d1 + d2 * d2)
        if not dn < 1e-4 * (a + b):
            return s1, s2, False
        s1 += d1
        s2 += d2
        if dn < tol:
            return s1, s2, True
    return s1, s2, False


@njit(cache=True)
def _view_eval(kind, A, p0, p1, az_step, u, v, sin_try, at_infinity, depth, vp, C, Rc, tc, a, b,
               rim_radius, K, dist, tilt, has_dist, tol, g1, g2):
    """Exact solution at output position (u, v) on the extended sheet, with its margins.

    Returns ``ok, s1, s2, x, y, vis, rim_m``: the mirror point, its (geometric) pixel,
    ``vis`` = the least of the visibility margins (relative rim, cosines of
    :func:`_view_pixel`, the body test of finite targets) over ``_VIEW_CLEAR`` (>= 1: clearly
    seen) and ``rim_m = 1 - |s|^2 / rim_radius^2``. ``ok`` is False when not solved.
    ``(g1, g2)``: a start for Newton from interpolated neighbours, or NaN.
    """
    dx, dy, dz = _view_direction(kind, A, p0, p1, az_step, u, v)
    if not dz <= sin_try:
        return False, _NAN, _NAN, _NAN, _NAN, _NAN, _NAN
    Xx, Xy, Xz = _view_target(dx, dy, dz, at_infinity, depth, vp)
    ok = False
    if g1 == g1 and g2 == g2:
        s1, s2, ok = _newton_warm(g1, g2, C, Xx, Xy, Xz, at_infinity, a, b, tol, 8)
    if not ok:
        s1, s2, ok = _view_solve(C, Xx, Xy, Xz, at_infinity, a, b, rim_radius, tol)
    if not ok:
        return False, _NAN, _NAN, _NAN, _NAN, _NAN, _NAN
    x, y, m = _view_pixel(s1, s2, Xx, Xy, Xz, at_infinity, C, Rc, tc, a, b, K, dist, tilt,
                          has_dist)
    if not (x == x and y == y):
        return False, _NAN, _NAN, _NAN, _NAN, _NAN, _NAN
    rim_m = 1.0 - (s1 * s1 + s2 * s2) / (rim_radius * rim_radius)
    vis = min(rim_m, m)
    if not at_infinity:
        rx = (Xx * Xx + Xy * Xy) / (a * a)
        rz = Xz * Xz / (b * b)
        if Xz > -_VIEW_CLEAR * math.sqrt(Xx * Xx + Xy * Xy + Xz * Xz):
            vis = min(vis, (rx - rz + 1.0) / (rx + rz + 1.0))
    return True, s1, s2, x, y, vis / _VIEW_CLEAR, rim_m


@njit(cache=True)
def _grid_node_row(p, S, P, NV, u0, v0, g, SG, gr, gk, gf, kind, A, p0, p1, az_step, sin_try,
                   at_infinity, depth, vp, C, Rc, tc, a, b, rim_radius, K, dist, tilt, has_dist,
                   tol):
    """Row ``p`` of a node grid: node (p, q) at output pixel (u0 + (q-1) g, v0 + (p-1) g).

    With ``gf > 0`` the grid refines cell (gr, gk) of the coarser grid ``SG`` ``gf`` times,
    whose interpolation starts Newton.
    """
    for q in range(S.shape[1]):
        g1 = _NAN
        g2 = _NAN
        if gf > 0:
            g1, g2 = _interp_cell(SG, gr, gk, (p - 1.0) / gf, (q - 1.0) / gf)
        ok, s1, s2, x, y, vis, rim_m = _view_eval(
            kind, A, p0, p1, az_step, u0 + (q - 1.0) * g, v0 + (p - 1.0) * g, sin_try,
            at_infinity, depth, vp, C, Rc, tc, a, b, rim_radius, K, dist, tilt, has_dist, tol,
            g1, g2)
        S[p, q, 0] = s1
        S[p, q, 1] = s2
        P[p, q, 0] = x
        P[p, q, 1] = y
        NV[p, q, 0] = vis if ok else -np.inf
        NV[p, q, 1] = rim_m if ok else np.inf


@njit(cache=True)
def _grid_check_row(r, S, P, CV, EP, ES, u0, v0, g, kind, A, p0, p1, az_step, sin_try,
                    at_infinity, depth, vp, C, Rc, tc, a, b, rim_radius, K, dist, tilt, has_dist,
                    tol):
    """Check points of row ``r`` of a grid of ny x nx cells (CV, EP, ES are (3, ny+1, nx+1)).

    which 0: cell centres; 1: middles of horizontal edges (rows 0..ny); 2: middles of vertical
    edges (columns 0..nx). EP / ES: error of interpolating the pixel / the mirror point against
    the exact answer there; CV: the exact margins (vis, rim_m).
    """
    ny = EP.shape[1] - 1
    nx = EP.shape[2] - 1
    for k in range(nx + 1):
        for which in range(3):
            CV[which, r, k, 0] = -np.inf
            CV[which, r, k, 1] = np.inf
            EP[which, r, k] = np.inf
            ES[which, r, k] = np.inf
            if which == 0 and (r == ny or k == nx):
                continue
            if which == 1 and k == nx:
                continue
            if which == 2 and r == ny:
                continue
            cr = r
            ck = k
            tv = 0.5
            tu = 0.5
            if which == 1:
                tv = 0.0
                if cr == ny:
                    cr = ny - 1
                    tv = 1.0
            elif which == 2:
                tu = 0.0
                if ck == nx:
                    ck = nx - 1
                    tu = 1.0
            si1, si2 = _interp_cell(S, cr, ck, tv, tu)
            ok, s1, s2, xe, ye, vis, rim_m = _view_eval(
                kind, A, p0, p1, az_step, u0 + (ck + tu) * g, v0 + (cr + tv) * g, sin_try,
                at_infinity, depth, vp, C, Rc, tc, a, b, rim_radius, K, dist, tilt, has_dist, tol,
                si1, si2)
            if not ok:
                continue
            CV[which, r, k, 0] = vis
            CV[which, r, k, 1] = rim_m
            xi, yi = _interp_cell(P, cr, ck, tv, tu)
            err = math.sqrt((xe - xi) ** 2 + (ye - yi) ** 2)
            if err == err:
                EP[which, r, k] = err
            # the pixel of a mirror point does not depend on the target (margins only)
            xi, yi, _m = _view_pixel(si1, si2, 1.0, 0.0, 0.0, True, C, Rc, tc, a, b, K, dist,
                                     tilt, has_dist)
            err = math.sqrt((xe - xi) ** 2 + (ye - yi) ** 2)
            if err == err:
                ES[which, r, k] = err


@njit(cache=True)
def _grid_classify_row(r, cls, NV, CV, EP, ES, half, allow_edge):
    """Classes of the cells of row ``r`` (see the _CELL_* constants); without ``allow_edge``
    a cell on the edge of what the mirror sees is refined instead (``_CELL_BAD``).

    The tensor cubic's error ~ A(v) w(t) + B(u) w(s) peaks mid-cell and is bounded by the sum of
    its mid-edge values: both that sum and the centre's error must be within ``half``.
    """
    for k in range(cls.shape[1]):
        solved = True
        for m in range(4):
            for n in range(4):
                if not NV[r + m, k + n, 0] > -np.inf:
                    solved = False
        # visibility of the cell's own area: its corners and its five check points (the
        # margins are smooth; "clearly" means beyond _VIEW_CLEAR at all nine)
        vmin = np.inf
        rmax = -np.inf
        for m in range(1, 3):
            for n in range(1, 3):
                vmin = min(vmin, NV[r + m, k + n, 0])
                rmax = max(rmax, NV[r + m, k + n, 1])
        for e_ in range(5):
            w_ = 0 if e_ == 0 else (1 if e_ <= 2 else 2)
            rr_ = r + 1 if e_ == 2 else r
            kk_ = k + 1 if e_ == 4 else k
            vmin = min(vmin, CV[w_, rr_, kk_, 0])
            rmax = max(rmax, CV[w_, rr_, kk_, 1])
        ep = max(EP[0, r, k], max(EP[1, r, k], EP[1, r + 1, k])
                 + max(EP[2, r, k], EP[2, r, k + 1]))
        es = max(ES[0, r, k], max(ES[1, r, k], ES[1, r + 1, k])
                 + max(ES[2, r, k], ES[2, r, k + 1]))
        c = _CELL_BAD
        if solved:
            if vmin >= 1.0 and ep <= half:
                c = _CELL_SEEN
            elif rmax <= -_VIEW_CLEAR:
                c = _CELL_UNSEEN
            elif es <= half and allow_edge:
                c = _CELL_EDGE
        cls[r, k] = c


@njit(cache=True)
def _edge_pixel(s1, s2, dx, dy, dz, at_infinity, depth, vp, C, Rc, tc, a, b, rim_radius, K, dist,
                tilt, has_dist):
    """Entry from an interpolated mirror point: ``(x, y, decided)``; undecided near the edge."""
    Xx, Xy, Xz = _view_target(dx, dy, dz, at_infinity, depth, vp)
    if (not at_infinity) and Xz > 0.0 and \
            (Xx * Xx + Xy * Xy) / (a * a) - Xz * Xz / (b * b) + 1.0 < 0.0:
        return _NAN, _NAN, True  # inside the mirror body, as project_points
    rim2 = rim_radius * rim_radius
    rim_m = (rim2 - (s1 * s1 + s2 * s2)) / rim2
    xi, yi, m = _view_pixel(s1, s2, Xx, Xy, Xz, at_infinity, C, Rc, tc, a, b, K, dist, tilt,
                            has_dist)
    if rim_m < -_VIEW_RIM_MARGIN or m < -_VIEW_COS_MARGIN:
        return _NAN, _NAN, True  # clearly unseen
    if rim_m > _VIEW_RIM_MARGIN and m > _VIEW_COS_MARGIN and xi == xi and yi == yi:
        return xi, yi, True
    return _NAN, _NAN, False


@njit(cache=True, parallel=True)
def view_table(kind, A, p0, p1, az_step, W, H, step, at_infinity, depth, vp, sin_reject,
               sin_try, C, Rc, tc, a, b, rim_radius, K, dist, tilt, has_dist, tol, mode,
               outx, outy, out16, outf16, stats):
    """Remap table of a view (see the section comment above); unseen entries are -10.

    Parameters are prepared by :mod:`omnicam.views`: ``kind, A, p0, p1, az_step`` define the
    output directions (:func:`_view_direction`), ``W, H`` the size, ``step`` the node spacing
    (a multiple of ``_FINE``), ``at_infinity, depth, vp`` the targets, ``sin_reject`` the sine
    of an elevation above which nothing is seen, ``sin_try`` the sine above which nodes are not
    solved, ``C, Rc, tc`` the camera centre (mirror frame) and mirror -> camera motion,
    ``K, dist (14), tilt (3x3), has_dist`` the pinhole and distortion, ``tol`` the entry
    tolerance in pixels. ``mode`` 0 writes float32 ``outx, outy`` (H, W); mode 1 writes
    ``out16`` (H, W, 2) int16 and ``outf16`` (H, W) uint16 as
    ``cv2.convertMaps(.., CV_16SC2)`` does. ``stats`` (8,) int64 receives: nodes and check
    points solved, coarse cells seen / unseen / edge / refined, fine cells computed exactly,
    pixels solved exactly.
    """
    h = step
    ny = (H + h - 1) // h
    nx = (W + h - 1) // h
    NY = ny + 3
    NX = nx + 3
    newton_tol = 1e-10 * (a + b)
    half = 0.5 * tol
    # 1. coarse nodes, 2. check points, 3. classes
    S = np.empty((NY, NX, 2))
    P = np.empty((NY, NX, 2))
    NV = np.empty((NY, NX, 2))
    for p_ in prange(NY):
        p = np.int64(p_)  # prange indices may be unsigned
        _grid_node_row(p, S, P, NV, 0.0, 0.0, float(h), S, 0, 0, 0, kind, A, p0, p1, az_step,
                       sin_try, at_infinity, depth, vp, C, Rc, tc, a, b, rim_radius, K, dist,
                       tilt, has_dist, newton_tol)
    EP = np.empty((3, ny + 1, nx + 1))
    ES = np.empty((3, ny + 1, nx + 1))
    CV = np.empty((3, ny + 1, nx + 1, 2))
    for r_ in prange(ny + 1):
        r = np.int64(r_)
        _grid_check_row(r, S, P, CV, EP, ES, 0.0, 0.0, float(h), kind, A, p0, p1, az_step,
                        sin_try, at_infinity, depth, vp, C, Rc, tc, a, b, rim_radius, K, dist,
                        tilt, has_dist, newton_tol)
    cls = np.empty((ny, nx), dtype=np.int64)
    for r in range(ny):
        _grid_classify_row(r, cls, NV, CV, EP, ES, half, False)
    # 4. refine failing cells on a grid _FINE times finer (its own nodes, checks and classes)
    F = _FINE
    g = h // F
    ref = np.full((ny, nx), -1, dtype=np.int64)
    nbad = 0
    for r in range(ny):
        for k in range(nx):
            if cls[r, k] == _CELL_BAD:
                ref[r, k] = nbad
                nbad += 1
    cells = np.empty((nbad, 2), dtype=np.int64)
    for r in range(ny):
        for k in range(nx):
            if ref[r, k] >= 0:
                cells[ref[r, k], 0] = r
                cells[ref[r, k], 1] = k
    fS = np.empty((nbad, F + 3, F + 3, 2))
    fP = np.empty((nbad, F + 3, F + 3, 2))
    fNV = np.empty((nbad, F + 3, F + 3, 2))
    fcls = np.empty((nbad, F, F), dtype=np.int64)
    n_fine_checks = np.zeros(max(nbad, 1), dtype=np.int64)
    for c_ in prange(nbad):
        c = np.int64(c_)
        u0 = float(cells[c, 1] * h)
        v0 = float(cells[c, 0] * h)
        for p in range(F + 3):
            _grid_node_row(p, fS[c], fP[c], fNV[c], u0, v0, float(g), S, cells[c, 0],
                           cells[c, 1], F, kind, A, p0, p1, az_step, sin_try, at_infinity,
                           depth, vp, C, Rc, tc, a, b, rim_radius, K, dist, tilt, has_dist,
                           newton_tol)
        fEP = np.empty((3, F + 1, F + 1))
        fES = np.empty((3, F + 1, F + 1))
        fCV = np.empty((3, F + 1, F + 1, 2))
        for r in range(F + 1):
            _grid_check_row(r, fS[c], fP[c], fCV, fEP, fES, u0, v0, float(g), kind, A, p0, p1,
                            az_step, sin_try, at_infinity, depth, vp, C, Rc, tc, a, b,
                            rim_radius, K, dist, tilt, has_dist, newton_tol)
        for r in range(F):
            _grid_classify_row(r, fcls[c], fNV[c], fCV, fEP, fES, half, True)
        nc = 0
        for r in range(F + 1):
            for k in range(F + 1):
                for w_ in range(3):
                    if fCV[w_, r, k, 0] > -np.inf:
                        nc += 1
        n_fine_checks[c] = nc
    # 5. pixels, rows interleaved over blocks so that threads share the exact work evenly
    colc = np.empty(W)
    cols = np.empty(W)
    if kind != 0:
        for j in range(W):
            colc[j] = math.cos(az_step * j)
            cols[j] = math.sin(az_step * j)
    wu = np.empty((4, h))  # weights of the four node columns, per column offset
    for t in range(h):
        w0, w1, w2, w3 = _lagrange4(t / h)
        wu[0, t] = w0
        wu[1, t] = w1
        wu[2, t] = w2
        wu[3, t] = w3
    nblk = 16
    blk = (H + nblk - 1) // nblk
    n_exact_rows = np.zeros(nblk * blk, dtype=np.int64)
    for rr_ in prange(nblk * blk):
        rr = np.int64(rr_)
        i = (rr % nblk) * blk + rr // nblk
        if i >= H:
            continue
        r = i // h
        v0, v1, v2, v3 = _lagrange4((i - r * h) / h)
        rp = np.empty((NX, 2))
        rs = np.empty((NX, 2))
        for q in range(NX):
            for cc in range(2):
                rp[q, cc] = v0 * P[r, q, cc] + v1 * P[r + 1, q, cc] + v2 * P[r + 2, q, cc] \
                    + v3 * P[r + 3, q, cc]
                rs[q, cc] = v0 * S[r, q, cc] + v1 * S[r + 1, q, cc] + v2 * S[r + 2, q, cc] \
                    + v3 * S[r + 3, q, cc]
        rowz = 0.0
        rowc = 0.0
        if kind == 1:
            rowz = p0 + p1 * i
            rowc = 1.0
        elif kind == 2:
            el = p0 + p1 * i
            rowz = math.sin(el)
            rowc = math.cos(el)
        fa = (i - r * h) // g       # fine row of refined cells
        ftv = (i - r * h - fa * g) / g
        n_ex = 0
        for k in range(nx):
            j0 = k * h
            j1 = min(W, j0 + h)
            c = cls[r, k]
            if c == _CELL_SEEN:
                a0 = rp[k, 0]
                a1 = rp[k + 1, 0]
                a2 = rp[k + 2, 0]
                a3 = rp[k + 3, 0]
                b0 = rp[k, 1]
                b1 = rp[k + 1, 1]
                b2 = rp[k + 2, 1]
                b3 = rp[k + 3, 1]
                if mode == 0:  # the bulk of a table: a tight loop the compiler can vectorise
                    for j in range(j0, j1):
                        tu = j - j0
                        outx[i, j] = np.float32(wu[0, tu] * a0 + wu[1, tu] * a1 + wu[2, tu] * a2
                                                + wu[3, tu] * a3)
                        outy[i, j] = np.float32(wu[0, tu] * b0 + wu[1, tu] * b1 + wu[2, tu] * b2
                                                + wu[3, tu] * b3)
                else:
                    for j in range(j0, j1):
                        tu = j - j0
                        x = wu[0, tu] * a0 + wu[1, tu] * a1 + wu[2, tu] * a2 + wu[3, tu] * a3
                        y = wu[0, tu] * b0 + wu[1, tu] * b1 + wu[2, tu] * b2 + wu[3, tu] * b3
                        _view_store(i, j, x, y, 1, outx, outy, out16, outf16)
                continue
            if c == _CELL_UNSEEN:
                for j in range(j0, j1):
                    _view_store(i, j, _NAN, _NAN, mode, outx, outy, out16, outf16)
                continue
            ci = ref[r, k]
            for j in range(j0, j1):
                x = _NAN
                y = _NAN
                decided = False
                fc = _CELL_BAD
                if c == _CELL_BAD:  # refined cell: its sub-cell's class first
                    fb = (j - j0) // g
                    fc = fcls[ci, fa, fb]
                    if fc == _CELL_SEEN:
                        x, y = _interp_cell(fP[ci], fa, fb, ftv, (j - j0 - fb * g) / g)
                        decided = True
                    elif fc == _CELL_UNSEEN:
                        decided = True
                if decided:
                    _view_store(i, j, x, y, mode, outx, outy, out16, outf16)
                    continue
                if kind == 0:
                    x0 = A[0, 0] * j + A[0, 1] * i + A[0, 2]
                    y0 = A[1, 0] * j + A[1, 1] * i + A[1, 2]
                    z0 = A[2, 0] * j + A[2, 1] * i + A[2, 2]
                else:
                    px = rowc * colc[j]
                    py = rowc * cols[j]
                    x0 = A[0, 0] * px + A[0, 1] * py + A[0, 2] * rowz
                    y0 = A[1, 0] * px + A[1, 1] * py + A[1, 2] * rowz
                    z0 = A[2, 0] * px + A[2, 1] * py + A[2, 2] * rowz
                nrm = math.sqrt(x0 * x0 + y0 * y0 + z0 * z0)
                dx = x0 / nrm
                dy = y0 / nrm
                dz = z0 / nrm
                decided = not dz <= sin_reject  # above every elevation the rig sees
                if not decided:
                    if c == _CELL_EDGE:
                        tu = j - j0
                        s1 = wu[0, tu] * rs[k, 0] + wu[1, tu] * rs[k + 1, 0] \
                            + wu[2, tu] * rs[k + 2, 0] + wu[3, tu] * rs[k + 3, 0]
                        s2 = wu[0, tu] * rs[k, 1] + wu[1, tu] * rs[k + 1, 1] \
                            + wu[2, tu] * rs[k + 2, 1] + wu[3, tu] * rs[k + 3, 1]
                        x, y, decided = _edge_pixel(s1, s2, dx, dy, dz, at_infinity, depth, vp,
                                                    C, Rc, tc, a, b, rim_radius, K, dist, tilt,
                                                    has_dist)
                    elif fc == _CELL_EDGE:
                        fb = (j - j0) // g
                        s1, s2 = _interp_cell(fS[ci], fa, fb, ftv, (j - j0 - fb * g) / g)
                        x, y, decided = _edge_pixel(s1, s2, dx, dy, dz, at_infinity, depth, vp,
                                                    C, Rc, tc, a, b, rim_radius, K, dist, tilt,
                                                    has_dist)
                if not decided:
                    x, y = _view_exact(dx, dy, dz, sin_reject, at_infinity, depth, vp, C, Rc, tc,
                                       a, b, rim_radius, K, dist, tilt, has_dist, newton_tol)
                    n_ex += 1
                _view_store(i, j, x, y, mode, outx, outy, out16, outf16)
        n_exact_rows[rr] = n_ex
    n = 0
    for p in range(NY):
        for q in range(NX):
            if NV[p, q, 0] > -np.inf:
                n += 1
    for c in range(nbad):
        for p in range(F + 3):
            for q in range(F + 3):
                if fNV[c, p, q, 0] > -np.inf:
                    n += 1
    stats[0] = n
    n = 0
    for c in range(nbad):
        n += n_fine_checks[c]
    for w_ in range(3):
        for r in range(ny + 1):
            for k in range(nx + 1):
                if CV[w_, r, k, 0] > -np.inf:
                    n += 1
    stats[1] = n
    for c in range(6):
        stats[2 + c] = 0
    for r in range(ny):
        for k in range(nx):
            if cls[r, k] == _CELL_SEEN:
                stats[2] += 1
            elif cls[r, k] == _CELL_UNSEEN:
                stats[3] += 1
            elif cls[r, k] == _CELL_EDGE:
                stats[4] += 1
            else:
                stats[5] += 1
    for c in range(nbad):
        for r in range(F):
            for k in range(F):
                if fcls[c, r, k] == _CELL_BAD:
                    stats[6] += 1
    stats[7] = n_exact_rows.sum()
