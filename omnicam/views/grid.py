"""The adaptive grid-table builder: the remap table of any view, to ``TOLERANCE`` (0.01 px).

How a table is built (:func:`_build_table`, phase by phase in :mod:`omnicam._kernels`): the
reflection point is solved exactly (Newton on Fermat's path length, the solver of ``project``) on a
grid of nodes about ``CELL_DEGREES`` apart, on the mirror sheet extended past the rim so that it is
smooth across the edge of what the mirror sees. Each cell is interpolated by the cubic Lagrange
polynomial of its 4x4 nodes, and its error is *measured* against the exact answer at the cell centre
and the middles of its edges (where the error of that interpolant peaks); a cell whose estimate
exceeds ``TOLERANCE / 2`` is refined on a grid 2 times finer, and what still fails is solved pixel
by pixel. Visibility is decided per cell when all of it is clearly seen or clearly unseen, else per
pixel with a margin, and exactly inside the margin. ``tests/test_views.py`` compares whole tables
with the exact projection of every pixel.

The directions a table shows come from its view (:class:`Directions`: the perspective or
panorama parameters of :mod:`omnicam.views.api`); :func:`_table` builds one and returns the maps
for an ``m1type``. The rig and view arguments of the kernels (:func:`_rig_args`,
:func:`_view_args`) and every call into :mod:`omnicam._kernels` are here, in this one module.
"""

from __future__ import annotations

import functools
import math
from typing import Any, NamedTuple

import cv2
import numpy as np
import numpy.typing as npt

from .. import _kernels
from .._jit import notice_if_cold, run_chunks
from .._kernels import (
    CHECK_CENTRE,
    CHECK_HORIZONTAL_EDGE,
    CHECK_VERTICAL_EDGE,
    FINE,
    NEWTON_TOL_REL,
    GridMargins,
    RigArgs,
    Solutions,
    TableGrids,
    TableOutputs,
    ViewArgs,
    ViewPoints,
    cubic_blocks,
)
from .._typing import ArrayLike, FloatArray, Maps, Size
from ..camera import MisalignedCatadioptricCamera
from .elevation import _rim_band

#: Source coordinate written for output pixels whose direction the mirror does not see: well
#: outside any image (at least 2 px) and inside the range of ``CV_16SC2``.
UNSEEN = -10.0


#: The four outputs of a table, as :func:`_build_table` writes them: float32 x and y maps
#: (mode 0), or CV_16SC2's int16 pairs and uint16 fractions (mode 1); the others unused (1x1).
_Outputs = tuple[
    npt.NDArray[np.float32], npt.NDArray[np.float32], npt.NDArray[np.int16], npt.NDArray[np.uint16]
]
_IntArray = npt.NDArray[np.int64]


#: Angular size of a coarse cell, degrees: the node spacing is the multiple of 4 output pixels
#: (between 8 and 64) closest to it. Cells whose measured interpolation error exceeds
#: TOLERANCE / 2 are refined on a grid 2 times finer, and sub-cells that still fail are computed
#: exactly pixel by pixel, so this only trades speed, never accuracy.
CELL_DEGREES = 5.0


def _step_for(deg_per_px: float) -> int:
    """Node spacing (pixels, a multiple of 4 in [8, 64]) of cells about CELL_DEGREES wide."""
    n = CELL_DEGREES / max(float(deg_per_px), 1e-9)
    return int(min(64, max(8, 4 * round(n / 4))))


#: Every float table entry is within this many pixels of the exact non-central projection.
TOLERANCE = 0.01

_KIND = {"perspective": 0, "cylindrical": 1, "equirectangular": 2}


