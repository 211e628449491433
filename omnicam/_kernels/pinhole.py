"""The pinhole camera in the kernels: mirror frame -> camera frame -> pixel (eq. 6 with
OpenCV's distortion model and ``K`` with skew).

``rig`` is :class:`omnicam._kernels.tables.RigArgs`. The numpy side of the same model is
:func:`omnicam.raytrace.to_pixels`.
"""

from __future__ import annotations

import math

from .._jit import kernel

_NAN = math.nan


@kernel(inline="always")
def distort(rig, xn, yn):
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
def camera_frame(rig, s1, s2, z):
    """The mirror point (s1, s2, z) in the camera frame."""
    Rc = rig.R
    tc = rig.t
    xc = Rc[0, 0] * s1 + Rc[0, 1] * s2 + Rc[0, 2] * z + tc[0]
    yc = Rc[1, 0] * s1 + Rc[1, 1] * s2 + Rc[1, 2] * z + tc[1]
    zc = Rc[2, 0] * s1 + Rc[2, 1] * s2 + Rc[2, 2] * z + tc[2]
    return xc, yc, zc


@kernel(inline="always")
def camera_pixel(rig, xc, yc, zc):
    """Pixel of a camera-frame point in front of the camera (eq. 6 with OpenCV's distortion,
    :func:`distort`, then ``K`` with skew): ``(x, y, True)``, or ``(NaN, NaN, False)`` if not
    finite. Inlined in the per-pixel loop of RIM cells (``fill._rim_pixel``); the other
    callers share one compiled copy, :func:`camera_pixel_call`."""
    xn = xc / zc
    yn = yc / zc
    if rig.has_dist:
        xn, yn = distort(rig, xn, yn)
    K = rig.K
    xi = K[0, 0] * xn + K[0, 1] * yn + K[0, 2]
    yi = K[1, 0] * xn + K[1, 1] * yn + K[1, 2]
    if xi == xi and yi == yi:
        return xi, yi, True
    return _NAN, _NAN, False


@kernel
def camera_pixel_call(rig, xc, yc, zc):
    """:func:`camera_pixel` as a function of its own, not inlined: one compiled copy of the
    distortion model for the exact solutions (a call per exact solution costs nothing
    measurable; per pixel of a RIM cell it cost a third of fill_rows)."""
    return camera_pixel(rig, xc, yc, zc)
