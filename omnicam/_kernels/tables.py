"""View-table kernels: the exact solutions of output pixels, cubic grids and cell classes.

The fill of the table from the classified cells is :mod:`omnicam._kernels.fill`; the mirror is
reached only through :mod:`omnicam._kernels.mirror` (``rig.mirror``), the camera through
:mod:`omnicam._kernels.pinhole`.
"""

from __future__ import annotations

import math
from collections import namedtuple

import numpy as np

from .._jit import kernel
from .mirror import body_margin, inside_body, rim_radius, sheet_slopes
from .pinhole import camera_pixel_call
from .raytrace import NEWTON_MAX_ITER, newton_warm, reflection_point

_NAN = math.nan

# -- view tables (omnicam.views): exact nodes, cubic interpolation with a verified error ----------
#
# A remap table entry is the exact projection (project_points) of the direction, or the point at
# a given distance from a viewpoint, that an output pixel looks along. The reflection point is
# solved exactly (``raytrace.reflection_point``, the Newton of project_points) on a coarse grid of
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
#: ``C`` (mirror frame), mirror -> camera motion ``R, t``, the mirror's parameter tuple
#: ``mirror`` (``kernel_params()``, :mod:`omnicam._kernels.mirror`), pinhole ``K`` (skew
#: allowed), OpenCV distortion ``dist`` (14 values, zeros padded) and its ``tilt`` matrix,
#: ``has_dist``.
RigArgs = namedtuple("RigArgs", ["C", "R", "t", "mirror", "K", "dist", "tilt", "has_dist"])

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


#: What solve_view_points is asked (omnicam.views._solve builds it): output ``positions``
#: (N, 2), Newton ``starts`` (N, 2, NaN: none), ``estimates`` (N, 2) of check points (empty
#: for nodes and pixels), ``pixels_only`` and ``with_mirror_error`` (see solve_view_points).
ViewPoints = namedtuple(
    "ViewPoints", ["positions", "starts", "estimates", "pixels_only", "with_mirror_error"]
)
#: What it writes: ``ok`` (N,), mirror points ``S`` and pixels ``P`` (N, 2), ``margins``
#: (N, 3), ``errors`` (N, 2) (only with estimates).
Solutions = namedtuple("Solutions", ["ok", "S", "P", "margins", "errors"])
#: A grid stack as classify_cells reads it (omnicam.views._GridStack): grid c's cell (r, k)
#: spans the output pixels from ``origins[c] + (k, r) spacing``; the margins (G, NY, NX, 3)
#: of the nodes and (G, 3, ny + 1, nx + 1, 3) of the check points, and the check points'
#: ``pixel_error`` and ``mirror_error`` (G, 3, ny + 1, nx + 1).
GridMargins = namedtuple(
    "GridMargins",
    ["origins", "spacing", "node_margins", "check_margins", "pixel_error", "mirror_error"],
)


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


@kernel(inline="always")
def _view_pixel(rig, s1, s2, Xx, Xy, Xz, at_infinity):
    """Pixel of the mirror point (s1, s2, f(s)) and the smallest visibility cosine.

    The pixel is the pinhole image (eq. 6) of the mirror point, with OpenCV's distortion model
    (:func:`omnicam._kernels.pinhole.distort`), then ``K`` with skew, as
    :func:`omnicam.raytrace.project` does. The cosine is the least of: camera on the outer side
    of the tangent plane (eq. 12), target on the outer side (eq. 15), mirror point in front of
    the camera; all positive means project_points' tests pass. NaN pixel behind the camera.
    """
    C = rig.C
    Rc = rig.R
    tc = rig.t
    z, Nx, Ny = sheet_slopes(rig.mirror, s1, s2)
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
    x, y, _finite = camera_pixel_call(rig, xc, yc, zc)
    return x, y, m