def _tilt_matrix(tau_x: float, tau_y: float) -> FloatArray:
    """OpenCV's ``computeTiltProjectionMatrix`` (the tau_x, tau_y of a 14-value ``D``)."""
    cx, sx, cy, sy = math.cos(tau_x), math.sin(tau_x), math.cos(tau_y), math.sin(tau_y)
    rot_x = np.array([[1.0, 0.0, 0.0], [0.0, cx, sx], [0.0, -sx, cx]])
    rot_y = np.array([[cy, 0.0, -sy], [0.0, 1.0, 0.0], [sy, 0.0, cy]])
    rot_xy: FloatArray = rot_y @ rot_x
    proj_z = np.array(
        [[rot_xy[2, 2], 0.0, -rot_xy[0, 2]], [0.0, rot_xy[2, 2], -rot_xy[1, 2]], [0.0, 0.0, 1.0]]
    )
    return proj_z @ rot_xy


def _cap_radius(camera: MisalignedCatadioptricCamera, viewpoint: FloatArray) -> float:
    """An upper bound of the distance from ``viewpoint`` to any point of the mirror cap."""
    m = camera.mirror
    r = np.linspace(0.0, m.rim_radius, 33)[:, None]
    t = np.linspace(0.0, 2.0 * np.pi, 96, endpoint=False)[None, :]
    X, Y = r * np.cos(t), r * np.sin(t)
    P = np.stack([X, Y, m.surface_z(X, Y)], axis=-1).reshape(-1, 3)
    # grid spacing <= rim_radius * 2 pi / 96 along the rim: add it as slack
    return float(np.linalg.norm(P - viewpoint, axis=1).max()) + m.rim_radius * 0.07


def _reject_sines(
    camera: MisalignedCatadioptricCamera, depth: float | None, viewpoint: FloatArray | None
) -> tuple[float, float]:
    """Sines of the elevation above which nothing is seen, and above which nodes are not solved.

    At infinity nothing above the highest rim ray is seen (:func:`visible_elevation_range`).
    A point at distance ``depth > rho`` from the viewpoint, ``rho`` bounding the distance to any
    mirror point, is seen along a ray within ``asin(rho / depth)`` of its direction from the
    viewpoint, so its elevation from there is at most ``hi + asin(rho / depth)``.
    """
    hi = _rim_band(camera)[1]
    limit = hi + 0.5  # slack for the rim sampling
    if depth is not None:
        assert viewpoint is not None, "_check_viewpoint gives a viewpoint with every depth"
        rho = _cap_radius(camera, viewpoint)
        if depth <= rho * 1.001:
            return 2.0, 2.0
        limit += math.degrees(math.asin(rho / depth))
    if limit >= 90.0:
        return 2.0, 2.0
    return math.sin(math.radians(limit)), math.sin(math.radians(min(limit + 30.0, 89.5)))


def _rig_args(camera: MisalignedCatadioptricCamera) -> RigArgs:
    """:class:`omnicam._kernels.RigArgs` of a camera: float64 C-contiguous writable copies (the
    kernels' one signature; numba types read-only arrays apart)."""
    D = camera.D
    dist = np.zeros(14)
    tilt = np.eye(3)
    if D is not None:
        dist[: D.size] = D
        if D.size == 14:
            tilt = _tilt_matrix(D[12], D[13])
    m = camera.mirror
    return RigArgs(
        _arg(camera.camera_center),
        _arg(camera.R),
        _arg(camera.tvec),
        m.kernel_params(),
        _arg(camera.K),
        dist,
        tilt,
        D is not None,
    )


def _view_args(
    camera: MisalignedCatadioptricCamera,
    kind: int,
    A: FloatArray,
    p0: float,
    p1: float,
    az_step: float,
    depth: float | None,
    viewpoint: FloatArray | None,
) -> ViewArgs:
    """:class:`omnicam._kernels.ViewArgs` of a view (see :func:`_table`)."""
    sin_reject, sin_try = _reject_sines(camera, depth, viewpoint)
    m = camera.mirror
    return ViewArgs(
        int(kind),
        _arg(A),
        float(p0),
        float(p1),
        float(az_step),
        depth is None,
        0.0 if depth is None else float(depth),
        np.zeros(3) if viewpoint is None else _arg(viewpoint),
        float(sin_reject),
        float(sin_try),
        NEWTON_TOL_REL * float(m.length_scale),
    )


