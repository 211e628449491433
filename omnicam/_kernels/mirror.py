"""The mirror seam: the only functions through which a kernel reaches the mirror's surface.

A mirror is a surface of revolution about the mirror frame's Z axis, ``Z = f(rho)`` with
``rho = sqrt(X^2 + Y^2)``, convex, seen from below (docs/conventions.md). The kernels take it as
one float64 parameter array ``mp`` (``mirror.kernel_params()``):

====  =============================================================================
mp    meaning
====  =============================================================================
0     kind: ``KIND_HYPERBOLOID`` or ``KIND_ASPHERE``
1     ``rim_radius``: the physical mirror is the cap ``rho <= rim_radius``
2     length scale of the mirror: Newton tolerances are relative to it
3..   the kind's own parameters (below)
====  =============================================================================

* hyperboloid (eq. 1): ``mp[3:5] = a, b``; ``Z = b sqrt(1 + rho^2 / a^2)``; scale ``a + b``.
* even asphere (:class:`omnicam.asphere.AsphericMirror`): ``mp[3:7] = R, k, vertex_z, rho_n``,
  ``mp[7:]`` the coefficients of ``(rho / rho_n)^4, ^6, ...``;
  ``Z = vertex_z + rho^2 / (R (1 + sqrt(1 - (1 + k) rho^2 / R^2))) + sum alpha_j
  (rho / rho_n)^(2 j + 4)``; scale ``2 rim_radius``.

The seam (every other kernel calls only these for the surface):

* :func:`sheet_z`, :func:`sheet_slopes`, :func:`sheet_derivs`: height, first and second
  derivatives of ``f`` over ``(X, Y)`` (the unnormalised normal is ``(f_X, f_Y, -1)``, eq. 14);
  defined past the rim where the formula is (the views solve on the extended sheet).
* :func:`normal_at`: ``(f_X, f_Y)`` at a point of the sheet given with its height.
* :func:`line_hit`: first hit ``k > 0`` of the line ``F + k V`` with the sheet (eqs. 8-12).
* :func:`start_hit`: a Newton start for the reflection point of a scene point or direction.
* :func:`inside_body`, :func:`body_margin`: the mirror's solid body, and a signed smooth
  margin to it (positive outside).

A new surface of revolution is one more kind in this module (and its class in Python): the
ray tracer, forward projection and table kernels do not change. The hyperboloid's branches
are the expressions the kernels had inline, operation for operation (the remap tables stay
byte-identical).
"""

from __future__ import annotations

import math

from .._jit import kernel

_NAN = math.nan

KIND_HYPERBOLOID = 0.0
KIND_ASPHERE = 1.0
MP_KIND, MP_RIM, MP_SCALE = 0, 1, 2  # the header every kind shares


@kernel
def _hyperboloid_hit_k(Fx, Fy, Fz, Vx, Vy, Vz, ia2, ib2):
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
def rim_radius(mp):
    """Radius of the rim circle."""
    return mp[MP_RIM]


@kernel
def length_scale(mp):
    """The mirror's length scale (Newton's tolerances are relative to it)."""
    return mp[MP_SCALE]


@kernel
def sheet_z(mp, s1, s2):
    """Height ``f(s1, s2)`` of the sheet (eq. 13 for the hyperboloid)."""
    a = mp[3]
    b = mp[4]
    return b * math.sqrt(1.0 + (s1 * s1 + s2 * s2) / (a * a))


@kernel
def sheet_slopes(mp, s1, s2):
    """``(z, f_X, f_Y)`` at ``(s1, s2)``: the height and the unnormalised normal
    ``(f_X, f_Y, -1)`` (eq. 14), which points down and out of the mirror."""
    a = mp[3]
    b = mp[4]
    a2 = a * a
    b2 = b * b
    z = b * math.sqrt(1.0 + (s1 * s1 + s2 * s2) / a2)
    return z, b2 * s1 / (a2 * z), b2 * s2 / (a2 * z)


@kernel
def normal_at(mp, Px, Py, Pz):
    """``(f_X, f_Y)`` of the normal ``(f_X, f_Y, -1)`` (eq. 14) at a point P of the sheet."""
    a = mp[3]
    b = mp[4]
    b2a2 = b * b * (1.0 / (a * a))
    return b2a2 * Px / Pz, b2a2 * Py / Pz


@kernel
def sheet_derivs(mp, s1, s2):
    """``(z, f_X, f_Y, f_XX, f_YY, f_XY)`` at ``(s1, s2)``: what Newton on Fermat's path
    length needs (the tangents ``(1, 0, f_X)``, ``(0, 1, f_Y)`` and their derivatives)."""
    a = mp[3]
    b = mp[4]
    a2 = a * a
    b2 = b * b
    z = b * math.sqrt(1.0 + (s1 * s1 + s2 * s2) / a2)
    fx = b2 * s1 / (a2 * z)
    fy = b2 * s2 / (a2 * z)
    kk = b2 / (a2 * z)
    fxx = kk * (1.0 - s1 * fx / z)
    fyy = kk * (1.0 - s2 * fy / z)
    fxy = -kk * s1 * fy / z
    return z, fx, fy, fxx, fyy, fxy


@kernel
def line_hit(mp, Fx, Fy, Fz, Vx, Vy, Vz):
    """First ``k > 0`` where ``F + k V`` meets the sheet from outside or inside (eqs. 8-11),
    NaN if none; the caller checks the rim and the side (eq. 12)."""
    a = mp[3]
    b = mp[4]
    return _hyperboloid_hit_k(Fx, Fy, Fz, Vx, Vy, Vz, 1.0 / (a * a), 1.0 / (b * b))


@kernel
def start_hit(mp, Cz, Xx, Xy, Xz, at_infinity):
    """Newton's start for the reflection point towards X: ``(s1, s2)``, NaN if none.

    Where the line from the mirror's inner viewpoint towards X (or along the direction X)
    leaves the sheet: for the hyperboloid the outer focus ``(0, 0, c)``, exact for the aligned
    rig (eqs. 2-5). ``Cz`` (the camera centre's height) is unused by the hyperboloid.
    """
    a = mp[3]
    b = mp[4]
    a2 = a * a
    b2 = b * b
    c = math.sqrt(a2 + b2)
    if at_infinity:
        Wx, Wy, Wz = Xx, Xy, Xz
    else:
        Wx, Wy, Wz = Xx, Xy, Xz - c
    k = _hyperboloid_hit_k(0.0, 0.0, c, Wx, Wy, Wz, 1.0 / a2, 1.0 / b2)
    return k * Wx, k * Wy


@kernel
def inside_body(mp, Xx, Xy, Xz):
    """Whether a finite point lies inside the mirror's body (above the sheet, eq. 1)."""
    a = mp[3]
    b = mp[4]
    return Xz > 0.0 and (Xx * Xx + Xy * Xy) / (a * a) - Xz * Xz / (b * b) + 1.0 < 0.0


@kernel
def body_margin(mp, Xx, Xy, Xz):
    """A smooth signed margin of a finite point to the mirror's body: positive outside,
    negative inside, of order 1 one mirror size away."""
    a = mp[3]
    b = mp[4]
    rx = (Xx * Xx + Xy * Xy) / (a * a)
    rz = Xz * Xz / (b * b)
    return (rx - rz + 1.0) / (rx + rz + 1.0)