@kernel
def _view_point(view, rig, u, v, g1, g2, pixels_only):
    """Exact solution at output position (u, v): ``ok, s1, s2, x, y, vis, rim_m, other``.

    The mirror point ``s`` whose reflection joins the camera centre and the pixel's target
    (``raytrace.reflection_point``; from ``(g1, g2)`` first when not NaN, a start interpolated from
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
    mp = rig.mirror
    rim = rim_radius(mp)
    rim2 = rim * rim
    dx, dy, dz = _view_direction(view, u, v)
    if not dz <= (view.sin_reject if pixels_only else view.sin_try):
        return False, _NAN, _NAN, _NAN, _NAN, _NAN, _NAN, _NAN
    Xx, Xy, Xz = _view_target(view, dx, dy, dz)
    target = (Xx, Xy, Xz)
    C = rig.C
    if pixels_only and not at_infinity and inside_body(mp, Xx, Xy, Xz):
        return False, _NAN, _NAN, _NAN, _NAN, _NAN, _NAN, _NAN
    ok = False
    if g1 == g1 and g2 == g2:
        s1, s2, ok = newton_warm(
            mp, (C[0], C[1], C[2]), g1, g2, target, at_infinity, view.newton_tol
        )
    if not ok:
        s1, s2, ok = reflection_point(
            mp, (C[0], C[1], C[2]), target, at_infinity, view.newton_tol, NEWTON_MAX_ITER
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
        if Xz > -VIEW_CLEAR * math.sqrt(Xx * Xx + Xy * Xy + Xz * Xz):
            body = body_margin(mp, Xx, Xy, Xz)
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
def solve_view_points(lo, hi, view, rig, points, out):
    """Exact solutions at the output positions ``lo:hi`` of ``points`` (:class:`ViewPoints`),
    written into ``out`` (:class:`Solutions`).

    :func:`_view_point` at each: the mirror point ``S``, its pixel ``P`` (the exact table
    entry for ``pixels_only``, NaN if unseen) and ``margins`` = (vis, rim_m, other)
    (``-inf, inf, -inf`` and ``ok`` False when not solved), Newton started from ``starts``
    where not NaN.
    Check points (``estimates`` (N, 2) the pixels interpolated from the nodes' pixels; empty
    for nodes and pixels) get their interpolation ``errors`` (N, 2): |exact pixel - estimate|
    and, ``with_mirror_error``, |exact pixel - pixel of the start| (the interpolated mirror
    point); inf where not solved or not computed.
    """
    # records' arrays taken out once: each access to a field costs a reference count
    positions = points.positions
    starts = points.starts
    estimates = points.estimates
    ok = out.ok
    S = out.S
    P = out.P
    margins = out.margins
    errors = out.errors
    checks = estimates.shape[0] > 0
    for n in range(lo, hi):
        xs = _NAN
        ys = _NAN
        if checks and points.with_mirror_error:
            # the pixel of a mirror point does not depend on the target (margins only)
            xs, ys, _m = _view_pixel(rig, starts[n, 0], starts[n, 1], 1.0, 0.0, 0.0, True)
        solved, s1, s2, x, y, vis, rim_m, other = _view_point(
            view,
            rig,
            positions[n, 0],
            positions[n, 1],
            starts[n, 0],
            starts[n, 1],
            points.pixels_only,
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
            _check_errors(errors, n, solved, x, y, estimates[n, 0], estimates[n, 1], xs, ys)


@kernel(inline="always")
def _check_errors(errors, n, solved, x, y, ex, ey, xs, ys):
    """Row n of a check point's ``errors``: |(x, y) - estimate|, |(x, y) - pixel of the start|
    (inf where not solved or not a number)."""
    errors[n, 0] = np.inf
    errors[n, 1] = np.inf
    if solved:
        err = math.sqrt((x - ex) ** 2 + (y - ey) ** 2)
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
def classify_cells(view, grid, W, H, half_tol, allow_edge, cls):
    """Classes (the CELL_* constants) of the cells of a grid stack, ``cls`` (G, ny, nx).

    A cell needs all 16 of its nodes solved; it is SEEN when clearly seen
    (:func:`_clearly`) with an error estimate (:func:`_cell_error`) of the pixels
    within ``half_tol``, UNSEEN when clearly outside the rim, EDGE
    when that of the mirror points is within ``half_tol`` (only with ``allow_edge``: on the
    coarse grid such a cell is refined instead), RIM instead of EDGE when every margin but
    the rim's is clearly positive over it (:func:`_clearly_seen_but_rim`), else BAD.

    ``grid``: the stack's :class:`GridMargins`. A BAD cell of a perspective view (grid c's
    cell (r, k) spans the output pixels from ``origins[c] + (k, r) spacing``; the view is
    ``W`` x ``H``) whose every pixel looks above
    ``sin_reject`` (where nothing is seen) is UNSEEN instead, neither refined nor visited:
    with ``sin_reject > 0`` the directions above that elevation form a convex cone, and the
    pixels whose directions lie in it a convex set of the image plane, so a cell is in it when
    its four corner pixels are (with a margin of ``1e-9`` for rounding).
    """
    above_band = view.kind == 0 and 0.0 < view.sin_reject < 1.0
    node_margins = grid.node_margins
    check_margins = grid.check_margins
    pixel_error = grid.pixel_error
    mirror_error = grid.mirror_error
    origins = grid.origins
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
                    u0 = origins[c, 0] + k * grid.spacing
                    v0 = origins[c, 1] + r * grid.spacing
                    if _corners_above(view, u0, v0, grid.spacing, W, H):
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
