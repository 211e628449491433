"""The fill of a view table: every entry from its classified cell, in float or fixed point.

:func:`fill_rows` writes rows of the table from the coarse grid's classes (SEEN cells
interpolate the pixel, UNSEEN ones are unseen, refined ones sub-cell by sub-cell, EDGE and RIM
sub-cells decide per pixel from the interpolated mirror point) and marks the pixels that need
an exact solution. The grids come from :mod:`omnicam._kernels.tables`; the mirror is reached
only through :mod:`omnicam._kernels.mirror`.
"""

from __future__ import annotations

import math
from collections import namedtuple

import numpy as np

from .._jit import kernel
from .mirror import inside_body, rim_radius, sheet_slopes, sheet_z
from .pinhole import camera_frame, camera_pixel, camera_pixel_call
from .tables import (
    CELL_EDGE,
    CELL_RIM,
    CELL_SEEN,
    CELL_UNSEEN,
    FINE,
    UNSEEN,
    VIEW_COS_MARGIN,
    VIEW_RIM_MARGIN,
    _lagrange4,
    _view_target,
)

_NAN = math.nan

#: The classified grids of a table as fill_rows reads them (omnicam.views._build_table):
#: ``cls`` (ny, nx) classes of the coarse cells, whose nodes' pixels are ``P`` (NY, NX, 2);
#: ``refined_index`` (ny, nx): which grid of the refined stack (``fine_*``: mirror points,
#: pixels (G, FINE + 3, FINE + 3, 2), classes (G, FINE, FINE)) refines a BAD cell;
#: ``column_cos, column_sin`` (W,): the panoramas' per-column azimuth trigonometry;
#: ``weights`` (4, step), ``fine_weights`` (4, step / FINE): the column weights per column
#: offset in a cell and a sub-cell.
TableGrids = namedtuple(
    "TableGrids",
    [
        "cls",
        "refined_index",
        "P",
        "fine_S",
        "fine_P",
        "fine_cls",
        "column_cos",
        "column_sin",
        "weights",
        "fine_weights",
    ],
)
#: Where fill_rows writes: ``mode`` 0 float32 ``outx, outy`` (H, W); mode 1 ``out16``
#: (H, W, 2) int16 and ``outf16`` (H, W) uint16 as ``cv2.convertMaps(.., CV_16SC2)``;
#: ``pending`` (H, W) bool, the pixels left to an exact solution; ``row_counts`` (H, 2):
#: pending and unseen entries per row.
TableOutputs = namedtuple(
    "TableOutputs", ["mode", "outx", "outy", "out16", "outf16", "pending", "row_counts"]
)


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
    ``tables._view_pixel``'s cosines below ``-VIEW_COS_MARGIN``; seen (its pixel, computed as
    ``tables._view_pixel`` does) when the rim margin and every cosine are above the margins;
    else undecided. The cosines are compared through their squares (:func:`_clear_sign`).
    """
    Xx, Xy, Xz = _view_target(view, dx, dy, dz)
    mp = rig.mirror
    if (not view.at_infinity) and inside_body(mp, Xx, Xy, Xz):
        return _NAN, _NAN, True  # inside the mirror body, as project_points
    rim = rim_radius(mp)
    rim2 = rim * rim
    rim_m = (rim2 - (s1 * s1 + s2 * s2)) / rim2
    if rim_m < -VIEW_RIM_MARGIN:
        return _NAN, _NAN, True  # clearly outside the rim
    C = rig.C
    z, Nx, Ny = sheet_slopes(mp, s1, s2)
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
    xc, yc, zc = camera_frame(rig, s1, s2, z)
    front = _clear_sign(zc, xc * xc + yc * yc + zc * zc, VIEW_COS_MARGIN)
    if camera < 0 or target < 0 or front < 0:
        return _NAN, _NAN, True  # clearly unseen
    if not (rim_m > VIEW_RIM_MARGIN and camera > 0 and target > 0 and front > 0):
        return _NAN, _NAN, False
    return camera_pixel_call(rig, xc, yc, zc)


@kernel(inline="always")
def _rim_pixel(rig, s1, s2):
    """Entry of a pixel of a RIM sub-cell from its interpolated mirror point: ``(x, y,
    decided)``. Every test but the rim's clearly passes in such a cell, so the entry is the
    one :func:`_edge_pixel` gives: unseen past the rim's margin, the pixel of the mirror
    point inside it, undecided within it."""
    rim = rim_radius(rig.mirror)
    rim2 = rim * rim
    rim_m = (rim2 - (s1 * s1 + s2 * s2)) / rim2
    if rim_m < -VIEW_RIM_MARGIN:
        return _NAN, _NAN, True
    if not rim_m > VIEW_RIM_MARGIN:
        return _NAN, _NAN, False
    z = sheet_z(rig.mirror, s1, s2)
    xc, yc, zc = camera_frame(rig, s1, s2, z)
    return camera_pixel(rig, xc, yc, zc)


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
def _fill_refined_cell(view, rig, grids, c, row, rowx, rowy, pending):
    """Entries of row i, columns j0:j1 of a refined coarse cell, sub-cell by sub-cell.

    ``c``: the cell's grid in the refined stack of ``grids`` (:class:`TableGrids`); ``row`` =
    ``(i, j0, j1, fine_row, fine_tv, row_z, row_cos)``: the row, the cell's columns, the
    sub-cell row and the position in it, and the row's trigonometry (:func:`fill_rows`).
    SEEN sub-cells interpolate the pixel, UNSEEN ones are unseen (both as :func:`fill_rows`
    writes coarse cells), EDGE ones decide per pixel from the interpolated mirror point
    (:func:`_edge_pixel`), RIM ones by its rim margin alone (:func:`_rim_pixel`: no direction
    to compute); what stays undecided is marked in ``pending``. ``rowx, rowy``: row i of the
    float maps (:func:`fill_rows`). Returns the counts of pending and of unseen entries.
    """
    i, j0, j1, fine_row, fine_tv, row_z, row_cos = row
    # the records' arrays taken out once: each access to a field costs a reference count
    fine_S = grids.fine_S[c]
    fine_P = grids.fine_P[c]
    fine_cls = grids.fine_cls[c]
    fine_weights = grids.fine_weights
    column_cos = grids.column_cos
    column_sin = grids.column_sin
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
                (a0, a1, a2, a3), (b0, b1, b2, b3), fine_weights, k1 - k0, rowx[k0:k1], rowy[k0:k1]
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
            rim = rim_radius(rig.mirror)
            rim2 = rim * rim
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
def _fill_seen(a, b, weights, n, ox, oy):
    """Entries ``0:n`` of a SEEN cell's row segment (float row slices ``ox, oy``): the cubic in
    the column (``weights`` (4, >= n)) of the row-interpolated values ``a`` (x) and ``b`` (y)
    (4-tuples) of the cell's four node columns; the bulk of a table, a tight loop the
    compiler vectorises.

    The outputs are 1-D slices indexed from 0, so the stores are contiguous (an index numba
    cannot prove non-negative gets a wraparound select, and the vectorised loop then scatters).
    """
    a0, a1, a2, a3 = a
    b0, b1, b2, b3 = b
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
def fill_rows(lo, hi, view, rig, grids, out):
    """Table entries of rows ``lo:hi``; pixels that need an exact solution are marked pending.

    ``grids`` (:class:`TableGrids`): the classified coarse cells and refined grids; ``out``
    (:class:`TableOutputs`): mode 0 writes the float32 maps; mode 1 the CV_16SC2 pair, each
    row written in float first (to a scratch row) and converted once (:func:`_row_fixed`):
    the cells' loops are compiled for one output type only. ``row_counts`` gets the pending
    and unseen entries of each row.
    """
    W = out.pending.shape[1]
    # (H, 2 W): the (x, y) pairs of a row one after the other, for contiguous 1-D row slices
    out16_rows = out.out16.reshape((out.out16.shape[0], 2 * out.out16.shape[1]))
    scratch = np.empty((2, W), np.float32)  # the float row of mode 1
    row_P = np.empty((grids.cls.shape[1] + 3, 2))
    for i in range(lo, hi):
        # this row of the maps being written (row 0 of the unused 1 x 1 ones)
        if out.mode == 0:
            rowx = out.outx[i]
            rowy = out.outy[i]
        else:
            rowx = scratch[0]
            rowy = scratch[1]
        n_pending, n_unseen = _fill_row(view, rig, grids, i, row_P, rowx, rowy, out.pending)
        if out.mode == 1:
            _row_fixed(rowx, rowy, out16_rows[i], out.outf16[i])
        out.row_counts[i, 0] = n_pending
        out.row_counts[i, 1] = n_unseen


@kernel(inline="always")
def _fill_row(view, rig, grids, i, row_P, rowx, rowy, pending):
    """Float entries of row i, cell by cell, into ``rowx, rowy``; ``row_P`` (nx + 3, 2) is
    scratch for the nodes' pixels interpolated to the row. Returns the counts of pending and
    of unseen entries."""
    # the records' arrays taken out once: each access to a field costs a reference count
    weights = grids.weights
    cls = grids.cls
    P = grids.P
    refined_index = grids.refined_index
    h = weights.shape[1]
    g = grids.fine_weights.shape[1]
    W = pending.shape[1]
    n_pending = 0
    n_unseen = 0
    r = i // h
    v0, v1, v2, v3 = _lagrange4((i - r * h) / h)
    for q in range(row_P.shape[0]):
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
    for k in range(cls.shape[1]):
        j0 = k * h
        j1 = min(W, j0 + h)
        cell_class = cls[r, k]
        if cell_class == CELL_SEEN:
            _fill_seen(
                (row_P[k, 0], row_P[k + 1, 0], row_P[k + 2, 0], row_P[k + 3, 0]),
                (row_P[k, 1], row_P[k + 1, 1], row_P[k + 2, 1], row_P[k + 3, 1]),
                weights,
                j1 - j0,
                rowx[j0:j1],
                rowy[j0:j1],
            )
        elif cell_class == CELL_UNSEEN:
            _fill_unseen(j1 - j0, rowx[j0:j1], rowy[j0:j1])
            n_unseen += j1 - j0
        else:  # refined (coarse cells are never EDGE: classify_cells without allow_edge)
            row = (i, j0, j1, fine_row, fine_tv, row_z, row_cos)
            p, u = _fill_refined_cell(
                view, rig, grids, refined_index[r, k], row, rowx, rowy, pending
            )
            n_pending += p
            n_unseen += u
    return n_pending, n_unseen
