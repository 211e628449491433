"""numba kernels of the per-point work: ray tracing (eqs. 6-19) and exact forward projection.

Only arithmetic on prepared float64 arrays lives here; validation, shapes, distortion and the
public API are in :mod:`omnicam.raytrace` and :mod:`omnicam.camera`. Every cached kernel and the
helpers it inlines stay in this one module (numba's cache does not see changes in other files).
The slow, obviously correct references are :mod:`omnicam.mirror` and ``tests/naive.py``.
"""

from __future__ import annotations

import math
from collections import namedtuple

import numpy as np

from ._jit import kernel

_NAN = math.nan

# -- Newton on Fermat's path length (_reflection_point): named tolerances and counts --------------
NEWTON_TOL_REL = 1e-10  # converged when a step is shorter than this times (a + b)
NEWTON_MAX_ITER = 50  # iterations from the aligned start
NEWTON_WARM_MAX_ITER = 8  # iterations from a start interpolated from solved neighbours
NEWTON_BASIN_REL = 1e-4  # steps shorter than this times (a + b) are taken whole (in the basin)
NEWTON_WARM_DONE_REL = 1e-6  # a warm start's full step this short leaves ~1e-12 (a + b)
LINE_SEARCH_HALVINGS = 30  # backtracking halvings before giving up on a descent step
LINE_SEARCH_SLACK = 1e-15  # relative increase of the path length still taken as no increase
GRADIENT_ZERO = 1e-9  # |grad L| under which a stalled line search counts as converged
GRADIENT_STEP_REL = 0.1  # gradient step where L is not convex, times min(|C - P|, rim radius)


@kernel
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


@kernel
def trace_rays(lo, hi, uv, Kinv, R, C, a, b, rim_radius, origins, directions):
    """Ray tracing of pixels ``lo:hi`` to reflected rays, written into ``origins``/``directions``.

    ``uv`` (N, 2): pixel (or, with ``Kinv = I``, undistorted normalised) coordinates.
    Camera ray ``V_C = Kinv (u, v, 1)`` (eq. 6), ``V_M = R^T V_C`` and ``F_M = C`` (eqs. 16-17),
    first hit inside the rim (eqs. 8-12), reflection about the unit normal (eqs. 14-15).
    Rows that miss the mirror, or NaN input, are written as NaN.
    """
    ia2 = 1.0 / (a * a)
    ib2 = 1.0 / (b * b)
    b2a2 = b * b * ia2
    rim2 = rim_radius * rim_radius
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


@kernel
def _path_length(s1, s2, Cx, Cy, Cz, Xx, Xy, Xz, at_infinity, a, b):
    """Fermat path length camera -> mirror point (s1, s2, f(s)) -> scene point (or direction)."""
    z = b * math.sqrt(1.0 + (s1 * s1 + s2 * s2) / (a * a))
    r1 = math.sqrt((Cx - s1) ** 2 + (Cy - s2) ** 2 + (Cz - z) ** 2)
    if at_infinity:
        return r1 - (Xx * s1 + Xy * s2 + Xz * z)
    return r1 + math.sqrt((Xx - s1) ** 2 + (Xy - s2) ** 2 + (Xz - z) ** 2)


@kernel
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


@kernel
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
        d1, d2, g1, g2, r1, convex = _newton_step(s1, s2, Cx, Cy, Cz, Xx, Xy, Xz, at_infinity, a, b)
        if not convex:  # not convex here: a gradient step of the local length scale
            gn = math.sqrt(g1 * g1 + g2 * g2) + 1e-300
            step = GRADIENT_STEP_REL * min(r1, rim_radius)
            d1 = -g1 / gn * step
            d2 = -g2 / gn * step
        t = 1.0
        dn = math.sqrt(d1 * d1 + d2 * d2)
        if convex and dn < NEWTON_BASIN_REL * (a + b):
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
        for _ls in range(LINE_SEARCH_HALVINGS):
            n1 = s1 + t * d1
            n2 = s2 + t * d2
            Ln = _path_length(n1, n2, Cx, Cy, Cz, Xx, Xy, Xz, at_infinity, a, b)
            if Ln <= L + LINE_SEARCH_SLACK * abs(L):
                accepted = True
                break
            t *= 0.5
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
def project_points(lo, hi, X, at_infinity, R, t, C, a, b, rim_radius, K, out):
    """Exact non-central projection of scene points ``lo:hi`` (or directions) to ``out`` (N, 2).

    ``out = K * (x/z, y/z)`` of the reflection point in the camera frame (pass ``K = I`` to get
    normalised coordinates). Unseen points, points that do not converge and NaN input give NaN.
    """
    a2 = a * a
    b2 = b * b
    rim2 = rim_radius * rim_radius
    tol = NEWTON_TOL_REL * (a + b)
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
        elif Xz > 0.0 and (Xx * Xx + Xy * Xy) / a2 - Xz * Xz / b2 + 1.0 < 0.0:
            continue  # inside the mirror body
        s1, s2, ok = _reflection_point(
            C[0], C[1], C[2], Xx, Xy, Xz, at_infinity, a, b, rim_radius, tol, NEWTON_MAX_ITER
        )
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
# a given distance from a viewpoint, that an output pixel looks along. The reflection point is
# solved exactly (``_reflection_point``, the same Newton as project_points) on a coarse grid of
# nodes every ``step`` output pixels, on the mirror sheet extended beyond the rim, so the mirror
# point s = (s1, s2) is a smooth function of the output pixel even across the edge of what the
# mirror sees. Each cell is interpolated by the tensor-product cubic Lagrange polynomial of its
# 4x4 nodes; its error (~ h^4 f^(4) w(t), largest mid-cell) is measured against the exact answer
# at the cell centre and the middle of its four edges. A cell whose estimate exceeds ``tol / 2``
# (or that has a node without a solution) is refined once: the same construction on a grid
# ``FINE`` times finer inside it; a sub-cell that still fails is computed exactly pixel by pixel.
# Cells wholly and clearly seen interpolate the pixel itself; cells wholly and clearly unseen are
# written unseen ("clearly": the exact margins at the 3 x 3 lattice of corners and check points
# beyond VIEW_CLEAR, or beyond VIEW_CLEAR_BOUND over the whole cell by the bound that their
# second differences give, _lattice_bounds); in the others visibility (rim, eqs. 12 and 15, in
# front of the camera) is decided per pixel from the interpolated mirror point with a margin,
# and pixels inside the margin are solved exactly.
#
# The phases, run in this order by omnicam.views._build_table (the first five by
# views._GridStack, for the coarse grid and then for the refined grids of its failing cells);
# the kernels are those with per-point work, the rest is a few array operations per node or
# cell in omnicam.views (no kernel to compile or load for them):
#   views._grid_nodes    output positions of the nodes (and Newton starts of refined grids)
#   solve_view_points    the nodes' exact solutions: mirror points, pixels and margins
#   views._grid_checks   positions of the check points, the interpolated starts and estimates
#   solve_view_points    the check points' exact solutions and margins, and the estimates'
#                        interpolation errors
#   classify_cells       each cell's class from its nodes and check points
#   fill_rows            table entries of decided pixels; the others are marked pending
#   solve_view_points    the exact solutions of the pending pixels
#   views._store_entries their table entries
# A "grid stack" holds G grids of the same shape and spacing: the coarse grid (G = 1) or the
# refined grids of the failing coarse cells (G = their number).

