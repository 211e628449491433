"""The mirror seam: the only functions through which a kernel reaches the mirror's surface.

A mirror is a surface of revolution about the mirror frame's Z axis, ``Z = f(rho)`` with
``rho = sqrt(X^2 + Y^2)``, convex, seen from below (docs/conventions.md). The kernels take it as
one tuple ``mp`` of floats (``mirror.kernel_params()``): a tuple, not an array, because it is
passed by value, where every access to an array argument or record field in the per-pixel
loops costs an atomic reference count. Its length tells the kind (``HYPERBOLOID_SIZE`` or
``ASPHERE_SIZE``): a constant at compile time, so numba compiles each kernel once per kind and
each kind's code carries no branch of the other's (the asphere's branches, inlined into the
hyperboloid's per-pixel loops, made its tables twice as slow).

====  =============================================================================
mp    meaning
====  =============================================================================
0     kind: ``KIND_HYPERBOLOID`` or ``KIND_ASPHERE``
1     ``rim_radius``: the physical mirror is the cap ``rho <= rim_radius``
2     length scale of the mirror: Newton tolerances are relative to it
3..   the kind's own parameters (below)
====  =============================================================================

* hyperboloid (eq. 1): ``mp[3:5] = a, b``; ``Z = b sqrt(1 + rho^2 / a^2)``; scale ``a + b``.
* even asphere (:class:`omnicam.asphere.AsphericMirror`): ``mp[3:8] = R, k, vertex_z, rho_n,
  n``, ``mp[8:8 + n]`` the coefficients of ``(rho / rho_n)^4, ^6, ...`` (``n <= MAX_ALPHA``);
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
HYPERBOLOID_SIZE = 15  # lengths of mp: the kind, known at compile time (see above)
ASPHERE_SIZE = 16
MAX_ALPHA = 8  # polynomial terms of an asphere that fit in ASPHERE_SIZE


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


# -- the even asphere: Z = vertex_z + sag(rho), all in u = rho^2 (smooth on the axis) ---------
A_R, A_K, A_VERTEX_Z, A_RHO_N, A_N_ALPHA, A_ALPHA = 3, 4, 5, 6, 7, 8
HIT_MAX_ITER = 100  # Newton steps of _asphere_hit (monotone, quadratic but for grazing rays)
HIT_TOL_REL = 1e-13  # a step this short times the mirror's scale ends it


@kernel
def _asphere_sag(mp, u):
    """``(sag, d sag / du, d^2 sag / du^2)`` at ``u = rho^2``; NaN past the conic's end.

    Conic: ``w = c u / (1 + q)``, ``q = sqrt(1 - (1 + k) c^2 u)``, ``c = 1 / R``, the root
    through the vertex of ``u - 2 R w + (1 + k) w^2 = 0``, so ``w' = 1 / (2 R q)`` and
    ``w'' = 2 (1 + k) w'^3``; then the terms ``alpha_j t^(j + 2)``, ``t = u / rho_n^2``.
    """
    c = 1.0 / mp[A_R]
    k1 = 1.0 + mp[A_K]
    q2 = 1.0 - k1 * c * c * u
    if not q2 > 0.0:
        return _NAN, _NAN, _NAN
    q = math.sqrt(q2)
    w = c * u / (1.0 + q)
    w1 = 0.5 * c / q
    w2 = 2.0 * k1 * w1 * w1 * w1
    rn2 = mp[A_RHO_N] * mp[A_RHO_N]
    t = u / rn2
    tp = 1.0  # t^(m - 2) of the term alpha t^m, m = j + 2
    for j in range(int(mp[A_N_ALPHA])):
        a = mp[A_ALPHA + j]
        m = j + 2.0
        w += a * tp * t * t
        w1 += a * m * tp * t / rn2
        w2 += a * m * (m - 1.0) * tp / (rn2 * rn2)
        tp *= t
    return w, w1, w2


@kernel
def _asphere_conic_hit(mp, Fx, Fy, Fz, Vx, Vy, Vz):
    """Smallest ``k > 0`` where ``F + k V`` meets the conic part's branch through the vertex
    (``R - (1 + k) w >= 0``), in closed form; NaN if none."""
    R = mp[A_R]
    k1 = 1.0 + mp[A_K]
    wF = Fz - mp[A_VERTEX_Z]
    a = Vx * Vx + Vy * Vy + k1 * Vz * Vz
    b = Fx * Vx + Fy * Vy + k1 * wF * Vz - R * Vz
    c = Fx * Fx + Fy * Fy + k1 * wF * wF - 2.0 * R * wF
    disc = b * b - a * c
    if not disc >= 0.0:
        return _NAN
    q = -(b + math.copysign(math.sqrt(disc), b))
    best = math.inf
    if a != 0.0:
        k = q / a
        if k > 0.0 and R - k1 * (wF + k * Vz) >= 0.0:
            best = k
    if q != 0.0:
        k = c / q
        if k > 0.0 and R - k1 * (wF + k * Vz) >= 0.0 and k < best:
            best = k
    if best == math.inf:
        return _NAN
    return best


@kernel
def _asphere_g(mp, Fx, Fy, Fz, Vx, Vy, Vz, t):
    """``g(t) = Z(t) - f(rho(t))`` along ``F + t V`` and ``dg/dt`` (negative g: below the
    surface); ``-dg/dt`` is ``(N, V)`` with ``N = (f_X, f_Y, -1)``."""
    Px = Fx + t * Vx
    Py = Fy + t * Vy
    s, s1, _s2 = _asphere_sag(mp, Px * Px + Py * Py)
    return Fz + t * Vz - mp[A_VERTEX_Z] - s, Vz - 2.0 * s1 * (Px * Vx + Py * Vy)


@kernel
def _asphere_hit(mp, Fx, Fy, Fz, Vx, Vy, Vz):
    """First ``t > 0`` where ``F + t V`` enters the cap from below; NaN if none.

    Inside the rim's cylinder (``t_in <= t <= t_out``) ``g`` (:func:`_asphere_g`) is concave
    (the surface is convex there), so a ray that enters the cylinder below the surface reaches
    it at the first root of g, where g' > 0 (eq. 12). Newton from any t with g' > 0 lands at or
    left of that root (the tangent lies above g) and then climbs to it monotonically: started
    at the conic's closed-form hit it needs a few steps for the polynomial terms, and grazing
    rays (a double root) still converge. g' <= 0 before the root, or the root past ``t_out``:
    the ray misses the cap.
    """
    rim = mp[MP_RIM]
    A = Vx * Vx + Vy * Vy
    B = Fx * Vx + Fy * Vy
    Cc = Fx * Fx + Fy * Fy - rim * rim
    if A > 0.0:
        disc = B * B - A * Cc
        if not disc >= 0.0:
            return _NAN
        sq = math.sqrt(disc)
        t_in = (-B - sq) / A
        t_out = (-B + sq) / A
    elif Cc <= 0.0:
        t_in = -math.inf
        t_out = math.inf
    else:
        return _NAN
    t0 = max(t_in, 0.0)
    if not t0 < t_out:
        return _NAN
    g0, _gp0 = _asphere_g(mp, Fx, Fy, Fz, Vx, Vy, Vz, t0)
    if not g0 < 0.0:
        return _NAN  # enters the cylinder inside the body (or the camera is in it)
    t = t0
    tc = _asphere_conic_hit(mp, Fx, Fy, Fz, Vx, Vy, Vz)
    if tc > t0 and tc < t_out and _asphere_g(mp, Fx, Fy, Fz, Vx, Vy, Vz, tc)[1] > 0.0:
        t = tc
    tol = HIT_TOL_REL * mp[MP_SCALE]
    for _ in range(HIT_MAX_ITER):
        g, gp = _asphere_g(mp, Fx, Fy, Fz, Vx, Vy, Vz, t)
        if not gp > 0.0:
            return _NAN
        step = -g / gp
        t = max(t + step, t0)
        if t > t_out:
            return _NAN
        if abs(step) <= tol:
            break
    return t


@kernel
def _asphere_start_height(mp, Cz):
    """Height of the paraxial virtual image of an axial camera at ``Cz`` in the convex mirror
    (``1 / s' = 1 / d + 2 / R``, d the camera's distance below the vertex): Newton's start
    looks from there. For a hyperboloid with the camera at its lower focus it is the outer
    focus."""
    R = mp[A_R]
    d = mp[A_VERTEX_Z] - Cz
    if d > 0.0:
        return mp[A_VERTEX_Z] + 1.0 / (1.0 / d + 2.0 / R)
    return mp[A_VERTEX_Z] + 0.5 * R


@kernel(inline="always")
def rim_radius(mp):
    """Radius of the rim circle."""
    return mp[MP_RIM]


@kernel(inline="always")
def length_scale(mp):
    """The mirror's length scale (Newton's tolerances are relative to it)."""
    return mp[MP_SCALE]


@kernel(inline="always")
def sheet_z(mp, s1, s2):
    """Height ``f(s1, s2)`` of the sheet (eq. 13 for the hyperboloid)."""
    if len(mp) == ASPHERE_SIZE:
        return mp[A_VERTEX_Z] + _asphere_sag(mp, s1 * s1 + s2 * s2)[0]
    a = mp[3]
    b = mp[4]
    return b * math.sqrt(1.0 + (s1 * s1 + s2 * s2) / (a * a))


@kernel(inline="always")
def sheet_slopes(mp, s1, s2):
    """``(z, f_X, f_Y)`` at ``(s1, s2)``: the height and the unnormalised normal
    ``(f_X, f_Y, -1)`` (eq. 14), which points down and out of the mirror."""
    if len(mp) == ASPHERE_SIZE:
        w, w1, _w2 = _asphere_sag(mp, s1 * s1 + s2 * s2)
        return mp[A_VERTEX_Z] + w, 2.0 * w1 * s1, 2.0 * w1 * s2
    a = mp[3]
    b = mp[4]
    a2 = a * a
    b2 = b * b
    z = b * math.sqrt(1.0 + (s1 * s1 + s2 * s2) / a2)
    return z, b2 * s1 / (a2 * z), b2 * s2 / (a2 * z)


@kernel
def normal_at(mp, Px, Py, Pz):
    """``(f_X, f_Y)`` of the normal ``(f_X, f_Y, -1)`` (eq. 14) at a point P of the sheet."""
    if len(mp) == ASPHERE_SIZE:
        w1 = _asphere_sag(mp, Px * Px + Py * Py)[1]
        return 2.0 * w1 * Px, 2.0 * w1 * Py
    a = mp[3]
    b = mp[4]
    b2a2 = b * b * (1.0 / (a * a))
    return b2a2 * Px / Pz, b2a2 * Py / Pz


@kernel
def sheet_derivs(mp, s1, s2):
    """``(z, f_X, f_Y, f_XX, f_YY, f_XY)`` at ``(s1, s2)``: what Newton on Fermat's path
    length needs (the tangents ``(1, 0, f_X)``, ``(0, 1, f_Y)`` and their derivatives).
    With ``f = g(u)``, ``u = X^2 + Y^2``: ``f_X = 2 g' X``, ``f_XX = 2 g' + 4 g'' X^2``,
    ``f_XY = 4 g'' X Y`` (no singularity on the axis)."""
    if len(mp) == ASPHERE_SIZE:
        w, w1, w2 = _asphere_sag(mp, s1 * s1 + s2 * s2)
        return (
            mp[A_VERTEX_Z] + w,
            2.0 * w1 * s1,
            2.0 * w1 * s2,
            2.0 * w1 + 4.0 * w2 * s1 * s1,
            2.0 * w1 + 4.0 * w2 * s2 * s2,
            4.0 * w2 * s1 * s2,
        )
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
    NaN if none; the caller checks the rim and the side (eq. 12). The asphere's hit is the
    first entry from below inside the rim (:func:`_asphere_hit`), NaN otherwise."""
    if len(mp) == ASPHERE_SIZE:
        return _asphere_hit(mp, Fx, Fy, Fz, Vx, Vy, Vz)
    a = mp[3]
    b = mp[4]
    return _hyperboloid_hit_k(Fx, Fy, Fz, Vx, Vy, Vz, 1.0 / (a * a), 1.0 / (b * b))


