"""numba kernels of the per-point work, one concern per module.

* :mod:`~omnicam._kernels.mirror` -- **the seam**: the mirror's surface (height, slopes,
  curvature, ray/surface intersection, body) as functions of its parameter tuple ``mp``. Every
  other kernel reaches the mirror through it; a new surface of revolution is added there.
* :mod:`~omnicam._kernels.raytrace` -- pixel -> reflected ray (``trace_rays``, eqs. 6-19),
  the reflection-point Newton on Fermat's path length and ``project_points``.
* :mod:`~omnicam._kernels.pinhole` -- mirror frame -> camera frame -> pixel with OpenCV's
  distortion model.
* :mod:`~omnicam._kernels.tables` -- view tables: output directions, exact solutions at grid
  nodes and check points (``solve_view_points``), cubic interpolation (``cubic_blocks``),
  cell classes (``classify_cells``).
* :mod:`~omnicam._kernels.fill` -- the table's entries from the classified cells
  (``fill_rows``), float or CV_16SC2 fixed point.
* :mod:`~omnicam._kernels.ellipse` -- points' orthogonal distances to an ellipse
  (``ellipse_feet``), for the rim's and the reflection's fits.

Only arithmetic on prepared float64 arrays lives here; validation, shapes and the public API
are in :mod:`omnicam.raytrace`, :mod:`omnicam.views` and :mod:`omnicam.camera`. The slow,
obviously correct references are :mod:`omnicam.mirror`, :mod:`omnicam.asphere` and
``tests/naive.py``. numba's cache checks a kernel against its own file only, so
:func:`omnicam._jit.kernel` stamps every kernel of this package with all of its files: an edit
to the seam recompiles the kernels that inline it.
"""

from .fill import TableGrids, TableOutputs, fill_rows
from .raytrace import NEWTON_TOL_REL, project_points, trace_rays
from .tables import (
    CELL_BAD,
    CELL_EDGE,
    CELL_RIM,
    CELL_SEEN,
    CELL_UNSEEN,
    CHECK_CENTRE,
    CHECK_HORIZONTAL_EDGE,
    CHECK_VERTICAL_EDGE,
    FINE,
    GridMargins,
    RigArgs,
    Solutions,
    ViewArgs,
    ViewPoints,
    classify_cells,
    cubic_blocks,
    solve_view_points,
)

__all__ = [
    "CELL_BAD",
    "CELL_EDGE",
    "CELL_RIM",
    "CELL_SEEN",
    "CELL_UNSEEN",
    "CHECK_CENTRE",
    "CHECK_HORIZONTAL_EDGE",
    "CHECK_VERTICAL_EDGE",
    "FINE",
    "NEWTON_TOL_REL",
    "GridMargins",
    "RigArgs",
    "Solutions",
    "TableGrids",
    "TableOutputs",
    "ViewArgs",
    "ViewPoints",
    "classify_cells",
    "cubic_blocks",
    "fill_rows",
    "project_points",
    "solve_view_points",
    "trace_rays",
]