#: What the table kernels know of the rig (omnicam.views._rig_args builds it): camera centre
#: ``C`` (mirror frame), mirror -> camera motion ``R, t``, mirror ``a, b, rim_radius``, pinhole
#: ``K`` (skew allowed), OpenCV distortion ``dist`` (14 values, zeros padded) and its ``tilt``
#: matrix, ``has_dist``.
RigArgs = namedtuple(
    "RigArgs", ["C", "R", "t", "a", "b", "rim_radius", "K", "dist", "tilt", "has_dist"]
)

#: What the table kernels know of the view (omnicam.views._view_args builds it): ``kind`` 0
#: perspective, 1 cylindrical, 2 equirectangular, with ``A, p0, p1, az_step`` as in
#: :func:`_view_direction`; targets at infinity or at ``depth`` from ``viewpoint``;
#: ``sin_reject``: sine of the elevation above which nothing is seen; ``sin_try``: above which
#: nodes are not solved; ``newton_tol``: Newton's step tolerance (mirror units).
ViewArgs = namedtuple(
    "ViewArgs",
    [
        "kind",
        "A",
        "p0",
        "p1",
        "az_step",
        "at_infinity",
        "depth",
        "viewpoint",
        "sin_reject",
        "sin_try",
        "newton_tol",
    ],
)

VIEW_RIM_MARGIN = 2e-3  # relative margin on s1^2 + s2^2 against rim_radius^2
VIEW_COS_MARGIN = 1e-3  # margin on the cosines of the other visibility tests
VIEW_CLEAR = 0.05  # margins (relative rim, cosines, body) of cells wholly seen or unseen
VIEW_CLEAR_BOUND = 5e-3  # the same, for a bound of the margin over the cell (_lattice_bounds)
LATTICE_SAFETY = 8.0  # factor on _lattice_bounds' estimate of the bilinear interpolation error
UNSEEN = -10.0  # omnicam.views.UNSEEN
#: refinement factor of failing cells: the cubic's error falls as h^4, so halving the node
#: spacing divides it by 16, which brings every refined cell of the perspective views that
#: straddle the mirror's visible band (1024x768, f = 400, looking horizontally; coarse
#: estimates up to 0.06 px) and of 108 tables over the test rigs within TOLERANCE / 2
#: (a sub-cell that still fails is solved pixel by pixel); 4 gave the same sub-cell verdicts
#: for a third more exact solutions at nodes and check points
FINE = 2
CELL_BAD = 0  # refined, else computed exactly pixel by pixel
CELL_SEEN = 1  # pixels interpolated directly from the nodes' pixels
CELL_UNSEEN = 2  # every pixel unseen
CELL_EDGE = 3  # mirror point interpolated, visibility decided per pixel
CELL_RIM = 4  # as EDGE, every test but the rim's clearly passed: the rim decides per pixel
CHECK_CENTRE, CHECK_HORIZONTAL_EDGE, CHECK_VERTICAL_EDGE = 0, 1, 2  # kinds of check points


@kernel
def _view_direction(view, u, v):
    """Unit mirror-frame direction of output pixel (u, v) (docs/conventions.md, "Views").

    kind 0: perspective, ``d = A (u, v, 1)`` with ``A = R^T K_new^-1``.
    kind 1: cylindrical panorama, azimuth ``az_step u``, ``tan(elevation) = p0 + p1 v``.
    kind 2: equirectangular panorama, elevation ``p0 + p1 v`` (radians). For panoramas ``A = R^T``.
    """
    A = view.A
    if view.kind == 0:
        x = A[0, 0] * u + A[0, 1] * v + A[0, 2]
        y = A[1, 0] * u + A[1, 1] * v + A[1, 2]
        z = A[2, 0] * u + A[2, 1] * v + A[2, 2]
    else:
        az = view.az_step * u
        ca = math.cos(az)
        sa = math.sin(az)
        if view.kind == 1:
            x0 = ca
            y0 = sa
            z0 = view.p0 + view.p1 * v
        else:
            el = view.p0 + view.p1 * v
            ce = math.cos(el)
            x0 = ce * ca
            y0 = ce * sa
            z0 = math.sin(el)
        x = A[0, 0] * x0 + A[0, 1] * y0 + A[0, 2] * z0
        y = A[1, 0] * x0 + A[1, 1] * y0 + A[1, 2] * z0
        z = A[2, 0] * x0 + A[2, 1] * y0 + A[2, 2] * z0
    n = math.sqrt(x * x + y * y + z * z)
    return x / n, y / n, z / n


@kernel(inline="always")
def _view_target(view, dx, dy, dz):
    """The scene target of a unit direction: itself at infinity, else ``viewpoint + depth d``."""
    if view.at_infinity:
        return dx, dy, dz
    vp = view.viewpoint
    return vp[0] + view.depth * dx, vp[1] + view.depth * dy, vp[2] + view.depth * dz


@kernel
def _inside_mirror_body(Xx, Xy, Xz, a, b):
    """Whether a finite point lies inside the mirror's body (above the sheet, eq. 1)."""
    return Xz > 0.0 and (Xx * Xx + Xy * Xy) / (a * a) - Xz * Xz / (b * b) + 1.0 < 0.0


@kernel(inline="always")
def _distort(rig, xn, yn):
    """OpenCV's distortion of normalised coordinates (``cv2.projectPoints``: k1..k6, p1, p2,
    s1..s4, then the tilt of tau_x, tau_y)."""
    dist = rig.dist
    tilt = rig.tilt
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
    return ip * vx, ip * vy


