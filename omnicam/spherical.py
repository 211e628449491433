"""360 output: the full-sphere equirectangular view 360 viewers take.

:func:`equirect_view`: a 2:1 equirectangular image of the whole sphere in the mirror frame,
the camera's forward direction at the centre column unless a ``yaw`` is given (as for
omnicam's panoramas, :func:`omnicam.views.camera_forward_yaw`), azimuth turning right as the
column grows, latitude of pixel row ``i`` ``90 - 180 (i + 0.5) / H`` degrees and longitude of
column ``j`` ``360 (j + 0.5) / W - 180`` from the centre (pixel centres, as 360 players
sample). The band the mirror sees sits at its true elevations; the rest is the border colour.
The metadata that makes players show it as 360 is :mod:`omnicam.formats.spherical_metadata`'s.
"""

from __future__ import annotations

from .views import PanoramaView

__all__ = ["equirect_view"]


def equirect_view(size, depth=None, yaw=None) -> PanoramaView:
    """A :class:`PanoramaView` of the full sphere in the equirectangular layout above.

    Parameters
    ----------
    size : (int, int)
        ``(W, H)`` with ``W = 2 H``.
    depth : float or None
        As for panoramas.
    yaw : float or None
        As for panoramas: the centre column looks at azimuth ``-yaw``; None, the camera's
        forward direction.
    """
    try:
        w, h = (int(v) for v in size)
    except (TypeError, ValueError):
        raise ValueError(f"size must be (width, height), got {size!r}") from None
    if w != 2 * h or h < 2:
        raise ValueError(f"size of an equirectangular 360 image must be 2:1 (W = 2 H), got {w}x{h}")
    half_row = 90.0 / h
    # a panorama's column j looks at -yaw - 360 (j - (W - 1) / 2) / W deg: the longitude above
    return PanoramaView(
        (w, h),
        elevation_range=(-90.0 + half_row, 90.0 - half_row),
        projection="equirectangular",
        depth=depth,
        yaw=yaw,
    )
