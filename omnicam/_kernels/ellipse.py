"""The orthogonal distances of points to an ellipse: each point's foot by Newton's method.

:func:`ellipse_feet` is the per-point loop of :func:`omnicam.calibration.ellipse.
orthogonal_residuals` (which validates, and documents the equations): the ellipse ``x(t) =
S u(t)``, ``u = (cos t, sin t)``, about the origin, ``S`` symmetric; each point ``q``'s foot
parameter ``t`` solves ``(x(t) - q) . x'(t) = 0`` by safeguarded Newton steps from the angle of
``S^-1 q``.
"""

from __future__ import annotations

import math

from .._jit import kernel


@kernel
def ellipse_feet(q, Si, S, iters, d, u, normal):  # pragma: no cover - compiled
    """Signed distances ``d`` (N,), feet ``u = (cos t, sin t)`` (N, 2) and outer unit normals
    ``normal`` (N, 2) of the points ``q`` (N, 2) (relative to the centre) to ``S u(t)``;
    ``Si`` is ``S^-1``; at most ``iters`` Newton steps per point, each clipped to 0.5 rad,
    until one is below 1e-13."""
    s11, s12, s22 = S[0, 0], S[0, 1], S[1, 1]
    for i in range(q.shape[0]):
        qx, qy = q[i, 0], q[i, 1]
        t = math.atan2(Si[1, 0] * qx + Si[1, 1] * qy, Si[0, 0] * qx + Si[0, 1] * qy)
        for _ in range(iters):
            c, s = math.cos(t), math.sin(t)
            xx, xy = s11 * c + s12 * s, s12 * c + s22 * s  # S u
            dx, dy = -s11 * s + s12 * c, -s12 * s + s22 * c  # S u'
            ex, ey = xx - qx, xy - qy
            f = ex * dx + ey * dy
            tt = dx * dx + dy * dy
            a = tt - (ex * xx + ey * xy)  # x'' = -S u
            b = 0.2 * tt
            fp = a if (a >= b or a != a) else b
            step = f / fp
            t -= 0.5 if step > 0.5 else (-0.5 if step < -0.5 else step)
            if abs(step) < 1e-13:
                break
        c, s = math.cos(t), math.sin(t)
        fx, fy = s11 * c + s12 * s, s12 * c + s22 * s
        dx, dy = -s11 * s + s12 * c, -s12 * s + s22 * c
        nrm = math.hypot(dx, dy)
        nx, ny = dy / nrm, -dx / nrm  # outward for det S > 0
        d[i] = (qx - fx) * nx + (qy - fy) * ny
        u[i, 0] = c
        u[i, 1] = s
        normal[i, 0] = nx
        normal[i, 1] = ny