@kernel(inline="always")
def _view_pixel(rig, s1, s2, Xx, Xy, Xz, at_infinity):
    """Pixel of the mirror point (s1, s2, f(s)) and the smallest visibility cosine.

    The pixel is the pinhole image (eq. 6) of the mirror point, with OpenCV's distortion model
    (:func:`_distort`), then ``K`` with skew, as :func:`omnicam.raytrace.project` does. The
    cosine is the least of: camera on the outer side of the tangent plane (eq. 12), target on
    the outer side (eq. 15), mirror point in front of the camera; all positive means
    project_points' tests pass. NaN pixel behind the camera.
    """
    a2 = rig.a * rig.a
    b2 = rig.b * rig.b
    C = rig.C
    Rc = rig.R
    tc = rig.t
    z = rig.b * math.sqrt(1.0 + (s1 * s1 + s2 * s2) / a2)
    Nx = b2 * s1 / (a2 * z)
    Ny = b2 * s2 / (a2 * z)
    nn2 = Nx * Nx + Ny * Ny + 1.0
    wx = C[0] - s1
    wy = C[1] - s2
    wz = C[2] - z
    cos_camera = (Nx * wx + Ny * wy - wz) / math.sqrt(nn2 * (wx * wx + wy * wy + wz * wz))
    if at_infinity:
        cos_target = (Nx * Xx + Ny * Xy - Xz) / math.sqrt(nn2)
    else:
        ex = Xx - s1
        ey = Xy - s2
        ez = Xz - z
        cos_target = (Nx * ex + Ny * ey - ez) / math.sqrt(nn2 * (ex * ex + ey * ey + ez * ez))
    xc = Rc[0, 0] * s1 + Rc[0, 1] * s2 + Rc[0, 2] * z + tc[0]
    yc = Rc[1, 0] * s1 + Rc[1, 1] * s2 + Rc[1, 2] * z + tc[1]
    zc = Rc[2, 0] * s1 + Rc[2, 1] * s2 + Rc[2, 2] * z + tc[2]
    cos_front = zc / math.sqrt(xc * xc + yc * yc + zc * zc)
    m = min(cos_camera, min(cos_target, cos_front))
    if not zc > 0.0:
        return _NAN, _NAN, m
    x, y, _finite = _camera_pixel_call(rig, xc, yc, zc)
    return x, y, m


@kernel
def _newton_warm(rig, s1, s2, Xx, Xy, Xz, at_infinity, tol):
    """Newton's full steps of ``_reflection_point`` from a start already in its basin.

    The start comes from the interpolated neighbours, so the step is small from the first
    iteration; the same gradient and Hessian of the path length as ``_reflection_point``.
    Stops at its step tolerance ``tol`` or after a full step shorter than
    ``NEWTON_WARM_DONE_REL (a + b)``: Newton converges quadratically in the basin, so the error
    left is of the order of that step squared over the mirror's scale, ~1e-12 (a + b), below
    the tolerance of 1e-10 (a + b). Returns ``(s1, s2, ok)``; not ok (the caller then solves
    from the aligned start) if a step is not a full Newton step of that basin or
    ``NEWTON_WARM_MAX_ITER`` pass.
    """
    C = rig.C
    a = rig.a
    b = rig.b
    for _ in range(NEWTON_WARM_MAX_ITER):
        d1, d2, _g1, _g2, _r1, convex = _newton_step(
            s1, s2, C[0], C[1], C[2], Xx, Xy, Xz, at_infinity, a, b
        )
        if not convex:
            return s1, s2, False
        dn = math.sqrt(d1 * d1 + d2 * d2)
        if not dn < NEWTON_BASIN_REL * (a + b):
            return s1, s2, False
        s1 += d1
        s2 += d2
        # quadratic convergence: the error left after a full step of dn is ~ dn^2 / (a + b)
        if dn < tol or dn < NEWTON_WARM_DONE_REL * (a + b):
            return s1, s2, True
    return s1, s2, False


@kernel
def _view_point(view, rig, u, v, g1, g2, pixels_only):
    """Exact solution at output position (u, v): ``ok, s1, s2, x, y, vis, rim_m, other``.

    The mirror point ``s`` whose reflection joins the camera centre and the pixel's target
    (``_reflection_point``; from ``(g1, g2)`` first when not NaN, a start interpolated from
    solved neighbours), and its (geometric) pixel ``(x, y)``.

    Grid points (``pixels_only`` False) are solved on the sheet extended past the rim, up to
    the elevation ``sin_try``, with their margins: ``vis`` = the least of the relative rim
    margin, the cosines of :func:`_view_pixel` and the body test of finite targets, over
    ``VIEW_CLEAR`` (>= 1: clearly seen), ``rim_m = 1 - |s|^2 / rim_radius^2`` and ``other``,
    the least of the same margins but the rim's, over ``VIEW_CLEAR``.
    Pixels (``pixels_only``) get project_points' answer: not ok (NaN) when unseen, i.e. above
    ``sin_reject`` (proved in omnicam.views), inside the mirror body, outside the rim, or
    failing a visibility test; no margins.
    """
    at_infinity = view.at_infinity
    a = rig.a
    b = rig.b
    rim2 = rig.rim_radius * rig.rim_radius
    dx, dy, dz = _view_direction(view, u, v)
    if not dz <= (view.sin_reject if pixels_only else view.sin_try):
        return False, _NAN, _NAN, _NAN, _NAN, _NAN, _NAN, _NAN
    Xx, Xy, Xz = _view_target(view, dx, dy, dz)
    if pixels_only and not at_infinity and _inside_mirror_body(Xx, Xy, Xz, a, b):
        return False, _NAN, _NAN, _NAN, _NAN, _NAN, _NAN, _NAN
    ok = False
    if g1 == g1 and g2 == g2:
        s1, s2, ok = _newton_warm(rig, g1, g2, Xx, Xy, Xz, at_infinity, view.newton_tol)
    if not ok:
        C = rig.C
        s1, s2, ok = _reflection_point(
            C[0],
            C[1],
            C[2],
            Xx,
            Xy,
            Xz,
            at_infinity,
            a,
            b,
            rig.rim_radius,
            view.newton_tol,
            NEWTON_MAX_ITER,
        )
    if not ok or (pixels_only and s1 * s1 + s2 * s2 > rim2):
        return False, _NAN, _NAN, _NAN, _NAN, _NAN, _NAN, _NAN
    x, y, m = _view_pixel(rig, s1, s2, Xx, Xy, Xz, at_infinity)
    if pixels_only:
        if not m > 0.0:
            return False, _NAN, _NAN, _NAN, _NAN, _NAN, _NAN, _NAN
        return True, s1, s2, x, y, _NAN, _NAN, _NAN
    if not (x == x and y == y):
        return False, _NAN, _NAN, _NAN, _NAN, _NAN, _NAN, _NAN
    rim_m = 1.0 - (s1 * s1 + s2 * s2) / rim2
    vis = min(rim_m, m)
    other = m  # every margin but the rim's
    if not at_infinity:
        rx = (Xx * Xx + Xy * Xy) / (a * a)
        rz = Xz * Xz / (b * b)
        if Xz > -VIEW_CLEAR * math.sqrt(Xx * Xx + Xy * Xy + Xz * Xz):
            body = (rx - rz + 1.0) / (rx + rz + 1.0)
            vis = min(vis, body)
            other = min(other, body)
    return True, s1, s2, x, y, vis / VIEW_CLEAR, rim_m, other / VIEW_CLEAR