@kernel
def start_hit(mp, Cz, Xx, Xy, Xz, at_infinity):
    """Newton's start for the reflection point towards X: ``(s1, s2)``, NaN if none.

    Where the line from the mirror's inner viewpoint towards X (or along the direction X)
    leaves the sheet: for the hyperboloid the outer focus ``(0, 0, c)``, exact for the aligned
    rig (eqs. 2-5). The asphere's viewpoint is the paraxial image of the camera at height
    ``Cz`` (:func:`_asphere_start_height`), and the line leaves its conic part.
    """
    if len(mp) == ASPHERE_SIZE:
        z0 = _asphere_start_height(mp, Cz)
        if at_infinity:
            Wx, Wy, Wz = Xx, Xy, Xz
        else:
            Wx, Wy, Wz = Xx, Xy, Xz - z0
        k = _asphere_conic_hit(mp, 0.0, 0.0, z0, Wx, Wy, Wz)
        return k * Wx, k * Wy
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


@kernel(inline="always")
def inside_body(mp, Xx, Xy, Xz):
    """Whether a finite point lies inside the mirror's body: above the sheet (eq. 1) for the
    hyperboloid, above the cap inside the rim's cylinder for the asphere."""
    if len(mp) == ASPHERE_SIZE:
        u = Xx * Xx + Xy * Xy
        return u <= mp[MP_RIM] * mp[MP_RIM] and Xz > mp[A_VERTEX_Z] + _asphere_sag(mp, u)[0]
    a = mp[3]
    b = mp[4]
    return Xz > 0.0 and (Xx * Xx + Xy * Xy) / (a * a) - Xz * Xz / (b * b) + 1.0 < 0.0


@kernel
def body_margin(mp, Xx, Xy, Xz):
    """A smooth signed margin of a finite point to the mirror's body: positive outside,
    negative inside, of order 1 one mirror size away. The asphere's: the larger of the height
    below the cap (at the radius clamped to the rim) and the distance outside the rim's
    cylinder, over the rim radius."""
    if len(mp) == ASPHERE_SIZE:
        rim = mp[MP_RIM]
        rho = math.sqrt(Xx * Xx + Xy * Xy)
        rc = min(rho, rim)
        below = mp[A_VERTEX_Z] + _asphere_sag(mp, rc * rc)[0] - Xz
        return max(below, rho - rim) / rim
    a = mp[3]
    b = mp[4]
    rx = (Xx * Xx + Xy * Xy) / (a * a)
    rz = Xz * Xz / (b * b)
    return (rx - rz + 1.0) / (rx + rz + 1.0)