class Directions(NamedTuple):
    """The directions of a view's output pixels (:func:`omnicam._kernels._view_direction`):
    ``kind`` (``_KIND``), ``A`` (``R^T K_new^-1`` of a perspective view, ``R^T`` of a
    panorama) and a panorama's rows ``p0, p1`` (``tan(elevation)`` or elevation of row 0 and
    per row) and ``az_step`` (radians of azimuth per column)."""

    kind: int
    A: FloatArray
    p0: float = 0.0
    p1: float = 0.0
    az_step: float = 0.0


def _table(
    camera: MisalignedCatadioptricCamera,
    directions: Directions,
    size: Size,
    depth: float | None,
    viewpoint: FloatArray | None,
    m1type: int,
    step: int | None = None,
    stats: _IntArray | None = None,
) -> Maps:
    """Build the table of a view (:func:`_build_table`) and return the maps for ``m1type``.

    ``directions`` are the output pixels' (:class:`Directions`), ``step`` the node spacing (a
    multiple of 4; by default from ``CELL_DEGREES``), ``stats`` (9,) int64 receives the counts
    of :func:`_build_table`.
    """
    kind, A, p0, p1, az_step = directions
    w, h = size
    if step is None:
        if kind == 0:
            deg = CELL_DEGREES / 32.0  # callers pass the step of a perspective view
        else:  # p1: tan(elevation) or elevation per row, the largest angle per row either way
            deg = max(360.0 / w, math.degrees(abs(p1)))
        step = _step_for(deg)
    step = int(step)
    if step < 4 or step % 4:
        raise ValueError(f"step must be a multiple of 4, got {step}")
    view = _view_args(camera, kind, A, p0, p1, az_step, depth, viewpoint)
    rig = _rig_args(camera)
    # both maps are views of one buffer: numpy asks the kernel for transparent huge pages from
    # 4 MiB on, which spares the page faults of first writing a fresh table (~2 ms of a 1024x768
    # one otherwise)
    if m1type == cv2.CV_16SC2:
        mode = 1
        outx = outy = np.empty((1, 1), np.float32)
        buf = np.empty(h * w * 6, np.uint8)
        out16 = buf[: h * w * 4].view(np.int16).reshape(h, w, 2)
        outf16 = buf[h * w * 4 :].view(np.uint16).reshape(h, w)
    else:
        mode = 0
        outx, outy = np.empty((2, h, w), np.float32)
        out16 = np.empty((1, 1, 2), np.int16)
        outf16 = np.empty((1, 1), np.uint16)
    st = np.zeros(9, np.int64) if stats is None else stats
    _build_table(view, rig, (w, h), step, mode, (outx, outy, out16, outf16), st)
    if mode == 1:
        return out16, outf16
    if m1type == cv2.CV_32FC2:
        return cv2.merge([outx, outy]), None
    return outx, outy


def _arg(x: ArrayLike) -> FloatArray:
    """A writable C-contiguous float64 copy (the kernels' one signature)."""
    return np.array(x, dtype=np.float64, order="C", copy=True)