@kernel
def _lagrange4(t):
    """Cubic Lagrange weights of nodes at -1, 0, 1, 2 for 0 <= t <= 1."""
    return (
        -t * (t - 1.0) * (t - 2.0) / 6.0,
        (t + 1.0) * (t - 1.0) * (t - 2.0) / 2.0,
        -(t + 1.0) * t * (t - 2.0) / 2.0,
        (t + 1.0) * t * (t - 1.0) / 6.0,
    )


# -- the phases ---------------------------------------------------------------------------------
@kernel
def cubic_blocks(offsets, blocks, weights, S, out):
    """Tensor cubic Lagrange interpolation of node values ``S`` into blocks of ``out``.

    ``out`` (G, rows, columns, 2); ``S`` (G, NY, NX, 2), or (1, NY, NX, 2) for one grid that
    all of ``out``'s grids interpolate. Block b: the entries (i, j) in rows
    ``blocks[b, 0]:blocks[b, 1]``, columns ``blocks[b, 2]:blocks[b, 3]`` of each grid c are the
    cubic of cell ``(i + blocks[b, 4] + offsets[c, 0], j + blocks[b, 5] + offsets[c, 1])`` at the
    cell coordinates whose :func:`_lagrange4` weights are ``weights[b, 0:4]`` (rows) and
    ``weights[b, 4:8]`` (columns): each of the cell's four node rows summed over its columns,
    then the rows.
    """
    for c in range(out.shape[0]):
        src = min(c, S.shape[0] - 1)
        for b in range(blocks.shape[0]):
            for i in range(blocks[b, 0], blocks[b, 1]):
                r = i + blocks[b, 4] + offsets[c, 0]
                for j in range(blocks[b, 2], blocks[b, 3]):
                    k = j + blocks[b, 5] + offsets[c, 1]
                    for cc in range(2):
                        o = 0.0
                        for m in range(4):
                            row = (
                                weights[b, 4] * S[src, r + m, k, cc]
                                + weights[b, 5] * S[src, r + m, k + 1, cc]
                                + weights[b, 6] * S[src, r + m, k + 2, cc]
                                + weights[b, 7] * S[src, r + m, k + 3, cc]
                            )
                            o += weights[b, m] * row
                        out[c, i, j, cc] = o


@kernel
def solve_view_points(
    lo,
    hi,
    view,
    rig,
    positions,
    starts,
    pixels_only,
    estimates,
    with_mirror_error,
    ok,
    S,
    P,
    margins,
    errors,
):
    """Exact solutions at the output positions ``lo:hi`` (N, 2).

    :func:`_view_point` at each: the mirror point ``S``, its pixel ``P`` (the exact table
    entry for ``pixels_only``, NaN if unseen) and ``margins`` = (vis, rim_m, other)
    (``-inf, inf, -inf`` and ``ok`` False when not solved), Newton started from ``starts``
    where not NaN.
    Check points (``estimates`` (N, 2) the pixels interpolated from the nodes' pixels; empty
    for nodes and pixels) get their interpolation ``errors`` (N, 2): |exact pixel - estimate|
    and, ``with_mirror_error``, |exact pixel - pixel of the start| (the interpolated mirror
    point); inf where not solved or not computed.
    """
    checks = estimates.shape[0] > 0
    for n in range(lo, hi):
        xs = _NAN
        ys = _NAN
        if checks and with_mirror_error:
            # the pixel of a mirror point does not depend on the target (margins only)
            xs, ys, _m = _view_pixel(rig, starts[n, 0], starts[n, 1], 1.0, 0.0, 0.0, True)
        solved, s1, s2, x, y, vis, rim_m, other = _view_point(
            view, rig, positions[n, 0], positions[n, 1], starts[n, 0], starts[n, 1], pixels_only
        )
        ok[n] = solved
        S[n, 0] = s1
        S[n, 1] = s2
        P[n, 0] = x
        P[n, 1] = y
        margins[n, 0] = vis if solved else -np.inf
        margins[n, 1] = rim_m if solved else np.inf
        margins[n, 2] = other if solved else -np.inf
        if checks:
            errors[n, 0] = np.inf
            errors[n, 1] = np.inf
            if solved:
                err = math.sqrt((x - estimates[n, 0]) ** 2 + (y - estimates[n, 1]) ** 2)
                if err == err:
                    errors[n, 0] = err
                err = math.sqrt((x - xs) ** 2 + (y - ys) ** 2)
                if err == err:
                    errors[n, 1] = err


@kernel
def _cell_check_extremes(node_margins, check_margins, r, k):
    """Least visibility and largest rim margin over cell (r, k)'s corners and check points.

    The margins are smooth; "clearly" seen or unseen means beyond ``VIEW_CLEAR`` at all nine,
    or beyond ``VIEW_CLEAR_BOUND`` everywhere by :func:`_lattice_bounds` (:func:`_clearly`).
    """
    vmin = np.inf
    rmax = -np.inf
    for m in range(1, 3):
        for n in range(1, 3):
            vmin = min(vmin, node_margins[r + m, k + n, 0])
            rmax = max(rmax, node_margins[r + m, k + n, 1])
    for e in range(5):
        which = (
            CHECK_CENTRE if e == 0 else (CHECK_HORIZONTAL_EDGE if e <= 2 else CHECK_VERTICAL_EDGE)
        )
        rr = r + 1 if e == 2 else r
        kk = k + 1 if e == 4 else k
        vmin = min(vmin, check_margins[which, rr, kk, 0])
        rmax = max(rmax, check_margins[which, rr, kk, 1])
    return vmin, rmax


@kernel
def _clearly(node_margins, check_margins, r, k, vmin, rmax):
    """Whether cell (r, k) is clearly seen and whether it is clearly outside the rim, from
    :func:`_cell_check_extremes` ``vmin, rmax`` or else :func:`_lattice_bounds`."""
    # the margins' indices typed int64, not as the literals 0 and 1: one signature of
    # _lattice_bounds, not one per literal (each compiled cold)
    MARGIN_VIS = np.int64(0)
    MARGIN_RIM = np.int64(1)
    seen = vmin >= 1.0  # vis is the visibility margin / VIEW_CLEAR
    if not seen:
        vlo, _vhi = _lattice_bounds(node_margins, check_margins, r, k, MARGIN_VIS)
        seen = vlo * VIEW_CLEAR >= VIEW_CLEAR_BOUND
    unseen = rmax <= -VIEW_CLEAR
    if not unseen and not seen:
        _rlo, rhi = _lattice_bounds(node_margins, check_margins, r, k, MARGIN_RIM)
        unseen = rhi <= -VIEW_CLEAR_BOUND
    return seen, unseen


