"""Remap tables for ``cv2.remap``: panoramas and virtual perspective views (paper section 4.1).

The views in three modules (and the checks they share, :mod:`omnicam.views.checks`):

- :mod:`omnicam.views.api`: the public functions and view specs (``init_panorama_maps``,
  ``init_perspective_maps``, ``PanoramaView``, ``PerspectiveView``, ``rotation_from_ypr``,
  ``K_from_fov``, ``camera_forward_yaw``: a default panorama's centre).
- :mod:`omnicam.views.elevation`: which elevations a panorama covers, what the mirror sees
  (``visible_elevation_range``) and where the default panorama's lower edge is chosen
  (``default_elevation_range``, ``camera_reflection_elevation``, ``LOWER_EDGE_*``).
- :mod:`omnicam.views.grid`: the adaptive grid-table builder (nodes solved exactly, cubic cells
  checked and refined, the calls into the numba kernels).

The conventions (which output pixel looks where) are docs/conventions.md's, section "Views".
"""

from .api import (
    FORWARD_MIN_TILT_DEG,
    R0,
    UNSEEN_WARN_FRACTION,
    K_from_fov,
    PanoramaView,
    PerspectiveView,
    camera_forward_yaw,
    init_panorama_maps,
    init_perspective_maps,
    rotation_from_ypr,
)
from .checks import M1TYPES, PROJECTIONS
from .elevation import (
    CYLINDRICAL_MIN_ELEVATION,
    LOWER_EDGE_ABOVE,
    LOWER_EDGE_FIXED,
    LOWER_EDGE_FLOOR,
    LOWER_EDGE_MIRROR,
    LOWER_EDGE_REFLECTION,
    REFLECTION_MARGIN_PX,
    DefaultElevationRange,
    camera_reflection_elevation,
    default_elevation_range,
    visible_elevation_range,
)
from .grid import CELL_DEGREES, TOLERANCE, UNSEEN

__all__ = [
    "init_panorama_maps",
    "init_perspective_maps",
    "rotation_from_ypr",
    "K_from_fov",
    "visible_elevation_range",
    "default_elevation_range",
    "camera_reflection_elevation",
    "camera_forward_yaw",
    "DefaultElevationRange",
    "PanoramaView",
    "PerspectiveView",
    "UNSEEN",
    "PROJECTIONS",
    "M1TYPES",
    "TOLERANCE",
    "R0",
    "FORWARD_MIN_TILT_DEG",
    "CELL_DEGREES",
    "CYLINDRICAL_MIN_ELEVATION",
    "REFLECTION_MARGIN_PX",
    "UNSEEN_WARN_FRACTION",
    "LOWER_EDGE_REFLECTION",
    "LOWER_EDGE_FIXED",
    "LOWER_EDGE_FLOOR",
    "LOWER_EDGE_ABOVE",
    "LOWER_EDGE_MIRROR",
]