class _GridStack:
    """G node grids of one shape and spacing with their check points, solved and classified.

    The coarse grid of a table (G = 1) or the refined grids of its failing cells; see the
    section comment of :mod:`omnicam._kernels`. ``S``, ``P``, ``node_margins``: (G, NY, NX, 2)
    mirror points, pixels and margins of the nodes; ``cls`` (G, ny, nx) the cells' classes.
    """

    def __init__(
        self,
        view: ViewArgs,
        rig: RigArgs,
        origins: FloatArray,
        spacing: float,
        shape: tuple[int, int],
        coarse: _GridStack | None = None,
        cells: _IntArray | None = None,
    ) -> None:
        ny, nx = shape
        self.origins, self.spacing = origins, spacing
        refined = cells is not None
        positions, starts = _grid_nodes(origins, spacing, shape, coarse, cells)
        self.S, self.P, self.node_margins, _ok, _e = _solve(view, rig, positions, starts)
        positions, starts, interpolated = _grid_checks(origins, spacing, self.S, self.P)
        # the pixels of the interpolated mirror points only where EDGE cells can be (refined
        # grids, classify's allow_edge); the coarse grid's mirror errors stay inf, unused
        _S, _P, self.check_margins, _ok, errors = _solve(
            view, rig, positions, starts, estimates=interpolated, with_mirror_error=refined
        )
        assert errors is not None, "_solve gives the errors of estimates"
        self.pixel_error = errors[..., 0]
        self.mirror_error = errors[..., 1]

    def classify(self, view: ViewArgs, size: Size, half_tol: float, allow_edge: bool) -> _IntArray:

        G, _w, ny1, nx1 = self.pixel_error.shape
        self.cls = np.empty((G, ny1 - 1, nx1 - 1), np.int64)
        grid = GridMargins(
            self.origins,
            self.spacing,
            self.node_margins,
            self.check_margins,
            np.ascontiguousarray(self.pixel_error),
            np.ascontiguousarray(self.mirror_error),
        )
        _kernels.classify_cells(view, grid, size[0], size[1], half_tol, allow_edge, self.cls)
        return self.cls

    def n_solved(self) -> tuple[int, int]:
        """Nodes and check points with a solution."""
        return (
            int(np.count_nonzero(self.node_margins[..., 0] > -np.inf)),
            int(np.count_nonzero(self.check_margins[..., 0] > -np.inf)),
        )


def _lagrange4(t: Any) -> tuple[Any, Any, Any, Any]:
    """Cubic Lagrange weights of nodes at -1, 0, 1, 2: the operations of
    :func:`omnicam._kernels._lagrange4` in the same order, so the same bits."""
    return (
        -t * (t - 1.0) * (t - 2.0) / 6.0,
        (t + 1.0) * (t - 1.0) * (t - 2.0) / 2.0,
        -(t + 1.0) * t * (t - 2.0) / 2.0,
        (t + 1.0) * t * (t - 1.0) / 6.0,
    )


def _cubic_weights(tv: float, tu: float) -> list[np.float64]:
    """Row and column weights of the cell coordinates (tv, tu), a row of ``cubic_blocks``'
    ``weights``."""
    return [*_lagrange4(np.float64(tv)), *_lagrange4(np.float64(tu))]


@functools.lru_cache(maxsize=16)
def _node_blocks(NY: int, NX: int) -> tuple[_IntArray, FloatArray]:
    """``cubic_blocks``' blocks and weights of the Newton starts of a refined grid's nodes:
    node (p, q) is the cubic of the refined coarse cell at ((p - 1) / FINE, (q - 1) / FINE)."""
    blocks = [(p, p + 1, q, q + 1, -p, -q) for p in range(NY) for q in range(NX)]
    weights = [
        _cubic_weights((p - 1.0) / FINE, (q - 1.0) / FINE) for p in range(NY) for q in range(NX)
    ]
    return np.array(blocks, np.int64), np.array(weights)