@kernel
def _clearly_seen_but_rim(node_margins, check_margins, r, k):
    """Whether every visibility margin of cell (r, k) but the rim's (margin 2: the cosines
    and the body test) is beyond ``VIEW_CLEAR_BOUND`` over the whole cell by
    :func:`_lattice_bounds`: then the rim alone decides what is seen in it."""
    lo, _hi = _lattice_bounds(node_margins, check_margins, r, k, np.int64(2))
    return lo * VIEW_CLEAR >= VIEW_CLEAR_BOUND


@kernel
def _lattice_bounds(node_margins, check_margins, r, k, m):
    """Bounds ``(lo, hi)`` of the smooth margin ``m`` (0 visibility, 1 rim, 2 visibility but
    the rim) over cell (r, k).

    Its nine samples form a 3 x 3 lattice of spacing h = 1/2 cell (corners: nodes; middles of
    the edges and centre: check points). On each quarter cell the bilinear interpolant of the
    four samples lies between their extremes, and the function differs from it by at most
    ``h^2 / 8 (|f_uu| + |f_vv|)``; the second derivatives are estimated by the largest second
    differences along the lattice's rows and columns (``f'' h^2``), so the error bound is
    ``(d_uu + d_vv) / 8``, widened by ``LATTICE_SAFETY`` for their variation over the cell.
    ``(-inf, inf)`` if a sample is not solved.
    """
    f00 = node_margins[r + 1, k + 1, m]
    f02 = node_margins[r + 1, k + 2, m]
    f20 = node_margins[r + 2, k + 1, m]
    f22 = node_margins[r + 2, k + 2, m]
    f01 = check_margins[CHECK_HORIZONTAL_EDGE, r, k, m]
    f21 = check_margins[CHECK_HORIZONTAL_EDGE, r + 1, k, m]
    f10 = check_margins[CHECK_VERTICAL_EDGE, r, k, m]
    f12 = check_margins[CHECK_VERTICAL_EDGE, r, k + 1, m]
    f11 = check_margins[CHECK_CENTRE, r, k, m]
    # an unsolved sample (+-inf) or NaN (compared one by one: no inf - inf, no max of a NaN)
    for f in (f00, f01, f02, f10, f11, f12, f20, f21, f22):
        if not abs(f) < np.inf:
            return -np.inf, np.inf
    d_uu = max(
        abs(f00 - 2.0 * f01 + f02), max(abs(f10 - 2.0 * f11 + f12), abs(f20 - 2.0 * f21 + f22))
    )
    d_vv = max(
        abs(f00 - 2.0 * f10 + f20), max(abs(f01 - 2.0 * f11 + f21), abs(f02 - 2.0 * f12 + f22))
    )
    widen = LATTICE_SAFETY * (d_uu + d_vv) / 8.0
    lo = min(min(min(f00, f01), min(f02, f10)), min(min(f11, f12), min(f20, min(f21, f22))))
    hi = max(max(max(f00, f01), max(f02, f10)), max(max(f11, f12), max(f20, max(f21, f22))))
    return lo - widen, hi + widen


@kernel
def _cell_error(errors, r, k):
    """Error estimate of cell (r, k): the tensor cubic's error ~ A(v) w(t) + B(u) w(s) peaks
    mid-cell and is bounded by the sum of its mid-edge values; also the centre's own error."""
    return max(
        errors[CHECK_CENTRE, r, k],
        max(errors[CHECK_HORIZONTAL_EDGE, r, k], errors[CHECK_HORIZONTAL_EDGE, r + 1, k])
        + max(errors[CHECK_VERTICAL_EDGE, r, k], errors[CHECK_VERTICAL_EDGE, r, k + 1]),
    )


@kernel
def classify_cells(
    view,
    origins,
    spacing,
    W,
    H,
    node_margins,
    check_margins,
    pixel_error,
    mirror_error,
    half_tol,
    allow_edge,
    cls,
):
    """Classes (the CELL_* constants) of the cells of a grid stack, ``cls`` (G, ny, nx).

    A cell needs all 16 of its nodes solved; it is SEEN when clearly seen
    (:func:`_clearly`) with an error estimate (:func:`_cell_error`) of the pixels
    within ``half_tol``, UNSEEN when clearly outside the rim, EDGE
    when that of the mirror points is within ``half_tol`` (only with ``allow_edge``: on the
    coarse grid such a cell is refined instead), RIM instead of EDGE when every margin but
    the rim's is clearly positive over it (:func:`_clearly_seen_but_rim`), else BAD.

    A BAD cell of a perspective view (grid c's cell (r, k) spans the output pixels from
    ``origins[c] + (k, r) spacing``; the view is ``W`` x ``H``) whose every pixel looks above
    ``sin_reject`` (where nothing is seen) is UNSEEN instead, neither refined nor visited:
    with ``sin_reject > 0`` the directions above that elevation form a convex cone, and the
    pixels whose directions lie in it a convex set of the image plane, so a cell is in it when
    its four corner pixels are (with a margin of ``1e-9`` for rounding).
    """
    above_band = view.kind == 0 and 0.0 < view.sin_reject < 1.0
    for c in range(cls.shape[0]):
        for r in range(cls.shape[1]):
            for k in range(cls.shape[2]):
                solved = True
                for m in range(4):
                    for n in range(4):
                        if not node_margins[c, r + m, k + n, 0] > -np.inf:
                            solved = False
                vmin, rmax = _cell_check_extremes(node_margins[c], check_margins[c], r, k)
                seen, unseen = _clearly(node_margins[c], check_margins[c], r, k, vmin, rmax)
                cell_class = CELL_BAD
                if solved:
                    if seen and _cell_error(pixel_error[c], r, k) <= half_tol:
                        cell_class = CELL_SEEN
                    elif unseen:
                        cell_class = CELL_UNSEEN
                    elif _cell_error(mirror_error[c], r, k) <= half_tol and allow_edge:
                        cell_class = CELL_EDGE
                        if _clearly_seen_but_rim(node_margins[c], check_margins[c], r, k):
                            cell_class = CELL_RIM
                if cell_class == CELL_BAD and above_band:
                    u0 = origins[c, 0] + k * spacing
                    v0 = origins[c, 1] + r * spacing
                    if _corners_above(view, u0, v0, spacing, W, H):
                        cell_class = CELL_UNSEEN
                cls[c, r, k] = cell_class


@kernel(inline="always")
def _corners_above(view, u0, v0, spacing, W, H):
    """Whether the four corner pixels of the perspective cell from output pixel (u0, v0) look
    above ``sin_reject + 1e-9`` (:func:`_view_direction`'s elevation)."""
    limit = view.sin_reject + 1e-9
    u1 = min(u0 + spacing - 1.0, W - 1.0)
    v1 = min(v0 + spacing - 1.0, H - 1.0)
    for corner in range(4):
        u = u0 if corner % 2 == 0 else u1
        v = v0 if corner < 2 else v1
        _dx, _dy, dz = _view_direction(view, u, v)
        if not dz > limit:
            return False
    return True


