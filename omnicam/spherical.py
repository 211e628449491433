"""360 output: the full-sphere equirectangular view 360 viewers take.

:func:`equirect_view`: a 2:1 equirectangular image of the whole sphere in the mirror frame,
forward (azimuth 0, the mirror's +X) at the centre column, azimuth turning right as the column
grows (as omnicam's panoramas), latitude of pixel row ``i`` ``90 - 180 (i + 0.5) / H`` degrees
and longitude of column ``j`` ``360 (j + 0.5) / W - 180`` (pixel centres, as 360 players
sample). The band the mirror sees sits at its true elevations; the rest is the border colour.
The metadata that makes players show it as 360 is :mod:`omnicam.formats.spherical_metadata`'s.
"""

from __future__ import annotations

import math

import numpy as np

from .views import PanoramaView

__all__ = ["equirect_view"]


def equirect_view(size, depth=None) -> PanoramaView:
    """A :class:`PanoramaView` of the full sphere in the equirectangular layout above.

    Parameters
    ----------
    size : (int, int)
        ``(W, H)`` with ``W = 2 H``.
    depth : float or None
        As for panoramas.
    """
    try:
        w, h = (int(v) for v in size)
    except (TypeError, ValueError):
        raise ValueError(f"size must be (width, height), got {size!r}") from None
    if w != 2 * h or h < 2:
        raise ValueError(f"size of an equirectangular 360 image must be 2:1 (W = 2 H), got {w}x{h}")
    half_row = 90.0 / h
    # panorama column j looks at azimuth -360 j / W in its frame; the mirror azimuth is
    # -(360 (j + 0.5) / W - 180) = that + delta, i.e. R^T = Rz(delta)
    delta = math.radians(180.0 - 180.0 / w)
    c, s = math.cos(delta), math.sin(delta)
    Rz = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
    return PanoramaView(
        (w, h),
        elevation_range=(-90.0 + half_row, 90.0 - half_row),
        projection="equirectangular",
        R=Rz.T,
        depth=depth,
    )