def _grid_nodes(
    origins: FloatArray,
    spacing: float,
    shape: tuple[int, int],
    coarse: _GridStack | None,
    cells: _IntArray | None,
) -> tuple[FloatArray, FloatArray]:
    """Output positions and Newton starts of the nodes of a grid stack, (G, NY, NX, 2) each.

    Grid ``c`` has node (p, q) at output pixel ``origins[c] + ((q - 1) spacing,
    (p - 1) spacing)``. A refined grid (``cells`` (G, 2): the coarse cell (row, column) it
    refines, FINE times finer) starts Newton from the ``coarse`` grid's cubic; the coarse grid
    (``cells`` None) has no start (NaN).
    """
    G = origins.shape[0]
    NY, NX = shape[0] + 3, shape[1] + 3
    positions = np.empty((G, NY, NX, 2))
    positions[..., 0] = origins[:, 0, None, None] + ((np.arange(NX) - 1.0) * spacing)[None, None]
    positions[..., 1] = origins[:, 1, None, None] + ((np.arange(NY) - 1.0) * spacing)[None, :, None]
    starts = np.full((G, NY, NX, 2), np.nan)
    if cells is not None and G:
        assert coarse is not None, "refined grids start from the coarse one"
        blocks, weights = _node_blocks(NY, NX)
        cubic_blocks(cells, blocks, weights, coarse.S, starts)
    return positions, starts


@functools.lru_cache(maxsize=16)
def _check_layout(ny: int, nx: int) -> tuple[_IntArray, FloatArray, FloatArray, FloatArray]:
    """Where the check points of a grid of ny x nx cells lie, in ``cubic_blocks``' terms.

    Check point (which, r, k), rows ``which (ny + 1) + r`` of a (3 (ny + 1), nx + 1) layout:
    ``which`` CHECK_CENTRE: centre of cell (r, k); CHECK_HORIZONTAL_EDGE: middle of the
    horizontal edge above cell (r, k) (r = ny: below the last row); CHECK_VERTICAL_EDGE:
    middle of the vertical edge left of it (k = nx: right of the last column). Returns
    ``blocks, weights`` and the output offsets ``(x, y)`` (3, ny + 1, nx + 1) of each check
    point in cells (``(cell column + tu, cell row + tv)``; NaN for the combinations that name
    no edge, never solved).
    """
    x = np.full((3, ny + 1, nx + 1), np.nan)
    y = np.full((3, ny + 1, nx + 1), np.nan)
    blocks, weights = [], []
    # (which, rows r0:r1 and columns k0:k1, the cell's offset from (r, k) (the last edge lies
    # in the last cell), the cell coordinates (tv, tu))
    for which, r0, r1, k0, k1, dr, dk, tv, tu in (
        (CHECK_CENTRE, 0, ny, 0, nx, 0, 0, 0.5, 0.5),
        (CHECK_HORIZONTAL_EDGE, 0, ny, 0, nx, 0, 0, 0.0, 0.5),
        (CHECK_HORIZONTAL_EDGE, ny, ny + 1, 0, nx, -1, 0, 1.0, 0.5),
        (CHECK_VERTICAL_EDGE, 0, ny, 0, nx, 0, 0, 0.5, 0.0),
        (CHECK_VERTICAL_EDGE, 0, ny, nx, nx + 1, 0, -1, 0.5, 1.0),
    ):
        row0 = which * (ny + 1)
        blocks.append((row0 + r0, row0 + r1, k0, k1, dr - row0, dk))
        weights.append(_cubic_weights(tv, tu))
        x[which, r0:r1, k0:k1] = (np.arange(k0, k1) + dk + tu)[None, :]
        y[which, r0:r1, k0:k1] = (np.arange(r0, r1) + dr + tv)[:, None]
    return np.array(blocks, np.int64), np.array(weights), x, y