@kernel(inline="always")
def _clear_sign(dot, D, margin):
    """Which side of ``+-margin`` the cosine ``dot / sqrt(D)`` (D > 0) is clearly on: 1 above
    ``margin``, -1 below ``-margin``, 0 between (or NaN); squares, no root or division."""
    if dot * dot > margin * margin * D:
        return 1 if dot > 0.0 else -1
    return 0


@kernel(inline="always")
def _edge_pixel(view, rig, s1, s2, dx, dy, dz):
    """Entry from an interpolated mirror point: ``(x, y, decided)``; undecided near the edge.

    Clearly unseen (NaN, decided) when the rim margin is below ``-VIEW_RIM_MARGIN`` or one of
    :func:`_view_pixel`'s cosines below ``-VIEW_COS_MARGIN``; seen (its pixel, computed as
    :func:`_view_pixel` does) when the rim margin and every cosine are above the margins;
    else undecided. The cosines are compared through their squares (:func:`_clear_sign`).
    """
    Xx, Xy, Xz = _view_target(view, dx, dy, dz)
    a2 = rig.a * rig.a
    b2 = rig.b * rig.b
    if (not view.at_infinity) and _inside_mirror_body(Xx, Xy, Xz, rig.a, rig.b):
        return _NAN, _NAN, True  # inside the mirror body, as project_points
    rim2 = rig.rim_radius * rig.rim_radius
    rim_m = (rim2 - (s1 * s1 + s2 * s2)) / rim2
    if rim_m < -VIEW_RIM_MARGIN:
        return _NAN, _NAN, True  # clearly outside the rim
    C = rig.C
    z = rig.b * math.sqrt(1.0 + (s1 * s1 + s2 * s2) / a2)
    Nx = b2 * s1 / (a2 * z)
    Ny = b2 * s2 / (a2 * z)
    nn2 = Nx * Nx + Ny * Ny + 1.0
    wx = C[0] - s1
    wy = C[1] - s2
    wz = C[2] - z
    camera = _clear_sign(
        Nx * wx + Ny * wy - wz, nn2 * (wx * wx + wy * wy + wz * wz), VIEW_COS_MARGIN
    )
    if view.at_infinity:
        ex, ey, ez = Xx, Xy, Xz
    else:
        ex = Xx - s1
        ey = Xy - s2
        ez = Xz - z
    target = _clear_sign(
        Nx * ex + Ny * ey - ez, nn2 * (ex * ex + ey * ey + ez * ez), VIEW_COS_MARGIN
    )
    xc, yc, zc = _camera_frame(rig, s1, s2, z)
    front = _clear_sign(zc, xc * xc + yc * yc + zc * zc, VIEW_COS_MARGIN)
    if camera < 0 or target < 0 or front < 0:
        return _NAN, _NAN, True  # clearly unseen
    if not (rim_m > VIEW_RIM_MARGIN and camera > 0 and target > 0 and front > 0):
        return _NAN, _NAN, False
    return _camera_pixel_call(rig, xc, yc, zc)


@kernel(inline="always")
def _camera_frame(rig, s1, s2, z):
    """The mirror point (s1, s2, z) in the camera frame."""
    Rc = rig.R
    tc = rig.t
    xc = Rc[0, 0] * s1 + Rc[0, 1] * s2 + Rc[0, 2] * z + tc[0]
    yc = Rc[1, 0] * s1 + Rc[1, 1] * s2 + Rc[1, 2] * z + tc[1]
    zc = Rc[2, 0] * s1 + Rc[2, 1] * s2 + Rc[2, 2] * z + tc[2]
    return xc, yc, zc


@kernel(inline="always")
def _camera_pixel(rig, xc, yc, zc):
    """Pixel of a camera-frame point in front of the camera (eq. 6 with OpenCV's distortion,
    :func:`_distort`, then ``K`` with skew): ``(x, y, True)``, or ``(NaN, NaN, False)`` if not
    finite. Inlined in the per-pixel loop of RIM cells (:func:`_rim_pixel`); the other callers
    share one compiled copy, :func:`_camera_pixel_call`."""
    xn = xc / zc
    yn = yc / zc
    if rig.has_dist:
        xn, yn = _distort(rig, xn, yn)
    K = rig.K
    xi = K[0, 0] * xn + K[0, 1] * yn + K[0, 2]
    yi = K[1, 0] * xn + K[1, 1] * yn + K[1, 2]
    if xi == xi and yi == yi:
        return xi, yi, True
    return _NAN, _NAN, False


@kernel
def _camera_pixel_call(rig, xc, yc, zc):
    """:func:`_camera_pixel` as a function of its own, not inlined: one compiled copy of the
    distortion model for :func:`_view_pixel` and :func:`_edge_pixel` (a call per exact
    solution costs nothing measurable; per pixel of a RIM cell it cost a third of fill_rows)."""
    return _camera_pixel(rig, xc, yc, zc)


@kernel(inline="always")
def _rim_pixel(rig, s1, s2):
    """Entry of a pixel of a RIM sub-cell from its interpolated mirror point: ``(x, y,
    decided)``. Every test but the rim's clearly passes in such a cell, so the entry is the
    one :func:`_edge_pixel` gives: unseen past the rim's margin, the pixel of the mirror
    point inside it, undecided within it."""
    rim2 = rig.rim_radius * rig.rim_radius
    rim_m = (rim2 - (s1 * s1 + s2 * s2)) / rim2
    if rim_m < -VIEW_RIM_MARGIN:
        return _NAN, _NAN, True
    if not rim_m > VIEW_RIM_MARGIN:
        return _NAN, _NAN, False
    z = rig.b * math.sqrt(1.0 + (s1 * s1 + s2 * s2) / (rig.a * rig.a))
    xc, yc, zc = _camera_frame(rig, s1, s2, z)
    return _camera_pixel(rig, xc, yc, zc)


@kernel(inline="always")
def _pixel_direction(view, i, j, row_z, row_cos, column_cos, column_sin):
    """Unit direction of output pixel (row i, column j), as :func:`_view_direction` with the
    row's and columns' trigonometry precomputed."""
    A = view.A
    if view.kind == 0:
        x0 = A[0, 0] * j + A[0, 1] * i + A[0, 2]
        y0 = A[1, 0] * j + A[1, 1] * i + A[1, 2]
        z0 = A[2, 0] * j + A[2, 1] * i + A[2, 2]
    else:
        px = row_cos * column_cos[j]
        py = row_cos * column_sin[j]
        x0 = A[0, 0] * px + A[0, 1] * py + A[0, 2] * row_z
        y0 = A[1, 0] * px + A[1, 1] * py + A[1, 2] * row_z
        z0 = A[2, 0] * px + A[2, 1] * py + A[2, 2] * row_z
    nrm = math.sqrt(x0 * x0 + y0 * y0 + z0 * z0)
    return x0 / nrm, y0 / nrm, z0 / nrm