def _grid_checks(
    origins: FloatArray, spacing: float, S: FloatArray, P: FloatArray
) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Check points of a grid stack (:func:`_check_layout`): output positions, Newton starts
    (the cubic of the nodes' mirror points ``S``) and estimates (the cubic of their pixels
    ``P``), (G, 3, ny + 1, nx + 1, 2) each, NaN where no check point is."""
    G, NY, NX, _two = S.shape
    ny, nx = NY - 3, NX - 3
    blocks, weights, x, y = _check_layout(ny, nx)
    shape = (G, 3, ny + 1, nx + 1, 2)
    positions = np.empty(shape)
    positions[..., 0] = origins[:, 0, None, None, None] + x * spacing
    positions[..., 1] = origins[:, 1, None, None, None] + y * spacing
    starts = np.full(shape, np.nan)
    estimates = np.full(shape, np.nan)
    if G:
        layout = (G, 3 * (ny + 1), nx + 1, 2)
        offsets = np.zeros((G, 2), np.int64)
        cubic_blocks(offsets, blocks, weights, S, starts.reshape(layout))
        cubic_blocks(offsets, blocks, weights, P, estimates.reshape(layout))
    return positions, starts, estimates


def _solve(
    view: ViewArgs,
    rig: RigArgs,
    positions: FloatArray,
    starts: FloatArray,
    pixels_only: bool = False,
    estimates: FloatArray | None = None,
    with_mirror_error: bool = False,
) -> tuple[FloatArray, FloatArray, FloatArray, npt.NDArray[np.bool_], FloatArray | None]:
    """:func:`omnicam._kernels.solve_view_points` over arrays of positions (..., 2): the mirror
    points, pixels, margins and ok of each, and the errors (..., 2) of check points'
    ``estimates`` (pixel error, mirror error) (None without estimates)."""
    shape = positions.shape[:-1]
    n = int(np.prod(shape))
    ok = np.zeros(shape, np.bool_)
    S = np.empty(shape + (2,))
    P = np.empty(shape + (2,))
    margins = np.empty(shape + (3,))
    checks = estimates is not None
    if estimates is None:
        estimates = errors = np.empty((0, 2))
    else:
        errors = np.empty(shape + (2,))
    points = ViewPoints(
        positions.reshape(-1, 2),
        starts.reshape(-1, 2),
        estimates.reshape(-1, 2),
        pixels_only,
        with_mirror_error,
    )
    out = Solutions(
        ok.reshape(-1),
        S.reshape(-1, 2),
        P.reshape(-1, 2),
        margins.reshape(-1, 3),
        errors.reshape(-1, 2),
    )
    run_chunks(_kernels.solve_view_points, n, view, rig, points, out, min_chunk=32)
    return S, P, margins, ok, errors if checks else None


def _build_table(
    view: ViewArgs,
    rig: RigArgs,
    size: Size,
    step: int,
    mode: int,
    outputs: _Outputs,
    stats: _IntArray,
) -> None:
    """The phases of a table (section comment of :mod:`omnicam._kernels`), writing ``outputs``.

    ``stats`` (9,) int64 receives: nodes and check points solved, coarse cells seen / unseen /
    edge / refined, refined sub-cells left to exact pixels, pixels solved exactly, entries
    written unseen.
    """
    notice_if_cold(_kernels.solve_view_points, _kernels.fill_rows)
    w, h = size
    ny, nx = (h + step - 1) // step, (w + step - 1) // step
    half_tol = 0.5 * TOLERANCE
    coarse = _GridStack(view, rig, np.zeros((1, 2)), float(step), (ny, nx))
    cls = coarse.classify(view, size, half_tol, False)[0]
    # refine the failing cells on grids FINE times finer (own nodes, checks and classes)
    # C order as every other array the kernels take (np.argwhere's is F: a second signature
    # of each grid kernel, compiled cold and loaded warm)
    cells = np.ascontiguousarray(np.argwhere(cls == _kernels.CELL_BAD), dtype=np.int64)
    refined_index = np.full((ny, nx), -1, np.int64)
    refined_index[cells[:, 0], cells[:, 1]] = np.arange(len(cells))
    fine = _GridStack(
        view,
        rig,
        np.ascontiguousarray(cells[:, ::-1] * step, dtype=np.float64),
        float(step // _kernels.FINE),
        (_kernels.FINE, _kernels.FINE),
        coarse,
        cells,
    )
    fine_cls = fine.classify(view, size, half_tol, True)
    # the pixels: interpolated, unseen, decided at the edge, or pending an exact solution
    # the cubic weights of the node columns per column offset in a cell and in a refined
    # sub-cell, and the panoramas' per-column cos / sin of the azimuth (as _view_direction)
    weights = np.array(_lagrange4(np.arange(step) / step))
    fine_weights = np.array(_lagrange4(np.arange(step // _kernels.FINE) / (step // _kernels.FINE)))
    azimuth = view.az_step * np.arange(w)
    column_cos, column_sin = np.cos(azimuth), np.sin(azimuth)
    pending = np.zeros((h, w), np.bool_)  # bool: numpy's nonzero is ten times faster than on uint8
    row_counts = np.empty((h, 2), np.int64)  # pending and unseen entries per row
    outx, outy, out16, outf16 = outputs
    grids = TableGrids(
        cls,
        refined_index,
        coarse.P[0],
        fine.S,
        fine.P,
        fine_cls,
        column_cos,
        column_sin,
        weights,
        fine_weights,
    )
    out = TableOutputs(mode, outx, outy, out16, outf16, pending, row_counts)
    run_chunks(_kernels.fill_rows, h, view, rig, grids, out, min_chunk=16)
    rows = np.flatnonzero(row_counts[:, 0])
    q = np.flatnonzero(pending[rows])
    index = rows[q // w] * w + q % w
    positions = np.stack([index % w, index // w], axis=1).astype(np.float64)
    n_unseen = int(row_counts[:, 1].sum())
    if len(index):
        # no start of the pixels' own (NaN): Newton from the aligned start
        P = _solve(view, rig, positions, np.full_like(positions, np.nan), pixels_only=True)[1]
        n_unseen += _store_entries(index, P, mode, outputs)
    n_nodes, n_checks = coarse.n_solved()
    f_nodes, f_checks = fine.n_solved()
    stats[0] = n_nodes + f_nodes
    stats[1] = n_checks + f_checks
    stats[2:6] = [
        np.count_nonzero(cls == c)
        for c in (_kernels.CELL_SEEN, _kernels.CELL_UNSEEN, _kernels.CELL_EDGE, _kernels.CELL_BAD)
    ]
    stats[6] = np.count_nonzero(fine_cls == _kernels.CELL_BAD)
    stats[7] = len(index)
    stats[8] = n_unseen


def _store_entries(index: _IntArray, P: FloatArray, mode: int, outputs: _Outputs) -> int:
    """Write the solved entries ``P`` (n, 2) of the pixels ``index`` (flat) into ``outputs``
    as fill_rows' ``_row_store`` does: NaN as ``UNSEEN``, float32 maps (mode 0) or
    ``cv2.convertMaps``' CV_16SC2 fixed point (mode 1). Returns how many were unseen."""
    outx, outy, out16, outf16 = outputs
    unseen = np.isnan(P).any(axis=1)
    fx = np.where(unseen, UNSEEN, P[:, 0]).astype(np.float32)
    fy = np.where(unseen, UNSEEN, P[:, 1]).astype(np.float32)
    if mode == 0:
        outx.reshape(-1)[index] = fx
        outy.reshape(-1)[index] = fy
        return int(np.count_nonzero(unseen))
    if len(index):
        # convertMaps' cvRound(x * 32) overflows int32 beyond 2^26 px; 2^25 px saturates the
        # int16 alike and, as every float32 that large, has no fraction (as _kernels' limit)
        fx, fy = (np.clip(f, -(2.0**25), 2.0**25).reshape(1, -1) for f in (fx, fy))
        pairs, fractions = cv2.convertMaps(fx, fy, cv2.CV_16SC2)
        out16.reshape(-1, 2)[index] = pairs.reshape(-1, 2)
        outf16.reshape(-1)[index] = fractions.reshape(-1)
    return int(np.count_nonzero(unseen))