@kernel(inline="always")
def _column_at_row(S, r, k, c, v0, v1, v2, v3):
    """Component ``c`` of the node values S (NY, NX, 2) of column ``k``, rows ``r:r + 4``,
    weighted by the row weights ``v*``."""
    return v0 * S[r, k, c] + v1 * S[r + 1, k, c] + v2 * S[r + 2, k, c] + v3 * S[r + 3, k, c]


@kernel(inline="always")
def _row_columns(S, r, k, v0, v1, v2, v3):
    """Node values S (NY, NX, 2) of columns ``k:k + 4`` interpolated to a row of cell (r, k)
    with the row weights ``v*``: ``(x0..x3, y0..y3)``. Their column-weighted sum is
    the tensor cubic of omnicam.views._interp_cells summed in the other order."""
    return (
        _column_at_row(S, r, k, 0, v0, v1, v2, v3),
        _column_at_row(S, r, k + 1, 0, v0, v1, v2, v3),
        _column_at_row(S, r, k + 2, 0, v0, v1, v2, v3),
        _column_at_row(S, r, k + 3, 0, v0, v1, v2, v3),
        _column_at_row(S, r, k, 1, v0, v1, v2, v3),
        _column_at_row(S, r, k + 1, 1, v0, v1, v2, v3),
        _column_at_row(S, r, k + 2, 1, v0, v1, v2, v3),
        _column_at_row(S, r, k + 3, 1, v0, v1, v2, v3),
    )


@kernel
def _fill_refined_cell(
    view,
    rig,
    i,
    j0,
    j1,
    fine_row,
    fine_tv,
    fine_S,
    fine_P,
    fine_cls,
    fine_weights,
    row_z,
    row_cos,
    column_cos,
    column_sin,
    rowx,
    rowy,
    pending,
):
    """Entries of row i, columns j0:j1 of a refined coarse cell, sub-cell by sub-cell.

    ``fine_S, fine_P`` (FINE + 3, FINE + 3, 2), ``fine_cls`` (FINE, FINE): the cell's refined
    grid; ``fine_row, fine_tv``: the sub-cell row and the position in it; ``fine_weights``
    (4, g): column weights per column offset in a sub-cell. SEEN sub-cells interpolate the
    pixel, UNSEEN ones are unseen (both as :func:`fill_rows` writes coarse cells), EDGE ones
    decide per pixel from the interpolated mirror point (:func:`_edge_pixel`), RIM ones by
    its rim margin alone (:func:`_rim_pixel`: no direction to compute); what stays
    undecided is marked in ``pending``. ``rowx, rowy``: row i of the float maps
    (:func:`fill_rows`). Returns the counts of pending and of unseen entries.
    """
    g = fine_weights.shape[1]
    v0, v1, v2, v3 = _lagrange4(fine_tv)
    n_pending = 0
    n_unseen = 0
    for fb in range(FINE):
        k0 = j0 + fb * g
        k1 = max(k0, min(j1, k0 + g))  # sub-cells past the image's last column are empty
        fine_class = fine_cls[fine_row, fb]
        if fine_class == CELL_UNSEEN:
            _fill_unseen(k1 - k0, rowx[k0:k1], rowy[k0:k1])
            n_unseen += k1 - k0
            continue
        # the sub-cell's four node columns interpolated to this row: pixels of SEEN sub-cells,
        # mirror points of the others; per pixel only the column weights remain
        src = fine_P if fine_class == CELL_SEEN else fine_S
        a0, a1, a2, a3, b0, b1, b2, b3 = _row_columns(src, fine_row, fb, v0, v1, v2, v3)
        if fine_class == CELL_SEEN:
            _fill_seen(
                a0,
                a1,
                a2,
                a3,
                b0,
                b1,
                b2,
                b3,
                fine_weights,
                k1 - k0,
                rowx[k0:k1],
                rowy[k0:k1],
            )
            continue
        for j in range(k0, k1):
            tu = j - k0
            u0 = fine_weights[0, tu]
            u1 = fine_weights[1, tu]
            u2 = fine_weights[2, tu]
            u3 = fine_weights[3, tu]
            c1 = u0 * a0 + u1 * a1 + u2 * a2 + u3 * a3
            c2 = u0 * b0 + u1 * b1 + u2 * b2 + u3 * b3
            x = _NAN
            y = _NAN
            rim2 = rig.rim_radius * rig.rim_radius
            if fine_class == CELL_RIM:
                x, y, decided = _rim_pixel(rig, c1, c2)
            elif fine_class == CELL_EDGE and (rim2 - (c1 * c1 + c2 * c2)) / rim2 < -VIEW_RIM_MARGIN:
                # clearly outside the rim: unseen whatever the tests on the direction say, as
                # _edge_pixel decides it (the half of an edge sub-cell past the rim costs no
                # direction)
                decided = True
            else:
                dx, dy, dz = _pixel_direction(view, i, j, row_z, row_cos, column_cos, column_sin)
                decided = not dz <= view.sin_reject  # above every elevation the rig sees
                if not decided and fine_class == CELL_EDGE:
                    x, y, decided = _edge_pixel(view, rig, c1, c2, dx, dy, dz)
            # pending entries are written too (unseen, until solved): every entry of the row
            # is finite for fill_rows' fixed-point conversion
            _row_store(j, x, y, rowx, rowy)
            if not decided:
                pending[i, j] = True
                n_pending += 1
            elif not (x == x and y == y):
                n_unseen += 1
    return n_pending, n_unseen


#: 1.5 * 2^52: ``(x + ROUND_MAGIC) - ROUND_MAGIC`` rounds |x| <= 2^51 to the nearest integer,
#: ties to even (IEEE default rounding), as np.rint does, in a loop the compiler vectorises
ROUND_MAGIC = 6755399441055744.0
FIXED_LIMIT = 2.0**40  # |x * 32| clamped here first: a multiple of 32, so ix >> 5 saturates alike


@kernel(inline="always")
def _round_fixed(f):
    """``int(np.rint(np.float64(f) * 32.0))`` of a finite float32 ``f`` (cv2.convertMaps'
    cvRound(f * 32)), with no call to rint. Beyond ``FIXED_LIMIT`` (|f| > 2^35 px) the result
    is the limit, whose low 5 bits are 0 like those of any float32 times 32 that large, and
    whose ``>> 5`` saturates the int16 as well."""
    x = min(max(np.float64(f) * 32.0, -FIXED_LIMIT), FIXED_LIMIT)
    return int((x + ROUND_MAGIC) - ROUND_MAGIC)


@kernel(inline="always")
def _fill_seen(a0, a1, a2, a3, b0, b1, b2, b3, weights, n, ox, oy):
    """Entries ``0:n`` of a SEEN cell's row segment (float row slices ``ox, oy``): the cubic in
    the column (``weights`` (4, >= n)) of the row-interpolated values ``a*`` (x) and ``b*`` (y)
    of the cell's four node columns; the bulk of a table, a tight loop the compiler vectorises.

    The outputs are 1-D slices indexed from 0, so the stores are contiguous (an index numba
    cannot prove non-negative gets a wraparound select, and the vectorised loop then scatters).
    """
    w0 = weights[0]
    w1 = weights[1]
    w2 = weights[2]
    w3 = weights[3]
    for t in range(n):
        ox[t] = np.float32(w0[t] * a0 + w1[t] * a1 + w2[t] * a2 + w3[t] * a3)
        oy[t] = np.float32(w0[t] * b0 + w1[t] * b1 + w2[t] * b2 + w3[t] * b3)


@kernel(inline="always")
def _row_store(j, x, y, rowx, rowy):
    """Write entry j of a float row; NaN is written ``UNSEEN``."""
    if not (x == x and y == y):
        x = UNSEEN
        y = UNSEEN
    rowx[j] = np.float32(x)
    rowy[j] = np.float32(y)


@kernel(inline="always")
def _fill_unseen(n, ox, oy):
    """Entries ``0:n`` of an UNSEEN cell's row segment: ``UNSEEN`` as :func:`_row_store`
    writes it."""
    for t in range(n):
        ox[t] = np.float32(UNSEEN)
        oy[t] = np.float32(UNSEEN)


@kernel(inline="always")
def _row_fixed(rowx, rowy, row16, rowf16):
    """A float row (finite: NaN is already ``UNSEEN``) in cv2.convertMaps' CV_16SC2 fixed
    point: cvRound(x * 32) (:func:`_round_fixed`), the integer part ``>> 5`` saturated to int16
    (``row16``: the row's (x, y) pairs) and the fraction ``& 31`` (``rowf16``)."""
    for t in range(rowx.shape[0]):
        ix = _round_fixed(rowx[t])
        iy = _round_fixed(rowy[t])
        row16[2 * t] = max(-32768, min(32767, ix >> 5))
        row16[2 * t + 1] = max(-32768, min(32767, iy >> 5))
        rowf16[t] = (iy & 31) * 32 + (ix & 31)


@kernel
def fill_rows(
    lo,
    hi,
    view,
    rig,
    cls,
    refined_index,
    P,
    fine_S,
    fine_P,
    fine_cls,
    column_cos,
    column_sin,
    weights,
    fine_weights,
    mode,
    outx,
    outy,
    out16,
    outf16,
    pending,
    row_counts,
):
    """Table entries of rows ``lo:hi``; pixels that need an exact solution are marked pending.

    ``cls`` (ny, nx): classes of the coarse cells, whose nodes' pixels are ``P`` (NY, NX, 2);
    ``refined_index`` (ny, nx): which grid of the refined stack (``fine_*``) refines a BAD cell.
    ``weights`` (4, step), ``fine_weights`` (4, step / FINE): the column weights per column
    offset in a cell and a sub-cell (omnicam.views._build_table).
    ``mode`` 0 writes float32 ``outx, outy`` (H, W); mode 1 writes ``out16`` (H, W, 2) int16
    and ``outf16`` (H, W) uint16 as ``cv2.convertMaps(.., CV_16SC2)`` does, each row written
    in float first (to a scratch row) and converted once (:func:`_row_fixed`): the cells'
    loops are compiled for one output type only.
    ``row_counts`` (H, 2): pending and unseen entries per row.
    """
    h = weights.shape[1]
    g = fine_weights.shape[1]
    W = pending.shape[1]
    nx = cls.shape[1]
    NX = nx + 3
    row_P = np.empty((NX, 2))
    # (H, 2 W): the (x, y) pairs of a row one after the other, for contiguous 1-D row slices
    out16_rows = out16.reshape((out16.shape[0], 2 * out16.shape[1]))
    scratch = np.empty((2, W), np.float32)  # the float row of mode 1
    for i in range(lo, hi):
        n_pending = 0
        n_unseen = 0
        r = i // h
        v0, v1, v2, v3 = _lagrange4((i - r * h) / h)
        for q in range(NX):
            for cc in range(2):
                row_P[q, cc] = (
                    v0 * P[r, q, cc]
                    + v1 * P[r + 1, q, cc]
                    + v2 * P[r + 2, q, cc]
                    + v3 * P[r + 3, q, cc]
                )
        row_z = 0.0
        row_cos = 0.0
        if view.kind == 1:
            row_z = view.p0 + view.p1 * i
            row_cos = 1.0
        elif view.kind == 2:
            el = view.p0 + view.p1 * i
            row_z = math.sin(el)
            row_cos = math.cos(el)
        fine_row = (i - r * h) // g  # row of the sub-cells of refined cells
        fine_tv = (i - r * h - fine_row * g) / g
        # this row of the maps being written (row 0 of the unused 1 x 1 ones)
        if mode == 0:
            rowx = outx[i]
            rowy = outy[i]
        else:
            rowx = scratch[0]
            rowy = scratch[1]
        for k in range(nx):
            j0 = k * h
            j1 = min(W, j0 + h)
            cell_class = cls[r, k]
            if cell_class == CELL_SEEN:
                _fill_seen(
                    row_P[k, 0],
                    row_P[k + 1, 0],
                    row_P[k + 2, 0],
                    row_P[k + 3, 0],
                    row_P[k, 1],
                    row_P[k + 1, 1],
                    row_P[k + 2, 1],
                    row_P[k + 3, 1],
                    weights,
                    j1 - j0,
                    rowx[j0:j1],
                    rowy[j0:j1],
                )
            elif cell_class == CELL_UNSEEN:
                _fill_unseen(j1 - j0, rowx[j0:j1], rowy[j0:j1])
                n_unseen += j1 - j0
            else:  # refined (coarse cells are never EDGE: classify_cells without allow_edge)
                c = refined_index[r, k]
                p, u = _fill_refined_cell(
                    view,
                    rig,
                    i,
                    j0,
                    j1,
                    fine_row,
                    fine_tv,
                    fine_S[c],
                    fine_P[c],
                    fine_cls[c],
                    fine_weights,
                    row_z,
                    row_cos,
                    column_cos,
                    column_sin,
                    rowx,
                    rowy,
                    pending,
                )
                n_pending += p
                n_unseen += u
        if mode == 1:
            _row_fixed(rowx, rowy, out16_rows[i], outf16[i])
        row_counts[i, 0] = n_pending
        row_counts[i, 1] = n_unseen
